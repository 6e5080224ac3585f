"""The compiled IDA backend (`solver.backend = "ida-compiled"`): the same SUNDIALS IDA as the `ida` backend, with
no Python call inside a segment.

`ida` (scikit-sundae's binding) calls a Python function for every residual, Jacobian and guard evaluation and
returns to Python at every output time; on the benchmark's case A that glue is about 90 % of the run
(docs/benchmarks.md). Here the mode's residual, exact Jacobian and guards are native callbacks
(`compiled_model.py`), and the loop over output times is numba-compiled code that calls IDASolve through the C
interface of the same SUNDIALS libraries (`sundials_c.py`). The algorithm is the `ida` backend's, option for
option (variable-order BDF, dense direct linear solver, exact Jacobian, multipliers' ids, tolerances per
component, IDA_NORMAL at each output time with the end as stop time, guards root-found by IDA and terminal),
so the two backends take the same steps and agree to round-off in the compiled expressions. Each mode keeps
one IDA memory for the backend's lifetime, re-initialised (IDAReInit) at each segment instead of rebuilt.
"""
from __future__ import annotations

import ctypes
import importlib
import importlib.util
import sys
import threading
import time as _time
from dataclasses import dataclass, field

import numpy as np

from mechsim.dynamics.backend import Backend, End, Request, Segment
from mechsim.dynamics.backends.ida import IdaBackend, atol_vector, resolving_first_step
from mechsim.dynamics.result import FailureCode
from mechsim.dynamics.settings import SolverSettings
from mechsim.dynamics.backends.sundials_c import (IDA_ROOT_RETURN, IDA_TOO_MUCH_WORK, SundialsUnavailable,
                                                   SundialsVersionMismatch, sundials)
from mechsim.dynamics.user_cache import cache_dir

#: scikit-sundae's defaults, kept so both IDA backends run the same algorithm
MAX_NONLINEAR_ITERATIONS, MAX_CONVERGENCE_FAILURES, MAX_ORDER = 4, 10, 5

_NOTED: set = set()


def note(text: str) -> None:
    """A one-line note on stderr, once per process and text."""
    if text not in _NOTED:
        _NOTED.add(text)
        print(f"mechsim: note: {text}", file=sys.stderr)


#: whether numba is installed (`unavailable`), once found out
_NUMBA_FOUND: list = []


def unavailable() -> Exception | None:
    """Why the compiled path cannot run in this installation (None: it can): numba missing, or scikit-sundae's
    SUNDIALS libraries missing, unloadable or of another release (`sundials_c.SundialsVersionMismatch`). Finding
    numba does not import it; it is looked for once per process (every backend built asks, and an installation does
    not change under a running process)."""
    if not _NUMBA_FOUND:
        _NUMBA_FOUND.append(importlib.util.find_spec("numba") is not None)
    if not _NUMBA_FOUND[0]:
        return ImportError("numba is not installed")
    try:
        sundials()
    except (ImportError, OSError, SundialsUnavailable) as exc:
        return exc
    return None


#: the most bytes of output rows an IDA memory keeps between segments (`_Memory.scratch`)
SCRATCH_BYTES = 1 << 20


@dataclass
class _Memory:
    """One mode's IDA memory and the arrays its vectors live in (kept alive with it)."""

    mem: int
    y: np.ndarray
    yp: np.ndarray
    yy_nv: int
    yp_nv: int
    p: np.ndarray
    owned_vectors: list = field(default_factory=list)
    matrix: int = 0
    linear_solver: int = 0
    n_guards: int = 0
    roots: np.ndarray | None = None
    roots_address: int = 0
    p_from: tuple | None = None       # the parameter tuple `p` holds (a tuple is immutable: the same one, same values)
    keep: list = field(default_factory=list)
    atol: np.ndarray | None = None
    #: the segment loop's rows are written here (grown as needed), then copied out at their count
    rows: tuple = (np.empty(0), np.empty((0, 0)), np.empty((0, 0)))

    def scratch(self, n: int) -> tuple:
        """(t, y, y') arrays of at least n rows: kept from segment to segment up to SCRATCH_BYTES (a memory lives
        as long as its thread's cache, `_kept_memories`), made for the segment beyond."""
        if len(self.rows[0]) >= n:
            return self.rows
        ny = self.y.size
        rows = (np.empty(n), np.empty((n, ny)), np.empty((n, ny)))
        if n * (2 * ny + 1) * rows[0].itemsize <= SCRATCH_BYTES:
            self.rows = rows
        return rows


