"""Traced programs kept on disk (`jax.export`), so that a later process skips tracing them.

A compiled JAX program is made in two stages: tracing the Python into a jaxpr and lowering it to StableHLO, then
XLA's compilation. JAX's persistent compilation cache (dynamics/user_cache.py `use_for_jax`) keeps the second
across processes, but it is keyed by the lowered program, so every process still traced it: about a second for
the compiled diffrax run and two for the sensitivity pass's solve and event rule, all Python. Here the lowered
program itself is kept: `jax.export` serialises it into the user's cache folder, a later process deserialises it
and lowers that (a tenth of a second), and XLA's cache supplies the compiled code (docs/diffrax.md, 'Compilation').

Every process compiles the program from its exported form, the one that exported it too, so every process runs
the same program. The disk key adds to the process's key (dynamics/programs.py: kind, the model's structure,
the options that shape the program) what one process takes for granted: mechsim's code
(`user_cache.code_fingerprint`), the versions of the libraries traced in, equinox's error mode and the example
arguments' shapes and types. What tracing records on the host beside the program (the compiled run's output
layout) is kept with it (`Record`). equinox's checks are NaN-returning while a program is traced, in the CLI and
in a library process alike (`xla_options.library_checks_without_callbacks`); a program that cannot be exported all
the same (host callbacks: a user's EQX_ON_ERROR=raise) or a key that names an object by its address is compiled as
before. The folder
never decides a result: a file that is missing, unreadable or corrupt is traced again and written anew.

One process at a time traces and compiles a given program (a lock file per program in the cache's `locks` folder,
`_one_at_a_time`): the workers of a sweep's pool on a fresh machine, or two commands started together, would
otherwise each trace and compile the same program at once, every worker paying the seconds that one pays; the
others wait and load what it kept.
"""
from __future__ import annotations

import hashlib
import json
import time
from contextlib import contextmanager
from importlib import metadata
from typing import Callable, Protocol

import numpy as np

#: libraries whose code is traced into mechsim's programs
LIBRARIES = ("jax", "jaxlib", "diffrax", "equinox", "lineax", "optimistix")
#: the layout of a kept file: one JSON line (what tracing recorded on the host), then the serialised program
FORMAT = 1
#: seconds a process waits for another that traces and compiles the same program (that takes seconds); a holder
#: still busy after this is not waited for: the program is traced and compiled here too, as without the lock
WAIT_S = 120.0
#: a program that could not be exported (`compile_ahead`) leaves a mark of this name beside its lock: no process
#: waits for it again
UNKEPT = ".unkept"


class Record(Protocol):
    """What tracing records on the host beside the program: read after tracing, restored instead of tracing."""

    def recorded(self): ...          # JSON-able

    def restore(self, value) -> None: ...


def _versions() -> tuple:
    out = []
    for name in LIBRARIES:
        try:
            out.append((name, metadata.version(name)))
        except metadata.PackageNotFoundError:
            out.append((name, None))
    return tuple(out)


def disk_name(kind: str, key, example: tuple) -> str | None:
    """The file name a program of `kind` under `key`, traced for `example`'s shapes, is kept under; None where
    `key` holds an object's address (not the same object in another process)."""
    import jax
    from mechsim.dynamics.backends.xla_options import checks_mode
    from mechsim.dynamics.user_cache import code_fingerprint
    avals = tuple((tuple(np.shape(x)), str(x.dtype if hasattr(x, "dtype") else np.result_type(x)), type(x).__name__)
                  for x in jax.tree_util.tree_leaves(example))
    text = repr((FORMAT, kind, key, avals, code_fingerprint(), _versions(), checks_mode(),
                 bool(jax.config.jax_enable_x64)))
    if " at 0x" in text:
        return None
    return f"{kind}-{hashlib.sha256(text.encode()).hexdigest()[:32]}"


def _folder():
    from mechsim.dynamics.user_cache import cache_dir
    return cache_dir() / "traced"


