"""SUNDIALS IDA's C interface, reached through ctypes in the shared libraries scikit-sundae ships.

scikit-sundae's wheel carries SUNDIALS (IDA, the serial vector, the dense matrix and linear solver) as shared
libraries; its Cython binding calls back into Python for every residual, Jacobian and root-function
evaluation. `dynamics/backends/ida_compiled.py` drives the same libraries directly, with compiled callbacks, so no model
call crosses into Python (docs/benchmarks.md, "Against the strongest peer").

Every pointer is declared as a plain 64-bit integer (`c_size_t`): on the platforms SUNDIALS supports a pointer
and a size_t travel the same way in a call, and numba-compiled code (the segment driver) can then pass the
addresses it holds without pointer types. The layout facts the compiled callbacks rely on (where a serial
vector's and a dense matrix's data pointer sit) are read from the library at load time, not assumed.

ctypes checks none of these prototypes against the library, so they hold only for the SUNDIALS release they were
written from (`WRITTEN_FOR`, checked against that release's headers). The library's own version
(SUNDIALSGetVersionNumber) is read before anything else is bound; any other release raises
`SundialsVersionMismatch`, and the callers run on the `ida` backend instead (dynamics/backends/ida_compiled.py).
"""
from __future__ import annotations

import ctypes
import glob
import importlib.util
import os
from functools import lru_cache

import numpy as np

P = ctypes.c_size_t          # every pointer (N_Vector, SUNMatrix, void* mem, double*, int*, ...)
R = ctypes.c_double          # sunrealtype
I = ctypes.c_int             # int return flags
L = ctypes.c_long            # long int

#: IDASolve's itask values and return flags (SUNDIALS IDA user guide, "IDASolve")
IDA_NORMAL, IDA_ONE_STEP = 1, 2
IDA_SUCCESS, IDA_TSTOP_RETURN, IDA_ROOT_RETURN = 0, 1, 2
IDA_TOO_MUCH_WORK = -1

#: the SUNDIALS release (major, minor) whose headers the prototypes below were written from and checked against;
#: a patch release keeps them (SUNDIALS changes its interface only in a major or minor release)
WRITTEN_FOR = (7, 9)

# name: (library, restype, argtypes)
_PROTOTYPES = {
    "SUNContext_Create": ("core", I, [I, P]),
    "SUNContext_Free": ("core", I, [P]),
    "SUNContext_ClearErrHandlers": ("core", I, [P]),
    "N_VMake_Serial": ("nvecserial", P, [ctypes.c_int64, P, P]),
    "N_VNew_Serial": ("nvecserial", P, [ctypes.c_int64, P]),
    "N_VGetArrayPointer": ("core", P, [P]),
    "N_VDestroy": ("core", None, [P]),
    "SUNDenseMatrix": ("sunmatrixdense", P, [ctypes.c_int64, ctypes.c_int64, P]),
    "SUNDenseMatrix_Data": ("sunmatrixdense", P, [P]),
    "SUNMatDestroy": ("core", None, [P]),
    "SUNLinSol_Dense": ("sunlinsoldense", P, [P, P, P]),
    "SUNLinSolFree": ("core", I, [P]),
    "IDACreate": ("ida", P, [P]),
    "IDAFree": ("ida", None, [P]),
    "IDAInit": ("ida", I, [P, P, R, P, P]),
    "IDAReInit": ("ida", I, [P, R, P, P]),
    "IDASVtolerances": ("ida", I, [P, R, P]),
    "IDASetLinearSolver": ("ida", I, [P, P, P]),
    "IDASetJacFn": ("ida", I, [P, P]),
    "IDARootInit": ("ida", I, [P, I, P]),
    "IDASetRootDirection": ("ida", I, [P, P]),
    "IDASetNoInactiveRootWarn": ("ida", I, [P]),
    "IDASetId": ("ida", I, [P, P]),
    "IDASetUserData": ("ida", I, [P, P]),
    "IDASetInitStep": ("ida", I, [P, R]),
    "IDASetMaxNumSteps": ("ida", I, [P, L]),
    "IDASetMaxNonlinIters": ("ida", I, [P, I]),
    "IDASetMaxConvFails": ("ida", I, [P, I]),
    "IDASetMaxOrd": ("ida", I, [P, I]),
    "IDASetStopTime": ("ida", I, [P, R]),
    "IDAClearStopTime": ("ida", I, [P]),
    "IDASolve": ("ida", I, [P, R, P, P, P, I]),
    "IDAGetRootInfo": ("ida", I, [P, P]),
    "IDAGetNumSteps": ("ida", I, [P, P]),
    "IDAGetNumResEvals": ("ida", I, [P, P]),
    "IDAGetNumJacEvals": ("ida", I, [P, P]),
    "IDAGetNumErrTestFails": ("ida", I, [P, P]),
    "IDAGetNumNonlinSolvConvFails": ("ida", I, [P, P]),
    "IDAGetLastStep": ("ida", I, [P, P]),
    "IDAGetCurrentStep": ("ida", I, [P, P]),
    "IDAGetReturnFlagName": ("ida", ctypes.c_char_p, [L]),
}