class IdaCompiledBackend(Backend):
    """SUNDIALS IDA (variable-order BDF) on the mode's residual with its exact Jacobian, every call compiled."""

    name = "ida-compiled"
    initial_step = 0.0
    recoverable = IdaBackend.recoverable
    unavailable: dict = {}
    notes = {"rejected_steps": "IDA's error-test and nonlinear-convergence failures",
             "compile_time_s": "compiling (or loading from the cache) the modes' callbacks "}

    def __new__(cls, settings: SolverSettings):
        """Another SUNDIALS release than the prototypes' gives the `ida` backend, with a one-line note (the same
        algorithm on the same libraries through scikit-sundae's own binding); a missing piece is a ValueError."""
        reason = unavailable()
        if isinstance(reason, SundialsVersionMismatch):
            note(f"{reason}: solver.backend = '{cls.name}' runs on 'ida' (the same IDA through scikit-sundae's "
                 "binding)")
            return IdaBackend(settings)
        if reason is not None:
            raise ValueError(f"solver.backend = 'ida-compiled' is not available in this installation ({reason}); "
                             "use solver.backend = 'ida'")
        return super().__new__(cls)

    def __init__(self, settings: SolverSettings):
        self.settings = settings
        self.solver = f"IDA (BDF, {settings.formulation}; compiled callbacks)"
        from mechsim.dynamics.backends.compiled_model import loop_entries
        segment, read_rows = loop_entries(cache_dir() / "compiled")
        self._segment, self._read_rows = _ENTRY(segment), _ENTRY(read_rows)
        self.lib = sundials()
        self._memories = _kept_memories(settings, self.lib)
        self._tret = np.zeros(1)
        self._tret_address = self._tret.ctypes.data
        self._read_addresses = np.array([ctypes.cast(getattr(self.lib, name), ctypes.c_void_p).value for name in
                                         ("IDASolve", "IDAReInit", "IDASetInitStep", "IDASetStopTime")], dtype=np.int64)
        # a segment's calls (`native.segment`): the read loop's, then the getters of IDA's counters, which are read into
        # one array (a C long each) in the order of `_COUNTERS`
        self._segment_addresses = np.concatenate([self._read_addresses, np.array(
            [ctypes.cast(getattr(self.lib, name), ctypes.c_void_p).value for name in _COUNTERS], dtype=np.int64)])
        self._counts = np.zeros(len(_COUNTERS), dtype=_C_LONG)
        self._no_reals = np.zeros(1)
        self._counts_address = self._counts.ctypes.data

    def hint(self, code: FailureCode) -> str:
        return IdaBackend.hint(self, code)

    # -- per-mode IDA memory ---------------------------------------------------------------------------------
    def _memory(self, mf, compiled, n_params: int) -> _Memory:
        hit = self._memories.get(id(mf))
        if hit is not None and hit[0] is mf:
            return hit[1]
        lib, s, ctx = self.lib, self.settings, self.lib.context
        y, yp = np.zeros(mf.ny), np.zeros(mf.ny)
        m = _Memory(mem=lib.IDACreate(ctx), y=y, yp=yp, yy_nv=lib.vector(y), yp_nv=lib.vector(yp),
                    p=np.zeros(n_params))
        if not m.mem:
            raise MemoryError("IDACreate failed")
        atol, ids = np.ascontiguousarray(atol_vector(mf, s)), np.ones(mf.ny)
        ids[mf.algebraic] = 0.0
        m.keep += [atol, ids]
        m.atol = atol
        atol_nv, id_nv = lib.vector(atol), lib.vector(ids)
        m.owned_vectors += [m.yy_nv, m.yp_nv, atol_nv, id_nv]
        check = self._check
        check(lib.IDAInit(m.mem, compiled.residual, 0.0, m.yy_nv, m.yp_nv), "IDAInit")
        check(lib.IDASVtolerances(m.mem, s.rtol, atol_nv), "IDASVtolerances")
        m.matrix = lib.SUNDenseMatrix(mf.ny, mf.ny, ctx)
        m.linear_solver = lib.SUNLinSol_Dense(m.yy_nv, m.matrix, ctx)
        check(lib.IDASetLinearSolver(m.mem, m.linear_solver, m.matrix), "IDASetLinearSolver")
        if s.jacobian == "exact":
            check(lib.IDASetJacFn(m.mem, compiled.jacobian), "IDASetJacFn")
        check(lib.IDASetMaxNonlinIters(m.mem, MAX_NONLINEAR_ITERATIONS), "IDASetMaxNonlinIters")
        check(lib.IDASetMaxConvFails(m.mem, MAX_CONVERGENCE_FAILURES), "IDASetMaxConvFails")
        check(lib.IDASetMaxOrd(m.mem, MAX_ORDER), "IDASetMaxOrd")
        check(lib.IDASetMaxNumSteps(m.mem, s.max_steps), "IDASetMaxNumSteps")
        check(lib.IDASetId(m.mem, id_nv), "IDASetId")
        check(lib.IDASetUserData(m.mem, m.p.ctypes.data), "IDASetUserData")    # m.p is written in place per segment
        m.n_guards = len(mf.guard_names) if s.events else 0
        if m.n_guards:
            check(lib.IDARootInit(m.mem, m.n_guards, compiled.guards), "IDARootInit")
            directions = np.ascontiguousarray(mf.guard_directions, dtype=np.intc)
            m.keep.append(directions)
            check(lib.IDASetRootDirection(m.mem, directions.ctypes.data), "IDASetRootDirection")
            check(lib.IDASetNoInactiveRootWarn(m.mem), "IDASetNoInactiveRootWarn")
            m.roots = np.zeros(m.n_guards, dtype=np.intc)
            m.roots_address = m.roots.ctypes.data
        self._memories[id(mf)] = (mf, m)
        return m

    @staticmethod
    def _check(flag: int, what: str) -> None:
        if flag < 0:
            raise RuntimeError(f"{what} failed with flag {flag}")

    def close(self) -> None:
        """Let go of this backend's IDA memories (freed once neither another backend of the thread with these
        settings nor the thread's cache holds them, `_kept_memories`)."""
        self._memories = _Memories(self.lib)

    # -- one segment -------------------------------------------------------------------------------------------
    def _begin(self, mf, p, t0: float, y0, yp0, first_step: float, t_end: float, counts: dict,
               t_first: float) -> tuple[_Memory, float]:
        """(the mode's IDA memory with (y0, y0') in its vectors and the parameters in its user data, the first step)
        for a segment from t0 (`native.segment` re-initialises IDA there); given the first output instant
        `t_first`, a first step of 0 is IDA's own estimate only where that moves t (`ida.resolving_first_step`, as
        the `ida` backend's segments)."""
        hit = self._memories.get(id(mf))
        m = hit[1] if hit is not None and hit[0] is mf else self._first_use(mf, counts, len(p))
        if first_step == 0.0:
            first_step = resolving_first_step(self.settings, m.atol, t0, y0, yp0, t_first, t_end)
        m.y[:] = y0
        m.yp[:] = yp0
        if m.p_from is not p:
            m.p[:] = p
            m.p_from = p if isinstance(p, tuple) else None
        return m, first_step

    def read(self, mf, p, t0: float, y0, yp0, t_out: np.ndarray, at_start: np.ndarray | None = None) -> tuple | None:
        """(t, y, y') at every t_out (ordered away from t0, the last one the stop time) from (y0, y0'), None where IDA
        fails first: `integrate` without its segment's bookkeeping (counters, guards, the end state), for what
        re-integrates a run's rows many times over (the located peaks' readings). The instants `at_start` (within
        round-off of t0) come first, read as (y0, y0') itself, in the same arrays. One reading of `read_many`."""
        t_out = np.asarray(t_out, dtype=float)
        n0 = 0 if at_start is None else len(at_start)
        rows = t_out if at_start is None else np.concatenate([at_start, t_out])
        t, y, yp, ok = self.read_many(mf, np.array([t0], dtype=float), np.asarray(y0, dtype=float)[None],
                                      np.asarray(yp0, dtype=float)[None], np.asarray(p, dtype=float)[None], rows,
                                      np.array([[0, n0, len(rows)]], dtype=np.int64))
        return (t, y, yp) if ok[0] else None

    def read_many(self, mf, t0: np.ndarray, y0: np.ndarray, yp0: np.ndarray, p: np.ndarray, rows_t: np.ndarray,
                  bounds: np.ndarray) -> tuple:
        """Many `read`s on the mode `mf` in one compiled call (`native.read_rows`), without a return to Python between
        them: reading i starts from (t0[i], y0[i], y0'[i]) with the parameters p[i] and fills rows bounds[i, 0] to
        bounds[i, 2] of rows_t (its instants, ordered away from t0): those up to bounds[i, 1] (within round-off of
        t0) with the start itself, the others by IDA (IDAReInit with IDA's own first step, the stop time its last
        instant, IDASolve in IDA_NORMAL mode at each instant, as `integrate` runs a segment). (t, y, y') of all
        rows, and per reading whether IDA reached all its instants (else it failed first)."""
        n = len(t0)
        hit = self._memories.get(id(mf))
        m = hit[1] if hit is not None and hit[0] is mf else self._first_use(mf, {}, p.shape[1])
        rows_t = np.array(rows_t, dtype=float)            # a copy: IDA's times are written over it
        rows_y, rows_yp = np.empty((len(rows_t), mf.ny)), np.empty((len(rows_t), mf.ny))
        written = np.empty(n, dtype=np.int64)
        t0, y0, yp0, p = (np.ascontiguousarray(a, dtype=float) for a in (t0, y0, yp0, p))
        first, bounds = np.zeros(n), np.ascontiguousarray(bounds, dtype=np.int64)
        ints = np.array([self._read_addresses.ctypes.data, len(self._read_addresses), m.mem, m.yy_nv, m.yp_nv,
                         self._tret_address, m.y.ctypes.data, m.y.size, m.yp.ctypes.data, m.p.ctypes.data, m.p.size,
                         self._tret_address, t0.ctypes.data, n, y0.ctypes.data, yp0.ctypes.data, p.ctypes.data,
                         first.ctypes.data, bounds.ctypes.data, written.ctypes.data, rows_t.ctypes.data,
                         len(rows_t), rows_y.ctypes.data, rows_yp.ctypes.data], dtype=np.int64)
        self._read_rows(ints.ctypes.data, self._no_reals.ctypes.data)
        m.p_from = None                       # m.p holds the last reading's parameters
        if np.any(written == -2):
            raise RuntimeError("IDAReInit, IDASetInitStep or IDASetStopTime failed")
        return rows_t, rows_y, rows_yp, written == bounds[:, 2] - bounds[:, 1]

    def integrate(self, request: Request) -> Segment:
        r, lib = request, self.lib
        counts = {}
        t_out = _ahead(np.ascontiguousarray(r.t_out, dtype=float), r.t0, r.t_end)
        n_req = len(t_out)
        if not (n_req and (t_out[-1] - r.t_end) * (r.t_end - r.t0) >= 0):
            t_out = np.append(t_out, r.t_end)
        m, first_step = self._begin(r.mf, r.p, r.t0, r.y0, r.yp0, r.first_step, r.t_end, counts, float(t_out[0]))
        rows_t, rows_y, rows_yp = m.scratch(len(t_out))
        ints = np.array([self._segment_addresses.ctypes.data, len(self._segment_addresses), m.mem, t_out.ctypes.data,
                         len(t_out), self._tret_address, m.yy_nv, m.yp_nv, m.y.ctypes.data, m.y.size,
                         m.yp.ctypes.data, self._tret_address, rows_t.ctypes.data, len(rows_t), rows_y.ctypes.data,
                         rows_yp.ctypes.data, self._counts_address, _C_LONG.itemsize, 0, 0], dtype=np.int64)
        reals = np.array([r.t0, first_step, r.t_end])
        self._segment(ints.ctypes.data, reals.ctypes.data)
        flag, k = int(ints[18]), int(ints[19])
        if k < 0:                                       # a setter failed: IDA was not run
            self._check(flag, ("IDAReInit", "IDASetInitStep", "IDASetStopTime")[-1 - k])
        counts.update(self._counters())
        keep = min(k, n_req)
        t_now = float(self._tret[0])
        if flag == IDA_ROOT_RETURN:
            lib.IDAGetRootInfo(m.mem, m.roots_address)
            fired = tuple(j for j, root in enumerate(m.roots.tolist()) if root)
            below = rows_t[:keep] < t_now
            keep = int(np.count_nonzero(below))
            if not below[:keep].all():                  # rows out of time order: those before the root, in order
                return Segment(rows_t[:len(below)][below], rows_y[:len(below)][below], rows_yp[:len(below)][below],
                               End.GUARD, t_now, m.y.copy(), m.yp.copy(), fired=fired, counts=counts)
            return Segment(rows_t[:keep].copy(), rows_y[:keep].copy(), rows_yp[:keep].copy(), End.GUARD, t_now,
                           m.y.copy(), m.yp.copy(), fired=fired, counts=counts)
        t_rows, y_rows, yp_rows = rows_t[:keep].copy(), rows_y[:keep].copy(), rows_yp[:keep].copy()
        if flag < 0:
            code = FailureCode.MAX_STEPS if flag == IDA_TOO_MUCH_WORK else FailureCode.INTEGRATOR_FAILED
            what = ("IDA failed on the index-3 formulation" if self.settings.formulation == "index3"
                    else "IDA failed")
            return Segment(t_rows, y_rows, yp_rows, End.FAILED, t_now, m.y.copy(), m.yp.copy(), code=code,
                           message=f"{what}: {lib.flag_name(flag)}", counts=counts)
        return Segment(t_rows, y_rows, yp_rows, End.END, t_now, m.y.copy(), m.yp.copy(), counts=counts)

    def _first_use(self, mf, counts: dict, n_params: int) -> _Memory:
        """The mode's IDA memory, built on the mode's compiled callbacks (compiled, or loaded from the cache, the
        first time in the process: the time goes into the compile counters)."""
        from mechsim.dynamics.backends.compiled_model import compiled_mode
        started = _time.perf_counter(), _time.process_time()
        compiled, built = compiled_mode(mf, cache_dir() / "compiled")
        if built:
            counts.update(compile_time_s=_time.perf_counter() - started[0],
                          compile_cpu_time_s=_time.process_time() - started[1], compilations=1)
        return self._memory(mf, compiled, n_params)

    def _counters(self) -> dict:
        """The segment's statistics from IDA's counters (read by `native.segment`)."""
        steps, error_fails, convergence_fails, residuals, jacobians = self._counts.tolist()
        rejected = error_fails + convergence_fails
        return dict(steps=steps + rejected, accepted_steps=steps, rejected_steps=rejected,
                    residual_evaluations=residuals, jacobian_evaluations=jacobians)


