"""The hybrid loop: integrate a mode, find its guard, apply the transition, re-initialise, go on.

One loop serves every mechanism; everything mechanism-specific comes through the `Mechanism` interface.
Each transition is an events-table row (time, from, to, kind, kinetic energy before and after).
"""
from __future__ import annotations

import time as _time
from dataclasses import dataclass, field
from typing import Callable

import numpy as np

from mechsim.mechanisms.base import Mechanism

from mechsim.dynamics.consistent import consistent_state
from mechsim.dynamics.drives import Drive
from mechsim.dynamics.ida import integrate_segment
from mechsim.dynamics.model import DerivedModel, StateExtension, derive
from mechsim.dynamics.result import FailureCode
from mechsim.dynamics.stats import new_stats
from mechsim.dynamics.transitions import apply_transition, chattering, rebased, stepped_over_failure
from mechsim.dynamics.settings import SolverSettings


@dataclass
class Piece:
    """Output rows of one segment with the mode and parameters that produced them."""

    mode: str
    params: tuple
    t: np.ndarray
    y: np.ndarray
    yp: np.ndarray
    offset: np.ndarray | None = None   # added to y's coordinates for output (re-based frame, see transitions.rebased)

    def coordinates(self, ix: slice) -> np.ndarray:
        """The unwrapped coordinates of the rows (y's q plus the re-based offset)."""
        q = self.y[:, ix]
        return q if self.offset is None else q + self.offset


@dataclass
class Trajectory:
    """Raw hybrid solution, before read-outs are evaluated."""

    model: DerivedModel
    pieces: list[Piece]
    events: list[dict]
    stats: dict
    failure: dict | None = None
    warnings: list[str] = field(default_factory=list)


def parameter_tuple(model: DerivedModel, values: dict[str, float]) -> tuple:
    missing = [n for n in model.parameter_names if n not in values]
    if missing:
        raise KeyError(f"missing parameter values: {missing}")
    return tuple(float(values[n]) for n in model.parameter_names)


@dataclass
class Start:
    """A run's derived model, parameter values, output times and consistent initial state."""

    model: DerivedModel
    derive_time: float
    values: dict
    mode: str
    t_out: np.ndarray
    mf: object
    p: tuple
    y: np.ndarray
    yp: np.ndarray
    offset: np.ndarray


def prepare(mech: Mechanism, drive: Drive, settings: SolverSettings, t_end: float, dt_out: float, angle0: float,
            speed0: float, ext: StateExtension | None = None, ext_initial=None, t0: float = 0.0) -> Start:
    """Everything a backend needs before its first segment (shared by the IDA and diffrax loops)."""
    wall0 = _time.perf_counter()
    model = derive(mech, settings.formulation, drive.is_prescribed, ext)
    derive_time = _time.perf_counter() - wall0
    values = dict(mech.parameter_values())
    values.update(drive.parameter_values(angle0, t0))
    values.update(baumgarte_alpha=settings.baumgarte_alpha, baumgarte_beta=settings.baumgarte_beta)
    if ext:
        values.update(ext.parameter_values())
    init = mech.initial_state(angle0, speed0)
    values.update(init.updates)
    n_out = int(np.floor((t_end - t0) / dt_out + 1e-9))
    t_out = np.minimum(t0 + dt_out * np.arange(1, n_out + 1), t_end)   # round-off must not pass t_end
    if t_out.size == 0 or t_out[-1] < t_end - 1e-12:
        t_out = np.append(t_out, t_end)
    mf = model.modes[init.mode]
    values, q_init, offset = rebased(mech, model, values, t0, np.asarray(init.q, dtype=float),
                                     np.zeros(len(model.coordinates)))
    p = parameter_tuple(model, values)
    work0 = np.zeros(len(model.work_names))
    x0 = np.zeros(len(model.extension_names)) if ext_initial is None else np.asarray(ext_initial, float)
    try:
        y, yp, _ = consistent_state(mf, t0, q_init, init.v, work0, x0, p)
    except (ValueError, np.linalg.LinAlgError) as exc:
        raise ValueError(f"initial state: {exc}") from None
    return Start(model, derive_time, values, init.mode, t_out, mf, p, y, yp, offset)


