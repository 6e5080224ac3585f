"""numba's compiled C callbacks kept as object code and loaded in a later process without importing numba.

Loading a cached numba function costs a later process most of a second (numba's import and its compiler's set-up,
docs/benchmarks.md "A later run's process") for code that is already machine code. So where numba has just compiled
a mode's callbacks or the segment loop's entry points (`compiled_model.compiled_mode`, `native.native_entries`),
their object code is written beside them (`save`); a later process loads it with llvmlite's MCJIT, the engine numba
itself links it with (`load`), and takes the functions' addresses: the same machine code, so the same results to the
bit. The object code calls a few of numba's C helpers (on error paths only: raising, the GIL, freeing) and libm;
they are bound to the same functions numba binds them to, taken from numba's own C extensions (loaded as files,
without the numba package), and the built-in exceptions' symbols to the exception objects, as numba does.

A file made by another numba or llvmlite, for another CPU, or that names a symbol this process cannot bind, is not
loaded (`load` returns None) and numba loads or compiles the functions as before.
"""
from __future__ import annotations

import builtins
import ctypes
import importlib.machinery
import importlib.util
import os
import pickle
import re
import sys
import threading
from functools import lru_cache
from pathlib import Path

from mechsim.dynamics.user_cache import write_atomically

#: bump when the file's layout changes
FORMAT = 1
_LOCK = threading.Lock()
_ENGINES: list = []           # the MCJIT engines holding loaded code (kept for the process's life)
_LOADED: dict = {}            # path -> the addresses loaded from it


@lru_cache(maxsize=1)
def machine_key() -> str:
    """What object code is valid for: the format, numba's and llvmlite's versions (read without importing numba),
    the CPU's name and features (numba compiles for the host's)."""
    from importlib.metadata import version

    import llvmlite.binding as llvm
    return "|".join([str(FORMAT), version("numba"), version("llvmlite"), llvm.get_host_cpu_name(),
                     llvm.get_host_cpu_features().flatten(), sys.platform])


def save(path: Path, functions: dict) -> bool:
    """Write the object code of numba's compiled C callbacks `functions` ({name: numba CFunc}, compiled in this
    process) to `path`, atomically; False (nothing written) where numba keeps no object code for one of them (it
    loaded them from its own cache) or its internals differ."""
    try:
        entries = {}
        for name, fn in functions.items():
            obj = fn._library._get_compiled_object()          # (numba's code library: internal, hence the guard)
            externals = {n for n in re.findall(r'^declare [^@]*@"?([^"(]+)"?\(', fn.inspect_llvm(), re.M)
                         if not n.startswith("llvm.")}         # (LLVM's intrinsics are code, not symbols)
            entries[name] = (fn.native_name, bytes(obj), sorted(externals))
        return write_atomically(Path(path), pickle.dumps({"key": machine_key(), "functions": entries}))
    except Exception:                 # noqa: BLE001  (an object kept is an optimisation; numba's path stands)
        return False


def load(path: Path) -> dict | None:
    """{name: address} of the functions `save` wrote to `path`, loaded once per process; None where the file is
    missing, unreadable, made for another machine key, or names a symbol that cannot be bound."""
    path = Path(path)
    with _LOCK:
        if str(path) in _LOADED:
            return _LOADED[str(path)]
        try:
            data = pickle.loads(path.read_bytes())
        except Exception:             # noqa: BLE001  (missing, partial or foreign: not loaded)
            return None
        if not isinstance(data, dict) or data.get("key") != machine_key():
            return None
        try:
            import llvmlite.binding as llvm
            _bind_helpers()
            functions = data["functions"]
            if not all(_bound(name) for _, _, externals in functions.values() for name in externals):
                return None           # (an unbound symbol would stop the process when the code is linked)
            engine = _engine()
            for _, obj, _ in functions.values():
                engine.add_object_file(llvm.ObjectFileRef.from_data(obj))
            engine.finalize_object()
            got = {name: engine.get_function_address(native) for name, (native, _, _) in functions.items()}
        except Exception:             # noqa: BLE001  (a platform or llvmlite that differs: numba's path stands)
            return None
        if not all(got.values()):
            return None
        _LOADED[str(path)] = got
        return got


def _bound(name: str) -> bool:
    """Whether the symbol `name` is bound, binding it to the process's own where it has one (the Python C API)."""
    import llvmlite.binding as llvm
    if llvm.address_of_symbol(name) is not None:
        return True
    try:
        address = ctypes.cast(getattr(ctypes.CDLL(None), name), ctypes.c_void_p).value
    except Exception:                 # noqa: BLE001  (not in the process, or no process handle on this platform)
        return False
    llvm.add_symbol(name, address)
    return True


def _engine():
    """A fresh MCJIT engine for the host (one per loaded file: an engine links its objects once)."""
    import llvmlite.binding as llvm
    llvm.initialize_native_target()
    llvm.initialize_native_asmprinter()
    machine = llvm.Target.from_default_triple().create_target_machine(codemodel="jitdefault")
    engine = llvm.create_mcjit_compiler(llvm.parse_assembly(""), machine)
    _ENGINES.append((engine, machine))
    return engine


@lru_cache(maxsize=1)
def _bind_helpers() -> None:
    """Bind the symbols numba binds before it links code (numba/core/base.py, externals.py, runtime/nrt.py): its C
    helpers as numba_<name> (libm's functions under their own names, as numba binds them), the runtime's as
    NRT_<name>, None and the built-in exceptions to their objects."""
    import llvmlite.binding as llvm
    helpers, dynfunc, nrt = (_extension(name) for name in ("_helperlib", "_dynfunc", "core.runtime._nrt_python"))
    for table in (helpers.c_helpers, dynfunc.c_helpers):
        for name, address in table.items():
            llvm.add_symbol(f"numba_{name}", address)
    for name, address in helpers.c_helpers.items():
        if llvm.address_of_symbol(name) is not None:       # a C library function (sin, pow, ...): numba's binding
            llvm.add_symbol(name, address)
    for name, address in nrt.c_helpers.items():
        llvm.add_symbol(name if name.startswith("_") else f"NRT_{name}", address)
    llvm.add_symbol("_Py_NoneStruct", id(None))
    for obj in vars(builtins).values():
        if isinstance(obj, type) and issubclass(obj, BaseException):
            llvm.add_symbol(f"PyExc_{obj.__name__}", id(obj))


def _extension(name: str):
    """numba's C extension module `numba.<name>`, loaded from its file without importing the numba package (the
    same module numba imports later, if it does)."""
    full = f"numba.{name}"
    if full in sys.modules:
        return sys.modules[full]
    package = Path(importlib.util.find_spec("numba").origin).parent
    folder, _, stem = name.rpartition(".")
    where = package.joinpath(*folder.split(".")) if folder else package
    path = next(str(where / f) for f in os.listdir(where)
                if f.startswith(stem + ".") and f.endswith(tuple(importlib.machinery.EXTENSION_SUFFIXES)))
    loader = importlib.machinery.ExtensionFileLoader(full, path)
    module = importlib.util.module_from_spec(importlib.util.spec_from_file_location(full, path, loader=loader))
    loader.exec_module(module)
    sys.modules[full] = module
    return module
