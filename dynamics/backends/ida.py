"""The IDA backend (SUNDIALS IDA through scikit-sundae): one smooth segment from a consistent state to the
next guard or the end, under the contract of `dynamics/backend.py`.

The residual, exact Jacobian and guards are the generated plain-Python functions of `model`; the mode's
parameter tuple travels as IDA's userdata.
"""
from __future__ import annotations

import contextlib
import io
import math

import numpy as np

from mechsim.dynamics.backend import FRESH_STEP_FRACTION, Backend, End, Request, Segment
from mechsim.dynamics.model import ModeFunctions
from mechsim.dynamics.result import FailureCode
from mechsim.dynamics.settings import SolverSettings

#: callables `observer(solver, solution, neq)` run after every IDA solve: the documented way for a benchmark to
#: read IDA's own counters (benchmarks/ida_counters.py), which scikit-sundae does not return
SOLVE_OBSERVERS: list = []


def atol_vector(mf: ModeFunctions, settings: SolverSettings, scales: np.ndarray | None = None) -> np.ndarray:
    """Per-component absolute tolerances: multipliers loose (see SolverSettings.multiplier_atol)."""
    atol = np.full(mf.ny, settings.atol)
    atol[mf.index["lam"]] = settings.lam_atol
    atol[mf.index["mu"]] = settings.lam_atol
    if scales is not None:
        atol[mf.index["work"]] = settings.atol * np.maximum(1.0, scales)
    return atol


#: IDA's return flag for "max_num_steps reached" (IDA_TOO_MUCH_WORK in the SUNDIALS IDA guide)
IDA_TOO_MUCH_WORK = -1


class IdaBackend(Backend):
    """SUNDIALS IDA (variable-order BDF) on the mode's residual F(t, y, y') = 0 with its exact Jacobian."""

    name = "ida"
    initial_step = 0.0
    #: IDA's error or convergence test failing (often right after a restart) and its step budget: the loop
    #: re-initialises and restarts (`hybrid.recover`) before it gives up
    recoverable = frozenset({FailureCode.INTEGRATOR_FAILED, FailureCode.MAX_STEPS})
    unavailable = {key: "scikit-sundae returns IDA's residual and Jacobian counts only (`mechsim bench` reads "
                        "IDA's own step counters)" for key in ("steps", "accepted_steps", "rejected_steps")}
    notes: dict = {}

    def __init__(self, settings: SolverSettings):
        self.settings = settings
        self.solver = f"IDA (BDF, {settings.formulation})"

    def integrate(self, request: Request) -> Segment:
        r = request
        return integrate_segment(r.mf, r.p, r.t0, r.y0, r.yp0, r.t_out, r.t_end, self.settings, r.first_step)

    def hint(self, code: FailureCode) -> str:
        formulation = self.settings.formulation
        if formulation == "index3":             # the likely cause, whichever way IDA gave up
            return ("the index-3 form is the likely cause: its Newton matrix is conditioned like h^-3 and the "
                    "error test breaks down at restarts and tight tolerances (docs/theory.md §K4); use "
                    "formulation = 'index2'")
        if code is FailureCode.MAX_STEPS:       # IDA_TOO_MUCH_WORK: its step budget between two output rows spent
            return (f"IDA took solver.max_steps = {self.settings.max_steps} steps without reaching the next output "
                    "row: raise solver.max_steps, or shorten output_step; if it is spent at any budget, check for a "
                    "singular configuration at this point")
        other = "index2" if formulation == "index1" else "index1"
        return (f"tighten or loosen rtol; formulation = '{other}' (or solver.backend = 'diffrax') where "
                f"{formulation} fails; check for a singular configuration at this point")


def _failed(t, y, yp, t_end, y_end, yp_end, sol, settings) -> Segment:
    code = FailureCode.MAX_STEPS if int(sol.status) == IDA_TOO_MUCH_WORK else FailureCode.INTEGRATOR_FAILED
    what = "IDA failed on the index-3 formulation" if settings.formulation == "index3" else "IDA failed"
    return Segment(t, y, yp, End.FAILED, t_end, y_end, yp_end, code=code, message=f"{what}: {sol.message}",
                   counts=dict(residual_evaluations=sol.nfev, jacobian_evaluations=sol.njev))