def _locks():
    """Where the lock files and the unkept marks are (apart from the programs: the folder above holds programs
    only)."""
    from mechsim.dynamics.user_cache import cache_dir
    return cache_dir() / "locks"


def _load(name: str, record: Record | None):
    """The kept program `name` (its record restored), or None where there is none that can be read."""
    from jax import export
    try:
        data = (_folder() / name).read_bytes()
        head, _, body = data.partition(b"\n")
        recorded = json.loads(head)["recorded"]
        exported = export.deserialize(bytearray(body))
        if record is not None:
            record.restore(recorded)
    except Exception:       # noqa: BLE001  missing, truncated, written by another version, or a record that does
        return None         # not read back: traced again
    return exported


def _store(name: str, body: bytes, record: Record | None) -> None:
    """Keep the serialised program (written whole, then renamed: a reader never sees part of a file); a folder that
    cannot be written only costs the tracing in the next process."""
    from mechsim.dynamics.user_cache import write_atomically
    head = json.dumps({"format": FORMAT, "recorded": record.recorded() if record is not None else None})
    write_atomically(_folder() / name, head.encode() + b"\n" + body)


@contextmanager
def _one_at_a_time(name: str):
    """Held while this process traces, keeps and compiles program `name`: another process that needs it meanwhile
    waits here (up to WAIT_S), then loads what this one kept, the traced program from the folder and the compiled
    one from JAX's persistent cache. An advisory lock (flock) on a file per program, released by the system however
    its holder ends; without fcntl or where the folder cannot be written, nothing is waited for."""
    try:
        import fcntl
        folder = _locks()
        folder.mkdir(parents=True, exist_ok=True)
        handle = open(folder / f"{name}.lock", "a")
    except (ImportError, OSError):
        yield
        return
    with handle:
        deadline, held = time.monotonic() + WAIT_S, False
        while not held:
            try:
                fcntl.flock(handle, fcntl.LOCK_EX | fcntl.LOCK_NB)
                held = True
            except BlockingIOError:
                if time.monotonic() > deadline or (folder / f"{name}{UNKEPT}").exists():
                    break
                time.sleep(0.05)
            except OSError:         # a file system without flock
                break
        yield


def _compiled(exported, example: tuple):
    import jax
    return jax.jit(exported.call).lower(*example).compile()


def compile_ahead(kind: str, key, make: Callable, example: tuple, record: Record | None = None):
    """`make().lower(*example).compile()` (make: the jitted function), from the program kept on disk under
    (kind, key) where there is one: then `make` is not called and nothing is traced (nor lambdified: the model's
    jax functions are built when first traced, dynamics/jax_model.py). Else traced, exported, compiled and kept,
    one process at a time (`_one_at_a_time`: the file is written once the compiled program is in JAX's cache, so a
    process that finds it compiles nothing). key None: not kept (compiled as it is)."""
    from jax import export
    name = disk_name(kind, key, example) if key is not None else None
    if name is None:
        return make().lower(*example).compile()
    exported = _load(name, record)
    if exported is not None:
        return _compiled(exported, example)
    from mechsim.dynamics.backends.xla_options import library_checks_without_callbacks
    with _one_at_a_time(name):
        exported = _load(name, record)          # kept by a process this one waited for
        if exported is not None:
            return _compiled(exported, example)
        jitted = make()
        try:
            with library_checks_without_callbacks():    # traced here, under the mode its name says (`disk_name`)
                exported = export.export(jitted)(*example)
            body = bytes(exported.serialize())
        except (ValueError, NotImplementedError):   # what jax.export refuses (host callbacks): compiled as it is,
            from mechsim.dynamics.user_cache import write_atomically    # and no process waits for it again
            write_atomically(_locks() / f"{name}{UNKEPT}", b"")
        else:
            fn = _compiled(exported, example)
            _store(name, body, record)
            return fn
    return jitted.lower(*example).compile()