def _ahead(t_out: np.ndarray, t0: float, t_end: float) -> np.ndarray:
    """The output times ahead of t0 (after it; before it where t_end < t0, backward in time). They come ordered away
    from t0 (IDA_NORMAL reaches them one after the other), so where the first is ahead all are, without a pass over
    the run's remaining times at every segment."""
    if not len(t_out):
        return t_out
    forward = t_end >= t0
    if (t_out[0] > t0) if forward else (t_out[0] < t0):
        return t_out
    return t_out[t_out > t0] if forward else t_out[t_out < t0]


#: IDA's counters a segment reports (`IdaCompiledBackend._counters`)
_COUNTERS = ("IDAGetNumSteps", "IDAGetNumErrTestFails", "IDAGetNumNonlinSolvConvFails", "IDAGetNumResEvals",
             "IDAGetNumJacEvals")
_C_LONG = np.dtype(ctypes.c_long)
#: the compiled segment loop's entry points (`native.ENTRY`), called with the GIL held as numba's own calls were
_ENTRY = ctypes.PYFUNCTYPE(ctypes.c_int32, ctypes.c_void_p, ctypes.c_void_p)


class _Memories(dict):
    """The IDA memories of one thread and settings, id(mf) -> (mf, _Memory); freed with the last reference."""

    def __init__(self, lib):
        super().__init__()
        self.lib = lib

    def free(self) -> None:
        lib = self.lib
        for _, m in self.values():
            box = ctypes.c_size_t(m.mem)
            lib.IDAFree(ctypes.addressof(box))
            lib.SUNLinSolFree(m.linear_solver)
            lib.SUNMatDestroy(m.matrix)
            for v in m.owned_vectors:
                lib.N_VDestroy(v)
        self.clear()

    def __del__(self):
        try:
            self.free()
        except Exception:   # interpreter shutdown: the libraries may be gone already
            pass