def simulate(mech: Mechanism, drive: Drive, settings: SolverSettings, t_end: float, dt_out: float,
             angle0: float, speed0: float, ext: StateExtension | None = None, ext_initial=None,
             progress: Callable[[float], None] | None = None, t0: float = 0.0) -> Trajectory:
    """Integrate the hybrid DAE from t0 to t_end with outputs every dt_out."""
    start = prepare(mech, drive, settings, t_end, dt_out, angle0, speed0, ext, ext_initial, t0)
    model, values, mode, t_out, mf, p, y, yp, offset = (start.model, start.values, start.mode, start.t_out,
                                                         start.mf, start.p, start.y, start.yp, start.offset)
    derive_time = start.derive_time
    pieces = [Piece(mode, p, np.array([t0]), y[None, :].copy(), yp[None, :].copy(), offset)]
    events: list[dict] = []
    stats = new_stats("ida", f"IDA (BDF, {settings.formulation})", derive_time, unavailable={
        key: "scikit-sundae returns IDA's residual and Jacobian counts only (`mechsim bench` reads IDA's own "
             "step counters)" for key in ("steps", "accepted_steps", "rejected_steps")})
    failure = None
    warnings: list[str] = []
    t = t0
    last = None
    first_step = 0.0
    in_row = 0
    solve0 = _time.perf_counter()
    while t < t_end - 1e-12:
        seg = integrate_segment(mf, p, t, y, yp, t_out[t_out > t], t_end, settings, first_step)
        stats["segments"] += 1
        stats["residual_evaluations"] += seg.nfev
        stats["jacobian_evaluations"] += seg.njev
        crossed = None if settings.events else stepped_over(mf, p, t, y, yp, seg)
        if crossed:
            seg.t, seg.y, seg.yp = seg.t[:crossed["rows"]], seg.y[:crossed["rows"]], seg.yp[:crossed["rows"]]
        if len(seg.t):
            pieces.append(Piece(mode, p, seg.t, seg.y, seg.yp, offset))
        if progress:
            progress(seg.t_end)
        if crossed:
            failure = dict(stepped_over_failure(model, mode, dict(crossed, q=crossed["q"] + offset)),
                           code=FailureCode.STEPPED_OVER)
            break
        if seg.status == "failed":
            recovered = recover(mf, p, seg, in_row, t_end)
            if recovered is not None:
                # IDA gave up (error or convergence test): restart from its last state, re-initialised
                # consistently (a fresh order-1 history) with a small first step; at most twice per instant
                t, y, yp, first_step = recovered
                in_row += 1
                stats["recoveries"] += 1
                continue
            q = seg.y_end[mf.index["q"]] + offset
            reason, hint = f"IDA failed: {seg.message}", (
                "tighten or loosen rtol; formulation = 'index1' (or solver.backend = 'diffrax') where index2 fails; "
                "check for a singular configuration at this point")
            if settings.formulation == "index1":
                hint = ("tighten or loosen rtol; formulation = 'index2' (or solver.backend = 'diffrax'); check for "
                        "a singular configuration at this point")
            if settings.formulation == "index3":
                reason = f"IDA failed on the index-3 formulation: {seg.message}"
                hint = ("the index-3 form is the likely cause: its Newton matrix is conditioned like h^-3 and the "
                        "error test breaks down at restarts and tight tolerances (docs/theory.md §K4); use "
                        "formulation = 'index2'")
            code = FailureCode.MAX_STEPS if seg.ida_status == IDA_TOO_MUCH_WORK else FailureCode.INTEGRATOR_FAILED
            if not np.all(np.isfinite(seg.y_end)):
                code = FailureCode.NON_FINITE
            failure = dict(time=seg.t_end, mode=mode, reason=reason, code=code,
                           where={c: float(v) for c, v in zip(model.coordinates, q)}, hint=hint)
            break
        first_step, in_row = 0.0, 0
        if seg.status == "end":
            t = seg.t_end
            break
        # a guard fired
        t = seg.t_end
        ix = mf.index
        q = seg.y_end[ix["q"]]
        guard = mf.guard_names[seg.guard]
        failure = chattering(model, mode, guard, t, q + offset, last)
        if failure:
            failure = dict(failure, code=FailureCode.CHATTERING)
            break
        last = (guard, t)
        stats["events"] += 1
        out = apply_transition(mech, model, parameter_tuple, mode, values, t, seg.y_end, [seg.guard, *seg.fired[1:]],
                               offset)
        events += out.rows
        warnings += out.warnings
        if out.failure:
            failure = dict(out.failure, code=transition_failure_code(out.failure))
            break
        mode, values, p, y, yp, offset = out.mode, out.values, out.p, out.y, out.yp, out.offset
        mf = model.modes[mode]
        stats["restarts"] += 1
    stats["solve_time_s"] = _time.perf_counter() - solve0
    return Trajectory(model, pieces, events, stats, failure, warnings)


