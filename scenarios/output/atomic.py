"""Write an output folder atomically: everything goes to a temporary sibling, then one rename.

A reader never sees a half-written folder; an existing folder is replaced only with `force`, and only when
mechsim wrote it (its `.mechsim-output` marker); on any error (or Ctrl-C) the temporary folder is removed and
the old one is left as it was. A run killed outright (kill -9, power cut) leaves its temporary folder behind:
the next run into the same parent removes the ones whose owning process is provably gone (docs/limits.md).
"""
from __future__ import annotations

import json
import os
import re
import shutil
import socket
from contextlib import contextmanager
from pathlib import Path
from typing import Iterator

import numpy as np

from mechsim.scenarios.units import ScenarioError

#: in every output folder mechsim writes: `--force` replaces only folders that hold it
MARKER = ".mechsim-output"
MARKER_TEXT = "This folder was written by mechsim; `mechsim ... --force` may replace it.\n"
#: in every temporary folder while it is being filled: which process on which host owns it
OWNER = ".mechsim-owner"
#: .<name>.tmp-<pid>-<random> (being written) and .<name>.old-<pid>-<random> (an old folder being replaced)
_TEMP_NAME = re.compile(r"^\..+\.(tmp|old)-(\d+)-[A-Za-z0-9_]+$")


def json_default(obj):
    """json.dumps fallback for numpy scalars/arrays and anything else printable."""
    if isinstance(obj, (np.floating, np.integer, np.bool_)):
        return obj.item()
    if isinstance(obj, np.ndarray):
        return obj.tolist()
    return str(obj)


def check_replaceable(out_dir: Path, force: bool) -> None:
    """Refuse (ScenarioError naming --out) unless out_dir is absent, or force is given and mechsim wrote it."""
    out_dir = Path(out_dir)
    if not (out_dir.exists() or out_dir.is_symlink()):
        return
    if not force:
        raise ScenarioError("--out", f"{out_dir} exists; pass --force to replace it")
    if out_dir.is_symlink() or not out_dir.is_dir():
        raise ScenarioError("--out", f"{out_dir} is not a folder mechsim wrote (a {'link' if out_dir.is_symlink() else 'file'}); "
                                     "--force replaces only mechsim's own output folders: choose another --out")
    if not (out_dir / MARKER).is_file() and any(out_dir.iterdir()):
        raise ScenarioError("--out", f"{out_dir} was not written by mechsim (it has no {MARKER} marker), so --force "
                                     "will not replace it: remove it yourself or choose another --out")


def _owner_text() -> str:
    return json.dumps({"pid": os.getpid(), "host": socket.gethostname()})


def _pid_alive(pid: int) -> bool:
    if pid == os.getpid():
        return True
    try:
        os.kill(pid, 0)
    except ProcessLookupError:
        return False
    except (PermissionError, OverflowError, OSError):
        return True                       # another user's process (or we cannot tell): assume alive
    return True


def _stale(path: Path) -> bool:
    """A temporary folder of ours whose owner is provably gone: our name pattern, our owner file naming this
    host, and no process with that id (a folder with no owner file at all must also be empty)."""
    m = _TEMP_NAME.match(path.name)
    if not m or path.is_symlink() or not path.is_dir():
        return False
    pid = int(m.group(2))
    owner = path / OWNER
    if owner.is_file():
        try:
            info = json.loads(owner.read_text())
        except (OSError, ValueError):
            return False
        if not isinstance(info, dict) or info.get("host") != socket.gethostname() or info.get("pid") != pid:
            return False
    elif any(path.iterdir()):
        return False                      # killed before the owner file was written: only an empty folder
    return not _pid_alive(pid)


def remove_stale_temporaries(parent: Path) -> list[Path]:
    """Remove the temporary folders left in `parent` by killed mechsim runs; the folders removed."""
    removed = []
    try:
        entries = list(Path(parent).iterdir())
    except OSError:
        return removed
    for path in entries:
        try:
            if _stale(path):
                shutil.rmtree(path)
                removed.append(path)
        except OSError:
            pass                          # another run cleaned it first, or we may not: leave it
    return removed


def _fresh(out_dir: Path, kind: str) -> Path:
    """The name of a new temporary sibling of out_dir (`_TEMP_NAME`: .<name>.<kind>-<pid>-<random>), not made yet."""
    return out_dir.parent / f".{out_dir.name}.{kind}-{os.getpid()}-{os.urandom(6).hex()}"


@contextmanager
def atomic_folder(out_dir: Path, force: bool = False) -> Iterator[Path]:
    """Yield a temporary folder to fill; on success it replaces `out_dir` in one rename.

    Each temporary folder is named before it is made, inside the block that removes it: a Ctrl-C that lands just
    after a folder was made (the moment its name appears, as a caller watching the parent sees it) still removes
    it, and one during the replacement puts the old folder back. OSError (a read-only or full disk) propagates
    after the temporary folder is removed."""
    out_dir = Path(out_dir)
    check_replaceable(out_dir, force)
    out_dir.parent.mkdir(parents=True, exist_ok=True)
    remove_stale_temporaries(out_dir.parent)
    tmp, trash = _fresh(out_dir, "tmp"), None
    try:
        try:
            tmp.mkdir(mode=0o700)
        except FileExistsError:          # another's (never in practice: a random name): not ours to remove
            tmp = None
            raise
        (tmp / OWNER).write_text(_owner_text())
        yield tmp
        (tmp / MARKER).write_text(MARKER_TEXT)
        (tmp / OWNER).unlink()
        if out_dir.exists():
            check_replaceable(out_dir, force)     # again: it may have appeared while we computed
            trash = _fresh(out_dir, "old")
            trash.mkdir(mode=0o700)
            (trash / OWNER).write_text(_owner_text())
            os.replace(out_dir, trash / "folder")
            tmp.rename(out_dir)
            shutil.rmtree(trash)
        else:
            tmp.rename(out_dir)
    except BaseException:
        if trash is not None:
            old = trash / "folder"
            if old.exists() and not out_dir.exists():      # interrupted between the two renames: the old one back
                os.replace(old, out_dir)
            shutil.rmtree(trash, ignore_errors=True)
        if tmp is not None:
            shutil.rmtree(tmp, ignore_errors=True)
        raise