class SundialsUnavailable(RuntimeError):
    """scikit-sundae's SUNDIALS libraries cannot be found or do not have the expected interface."""


class SundialsVersionMismatch(SundialsUnavailable):
    """scikit-sundae ships another SUNDIALS release than the one the prototypes were written for."""


def library_version(core: ctypes.CDLL) -> tuple[int, int, int]:
    """(major, minor, patch) of the loaded SUNDIALS, from SUNDIALSGetVersionNumber(int*, int*, int*, char*, int)
    (a prototype unchanged since SUNDIALS 3)."""
    fn = getattr(core, "SUNDIALSGetVersionNumber", None)
    if fn is None:
        raise SundialsUnavailable("SUNDIALSGetVersionNumber not found in scikit-sundae's SUNDIALS")
    fn.restype, fn.argtypes = I, [P, P, P, P, I]
    parts, label = [ctypes.c_int(0) for _ in range(3)], ctypes.create_string_buffer(64)
    if fn(*(ctypes.addressof(x) for x in parts), ctypes.addressof(label), len(label)) != 0:
        raise SundialsUnavailable("SUNDIALSGetVersionNumber failed")
    return parts[0].value, parts[1].value, parts[2].value


def check_version(version: tuple[int, int, int]) -> None:
    """SundialsVersionMismatch (one line) unless `version` is a release of `WRITTEN_FOR`."""
    if tuple(version[:2]) != WRITTEN_FOR:
        raise SundialsVersionMismatch(
            f"scikit-sundae ships SUNDIALS {'.'.join(map(str, version))}, and the compiled path's C prototypes "
            f"are written for SUNDIALS {'.'.join(map(str, WRITTEN_FOR))}.x")


def _library_files() -> dict[str, str]:
    """The SUNDIALS shared libraries bundled with the installed scikit-sundae wheel (Linux: scikit_sundae.libs,
    macOS: sksundae/.dylibs, Windows: scikit_sundae.libs with .dll files)."""
    spec = importlib.util.find_spec("sksundae")
    if spec is None or not spec.submodule_search_locations:
        raise SundialsUnavailable("scikit-sundae is not installed")
    package = list(spec.submodule_search_locations)[0]
    site = os.path.dirname(package)
    folders = [os.path.join(site, "scikit_sundae.libs"), os.path.join(package, ".dylibs"), package]
    found = {}
    for part in ("core", "nvecserial", "sunmatrixdense", "sunlinsoldense", "ida"):
        for folder in folders:
            hits = sorted(glob.glob(os.path.join(folder, f"libsundials_{part}*")) +
                          glob.glob(os.path.join(folder, f"sundials_{part}*.dll")))
            if hits:
                found[part] = hits[0]
                break
        else:
            raise SundialsUnavailable(f"scikit-sundae's SUNDIALS library '{part}' was not found in {folders}")
    return found