def resolving_first_step(settings: SolverSettings, atol: np.ndarray, t0: float, y0: np.ndarray, yp0: np.ndarray,
                         t_first: float, t_end: float) -> float:
    """IDA's first step: 0 (its own estimate) unless that estimate cannot move t, then FRESH_STEP_FRACTION of
    the segment's span.

    IDA's estimate is min(0.001 |t_first - t0|, 0.5 / ||y'0||) in its weighted RMS norm, weights
    1/(rtol |y| + atol) (SUNDIALS IDA guide, IDASolve's initial step). At tight tolerances right after an entry
    (a wheel at rest, |v| ~ atol, its acceleration jumping) that is below half a unit of round-off of t: t0 + h
    rounds to t0, and the Newton iteration on differences of y at the round-off level of its positions fails
    and succeeds by turns until the step budget is spent."""
    h = 1e-3 * abs(t_first - t0)
    z = yp0 / (settings.rtol * np.abs(y0) + atol)
    ypnorm = math.sqrt(float(np.add.reduce(z * z)) / z.size)     # np.mean's sum and division, without its wrapping
    if ypnorm * h > 0.5:
        h = 0.5 / ypnorm
    return 0.0 if t0 + h != t0 else FRESH_STEP_FRACTION * (t_end - t0)


def solve_quietly(solver, tspan: np.ndarray, y0: np.ndarray, yp0: np.ndarray):
    """`solver.solve` (scikit-sundae's IDA) without its error handler's lines ("[IDASolve, Error: -22] At t = ...")
    on the caller's stdout: its solution's flag and message say the same, and the callers report them."""
    with contextlib.redirect_stdout(io.StringIO()):
        return solver.solve(tspan, y0, yp0)


def integrate_segment(mf: ModeFunctions, p: tuple, t0: float, y0: np.ndarray, yp0: np.ndarray,
                      t_out: np.ndarray, t_end: float, settings: SolverSettings, first_step: float = 0.0) -> Segment:
    """Integrate from t0 through the output times t_out (all > t0, <= t_end) until a guard or t_end.

    first_step: IDA's initial step (0: its own estimate)."""
    from sksundae.ida import IDA        # with scipy.optimize: only where this backend solves (not on ida-compiled)
    atol = atol_vector(mf, settings)
    tspan = np.concatenate([[t0], t_out[t_out > t0], [] if (len(t_out) and t_out[-1] >= t_end) else [t_end]])
    if len(tspan) == 2:
        tspan = np.array([t0, 0.5 * (t0 + t_end), t_end])  # force output at the given times
    if first_step == 0.0:
        first_step = resolving_first_step(settings, atol, t0, y0, yp0, tspan[1], t_end)
    opts = dict(first_step=first_step,
        userdata=p, rtol=settings.rtol, atol=atol, algebraic_idx=mf.algebraic or None,
        jacfn=mf.jacobian if settings.jacobian == "exact" else None, max_num_steps=settings.max_steps, linsolver="dense",
    )
    n_ev = len(mf.guard_names) if settings.events else 0
    if n_ev:
        events = mf.events

        def eventsfn(t, y, yp, out, ud):
            events(t, y, yp, out, ud)

        eventsfn.terminal = [True] * n_ev
        eventsfn.direction = list(mf.guard_directions)
        opts.update(eventsfn=eventsfn, num_events=n_ev)
    solver = IDA(mf.residual, **opts)
    sol = solve_quietly(solver, tspan, y0, yp0)     # the Segment carries a failure: recovered or reported
    for observe in SOLVE_OBSERVERS:
        observe(solver, sol, len(y0))
    t, y, yp = np.asarray(sol.t), np.asarray(sol.y), np.asarray(sol.yp)
    counts = dict(residual_evaluations=sol.nfev, jacobian_evaluations=sol.njev)
    # rows at requested output instants only (tspan[0] is the start; a terminal event is appended last)
    requested = np.isin(t, t_out) & (t > t0)
    if sol.t_events is not None and len(sol.t_events) and sol.success:
        ie = np.asarray(sol.i_events)[-1]
        fired = tuple(int(i) for i in np.flatnonzero(ie))
        te = float(np.asarray(sol.t_events)[-1])
        requested &= t < te
        return Segment(t[requested], y[requested], yp[requested], End.GUARD, te, np.asarray(sol.y_events)[-1],
                       np.asarray(sol.yp_events)[-1], fired=fired, counts=counts)
    if not sol.success:
        return _failed(t[requested], y[requested], yp[requested], float(t[-1]), y[-1], yp[-1], sol, settings)
    return Segment(t[requested], y[requested], yp[requested], End.END, float(t[-1]), y[-1], yp[-1], counts=counts)
