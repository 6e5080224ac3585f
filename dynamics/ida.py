"""One smooth segment on SUNDIALS IDA (scikit-sundae): from a consistent state to the next guard or the end.

The residual, exact Jacobian and guards are the generated plain-Python functions of `model`; the mode's
parameter tuple travels as IDA's userdata.
"""
from __future__ import annotations

from dataclasses import dataclass

import numpy as np
from sksundae.ida import IDA

from mechsim.dynamics.model import ModeFunctions
from mechsim.dynamics.settings import SolverSettings

#: callables `observer(solver, solution, neq)` run after every IDA solve: the documented way for a benchmark to
#: read IDA's own counters (benchmarks/ida_counters.py), which scikit-sundae does not return
SOLVE_OBSERVERS: list = []


@dataclass
class Segment:
    """Output of one segment: rows at the requested output times, and how it ended."""

    t: np.ndarray
    y: np.ndarray
    yp: np.ndarray
    status: str                   # "end", "event" or "failed"
    t_end: float
    y_end: np.ndarray
    yp_end: np.ndarray
    guard: int | None = None
    message: str = ""
    nfev: int = 0
    njev: int = 0
    fired: tuple[int, ...] = ()   # every guard that found a root at t_end (guard is the first of them)
    ida_status: int = 0           # IDA's return flag (-1: max_num_steps reached; other negatives: failures)


def atol_vector(mf: ModeFunctions, settings: SolverSettings, scales: np.ndarray | None = None) -> np.ndarray:
    """Per-component absolute tolerances: multipliers loose (see SolverSettings.multiplier_atol)."""
    atol = np.full(mf.ny, settings.atol)
    atol[mf.index["lam"]] = settings.lam_atol
    atol[mf.index["mu"]] = settings.lam_atol
    if scales is not None:
        atol[mf.index["work"]] = settings.atol * np.maximum(1.0, scales)
    return atol


def integrate_segment(mf: ModeFunctions, p: tuple, t0: float, y0: np.ndarray, yp0: np.ndarray,
                      t_out: np.ndarray, t_end: float, settings: SolverSettings, first_step: float = 0.0) -> Segment:
    """Integrate from t0 through the output times t_out (all > t0, <= t_end) until a guard or t_end.

    first_step: IDA's initial step (0: its own estimate)."""
    opts = dict(first_step=first_step,
        userdata=p, rtol=settings.rtol, atol=atol_vector(mf, settings), algebraic_idx=mf.algebraic or None,
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
    tspan = np.concatenate([[t0], t_out[t_out > t0], [] if (len(t_out) and t_out[-1] >= t_end) else [t_end]])
    if len(tspan) == 2:
        tspan = np.array([t0, 0.5 * (t0 + t_end), t_end])  # force output at the given times
    sol = solver.solve(tspan, y0, yp0)
    for observe in SOLVE_OBSERVERS:
        observe(solver, sol, len(y0))
    t, y, yp = np.asarray(sol.t), np.asarray(sol.y), np.asarray(sol.yp)
    # rows at requested output instants only (tspan[0] is the start; a terminal event is appended last)
    requested = np.isin(t, t_out) & (t > t0)
    if sol.t_events is not None and len(sol.t_events) and sol.success:
        ie = np.asarray(sol.i_events)[-1]
        fired = tuple(int(i) for i in np.flatnonzero(ie))
        te = float(np.asarray(sol.t_events)[-1])
        requested &= t < te
        return Segment(t[requested], y[requested], yp[requested], "event", te, np.asarray(sol.y_events)[-1],
                       np.asarray(sol.yp_events)[-1], fired[0], nfev=sol.nfev, njev=sol.njev, fired=fired)
    if not sol.success:
        return Segment(t[requested], y[requested], yp[requested], "failed", float(t[-1]), y[-1], yp[-1],
                       message=str(sol.message), nfev=sol.nfev, njev=sol.njev, ida_status=int(sol.status))
    return Segment(t[requested], y[requested], yp[requested], "end", float(t[-1]), y[-1], yp[-1],
                   nfev=sol.nfev, njev=sol.njev)
