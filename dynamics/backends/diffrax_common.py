"""What the diffrax backend and its compiled whole run share: the options of one compiled solve, and the state
layout between the mode's IDA rows y = [q, v, lam, mu, work, ext] and the ODE state z = [q, v, work, ext] that
diffrax integrates. diffrax itself is not imported here: its objects are traced into the programs
(dynamics/backends/diffrax_solvers.py), and a process that loads its programs (dynamics/traced.py) runs them
without it.
"""
from __future__ import annotations

from dataclasses import dataclass, replace

import numpy as np

from mechsim.dynamics.model import ModeFunctions
from mechsim.dynamics.settings import SolverSettings

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
#: vector-field evaluations per attempted step of each explicit Runge-Kutta method: its tableau's stages, less
#: one where the last stage is the next step's first (FSAL); tests/test_diffrax_backend.py reads them off
#: diffrax's tableaux. A table here, so that a process that loads its compiled programs never imports diffrax.
EVALUATIONS_PER_STEP = {"Tsit5": 6, "Dopri5": 6, "Dopri8": 13, "Bosh3": 3, "Heun": 2, "Midpoint": 2, "Ralston": 2,
                        "Euler": 1}


def evaluations_per_step(o: DiffraxOptions) -> int | None:
    """Vector-field evaluations per attempted step of an explicit Runge-Kutta method (None if implicit)."""
    return None if o.implicit else EVALUATIONS_PER_STEP.get(o.solver)


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