#: per thread (an IDA memory serves one segment at a time), by settings: the IDA memories the thread's backends share
_KEPT = threading.local()
#: settings kept per thread (the oldest is dropped beyond this): a run, its located peaks' two tolerance tries and a
#: benchmark's or study's few variants each hold one
REUSABLE_SETTINGS = 32


def _kept_memories(settings: SolverSettings, lib) -> _Memories:
    """The thread's IDA memories for these settings, shared by its backends: each mode's memory is created once per
    thread and re-initialised at every segment (IDAReInit: no state of an earlier segment carries over), run after
    run as within one run. The latest REUSABLE_SETTINGS settings are kept."""
    kept = getattr(_KEPT, "memories", None)
    if kept is None:
        kept = _KEPT.memories = {}
    memories = kept.pop(settings, None)
    if memories is None:
        memories = _Memories(lib)
        while len(kept) >= REUSABLE_SETTINGS:
            kept.pop(next(iter(kept)))
    kept[settings] = memories                    # the newest last
    return memories


def reusable(settings: SolverSettings) -> Backend:
    """An `IdaCompiledBackend` for these settings, for what integrates many short segments run after run (the located
    peaks' readings): the thread's, kept with the latest REUSABLE_SETTINGS settings' (its modes' IDA memories are
    the thread's too, `_kept_memories`)."""
    kept = getattr(_KEPT, "backends", None)
    if kept is None:
        kept = _KEPT.backends = {}
    backend = kept.get(settings)
    if backend is None:
        while len(kept) >= REUSABLE_SETTINGS:
            kept.pop(next(iter(kept)))
        backend = kept[settings] = IdaCompiledBackend(settings)
    return backend


