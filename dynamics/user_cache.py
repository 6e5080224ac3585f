"""The user's cache folder for mechsim: results a later process may reuse (compiled callbacks, converted
quantities). $MECHSIM_CACHE_DIR, else platformdirs' user cache folder for "mechsim" (~/.cache/mechsim on Linux).
Correctness never depends on what is there: everything in it is rebuilt when missing."""
from __future__ import annotations

import hashlib
import os
from functools import lru_cache
from pathlib import Path


def cache_dir() -> Path:
    env = os.environ.get("MECHSIM_CACHE_DIR")
    if env:
        return Path(env)
    from platformdirs import user_cache_dir
    return Path(user_cache_dir("mechsim", appauthor=False))


@lru_cache(maxsize=1)
def code_fingerprint() -> str:
    """A hash of the code that turns a scenario into the expressions (mechanisms/, dynamics/, thermal/): a cached
    derivation or compiled module made by other code is never reused."""
    root = Path(__file__).resolve().parents[1]
    h = hashlib.sha256()
    for folder in ("mechanisms", "dynamics", "thermal"):
        for path in sorted((root / folder).rglob("*.py")):
            h.update(path.relative_to(root).as_posix().encode())
            h.update(path.read_bytes())
    return h.hexdigest()
