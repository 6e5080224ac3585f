"""What the diffrax backend and its compiled whole run share: the options of one compiled solve, the solver they
name, and the state layout between the mode's IDA rows y = [q, v, lam, mu, work, ext] and the ODE state
z = [q, v, work, ext] that diffrax integrates.
"""
from __future__ import annotations

from dataclasses import dataclass, replace
from functools import lru_cache

import numpy as np

from mechsim.dynamics.jax_model import jax_model  # noqa: F401  (switches on float64 before diffrax loads)
from mechsim.dynamics.model import ModeFunctions
from mechsim.dynamics.settings import SolverSettings

import diffrax  # noqa: E402
import jax.numpy as jnp  # noqa: E402
import optimistix as optx  # noqa: E402

EXPLICIT = ("Tsit5", "Dopri5", "Dopri8", "Bosh3", "Heun", "Midpoint", "Ralston", "Euler")
IMPLICIT = ("Kvaerno3", "Kvaerno4", "Kvaerno5", "ImplicitEuler")
SOLVERS = EXPLICIT + IMPLICIT
#: first trial step (s) of a run; the step controller grows it by up to 10x per accepted step
DT0_FIRST = 1e-5
DT0_FLOOR = 1e-12


@dataclass(frozen=True)
class DiffraxOptions:
    """Everything that shapes one compiled solve (hashable: part of the compilation cache key).

    pcoeff/icoeff/dcoeff: PID step-size controller gains (diffrax.PIDController; I-only is 0/1/0).
    newton: root finder of implicit stages: "verychord" (diffrax's default), "patient" (the same with its
        termination test corrected, see PatientVeryChord), "chord" or "newton"
        (optimistix, with their Cauchy termination on |f| < atol).
    newton_tol: tolerance of that root finder as a multiple of the step controller's rtol/atol.
    newton_kappa: the contraction criterion of the chord/Newton iterations.
    event_rtol/event_atol: width (relative, absolute in s) to which the bisection brackets a guard crossing.
    n_save: output rows per compiled call (padded); longer segments continue in chunks. None: 2048 state
        values (256 rows of the Geneva's 8 states, at least 32 rows). diffrax's SaveAt(ts) carries its save buffer
        through the step loop and a too large one makes every step slower (geneva-motor, warm CPU time: 0.19 s
        with 32 rows, 0.05 s with 256, 0.19 s with 512; docs/diffrax.md).
    projection: project q and v onto the constraints at every restart (mode change or chunk boundary).
    compiled_run: run the whole hybrid run as one compiled call (`dynamics/backends/diffrax_run.py`) where the mechanism
        has a transition table (`Mechanism.transitions`), the solver is explicit and events are on;
        False (or any of those missing): one compiled solve per segment, transitions in Python.
    """

    solver: str = "Tsit5"
    rtol: float = 1e-8
    atol: float = 1e-10
    max_steps: int = 20000
    pcoeff: float = 0.0
    icoeff: float = 1.0
    dcoeff: float = 0.0
    newton: str = "verychord"
    newton_tol: float = 1.0
    newton_kappa: float = 1e-2
    newton_floor: float = 1e-3
    event_rtol: float = 1e-14
    event_atol: float = 1e-13
    n_save: int | None = None
    projection: bool = True
    compiled_run: bool = True

    @property
    def implicit(self) -> bool:
        return self.solver in IMPLICIT

    def rows(self, nz: int) -> int:
        """Output rows per compiled call for a state of nz values."""
        return self.n_save if self.n_save else max(32, 2048 // max(nz, 1))


#: Defaults for implicit solvers, picked by measurement (docs/diffrax.md).
IMPLICIT_DEFAULTS = dict(newton="patient", newton_kappa=0.1)


def default_options(settings: SolverSettings) -> DiffraxOptions:
    """The options a scenario's solver settings imply (implicit solvers get the best defaults of docs/diffrax.md)."""
    name = settings.diffrax_solver
    if name not in SOLVERS:
        raise ValueError(f"solver.diffrax_solver must be one of {', '.join(SOLVERS)}; got {name!r}")
    opts = DiffraxOptions(solver=name, rtol=settings.rtol, atol=settings.atol, max_steps=settings.max_steps,
                          projection=getattr(settings, "diffrax_projection", True),
                          compiled_run=settings.diffrax_compiled_run)
    if opts.implicit:
        opts = replace(opts, **IMPLICIT_DEFAULTS)
    return opts


# -- the solver ------------------------------------------------------------------------------------------------
class PatientVeryChord(diffrax.VeryChord):
    """diffrax's VeryChord with a corrected termination test (the cause of diffrax 0.7.2's rejected steps).

    In diffrax 0.7.2 `VeryChord.terminate` reports `nonlinear_divergence` whenever, from the second iteration on,
    the iteration has not yet converged, even while it is contracting; optimistix stops at the first
    non-successful result, so every stage that needs a third chord iteration fails, the step's error becomes
    inf and the step is rejected (about half the steps, docs/diffrax.md). Here divergence means divergence:
    the corrections grow (rate > 2) or are not finite. The iteration also stops when a correction is already
    below `floor` tolerance units, where the rate of two round-off-sized corrections is noise.
    """

    floor: float = 1e-3

    def terminate(self, fn, y, args, options, state, tags):
        at_least_two = state.step >= 2
        rate = state.diffsize / state.diffsize_prev
        factor = state.diffsize * rate / (1 - rate)
        tiny = (state.step >= 1) & (state.diffsize < self.floor)
        converged = tiny | (at_least_two & (factor > 0) & (factor < self.kappa))
        diverged = at_least_two & jnp.invert(tiny) & (jnp.invert(jnp.isfinite(rate)) | (rate > 2))
        linsolve_fail = state.result != optx.RESULTS.successful
        result = optx.RESULTS.where(diverged, optx.RESULTS.nonlinear_divergence, optx.RESULTS.successful)
        result = optx.RESULTS.where(linsolve_fail, state.result, result)
        return converged | diverged | linsolve_fail, result


def _stage_root_finder(o: DiffraxOptions):
    rtol, atol = o.newton_tol * o.rtol, o.newton_tol * o.atol
    if o.newton == "verychord":
        return diffrax.VeryChord(rtol=rtol, atol=atol, kappa=o.newton_kappa)
    if o.newton == "patient":
        return PatientVeryChord(rtol=rtol, atol=atol, kappa=o.newton_kappa, floor=o.newton_floor)
    if o.newton == "chord":
        return optx.Chord(rtol=rtol, atol=atol, kappa=o.newton_kappa, cauchy_termination=True)
    if o.newton == "newton":
        return optx.Newton(rtol=rtol, atol=atol, kappa=o.newton_kappa, cauchy_termination=True)
    raise ValueError(f"unknown implicit root finder {o.newton!r}")


def solver_for(o: DiffraxOptions):
    cls = getattr(diffrax, o.solver)
    return cls(root_finder=_stage_root_finder(o)) if o.implicit else cls()


@lru_cache(maxsize=64)
def evaluations_per_step(o: DiffraxOptions) -> int | None:
    """Vector-field evaluations per attempted step of an explicit Runge-Kutta method (None if implicit)."""
    if o.implicit:
        return None
    tab = getattr(solver_for(o), "tableau", None)
    if tab is None:
        return {"Euler": 1}.get(o.solver)
    stages = len(tab.c) + 1
    return stages - 1 if tab.fsal else stages


# -- the solves' inputs ------------------------------------------------------------------------------------------
def save_times(times, t0: float, t1: float, n: int) -> np.ndarray:
    """The n output times of a segment solve's `SaveAt(ts=...)`: `times` (at most n), padded with t1.

    diffrax checks its save times inside the compiled program, where mechsim's processes make a failed check
    return NaN rather than raise (`xla_options.checks_without_callbacks`): they are checked here instead, in
    diffrax's words, so that a broken caller still stops with an error, never with rows silently dropped."""
    ts = np.full(n, t1, dtype=np.float64)
    ts[:len(times)] = times
    d = 1.0 if t0 < t1 else -1.0            # diffrax's checks, in its normalised time (`diffeqsolve`)
    if np.any(d * ts[1:] < d * ts[:-1]):
        raise RuntimeError("saveat.ts must be increasing or decreasing.")
    if np.any((d * ts > d * t1) | (d * ts < d * t0)):
        raise RuntimeError("saveat.ts must lie between t0 and t1.")
    return ts


# -- state layout ----------------------------------------------------------------------------------------------
def mode_z(mf: ModeFunctions, y: np.ndarray) -> np.ndarray:
    ix = mf.index
    return np.concatenate([y[ix["q"]], y[ix["v"]], y[ix["work"]], y[ix["ext"]]])


def ida_rows(mf: ModeFunctions, nq: int, z: np.ndarray, zp: np.ndarray, a: np.ndarray, lam: np.ndarray
              ) -> tuple[np.ndarray, np.ndarray]:
    """Rows (y, y') in the IDA layout of the mode: y = [q, v, lam, mu = 0, work, ext], y' = [v, a, 0, 0, ...]."""
    z, zp, a, lam = (np.atleast_2d(x) for x in (z, zp, a, lam))
    n = len(z)
    n_mu = mf.index["mu"].stop - mf.index["mu"].start
    y = np.hstack([z[:, :2 * nq], lam[:, :mf.m], np.zeros((n, n_mu)), z[:, 2 * nq:]])
    yp = np.hstack([z[:, nq:2 * nq], a, np.zeros((n, mf.m + n_mu)), zp[:, 2 * nq:]])
    return y, yp


def state_rows(mf: ModeFunctions, nq: int, z: np.ndarray) -> np.ndarray:
    """Rows y in the IDA layout of the mode from states z = [q, v, work, ext], the multiplier columns (lam, mu)
    NaN: the compiled whole run interpolates states only, and the read-outs solve the KKT system at every row
    from (q, v) (`tables.kkt_rows`); `hybrid.Piece`."""
    n, width = z.shape
    n_alg = mf.index["mu"].stop - mf.index["lam"].start
    y = np.empty((n, width + n_alg), dtype=np.result_type(z.dtype, float))   # filled in place: cheaper than a hstack
    y[:, :2 * nq] = z[:, :2 * nq]
    y[:, 2 * nq:2 * nq + n_alg] = np.nan
    y[:, 2 * nq + n_alg:] = z[:, 2 * nq:]
    return y


def result_message(code: int) -> str:
    """diffrax's words for a solve's result code, first line (diffrax keeps its message table private: read
    in this one place)."""
    return diffrax.RESULTS._index_to_message[int(code)].splitlines()[0]
