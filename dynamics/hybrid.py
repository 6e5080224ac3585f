"""The hybrid loop: integrate a mode, find its guard, apply the transition, re-initialise, go on.

One loop serves every mechanism and every backend: everything mechanism-specific comes through the
`Mechanism` interface, everything integrator-specific through the backend contract (`dynamics/backend.py`).
Each transition is an events-table row (time, from, to, kind, kinetic energy before and after).
"""
from __future__ import annotations

import time as _time
from dataclasses import dataclass, field
from typing import Callable, Generator

import numpy as np

from mechsim.mechanisms.base import Mechanism

from mechsim.dynamics.consistent import consistent_state
from mechsim.dynamics.drives import Drive
from mechsim.dynamics.backend import FRESH_STEP_FRACTION, End, Request, Segment, backend_for
from mechsim.dynamics.model import DerivedModel, StateExtension, derive
from mechsim.dynamics.result import FailureCode
from mechsim.dynamics.stats import new_stats
from mechsim.dynamics.transitions import apply_transition, chattering, rebased, stepped_over_failure
from mechsim.dynamics.settings import SolverSettings


@dataclass
class Piece:
    """Output rows of one segment with the mode and parameters that produced them.

    y is in the mode's IDA layout (`dynamics.model`); read-outs use its states (q, v, work, ext) and solve the
    KKT system for accelerations and forces at every row (`tables.kkt_rows`). The multiplier columns and yp are
    the integrator's where it has them (IDA, the diffrax segment loop); the compiled diffrax run interpolates
    states only: NaN multipliers, yp None.
    """

    mode: str
    params: tuple
    t: np.ndarray
    y: np.ndarray
    yp: np.ndarray | None
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
    #: the consistent state each segment of the run started from (one row each, in time order; after an event, the
    #: state after it): where a reading of the continuous solution starts, forward, when no output row precedes it
    starts: list[Piece] = field(default_factory=list)
    #: the state each of those segments ended at (one row, before the transition at its end: the one-sided limit
    #: from before an event), None where it failed; a reading at that instant is this state
    stops: list[Piece | None] = field(default_factory=list)


def parameter_tuple(model: DerivedModel, values: dict[str, float]) -> tuple:
    try:
        return tuple(map(float, map(values.__getitem__, model.parameter_names)))
    except KeyError:
        missing = [n for n in model.parameter_names if n not in values]
        if missing:
            raise KeyError(f"missing parameter values: {missing}") from None
        raise


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
    #: the breakpoints inside (t0, t_end) (`schedule`): (time, parameter updates, events-table kind), by time
    knots: list = field(default_factory=list)
    #: whether t_out is known to be non-decreasing (as `prepare` makes it): the loop then takes a segment's output
    #: times by two searches without checking the order of all of them first
    ordered: bool = False

    def output_times_ordered(self) -> bool:
        """Whether t_out is non-decreasing (known from `prepare`, else checked): the hybrid loop and the compiled
        diffrax run then take a call's output times by two searches."""
        t_out = self.t_out
        return self.ordered or (t_out.ndim == 1 and bool(np.all(t_out[1:] >= t_out[:-1])))


def schedule(mech: Mechanism, drive: Drive, t0: float, t_end: float) -> tuple[dict, list]:
    """The time-varying inputs' breakpoints (`Mechanism.schedule`, `Drive.schedule`): (the updates in force at t0,
    the knots in (t0, t_end) as (time, updates, kind), those at one instant merged). docs/theory.md,
    'Time-varying loads and drives'."""
    points = sorted(mech.schedule(t_end) + drive.schedule(t_end), key=lambda b: b.time)
    initial, knots = {}, []
    for b in points:
        if b.time <= t0:
            initial.update(b.updates)
        elif b.time < t_end:
            if knots and knots[-1][0] == b.time:
                knots[-1] = (b.time, {**knots[-1][1], **b.updates}, f"{knots[-1][2]}, {b.kind}")
            else:
                knots.append((b.time, dict(b.updates), b.kind))
    return initial, knots


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
    initial, knots = schedule(mech, drive, t0, t_end)
    values.update(initial)
    t_out = output_times(t0, t_end, dt_out)
    if t_out.size == 0 or t_out[-1] < t_end - 1e-12:
        t_out = np.append(t_out, t_end)
    for time, _, _ in knots:         # an output time within round-off of a breakpoint is taken at it
        t_out[np.abs(t_out - time) <= 1e-12 * max(1.0, abs(time))] = time
    mf = model.modes[init.mode]
    values, q_init, offset = rebased(mech, model, values, t0, np.asarray(init.q, dtype=float),
                                     np.zeros(len(model.coordinates)))
    p = parameter_tuple(model, values)
    work0 = np.zeros(len(model.work_names))
    x0 = np.zeros(len(model.extension_names)) if ext_initial is None else np.asarray(ext_initial, float)
    try:
        y, yp = consistent_start(mf, t0, q_init, init.v, work0, x0, p)
    except (ValueError, np.linalg.LinAlgError) as exc:
        raise ValueError(f"initial state: {exc}") from None
    return Start(model, derive_time, values, init.mode, t_out, mf, p, y, yp, offset, knots, ordered=True)


