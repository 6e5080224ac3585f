"""JAX's persistent compilation cache for one test session: the xdist workers, the test subprocesses and (with
.ci/run, which exports the folder for both of its passes) the second pass on another OpenBLAS kernel share it, so a
program compiled once in a session is loaded, not compiled, wherever else it is needed.

A loaded program is the compiled executable itself (jax keys it by the lowered program, the compile options and
the jax/jaxlib versions), so every test computes exactly what it computed before; only the compilation is skipped.
What it saves (measured 2026-11-27 on the shared 2-core machine, load 1.9-3.4): the hybrid-loop files of .ci/run's
second pass 82 -> 42 s of CPU (four programs of the diffrax solves, 38 s of compilation), and 8.6 s of programs
compiled twice within one process (jit caches by the function object, the persistent cache by the program).
OPENBLAS_CORETYPE is not part of it: XLA's code does not link OpenBLAS; the LAPACK calls it makes (scipy's,
OpenBLAS) are resolved when the program runs, so the second pass still runs them on its own kernel.

Without JAX_COMPILATION_CACHE_DIR in the environment the first process of the session (the xdist controller, or the
only process) makes a fresh folder, exports it to the workers and subprocesses it starts, and removes it at the end:
a session never reads another session's programs, so the suite's time on the shared machine is the time a clean
checkout takes. The session's equinox checks are the CLI's (EQX_ON_ERROR=nan, dynamics/backends/xla_options.py
`checks_without_callbacks`): with equinox's default the segment solves hold host callbacks, which jax never keeps.
Every program the session compiles is kept, however short its compilation (jax's default keeps only
those of 1 s or more, which on a loaded machine is some and on a quiet one others): a program built again in the same
process (the sensitivity pass's tools are built per set of read-out columns, and each builds the same event and reset
functions; jit caches by the function object) and the small ones every worker and subprocess compiles again are
loaded; only their tracing is paid again.
"""
from __future__ import annotations

import os
import shutil
import sys
import tempfile

VARIABLE = "JAX_COMPILATION_CACHE_DIR"
#: jax keeps only programs that took at least this long to compile (its default 1 s); the session keeps every one
MIN_TIME = "JAX_PERSISTENT_CACHE_MIN_COMPILE_TIME_SECS"

#: the folder this process made (and removes at the end), None when it was given one
_OWN: str | None = None


def share() -> None:
    """Point this process (and the processes it starts) at the session's cache folder, made here if none is set."""
    global _OWN
    if not os.environ.get(VARIABLE):
        _OWN = tempfile.mkdtemp(prefix="mechsim-tests-jax-")
        os.environ[VARIABLE] = _OWN
    os.environ.setdefault(MIN_TIME, "0")
    # equinox's checks as in mechsim's CLI, so that the diffrax solves are kept too (before equinox is imported)
    from mechsim.dynamics.backends.xla_options import checks_without_callbacks
    checks_without_callbacks()
    if "jax" in sys.modules:        # jax reads the variables at import; a process that imported it already
        sys.modules["jax"].config.update("jax_compilation_cache_dir", os.environ[VARIABLE])
        sys.modules["jax"].config.update("jax_persistent_cache_min_compile_time_secs", float(os.environ[MIN_TIME]))


def remove() -> None:
    """Remove the folder if this process made it."""
    if _OWN is not None:
        shutil.rmtree(_OWN, ignore_errors=True)