class Sundials:
    """The loaded C functions (attributes named as in SUNDIALS) and the layout offsets the callbacks use."""

    def __init__(self):
        files = _library_files()
        mode = getattr(os, "RTLD_GLOBAL", 0)
        try:        # by path (each library finds the others beside it): scikit-sundae's import costs scipy.optimize
            libs = {part: ctypes.CDLL(path, mode=mode) for part, path in files.items()}
        except OSError:     # a platform whose loader needs scikit-sundae's own set-up first (its DLL folders)
            import sksundae.ida  # noqa: F401
            libs = {part: ctypes.CDLL(path, mode=mode) for part, path in files.items()}
        self.files = files
        self.version = library_version(libs["core"])
        check_version(self.version)       # before any prototype is bound or called
        for name, (part, restype, argtypes) in _PROTOTYPES.items():
            try:
                fn = getattr(libs[part], name)
            except AttributeError:
                fn = None
                for other in libs.values():
                    fn = getattr(other, name, None)
                    if fn is not None:
                        break
                if fn is None:
                    raise SundialsUnavailable(f"SUNDIALS function {name} not found in {files[part]}") from None
            fn.restype, fn.argtypes = restype, argtypes
            setattr(self, name, fn)
        self.context = self._new_context()
        self.vector_data_offset, self.matrix_data_offset = self._layout()

    def _new_context(self) -> int:
        box = ctypes.c_size_t(0)
        if self.SUNContext_Create(0, ctypes.addressof(box)) != 0 or not box.value:
            raise SundialsUnavailable("SUNContext_Create failed")
        self.SUNContext_ClearErrHandlers(box.value)   # IDA's failures are reported by return flags, not on stderr
        return box.value

    def _layout(self) -> tuple[int, int]:
        """Byte offset of the data pointer inside a serial vector's and a dense matrix's content struct, found by
        comparing the struct's words with N_VGetArrayPointer / SUNDenseMatrix_Data."""
        def offset(obj: int, data: int, what: str) -> int:
            content = ctypes.c_size_t.from_address(obj).value     # first member of the generic object
            for off in (8, 16, 24):
                if ctypes.c_size_t.from_address(content + off).value == data:
                    return off
            raise SundialsUnavailable(f"unexpected {what} layout in SUNDIALS")
        v = self.N_VNew_Serial(3, self.context)
        m = self.SUNDenseMatrix(3, 3, self.context)
        try:
            return (offset(v, self.N_VGetArrayPointer(v), "serial vector"),
                    offset(m, self.SUNDenseMatrix_Data(m), "dense matrix"))
        finally:
            self.N_VDestroy(v)
            self.SUNMatDestroy(m)

    def vector(self, array: np.ndarray) -> int:
        """A serial N_Vector whose data IS `array` (float64, contiguous; the caller keeps it alive)."""
        assert array.dtype == np.float64 and array.flags.c_contiguous
        v = self.N_VMake_Serial(array.size, array.ctypes.data, self.context)
        if not v:
            raise MemoryError("N_VMake_Serial failed")
        return v

    def flag_name(self, flag: int) -> str:
        name = self.IDAGetReturnFlagName(flag)
        return name.decode() if name else str(flag)

    def counter(self, getter, mem: int) -> int:
        box = ctypes.c_long(0)
        getter(mem, ctypes.addressof(box))
        return int(box.value)

    def real(self, getter, mem: int) -> float:
        box = ctypes.c_double(0.0)
        getter(mem, ctypes.addressof(box))
        return float(box.value)


@lru_cache(maxsize=1)
def sundials() -> Sundials:
    """The process's SUNDIALS interface (loaded once)."""
    return Sundials()