def runs_compiled(settings: SolverSettings, model) -> bool:
    """Whether a run of `model` with these settings ran on the compiled callbacks (`ida-compiled`, or `auto` where
    it chose them in this process), so that what re-integrates it (the located peaks' readings) can too."""
    if settings.backend == "ida-compiled":
        return unavailable() is None
    if settings.backend != "auto":
        return False
    from mechsim.dynamics.programs import structure
    return bool(AutoBackend._CHOSEN.get(structure(model), (False,))[0]) and unavailable() is None


class AutoBackend(Backend):
    """The default (`solver.backend = "auto"`): `ida-compiled` for a model whose callbacks are compiled already
    (cached on disk once per machine), else `ida`, with the model's callbacks then compiled in a background
    process for the runs after. Both run the same IDA algorithm (docs/benchmarks.md, "The default backend").

    The choice is made once per model and process, at its first run in the process, so that every run of a model
    in one process is computed the same way; a process that starts after the background compilation has
    finished runs the model compiled. Where the compiled path is unavailable (`unavailable`), every run is on
    `ida`, with a one-line note when the cause is another SUNDIALS release.
    """

    name = "auto"
    _CHOSEN: dict = {}        # the model's structure (dynamics/programs.py) -> (compiled?, model): the choice

    def __init__(self, settings: SolverSettings):
        self.settings = settings
        self._ida = IdaBackend(settings)
        reason = unavailable()
        if isinstance(reason, SundialsVersionMismatch):
            note(f"{reason}: the default solver.backend runs on 'ida' (the same IDA through scikit-sundae's "
                 "binding)")
        self._compiled = reason is None      # whether the compiled path can run here
        self._use(self._ida)
        self._inner = None

    def _use(self, inner: Backend) -> None:
        self._inner = inner
        for key in ("name", "solver", "initial_step", "recoverable", "unavailable", "notes"):
            setattr(self, key, getattr(inner, key))

    def choose(self, model) -> Backend:
        """The backend for `model` in this process (chosen at the model's first run here, then kept)."""
        from mechsim.dynamics.backends import compiled_model
        from mechsim.dynamics.programs import structure
        key = structure(model)
        compiled = self._CHOSEN.get(key, (None,))[0]
        if compiled is None:
            compiled = False
            if self._compiled:
                folder = cache_dir() / "compiled"
                compiled = compiled_model.ready(model.modes.values(), folder)
                if not compiled:
                    compiled_model.compile_in_background(model.modes.values(), folder, model.recipe)
            self._CHOSEN[key] = (compiled, model)     # the model kept alive: a structure by identity stays valid
        compiled = compiled and self._compiled   # another instance may have chosen where this one can't
        if compiled and not isinstance(self._inner, IdaCompiledBackend):
            self._use(reusable(self.settings))      # the thread's, as the readings': none is built per run
        elif not compiled and self._inner is not self._ida:
            self._use(self._ida)
        return self._inner

    def whole_run(self, mech, start, t0: float, t_end: float, progress=None):
        """Chooses the backend for the run's model before the hybrid loop starts (so that the run's statistics
        are the chosen backend's); returns None: the run goes segment by segment."""
        self.choose(start.model)
        return None

    def integrate(self, request: Request) -> Segment:
        return self.choose(request.model).integrate(request)

    def hint(self, code: FailureCode) -> str:
        return self._inner.hint(code)
