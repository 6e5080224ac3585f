"""The derived model kept on disk, so that a later process skips the sympy derivation (docs/benchmarks.md, "Cold
start"); and a mechanism's own lambdified functions (`store_functions`: the chain's and rolling pair's closed-form
inverse dynamics), so that their closed-form runs skip it too.

What is stored is what the solvers call: the source of every generated function (the plain-Python residual,
Jacobian and guards of `codegen.emit`, and the numpy functions of `codegen.lambdify`), with the numpy names
each lambdified function reads, and the mode's layout. Loading executes the same source in the same namespace, so
a loaded model computes bit for bit what a fresh derivation computes. The sympy expressions themselves
(`ModeFunctions.symbolic`, which the diffrax backend, the compiled IDA callbacks and the sensitivities build on)
are kept beside it as a pickle (`store_symbolic`) and loaded on first use (0.01-0.06 s against 1-6 s of derivation
a model): the same expression trees, node for node (rebuilt unevaluated); the heat share's opaque functions,
classes made at run time, are pickled by their origin and made again (thermal/coupling.py `opaque_class`). What is
traced or emitted from them later can differ in round-off from what a process that has just derived them traces:
sympy's cache of the derivation's intermediate results shapes what a later differentiation returns (equal
expressions, other trees; measured 2e-15 relative on internal-geneva-motor's diffrax run, three other models the
same to the bit; docs/benchmarks.md). The pickle is read from the user's own cache folder only, as the stored
source above is executed.

One JSON file per derivation and per target in the user's cache folder (`dynamics/user_cache.py`), named by a
hash of everything the stored functions depend on: the derivation key (mechanism structure, formulation, drive
kind, state extension), the `codegen` targets they were emitted for (`TARGETS`), a fingerprint of the code that
derives it (mechanisms/, dynamics/, thermal/), this file's format, Python, sympy and numpy. Written atomically;
a file that is missing, damaged or of another format is ignored and written again. Correctness never depends on
the cache.
"""
from __future__ import annotations

import builtins
import hashlib
import json
import linecache
import pickle
import sys
import types
from pathlib import Path

import numpy as np

from mechsim.dynamics.user_cache import write_atomically

#: bump when what is stored, or how it is read back, changes
FORMAT = 1
#: the `codegen` target each kind of stored function is emitted for (dynamics/model.py emits with these): part
#: of the file's key, so functions emitted for one target are never loaded as another's
TARGETS = {"codegen": "python", "lambdified": "numpy"}
#: the lambdified functions of a mode (attribute names of ModeFunctions; kkt_flat entries as "kkt_flat.<name>")
LAMBDIFIED = ("phi", "G", "phi_dot", "mass", "force0", "force_lam", "gamma")
CODEGEN = ("residual", "jacobian", "events")
KKT_FLAT = ("mass", "force0", "G", "force_lam", "gamma")


class NotStorable(ValueError):
    """A function whose namespace cannot be written down (a global that is not a numpy attribute or a number)."""


def file_for(key: tuple, targets: dict[str, str] = TARGETS) -> Path:
    """The cache file of a derivation key emitted for `targets` (see the module docstring for what the name
    hashes)."""
    from importlib.metadata import version

    from mechsim.dynamics.user_cache import cache_dir, code_fingerprint
    parts = [f"format {FORMAT}", repr(key), f"targets {sorted(targets.items())!r}", code_fingerprint(),
             sys.version, version("sympy"), np.__version__]
    name = hashlib.sha256("\n".join(parts).encode()).hexdigest()[:32]
    return cache_dir() / "derived" / f"{name}.json"


# -- storing --------------------------------------------------------------------------------------------------
def _global_names(code: types.CodeType) -> set[str]:
    names = set(code.co_names)
    for const in code.co_consts:
        if isinstance(const, types.CodeType):
            names |= _global_names(const)
    return names


def _numpy_name(value) -> str:
    """The numpy attribute that is `value` ("numpy.sin"), or a number's repr ("float:nan")."""
    if isinstance(value, (int, float, complex)) and not isinstance(value, bool):
        return f"{type(value).__name__}:{value!r}"
    name = getattr(value, "__name__", None)
    if name and getattr(np, name, None) is value:
        return f"numpy.{name}"
    for attr in dir(np):
        if getattr(np, attr, None) is value:
            return f"numpy.{attr}"
    raise NotStorable(f"global {value!r} is not a numpy attribute")


