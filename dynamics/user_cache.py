"""The user's cache folder for mechsim: results a later process may reuse (compiled callbacks, converted
quantities). $MECHSIM_CACHE_DIR, else platformdirs' user cache folder for "mechsim" (~/.cache/mechsim on Linux).
Correctness never depends on what is there: everything in it is rebuilt when missing."""
from __future__ import annotations

import os
from pathlib import Path


def cache_dir() -> Path:
    env = os.environ.get("MECHSIM_CACHE_DIR")
    if env:
        return Path(env)
    from platformdirs import user_cache_dir
    return Path(user_cache_dir("mechsim", appauthor=False))
