"""IDA's own step counters, which scikit-sundae does not return (its result has nfev/njev only).

For the work-precision benchmark only. The SUNDIALS IDA memory pointer is the first C field of
scikit-sundae's `_cy_ida.IDA` extension object (after the object header and Cython's vtable pointer), and
`NEQ` follows eight pointers later; the pointer is used only when that `NEQ` equals the system size and
IDA's residual count read through it equals the count scikit-sundae reports, otherwise the counters are
reported as unavailable. `counting()` registers an observer in `dynamics.backends.ida.SOLVE_OBSERVERS` that reads the
counters after each segment's solve, and removes it on exit.
"""
from __future__ import annotations

import ctypes
import glob
import os
from contextlib import contextmanager

import numpy as np

COUNTERS = {"steps": "IDAGetNumSteps", "rejected_steps": "IDAGetNumErrTestFails",
            "convergence_failures": "IDAGetNumNonlinSolvConvFails", "guard_evaluations": "IDAGetNumGEvals",
            "residual_evaluations": "IDAGetNumResEvals", "jacobian_evaluations": "IDAGetNumJacEvals"}
_HEADER = 3 * ctypes.sizeof(ctypes.c_void_p)      # ob_refcnt, ob_type, __pyx_vtab
_LIB = None


def _library():
    global _LIB
    if _LIB is None:
        import sksundae
        root = os.path.dirname(os.path.dirname(sksundae.__file__))
        found = sorted(glob.glob(os.path.join(root, "scikit_sundae.libs", "libsundials_ida*.so*")))
        if not found:
            raise OSError("libsundials_ida of scikit-sundae not found")
        _LIB = ctypes.CDLL(found[0])
    return _LIB


def read(solver, neq: int, nfev: int) -> dict | None:
    """IDA's counters of a scikit-sundae `IDA` after a solve, or None if they cannot be read safely."""
    inner = getattr(solver, "_IDA__IDA", None)
    if inner is None:
        return None
    base = id(inner)
    ptr = ctypes.c_void_p.from_address(base + _HEADER).value
    n = ctypes.c_int64.from_address(base + _HEADER + 9 * ctypes.sizeof(ctypes.c_void_p)).value
    if not ptr or n != neq:
        return None
    lib = _library()
    out = {}
    for name, fn in COUNTERS.items():
        value = ctypes.c_long(0)
        getattr(lib, fn).argtypes = [ctypes.c_void_p, ctypes.POINTER(ctypes.c_long)]
        if getattr(lib, fn)(ptr, ctypes.byref(value)) < 0:
            return None
        out[name] = int(value.value)
    return out if out["residual_evaluations"] == nfev else None


@contextmanager
def counting():
    """Within the block, every IDA segment of `dynamics.backends.ida` adds its counters to the yielded dict
    (values are NaN when they could not be read); through the module's documented SOLVE_OBSERVERS hook."""
    from mechsim.dynamics.backends.ida import SOLVE_OBSERVERS

    totals = {name: 0.0 for name in COUNTERS}

    def observe(solver, sol, neq):
        got = read(solver, neq, int(sol.nfev))
        for name in COUNTERS:
            totals[name] += got[name] if got else np.nan

    SOLVE_OBSERVERS.append(observe)
    try:
        yield totals
    finally:
        SOLVE_OBSERVERS.remove(observe)