def _lambdified(fn) -> dict:
    import inspect
    source = inspect.getsource(fn)
    used = _global_names(fn.__code__)
    refs = {name: _numpy_name(fn.__globals__[name]) for name in sorted(used) if name in fn.__globals__}
    return {"name": fn.__name__, "source": source, "globals": refs}


def _mode_record(mf) -> dict:
    record = {"name": mf.name, "m": mf.m, "ny": mf.ny, "index": {k: [s.start, s.stop] for k, s in mf.index.items()},
              "algebraic": list(mf.algebraic), "guard_names": list(mf.guard_names),
              "guard_directions": list(mf.guard_directions), "readout_names": list(mf.readout_names),
              "codegen": {k: {"name": getattr(mf, k).__name__, "source": getattr(mf, k).__source__} for k in CODEGEN},
              "lambdified": {k: _lambdified(getattr(mf, k)) for k in LAMBDIFIED},
              "readouts": {k: _lambdified(fn) for k, fn in mf.readouts.items()},
              "kkt_flat": {k: (None if mf.kkt_flat.get(k) is None else _lambdified(mf.kkt_flat[k]))
                           for k in KKT_FLAT}}
    return record


def store(key: tuple, model) -> Path | None:
    """Write the derived model's file (atomically); None where it cannot be stored or written (no error: the cache
    is an optimisation)."""
    try:
        record = {"format": FORMAT, "key": repr(key), "targets": TARGETS, "coordinates": list(model.coordinates),
                  "parameter_names": list(model.parameter_names), "work_names": list(model.work_names),
                  "extension_names": list(model.extension_names), "formulation": model.formulation,
                  "prescribed": bool(model.prescribed),
                  "modes": [_mode_record(mf) for mf in model.modes.values()]}
        path = file_for(key)
        return path if write_atomically(path, json.dumps(record).encode(), prefix=".derived-") else None
    except (NotStorable, TypeError, AttributeError):
        return None


def store_functions(key: tuple, functions: dict, meta: dict | None = None) -> Path | None:
    """Write lambdified numpy functions of a mechanism's own (its closed form's inverse dynamics: the chain's, the
    rolling pair's) under `key`, with `meta` (names, JSON), as `store` writes a derived model; None where they cannot
    be stored or written."""
    try:
        record = {"format": FORMAT, "key": repr(key), "targets": TARGETS, "meta": meta or {},
                  "functions": {name: _lambdified(fn) for name, fn in functions.items()}}
        path = file_for(key)
        return path if write_atomically(path, json.dumps(record).encode(), prefix=".derived-") else None
    except (NotStorable, TypeError, AttributeError, OSError):
        return None


def load_functions(key: tuple) -> tuple[dict, dict] | None:
    """(functions, meta) stored for `key` by `store_functions`, or None where there is no usable file."""
    try:
        record = json.loads(file_for(key).read_text())
        if record.get("format") != FORMAT or record.get("key") != repr(key) or record.get("targets") != TARGETS:
            return None
        return ({name: _lambdified_fn(entry, f"{key[0]} {name}") for name, entry in record["functions"].items()},
                record["meta"])
    except (OSError, ValueError, KeyError, TypeError, AttributeError, SyntaxError):
        return None


def _symbolic_file(key: tuple) -> Path:
    return file_for(key).with_suffix(".symbolic.pickle")


class _SymbolicPickler(pickle.Pickler):
    """Pickles the opaque function classes (thermal/coupling.py `opaque_function`) by their origin."""

    def reducer_override(self, obj):
        origin = getattr(obj, "opaque_origin", None) if isinstance(obj, type) else None
        if origin is None:
            return NotImplemented
        from mechsim.thermal.coupling import opaque_class
        return opaque_class, (origin,)


def store_symbolic(key: tuple, pieces: dict[str, dict]) -> Path | None:
    """Write every mode's sympy pieces ({mode: ModeFunctions.symbolic}) of the derivation `key` (atomically); None
    where they cannot be pickled or written."""
    import io
    try:
        buffer = io.BytesIO()
        _SymbolicPickler(buffer, protocol=pickle.HIGHEST_PROTOCOL).dump((FORMAT, repr(key), pieces))
        path = _symbolic_file(key)
        return path if write_atomically(path, buffer.getvalue(), prefix=".derived-") else None
    except (pickle.PicklingError, TypeError, AttributeError, ValueError, RecursionError, OSError):
        return None


