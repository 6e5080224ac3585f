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


def write_atomically(path: Path, data: bytes, prefix: str = ".part-") -> bool:
    """Write a cache file whole, then rename it into place (a reader never sees part of it); False where the folder
    cannot be written (the cache is an optimisation: the caller goes on without it). The temporary file is named
    before it is made, inside the block that removes it: a Ctrl-C just after it was made leaves nothing behind."""
    tmp = path.parent / f"{prefix}{os.getpid()}-{os.urandom(6).hex()}.tmp"
    try:
        path.parent.mkdir(parents=True, exist_ok=True)
        try:
            fd = os.open(tmp, os.O_WRONLY | os.O_CREAT | os.O_EXCL, 0o600)
        except FileExistsError:       # another's (never in practice: a random name): not ours to remove
            tmp = None
            raise
        with os.fdopen(fd, "wb") as f:
            f.write(data)
        os.replace(tmp, path)
    except BaseException as exc:
        if tmp is not None:
            try:
                os.unlink(tmp)
            except OSError:
                pass
        if isinstance(exc, OSError):
            return False
        raise
    return True


@lru_cache(maxsize=None)
def code_fingerprint(folders: tuple[str, ...] = ("mechanisms", "dynamics", "thermal")) -> str:
    """A hash of mechsim's modules in `folders` (default: the code that turns a scenario into the expressions): a
    cached derivation or compiled module made by other code is never reused. "" names the package's own top-level
    modules."""
    root = Path(__file__).resolve().parents[1]
    h = hashlib.sha256()
    for folder in folders:
        for path in sorted((root / folder).rglob("*.py") if folder else root.glob("*.py")):
            h.update(path.relative_to(root).as_posix().encode())
            h.update(path.read_bytes())
    return h.hexdigest()


#: the distributions whose versions a run's numbers depend on (`results_fingerprint`)
COMPUTING_LIBRARIES = ("numpy", "scipy", "sympy", "jax", "jaxlib", "diffrax", "equinox", "optimistix",
                       "scikit-sundae", "numba", "llvmlite", "pandas", "pint")


@lru_cache(maxsize=1)
def results_fingerprint() -> str:
    """A hash of everything a run's numbers depend on besides its scenario: every module a run executes
    (mechanisms/, dynamics/, thermal/, scenarios/ and the top level) and the versions of the libraries that compute
    them (`COMPUTING_LIBRARIES`). A stored result made under another (a sweep's finished case) is not reused."""
    from importlib.metadata import PackageNotFoundError, version

    def installed(name: str) -> str:
        try:
            return version(name)
        except PackageNotFoundError:
            return "absent"
    h = hashlib.sha256(code_fingerprint(("", "mechanisms", "dynamics", "thermal", "scenarios")).encode())
    for name in COMPUTING_LIBRARIES:
        h.update(f"\n{name} {installed(name)}".encode())
    return h.hexdigest()[:16]


#: JAX's setting of the shortest compilation it keeps (its default 1 s)
MIN_COMPILE_TIME = "JAX_PERSISTENT_CACHE_MIN_COMPILE_TIME_SECS"


def use_for_jax(jax) -> str | None:
    """Keep JAX's compiled programs in <cache_dir>/jax across processes (JAX's persistent compilation cache),
    unless a folder is chosen already (JAX_COMPILATION_CACHE_DIR, or `jax_compilation_cache_dir` set by the
    caller), which is then kept. The folder in use, or None when JAX has no such option.

    Why: the compiled diffrax run takes seconds to compile in every new process; a later process loads it and
    skips even the tracing where the traced program is kept too (dynamics/traced.py; docs/diffrax.md
    'Compilation'). JAX keys each program by the lowered program, the compile options and the jax/jaxlib versions,
    so a loaded program is the one a fresh compilation would give; a folder that cannot be written only costs the
    compilation (JAX warns). In mechsim's folder every program is kept, however short its compilation (JAX's
    default keeps those of a second or more: the sensitivity pass's resets and read-outs, compiled in a few tenths
    each, were compiled again by every process), unless JAX_PERSISTENT_CACHE_MIN_COMPILE_TIME_SECS says otherwise."""
    try:
        chosen = jax.config.jax_compilation_cache_dir
    except AttributeError:
        return None
    if chosen:
        return chosen
    folder = str(cache_dir() / "jax")
    jax.config.update("jax_compilation_cache_dir", folder)
    if MIN_COMPILE_TIME not in os.environ:
        jax.config.update("jax_persistent_cache_min_compile_time_secs", 0.0)
    return folder