#: IDA's return flag for "max_num_steps reached" (IDA_TOO_MUCH_WORK in the SUNDIALS IDA guide)
IDA_TOO_MUCH_WORK = -1


def transition_failure_code(failure: dict) -> FailureCode:
    """The code of a failure that `apply_transition` reports: a physical stop, or a failed re-initialisation."""
    if failure.get("kind", "solver") != "solver":
        return FailureCode.PHYSICAL_STOP
    return FailureCode.REINITIALISATION_FAILED


#: restarts of failed segments allowed in a row (without a segment that ends normally) before giving up
MAX_RECOVERIES = 2


def recover(mf, p: tuple, seg, in_row: int, t_end: float):
    """(t, y, yp, first_step) to restart a failed IDA segment from, or None when not possible.

    IDA's last reached state is re-initialised consistently (positions to round-off, velocities, accelerations
    and multipliers from the KKT system: `consistent_state`) and restarted with a fresh order-1 history and a
    first step of 1e-6 of the remaining time (IDA's own estimate is what failed). More than MAX_RECOVERIES
    failures in a row, a non-finite state or a state that cannot be made consistent gives up.
    """
    t = float(seg.t_end)
    if in_row >= MAX_RECOVERIES:
        return None
    if not (np.all(np.isfinite(seg.y_end)) and t < t_end):
        return None
    ix = mf.index
    try:
        y, yp, _ = consistent_state(mf, t, seg.y_end[ix["q"]], seg.y_end[ix["v"]], seg.y_end[ix["work"]],
                                    seg.y_end[ix["ext"]], p)
    except (ValueError, np.linalg.LinAlgError):
        return None
    return t, y, yp, 1e-6 * (t_end - t)


def stepped_over(mf, p: tuple, t0: float, y0: np.ndarray, yp0: np.ndarray, seg) -> dict | None:
    """The first guard that crossed zero in its direction between the segment's start, its output rows and its
    end, or None (for runs with events disabled, where the integrator does not root-find the guards).

    A guard exactly zero at the start is not counted (as IDA ignores roots at the initial point).
    Returns the guard, the times around the crossing, the number of output rows before it and q just after.
    """
    n = len(mf.guard_names)
    if not n:
        return None
    times = np.concatenate([[t0], seg.t, [seg.t_end]])
    ys = np.vstack([y0[None, :], seg.y, seg.y_end[None, :]])
    yps = np.vstack([yp0[None, :], seg.yp, seg.yp_end[None, :]])
    g = np.empty((len(times), n))
    for i, (ti, yi, ypi) in enumerate(zip(times, ys, yps)):
        mf.events(ti, yi, ypi, g[i], p)
    a, b = g[:-1], g[1:]
    d = np.asarray(mf.guard_directions)
    rising, falling = (a < 0) & (b >= 0), (a > 0) & (b <= 0)
    cross = np.where(d > 0, rising, np.where(d < 0, falling, rising | falling))
    cross[0] &= g[0] != 0
    hits = np.argwhere(cross)
    if not len(hits):
        return None
    k, j = hits[0]                       # the earliest sample (argwhere is in row order)
    return dict(guard=mf.guard_names[j], before=float(times[k]), after=float(times[k + 1]), rows=int(k),
                q=ys[k + 1][mf.index["q"]])