def load_symbolic(key: tuple) -> dict[str, dict] | None:
    """The sympy pieces `store_symbolic` wrote for `key`, or None where there is no usable file."""
    from sympy.core.parameters import evaluate
    try:
        data = _symbolic_file(key).read_bytes()
        with evaluate(False):           # each node rebuilt from its arguments as stored, not simplified again
            stored_format, stored_key, pieces = pickle.loads(data)
    except Exception:               # a missing, damaged or foreign file: derived again, never an error
        return None
    return pieces if stored_format == FORMAT and stored_key == repr(key) and isinstance(pieces, dict) else None


class FunctionStore:
    """`load_functions` and `store_functions` as the object a mechanism holds (`Mechanism.function_store`: what the
    scenario loader gives it, so that mechanisms/ imports no dynamics/; an object, not this module, so that the
    mechanism pickles)."""

    def load_functions(self, key: tuple) -> tuple[dict, dict] | None:
        return load_functions(key)

    def store_functions(self, key: tuple, functions: dict, meta: dict | None = None) -> Path | None:
        return store_functions(key, functions, meta)


# -- loading --------------------------------------------------------------------------------------------------
_CODEGEN_GLOBALS: dict | None = None


def _codegen_globals() -> dict:
    """The namespace `codegen.emit` executes its source in (the math module's names), without importing sympy."""
    global _CODEGEN_GLOBALS
    if _CODEGEN_GLOBALS is None:
        import math
        _CODEGEN_GLOBALS = {name: getattr(math, name) for name in dir(math) if not name.startswith("_")}
        _CODEGEN_GLOBALS["Infinity"] = math.inf
    return _CODEGEN_GLOBALS


def _resolve(ref: str):
    kind, _, value = ref.partition(":") if not ref.startswith("numpy.") else ("numpy", "", ref[6:])
    if kind == "numpy":
        return getattr(np, value)
    return {"int": int, "float": float, "complex": complex}[kind](value)


def _compiled(source: str, name: str, namespace: dict, label: str):
    """Execute `source` in `namespace` and return its function `name`; the source is registered with linecache
    (as sympy.lambdify does) so that tracebacks and `inspect.getsource` show it."""
    filename = f"<mechsim-derived {label}>"
    linecache.cache[filename] = (len(source), None, source.splitlines(True), filename)
    exec(compile(source, filename, "exec"), namespace)
    return namespace[name]


def _lambdified_fn(entry: dict, label: str):
    namespace = {"__builtins__": builtins}
    namespace.update({name: _resolve(ref) for name, ref in entry["globals"].items()})
    return _compiled(entry["source"], entry["name"], namespace, label)


def load(key: tuple, symbolic_of):
    """The DerivedModel stored for `key`, or None where there is no usable file. `symbolic_of(mode name)` gives a
    mode's sympy pieces on demand (a fresh derivation)."""
    from mechsim.dynamics.model import DerivedModel, ModeFunctions
    path = file_for(key)
    try:
        record = json.loads(path.read_text())
        if record.get("format") != FORMAT or record.get("key") != repr(key) or record.get("targets") != TARGETS:
            return None
        modes = {}
        for r in record["modes"]:
            name = r["name"]
            fns = {}
            for k, entry in r["codegen"].items():
                fn = _compiled(entry["source"], entry["name"], dict(_codegen_globals()), f"{name} {k}")
                fn.__source__ = entry["source"]
                fns[k] = fn
            for k, entry in r["lambdified"].items():
                fns[k] = _lambdified_fn(entry, f"{name} {k}")
            mf = ModeFunctions(
                name=name, m=r["m"], ny=r["ny"], index={k: slice(*v) for k, v in r["index"].items()},
                algebraic=list(r["algebraic"]), guard_names=list(r["guard_names"]),
                guard_directions=list(r["guard_directions"]), readout_names=list(r["readout_names"]),
                readouts={k: _lambdified_fn(e, f"{name} readouts {k}") for k, e in r["readouts"].items()},
                kkt_flat={k: (None if e is None else _lambdified_fn(e, f"{name} kkt {k}"))
                          for k, e in r["kkt_flat"].items()},
                cache_key=(key, name), symbolic_source=(lambda mode=name: symbolic_of(mode)), **fns)
            modes[name] = mf
        return DerivedModel(coordinates=tuple(record["coordinates"]),
                            parameter_names=tuple(record["parameter_names"]),
                            work_names=tuple(record["work_names"]), extension_names=tuple(record["extension_names"]),
                            modes=modes, formulation=record["formulation"], prescribed=bool(record["prescribed"]),
                            key=key)
    except (OSError, ValueError, KeyError, TypeError, AttributeError, SyntaxError):
        return None
