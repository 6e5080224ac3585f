"""Write an output folder atomically: everything goes to a temporary sibling, then one rename.

A reader never sees a half-written folder; an existing folder is replaced only with `force`; on any error
(or Ctrl-C) the temporary folder is removed and the old one is left as it was.
"""
from __future__ import annotations

import shutil
import tempfile
from contextlib import contextmanager
from pathlib import Path
from typing import Iterator

import numpy as np

from mechsim.scenarios.units import ScenarioError


def json_default(obj):
    """json.dumps fallback for numpy scalars/arrays and anything else printable."""
    if isinstance(obj, (np.floating, np.integer, np.bool_)):
        return obj.item()
    if isinstance(obj, np.ndarray):
        return obj.tolist()
    return str(obj)


@contextmanager
def atomic_folder(out_dir: Path, force: bool = False) -> Iterator[Path]:
    """Yield a temporary folder to fill; on success it replaces `out_dir` in one rename."""
    out_dir = Path(out_dir)
    if out_dir.exists() and not force:
        raise ScenarioError("--out", f"{out_dir} exists; pass --force to replace it")
    out_dir.parent.mkdir(parents=True, exist_ok=True)
    tmp = Path(tempfile.mkdtemp(prefix=f".{out_dir.name}.", dir=out_dir.parent))
    try:
        yield tmp
        if out_dir.exists():
            trash = out_dir.with_name(f".{out_dir.name}.old")
            shutil.rmtree(trash, ignore_errors=True)
            out_dir.rename(trash)
            tmp.rename(out_dir)
            shutil.rmtree(trash)
        else:
            tmp.rename(out_dir)
    except BaseException:
        shutil.rmtree(tmp, ignore_errors=True)
        raise