def output_times(t0: float, t_end: float, dt_out: float) -> np.ndarray:
    """t0 + k dt_out for k = 1, 2, ... up to t_end, none past it (round-off included); one array, its operations
    done in place (a run's thousands of times)."""
    t_out = np.arange(1, int(np.floor((t_end - t0) / dt_out + 1e-9)) + 1, dtype=float)
    t_out *= dt_out
    t_out += t0
    return np.minimum(t_out, t_end, out=t_out)


#: the consistent initial states of the latest runs, by mode and inputs (`consistent_start`)
_INITIAL: dict = {}
#: runs whose initial states are kept
INITIAL_KEPT = 16


def consistent_start(mf, t0: float, q, v, work, ext, p: tuple) -> tuple[np.ndarray, np.ndarray]:
    """`consistent_state`'s (y, y') at a run's start, kept for the latest INITIAL_KEPT (mode, inputs): a scenario run
    again (a warm run, a sweep's repeated point) starts from the same state without projecting it again. Copies:
    the caller owns what it gets."""
    arrays = tuple(np.asarray(a, dtype=float) for a in (q, v, work, ext))
    key = (id(mf), float(t0), p) + tuple((a.shape, a.tobytes()) for a in arrays)
    hit = _INITIAL.get(key)
    if hit is None or hit[0] is not mf:
        y, yp, _ = consistent_state(mf, t0, *arrays, p)
        hit = (mf, y, yp)
        _INITIAL.pop(key, None)
        while len(_INITIAL) >= INITIAL_KEPT:
            _INITIAL.pop(next(iter(_INITIAL)))
        _INITIAL[key] = hit
    return hit[1].copy(), hit[2].copy()


def simulate(mech: Mechanism, drive: Drive, settings: SolverSettings, t_end: float, dt_out: float,
             angle0: float, speed0: float, ext: StateExtension | None = None, ext_initial=None,
             progress: Callable[[float], None] | None = None, t0: float = 0.0, backend=None) -> Trajectory:
    """Integrate the hybrid DAE from t0 to t_end with outputs every dt_out, on `backend` (default: the one
    `settings.backend` names, see `dynamics.backend.REGISTRY`)."""
    backend = backend if backend is not None else backend_for(settings.backend, settings)
    start = prepare(mech, drive, settings, t_end, dt_out, angle0, speed0, ext, ext_initial, t0)
    # a backend that can run everything in one compiled call (`Backend.whole_run`, None where it cannot)
    traj = backend.whole_run(mech, start, t0, t_end, progress) if backend.whole_run is not None else None
    if traj is not None:
        return traj
    loop = hybrid_loop(mech, start, settings, backend, t0, t_end, progress)
    return drive_loop(loop, backend.integrate)


def drive_loop(loop: Generator[Request, Segment, Trajectory], integrate: Callable[[Request], Segment]
               ) -> Trajectory:
    """Run one hybrid loop to its end, integrating every segment it asks for."""
    try:
        request = next(loop)
        while True:
            request = loop.send(integrate(request))
    except StopIteration as done:
        return done.value


#: a first step after a mode change: this fraction of the step the previous segment suggests
RESTART_STEP_FACTOR = 0.1
#: segments in a row that end without time advancing before the loop calls it chattering
MAX_STUCK = 50


def hybrid_loop(mech: Mechanism, start: Start, settings: SolverSettings, backend, t0: float, t_end: float,
                progress: Callable[[float], None] | None = None) -> Generator[Request, Segment, Trajectory]:
    """THE hybrid loop, for every backend: yields a `Request` per segment, is sent the backend's `Segment`,
    and returns the `Trajectory`.

    It owns guards and transitions (`apply_transition`), re-initialisation, recoveries from integrator failures
    (`recover`), events stepped over when root-finding is off (`stepped_over`), chattering, output pieces,
    statistics (same keys for every backend) and failures (a `FailureCode` each). Written as a generator so
    that one loop also serves many lanes advanced together (`dynamics.backends.diffrax_batch`).
    """
    model, values, mode, t_out, mf, p, y, yp, offset = (start.model, start.values, start.mode, start.t_out,
                                                         start.mf, start.p, start.y, start.yp, start.offset)
    pieces = [Piece(mode, p, np.array([t0]), y[None, :].copy(), yp[None, :].copy(), offset)]
    starts: list[Piece] = []
    stops: list[Piece | None] = []
    events: list[dict] = []
    stats = new_stats(backend.name, backend.solver, start.derive_time, unavailable=backend.unavailable)
    stats["notes"].update(backend.notes)
    failure = None
    warnings: list[str] = []
    t = t0
    last = None
    first_step = backend.initial_step
    in_row = stuck = 0
    knots = list(start.knots)
    ordered = start.output_times_ordered()
    wall0 = _time.perf_counter()
    while t < t_end - 1e-12:
        while knots and reached(knots, t):     # a breakpoint reached (a segment's end, or a guard's root on it)
            _, updates, kind = knots.pop(0)
            values, p, y, yp, row = at_breakpoint(model, mode, values, t, y, updates, kind, offset)
            events.append(row)
            stats["restarts"] += 1
        stop = knots[0][0] if knots else t_end   # a breakpoint is a segment's end: never stepped over
        starts.append(Piece(mode, p, np.array([t]), np.array(y, dtype=float, ndmin=2),
                            np.array(yp, dtype=float, ndmin=2), offset))
        stops.append(None)
        ahead = (t_out[t_out.searchsorted(t, "right"):t_out.searchsorted(stop, "right")] if ordered
                 else t_out[(t_out > t) & (t_out <= stop)])      # the output times in (t, stop]
        seg = yield Request(model, mode, mf, p, t, y, yp, ahead, stop, first_step)
        stats["segments"] += 1
        for key, count in seg.counts.items():
            if stats[key] is None:            # said unavailable by a backend whose choice came later (`auto`)
                stats[key] = 0
                stats["notes"].pop(key, None)
            stats[key] += count
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
        if seg.end is End.FAILED:
            recovered = recover(mf, p, seg, in_row, t_end) if seg.code in backend.recoverable else None
            if recovered is not None:
                # the integrator gave up: restart from its last state, re-initialised consistently (a fresh
                # order-1 history) with a small first step; at most MAX_RECOVERIES times per instant
                t, y, yp, first_step = recovered
                in_row += 1
                stats["recoveries"] += 1
                continue
            q = seg.y_end[mf.index["q"]] + offset
            code = seg.code if np.all(np.isfinite(seg.y_end)) else FailureCode.NON_FINITE
            failure = dict(time=seg.t_end, mode=mode, reason=seg.message, code=code,
                           where={c: float(v) for c, v in zip(model.coordinates, q)}, hint=backend.hint(code))
            break
        in_row = 0
        stops[-1] = Piece(mode, p, np.array([seg.t_end]), np.array(seg.y_end, dtype=float, ndmin=2),
                          np.array(seg.yp_end, dtype=float, ndmin=2), offset)
        stuck = stuck + 1 if seg.t_end - t <= 1e-12 * max(1.0, abs(t)) else 0
        t = seg.t_end
        if seg.end is End.END:
            if not knots:
                break
            t, y, yp, first_step = stop, seg.y_end, seg.yp_end, RESTART_STEP_FACTOR * seg.next_step
            continue
        q = seg.y_end[mf.index["q"]]
        if stuck > MAX_STUCK:
            guard = mf.guard_names[seg.fired[0]] if seg.fired else "?"
            failure = dict(time=t, mode=mode, reason=f"guard '{guard}' keeps firing without time advancing",
                           code=FailureCode.CHATTERING,
                           where={c: float(v) for c, v in zip(model.coordinates, q + offset)},
                           hint="the mode sequence chatters here (Zeno behaviour?)")
            break
        if seg.end is End.PAUSE:
            y, yp, first_step = seg.y_end, seg.yp_end, seg.next_step
            continue
        # a guard fired
        out, failure, last = fire(mech, model, mode, values, t, seg.y_end, q, list(seg.fired), offset, last, stats, p)
        if out is not None:
            events += out.rows
            warnings += out.warnings
        if failure:
            break
        mode, values, p, y, yp, offset = out.mode, out.values, out.p, out.y, out.yp, out.offset
        mf = model.modes[mode]
        first_step = RESTART_STEP_FACTOR * seg.next_step
    stats["solve_time_s"] = _time.perf_counter() - wall0 - stats["compile_time_s"]
    return Trajectory(model, pieces, events, stats, failure, warnings, starts, stops)


def reached(knots: list, t: float) -> bool:
    """Whether the next breakpoint is at t (within round-off: a guard's root may fall a few ulp before it, and a
    segment that short is no step at all)."""
    return bool(knots) and knots[0][0] <= t + 1e-12 * max(1.0, abs(t))


def at_breakpoint(model: DerivedModel, mode: str, values: dict, t: float, y_end: np.ndarray, updates: dict,
                  kind: str, offset: np.ndarray) -> tuple[dict, tuple, np.ndarray, np.ndarray, dict]:
    """Restart at a breakpoint of the time-varying inputs (`schedule`), for every loop: (values, p, y, yp, the
    events-table row). The state is kept (positions and velocities are continuous: a load or drive torque only
    changes the accelerations and multipliers, re-solved from the KKT system, `consistent_state`); the index-1 form
    keeps q and v as they are, the others are projected onto their constraints as after a guard."""
    mf = model.modes[mode]
    ix = mf.index
    values = {**values, **updates}
    p = parameter_tuple(model, values)
    q, v = y_end[ix["q"]], y_end[ix["v"]]
    y, yp, impact = consistent_state(mf, t, q, v, y_end[ix["work"]], y_end[ix["ext"]], p,
                                     project=model.formulation != "index1")
    row = dict(t_s=t, from_mode=mode, to_mode=mode, kind=kind, guard="breakpoint",
               **{f"{c}_q": float(val) for c, val in zip(model.coordinates, q + offset)},
               kinetic_energy_before_J=impact.energy_before, kinetic_energy_after_J=impact.energy_after,
               message="")
    return values, p, y, yp, row


def fire(mech: Mechanism, model: DerivedModel, mode: str, values: dict, t: float, y_end: np.ndarray, q: np.ndarray,
         fired: list[int], offset: np.ndarray, last, stats: dict, p: tuple | None = None):
    """The guards `fired` (the first the primary) at time t, for every loop (this one and the compiled diffrax
    run's hand-backs): the chattering check, then the transition (`transitions.apply_transition`; p: the parameter
    tuple of `values` where the caller has it).

    Returns (outcome or None, failure with its code or None, the new `last` (guard, time)); counts the event and,
    after a successful re-initialisation, the restart in `stats`."""
    guard = model.modes[mode].guard_names[fired[0]]
    failure = chattering(model, mode, guard, t, q + offset, last)
    if failure:
        return None, dict(failure, code=FailureCode.CHATTERING), last
    stats["events"] += 1
    out = apply_transition(mech, model, parameter_tuple, mode, values, t, y_end, fired, offset, p)
    if out.failure:
        return out, dict(out.failure, code=transition_failure_code(out.failure)), (guard, t)
    stats["restarts"] += 1
    return out, None, (guard, t)


def transition_failure_code(failure: dict) -> FailureCode:
    """The code of a failure that `apply_transition` reports: a physical stop, or a failed re-initialisation."""
    if failure.get("kind", "solver") != "solver":
        return FailureCode.PHYSICAL_STOP
    return FailureCode.REINITIALISATION_FAILED


#: restarts of failed segments allowed in a row (without a segment that ends normally) before giving up
MAX_RECOVERIES = 2


def recover(mf, p: tuple, seg: Segment, in_row: int, t_end: float):
    """(t, y, yp, first_step) to restart a failed segment from, or None when not possible.

    The integrator's last reached state is re-initialised consistently (positions to round-off, velocities,
    accelerations and multipliers from the KKT system: `consistent_state`) and restarted with a fresh
    history and a first step of FRESH_STEP_FRACTION of the remaining time (the integrator's own estimate is what
    failed).
    More than MAX_RECOVERIES failures in a row, a non-finite state or a state that cannot be made consistent
    gives up.
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
    return t, y, yp, FRESH_STEP_FRACTION * (t_end - t)


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
