"""The summary's `peaks`: the maximum and minimum of each key column of the continuous solution, located between
output rows (`dynamics/extrema.py`), with its instant and drive angle (docs/theory.md §K5).

Which columns are located and how is part of every entry (`how`): a DAE run's mechanical columns on the run's own
dense output where its integrator keeps one (the compiled diffrax run), else by re-integrating the mode from the
nearest output row, a closed-form run's by the closed form; the thermal model's columns by its formulas on those
readings with the network's states there (scenarios/thermal_peaks.py). Where a run settles into a periodic regime
(crank turn to turn) the entries are the regime's, the start-up's beside them; a column that grows without bound
toward an event has no value there, and its events, growth, impulse and energy lost are listed instead
(`singular`).
"""
from __future__ import annotations

import dataclasses
import math
from dataclasses import dataclass

import numpy as np
import pandas as pd

from mechsim.dynamics.extrema import (ROWLESS_READINGS, Interval, ReadingFailed, apart, between,
                                      end_guesses, end_limit_requests, end_limits, end_lines, every_end, finish_all,
                                      intervals_of, read_all, refine_further, read_tables, stored_limits, with_rowless)
from mechsim.dynamics.extrema import plans as plan_windows
from mechsim.dynamics.tables import TableColumns
from mechsim.dynamics.trajectory_reader import TrajectoryReader
from mechsim.scenarios.singular import (first_approaches, growth_requests, limit_edge, readings_ahead,
                                        singular_approaches)

HOW_DAE = "located: the mode re-integrated from the nearest output row at 1/10 of the run's tolerances"
HOW_DENSE = "located: the run's own dense output (the step interpolants its output rows come from)"
#: what `how` adds where a DAE run's columns were sampled between its rows (`_rows_finest`)
SAMPLED_DENSE = "; its candidates also read between output rows at most 0.5° of drive angle apart"
SAMPLED_STATES = ("; its candidates also from the states interpolated between output rows at most 0.5° of drive angle "
                  "apart (re-integrated where the interpolation's estimated error exceeds 0.001°)")
HOW_DENSE_SAMPLED = HOW_DENSE + SAMPLED_DENSE
HOW_DAE_SAMPLED = HOW_DAE + SAMPLED_STATES
HOW_CLOSED = ("located: the closed form's extremum between output rows, its candidates sampled at most 0.5° of drive "
              "angle apart (100 000 samples a run at most)")

#: a closed-form run's columns are sampled (beside its rows) at least this often in drive angle (rad) before their
#: candidates are ranked (`_finest`); at most CLOSED_READINGS samples a run (its resources bounded before any work)
CLOSED_STEP_RAD = math.radians(0.5)
CLOSED_READINGS = 100_000
#: a DAE run's columns are sampled (beside its rows) at least this often in drive angle (rad) where its rows are
#: farther apart (`_rows_finest`), from its states interpolated between its rows (or its dense output), as a closed
#: form's are; as many samples at most
DAE_STEP_RAD = CLOSED_STEP_RAD
#: a gap between those rows whose interpolated states may err by more than this (rad of any coordinate angle) has its
#: samples re-integrated (`TrajectoryReader.sampler`): a thousandth of a degree, far below what moves a peak a
#: degree wide from one candidate to another, far above what rows a few degrees apart err by
TRUSTED_RAD = math.radians(1e-3)
HOW_ROWS = "output rows (not located: a column computed after the run from the rows)"
#: a turn's mean not read on the continuous solution (a column not read between rows, or a reading there failed)
HOW_ROWS_MEAN = "the trapezoidal rule on the output rows (not read between them, or a reading there failed)"


@dataclass
class Source:
    """What the locating needs of a finished run: the method, the DAE's trajectory (None for the closed form), the
    mechanism and drive, the settings, the scenario's SI values and the columns the table had before any
    post-processing (those are read between rows; the thermal columns through the thermal plan and the mechanics
    table `window`, scenarios/thermal_peaks.py)."""

    method: str
    traj: object
    mech: object
    drive: object
    settings: object
    si: dict
    columns: frozenset
    thermal: object = None          # the thermal plan, whose columns are read between rows (scenarios/thermal_peaks.py)
    window: pd.DataFrame | None = None   # the mechanics table before the thermal finish


def _wrapped_deg(angle: float) -> float:
    return math.degrees((angle + np.pi) % (2 * np.pi) - np.pi)         # as np.degrees: x * (180 / pi)


def _entry(value: float, t: float, angle: float, at: str, row_value: float | None = None,
           limit: str | None = None) -> dict:
    out = {"value": float(value), "t_s": float(t), "drive_angle_rad": float(angle),
           "drive_angle_wrapped_deg": _wrapped_deg(angle), "at": at}
    if limit:
        out["limit"] = limit
    if row_value is not None:
        out["best_row_value"] = float(row_value)
    return out


def _median_step(t: np.ndarray) -> float:
    """The median output step, np.median(np.diff(t)) (the middle order statistics by one partition, the mean of
    the two of an even count as np.mean forms it; NaN where a step is NaN), without np.median's generic machinery."""
    part = t[1:] - t[:-1]            # np.diff(t), partitioned in place (np.partition of a copy)
    m = len(part)
    k = m // 2
    part.partition([k - 1, k, m - 1] if m % 2 == 0 else [k, m - 1])
    if np.isnan(part[-1]):
        return float("nan")
    return float((part[k - 1] + part[k]) / 2) if m % 2 == 0 else float(part[k])


def _valued(f: np.ndarray) -> bool:
    """Whether a column holds a value (not NaN on every row; a first row with one says so without the rest)."""
    return bool(len(f)) and (not np.isnan(f[0]) or not np.isnan(f).all())


def _closed_form_reader(source: Source, angle0: float, t_rows: np.ndarray, table: dict, check: list[str]):
    """Every closed-form column at any instants, at an interval's ends 1e-12 s inside (the one-sided limits). The
    closed form is evaluated on the table's own instants with the new ones among them, in time order: it counts the
    angle from the run's first instant, and a mechanism's branch may follow the motion's history (the chain's apex
    law). That history is shortened to what it depends on: the first instant's rows, the rows where an unwrapped angle
    of the table crosses a quarter turn (`turns`) and the row before each instant, checked against the table (else
    the whole history up to there); `read_many` takes many readings in one evaluation."""
    mech, speed = source.mech, source.drive.speed
    if mech.closed_form_pointwise:
        return _pointwise_reader(mech, angle0, speed, t_rows[:1])
    # the table's instants in order (as a run's are): the rows of a history are found by bisection, not by comparing
    # every row (an hour's table read a hundred times)
    ordered = bool((t_rows[1:] >= t_rows[:-1]).all())
    perm = None if ordered else np.argsort(t_rows, kind="stable")
    ts = t_rows if perm is None else t_rows[perm]
    starts = int(ts.searchsorted(ts[0], side="right")) if len(ts) else 0
    # the rows on either side of each crossing of a quarter turn by an unwrapped angle of the table: the two rows of a
    # crossing stay neighbours, and between crossings every row lies within one quarter turn, so a history of these
    # rows unwraps the angles as one of every row does (to round-off)
    angles = [np.asarray(table[c], dtype=float) for c in check if c.endswith("_angle_rad")]
    turns = np.zeros(0, dtype=np.intp)
    if angles and len(ts) > 1:
        quarter = np.floor(np.array(angles if perm is None else [a[perm] for a in angles]) / (0.5 * np.pi))
        cross = np.flatnonzero((quarter[:, 1:] != quarter[:, :-1]).any(axis=0))
        turns = np.union1d(cross, cross + 1)

    def evaluate(asked: np.ndarray) -> dict:
        """Every column at the instants `asked`: from the history of the first instant's rows, the `turns` up to the
        last instant and the row at or before each instant, checked against the table (a shortened history must give
        the table's own rows); where the check fails, from all rows up to the last instant."""
        last = int(ts.searchsorted(asked.max(), side="right")) if len(asked) else starts
        if last > starts:
            rows = np.union1d(turns[turns.searchsorted(starts):turns.searchsorted(last)],
                              ts.searchsorted(asked, side="right") - 1)
            rows = np.concatenate([np.arange(starts), rows[rows >= starts]])
            if len(rows) < last:
                got = _at(rows, asked, True)
                if got is not None:
                    return got
        return _at(np.arange(max(last, starts)), asked, False)

    def _at(rows: np.ndarray, asked: np.ndarray, checked: bool) -> dict | None:
        at = np.concatenate([ts[rows], asked])
        order = np.argsort(at, kind="stable")               # a row before an instant at the same time
        cols = _closed_form_at(mech, at[order], angle0, speed)
        place = np.empty(len(at), dtype=np.intp)
        place[order] = np.arange(len(at))
        if checked and check:
            own = rows if perm is None else perm[rows]
            got = np.array([np.asarray(cols[name], float)[place[:len(rows)]] for name in check])
            mine = np.array([table[name][own] for name in check], dtype=float)
            if not np.allclose(got, mine, rtol=1e-9, atol=1e-12, equal_nan=True):     # every column's rows at once
                return None
        return {name: np.asarray(v)[place[len(rows):]] for name, v in cols.items()}

    def read_many(requests: list[tuple[Interval, int, np.ndarray]]) -> list[dict]:
        """Each request's columns: every request with instants, all finite, in one evaluation; any other alone."""
        inner = [np.asarray(iv.inside(times), dtype=float) for iv, _, times in requests]
        finite = [bool(len(x)) and bool(np.isfinite(x).all()) for x in inner]
        together = [r for r, ok in enumerate(finite) if ok]
        out: list = [None] * len(requests)
        for group in [together] * bool(together) + [[r] for r, ok in enumerate(finite) if not ok]:
            cols = evaluate(np.concatenate([inner[r] for r in group]))
            a = 0
            for r in group:
                frame = {name: v[a:a + len(inner[r])] for name, v in cols.items()}
                frame["t_s"] = requests[r][2]
                out[r] = frame
                a += len(inner[r])
        return out

    def read(iv: Interval, position: int, times: np.ndarray) -> dict:
        return read_many([(iv, position, times)])[0]
    read.read_many = read_many
    return read


def _contact_switches(source: Source, t: np.ndarray, cols, breaks: list[tuple[float, str]]
                      ) -> list[tuple[float, str]]:
    """The closed form's contact switches between output rows that are no event, as breaks (time, kind): a slip
    reversal (the friction force, and with it the normal force, jumps) and a flank switch (the slip jumps). A DAE
    run lists both as events; a closed form lists only entries and exits, so without these an extremum at a
    switch was read as a smooth interior one (a parabola across the jump: geneva-seed-lc3's contact force 242.13 to
    242.37 N with the output step). Located as the thermal path locates them (thermal/exact.py `switch_times`:
    bisection between the rows where the contact's code changes); each is named by which sign changed there."""
    mech = source.mech
    needed = ("mode", "slip_speed_m_s", "contact_force_N")
    if getattr(mech, "closed_form_contact", None) is None or not all(c in cols for c in needed):
        return []
    from mechsim.thermal.exact import contact_code, contact_columns, contact_switches
    angle0 = source.si["initial"][mech.initial_keys[0]]
    contact = contact_columns(mech, angle0, source.drive.speed, None)
    grid = {c: np.asarray(cols[c])[:len(t)] for c in needed}
    known = np.array([b for b, _ in breaks], dtype=float)
    found = contact_switches(mech, angle0, source.drive.speed, t, grid_columns=grid, known=known)
    kept = apart([(x, "") for x in found], known, 1e-9 * max(1.0, abs(float(t[-1]))))
    if not kept:
        return []
    at = np.array([x for x, _ in kept])
    eps = 1e-12 * np.maximum(1.0, np.abs(at))          # the one-sided limits' distance (`Interval.inside`)
    code = contact_code(contact(np.concatenate([at - eps, at + eps])))
    flank = (code[:len(at)] % 3) != (code[len(at):] % 3)         # the normal force's sign changed: the other flank
    return [(x, f"{'flank switch' if f else 'slip reversal'} of the closed form at t = {x:.9g} s")
            for x, f in zip(at.tolist(), flank.tolist())]


def _closed_form_at(mech, at: np.ndarray, angle0: float, speed: float) -> dict[str, np.ndarray]:
    """The closed form's columns at the instants `at`, each an array of their length (a scalar column broadcast;
    its powers and events, and a column of another length, left out)."""
    cols = mech.closed_form(at, angle0, speed)
    cols.pop("powers", None)
    cols.pop("events", None)
    n = len(at)
    return {name: np.broadcast_to(np.asarray(v), (n,)) for name, v in cols.items()
            if np.ndim(v) == 0 or len(np.ravel(v)) == n}


def _pointwise_reader(mech, angle0: float, speed: float, t0: np.ndarray):
    """`_closed_form_reader` of a closed form whose columns at an instant depend on it and the first instant `t0`
    alone (`Mechanism.closed_form_pointwise`): the instants asked for, after t0, and nothing between (the same
    operations on each instant as on the table's rows); `read_many` reads many requests in one evaluation."""
    def read_many(requests: list[tuple[Interval, int, np.ndarray]]) -> list[dict]:
        """Each request's columns, all requests in one evaluation."""
        inner = [iv.inside(times) for iv, _, times in requests]
        full = _closed_form_at(mech, np.concatenate([t0, *inner]), angle0, speed)
        out, a = [], 1
        for (_, _, times), x in zip(requests, inner):
            frame = {name: v[a:a + len(x)] for name, v in full.items()}
            frame["t_s"] = times
            out.append(frame)
            a += len(x)
        return out

    def read(iv: Interval, position: int, times: np.ndarray) -> dict:
        return read_many([(iv, position, times)])[0]
    read.read_many = read_many
    return read


def _breaks(events: pd.DataFrame, ev: TableColumns | None = None) -> list[tuple[float, str]]:
    """(time, its description) of each event, in order; ev: the events' TableColumns where at hand."""
    if events is None or not len(events):
        return []
    if ev is None:
        ev = TableColumns(events)           # the frame's own arrays (a pandas column read is not free)
    kinds = [str(k) for k in ev["kind"].tolist()] if "kind" in ev else ["event"] * len(events)
    return sorted((t, f"event '{k}' at t = {t:.9g} s") for t, k in zip(np.asarray(ev["t_s"], float).tolist(), kinds))


#: a gap between rows wider than this much drive angle has the turns' ends estimated from samples between the rows
#: (`_turn_estimates`); rows four a turn estimate them well enough for Newton's method to converge
ESTIMATE_RAD = math.pi / 2
#: consecutive crank turns agree to this (their durations, and the drive speed at their starts, relative) where the
#: motion counts as periodic
PERIODIC_RTOL = 1e-3


def periodic_regime(t: np.ndarray, angle: np.ndarray, speed: np.ndarray, locate=None, works: dict | None = None,
                    speed_column: str | None = None, estimates: tuple | None = None) -> dict | None:
    """Where a run reaches a periodic regime: the first turn of the drive (from the run's first angle) from which
    every turn lasts as long as the last turn and starts at the same drive speed, to PERIODIC_RTOL (against the last
    turn, so that a slow drift is not taken for periodic); at least two such turns. None without (a prescribed or
    accelerating drive, a stall, fewer than three turns). The turns' ends from the rows (`turns.crossings`, O(h^4)),
    each turn's starting speed interpolated there; locate(times, levels): (the instants the angle reaches `levels`,
    located on the continuous solution from those estimates; their column tables and the instants those were read
    at, within a Newton step of them), as `_located_turns` makes it. Every turn's end and starting speed (the table's
    `speed_column`) are then those, so that whether and where the regime begins does not depend on the output step,
    and the last turn's work of each power flow (`last_turn_work_J`) is the `works` columns ({name: rows}) read there
    (`turns.carried` over the step). estimates: (instants, drive angle, drive speed) the turns' ends are estimated
    from instead of the rows (`_turn_estimates`: the rows with the samples between them, where the rows lie turns
    apart)."""
    from mechsim.scenarios.turns import carried, crossings
    te, ae, we = (t, angle, speed) if estimates is None else estimates
    bounds = crossings(te, ae, we, float(angle[0]))
    if len(bounds) < 3:
        return None
    b = np.concatenate([[t[0]], bounds])
    w = np.interp(b, te, we)
    located = tables = read = None
    if locate is not None:
        located, tables, read = locate(bounds, float(angle[0]) + 2 * np.pi * np.arange(1, len(b), dtype=float))
        for i, (x, table) in enumerate(zip(located, tables), start=1):
            if table is not None:
                b[i] = x
                if speed_column is not None:        # (a state column: read without the reading's read-out)
                    w[i] = float(np.asarray(table[speed_column])[0])
    periods = b[1:] - b[:-1]
    scale = max(float(np.abs(speed).max()), 1e-300)
    same = ((np.abs(periods - periods[-1]) <= PERIODIC_RTOL * periods[-1])
            & (np.abs(w[:-1] - w[-2]) <= PERIODIC_RTOL * scale))          # each turn against the last
    k = len(same)
    while k > 0 and same[k - 1]:
        k -= 1
    if len(same) - k < 3:
        return None
    work = {}
    if located is not None:
        ia, ib = len(b) - 3, len(b) - 2              # the last turn's ends among the located (b[1:])
        if tables[ia] is not None and tables[ib] is not None:
            work = {c[5:-2]: carried(t, f, float(np.asarray(tables[ib][c])[0]), read[ib], located[ib])
                    - carried(t, f, float(np.asarray(tables[ia][c])[0]), read[ia], located[ia])
                    for c, f in (works or {}).items()}
    out = {"from_t_s": float(b[k]), "startup_turns": int(k), "periodic_turns": int(len(periods) - k),
           "period_s": float(periods[-1]), "last_turn": (float(b[-2]), float(b[-1])),
           "criterion": (f"every drive turn from here equal to the last in duration and in starting drive speed to "
                         f"{PERIODIC_RTOL:g} (relative)"),
           "turn_spread": float(np.abs(periods[k:] - periods[-1]).max() / periods[-1])}
    if work:
        out["last_turn_work_J"] = work
    return out


def _turn_estimates(source: Source, read, intervals: list[Interval], t: np.ndarray, cols, angle_column: str,
                    speed_column: str) -> tuple | None:
    """(instants, drive angle, drive speed): the rows with the samples between them (`_samples_between_rows`, as
    the located peaks sample) where a gap between rows spans more than ESTIMATE_RAD of the drive's angle, for
    `periodic_regime`'s first estimates of the turns' ends; None where none does (the rows' cubic Hermite then
    estimates a crossing to O(h^4), and Newton's method converges from there). Rows turns apart (three rows a
    run) place a crossing nowhere near it, and Newton's method from there does not reach it: the regime was not
    found and the start-up's extremes were reported as the run's."""
    angle, speed = np.asarray(cols[angle_column], float)[:len(t)], np.asarray(cols[speed_column], float)[:len(t)]
    h = np.diff(t)
    with np.errstate(invalid="ignore"):
        spans = np.fmax(np.abs(np.diff(angle)), np.fmax(np.abs(speed[1:]), np.abs(speed[:-1])) * h)
    if not np.nanmax(spans, initial=0.0) > ESTIMATE_RAD:
        return None
    got = _samples_between_rows(source, read, intervals, t, cols, angle_column, speed_column)
    if got is None or angle_column not in got[1] or speed_column not in got[1]:
        return None
    at, table = got
    instants = np.concatenate([t, at])
    order = np.argsort(instants, kind="stable")
    return (instants[order], np.concatenate([angle, table[angle_column]])[order],
            np.concatenate([speed, table[speed_column]])[order])


def last_drive_cycle(t: np.ndarray, angle: np.ndarray, speed: np.ndarray | None, cycle, locate=None
                     ) -> tuple[float, float] | None:
    """(start, end) of the last complete drive cycle within the rows, for the cycle means of a run without a
    periodic regime: the last two instants the drive angle (increasing) reaches cycle.start + k cycle.period (the
    mechanism's `drive_cycle`), each the root of the rows' cubic Hermite interpolant (`turns.hermite_crossings`;
    linear between rows without the speed), then located on the continuous solution by locate(times, levels) where
    given (as `periodic_regime`'s: `_located_turns`); None where the angle does not increase through a whole
    cycle."""
    from mechsim.scenarios.turns import hermite_crossings
    period = getattr(cycle, "period", None)
    if not period or len(t) < 2 or not np.all(np.diff(angle) > 0):
        return None
    last = math.floor((float(angle[-1]) - cycle.start) / period + 1e-12)
    if last - math.ceil((float(angle[0]) - cycle.start) / period - 1e-12) < 1:
        return None
    levels = cycle.start + period * np.array([last - 1, last], dtype=float)
    ends = (hermite_crossings(t, angle, speed, levels) if speed is not None and np.all(np.isfinite(speed))
            else np.interp(levels, angle, t))
    if locate is not None:
        located, tables, _ = locate(ends, levels)
        ends = np.where([table is not None for table in tables], located, ends)
    return float(ends[0]), float(ends[1])


def _reads_at(read, intervals: list[Interval], t: np.ndarray):
    """read_at(times, groups=False): the columns at each instant (one table each; None where it was not read), or
    with groups, at each array of instants (ascending, within one smooth interval: one table each), each read from
    the last row before its first instant in the smooth interval that holds that (`intervals`: the whole run's, an
    instant at an event read as the limit from before), all in one pass of `read` (a `_Readings`: its `prefetch`,
    else `read_tables`)."""
    his = np.array([iv.hi for iv in intervals])

    def read_at(times, groups: bool = False) -> list:
        asked = list(times) if groups else [np.array([x]) for x in np.asarray(times, dtype=float).tolist()]
        requests, where = [], []
        for j, x in enumerate(asked):
            x = np.asarray(x, dtype=float)
            if not len(x):
                continue
            i = min(int(his.searchsorted(0.5 * (x[0] + x[-1]), side="left")), len(intervals) - 1)
            iv = intervals[i]
            if not len(iv.rows) or not (iv.lo <= x[0] and x[-1] <= iv.hi):
                continue
            position = max(int(t[iv.rows].searchsorted(x[0], side="right")) - 1, 0)
            requests.append((iv, position, x))
            where.append(j)
        got = [None] * len(asked)
        tables = read.prefetch(requests) if hasattr(read, "prefetch") else read_tables(read, requests)
        for j, table in zip(where, tables if requests else []):
            got[j] = table
        return got
    return read_at


def _located_turns(read, intervals: list[Interval], t: np.ndarray, angle_column: str, speed_column: str):
    """`periodic_regime`'s locate for a run with a reader: the instants the drive angle reaches the levels, by
    Newton's method on the angle read at the rows' estimates (`turns.newton_passes`, `_reads_at`);
    (instants, tables, the instants those were read at)."""
    from mechsim.scenarios.turns import newton_passes
    read_at = _reads_at(read, intervals, t)

    def locate(times: np.ndarray, levels: np.ndarray):
        return newton_passes(read_at, times, levels, angle_column, speed_column)
    return locate


def point_reader(source: Source | None, cols, events: pd.DataFrame | None, event_cols: TableColumns | None = None):
    """(read_at, the smooth intervals' ends, the reader behind them) for a finished run (`_reads_at`): every column
    of the run at any instants of it, read on its continuous solution as the located peaks read it (a DAE run's
    dense output or re-integration from its rows, a closed form evaluated); None without a source (a failed run) or
    rows."""
    t = np.asarray(cols["t_s"], dtype=float)
    if source is None or len(t) < 2:
        return None
    t_end = float(t[-1]) if source.traj is None else float(source.traj.pieces[-1].t[-1])
    n = int(t.searchsorted(t_end, side="right"))
    tn = t[:n]
    breaks = _breaks(events, event_cols) if events is not None else []
    if source.method == "closed-form":
        check = [c for c in source.mech.peak_columns if c in cols] + [c for c in cols if c.endswith("_angle_rad")]
        read = _closed_form_reader(source, source.si["initial"][source.mech.initial_keys[0]], tn,
                                   {c: np.asarray(cols[c], float)[:n] for c in check}, check)
        breaks = sorted(breaks + _contact_switches(source, tn, cols, breaks))
    else:
        read = TrajectoryReader(source.traj, source.mech.angle_coordinates, source.settings)
    intervals = _intervals(tn, breaks, float(t[0]), t_end, ("start", "end"), read)
    if not intervals:
        return None

    def samples(angle_column: str, speed_column: str | None = None):
        return _samples_between_rows(source, read, intervals, tn, cols, angle_column, speed_column)
    return _reads_at(read, intervals, tn), np.array([intervals[0].lo] + [iv.hi for iv in intervals]), read, samples


def _samples_between_rows(source: Source, read, intervals: list[Interval], t: np.ndarray, cols, angle_column: str,
                          speed_column: str | None = None):
    """(instants, their columns) of a finished run sampled between its rows as its located peaks are
    (`with_rowless`'s finest: CLOSED_STEP_RAD of drive angle on a closed form, DAE_STEP_RAD on a DAE run), or None
    where no two rows lie farther apart than that: the validity's candidates between rows (`validity.located`, which
    reads every number it reports on the continuous solution). read: the mechanics' reader (`point_reader`), or the
    thermal one (`thermal_point_reader`): read by its `sampler` where it has one (a DAE run's states interpolated
    between its rows or its dense output, `TrajectoryReader.sampler`; a thermal reader's), else itself (a closed
    form, exact); none on a cycle-averaged thermal reader, whose table repeats the simulated turns."""
    from mechsim.dynamics.extrema import sample_instants
    if getattr(read, "cycle", False):
        return None
    if source.method == "closed-form":
        finest = _finest(source, t)
    elif angle_column in cols:
        finest = _rows_finest(t, np.asarray(cols[angle_column], dtype=float)[:len(t)],
                              np.asarray(cols[speed_column], dtype=float)[:len(t)] if speed_column in cols else None)
    else:
        return None
    if finest is None:
        return None
    make = getattr(read, "sampler", None)
    sampler = make(TRUSTED_RAD) if make is not None else read
    if sampler is None:
        return None
    at, of = sample_instants(t, intervals, {}, finest)
    if not len(at):
        return None
    ks = np.unique(of).tolist()
    if hasattr(sampler, "read_at"):
        cuts = of.searchsorted(np.arange(len(intervals) + 1))
        return at, sampler.read_at(at, [(intervals[k], cuts[k], cuts[k + 1]) for k in ks])
    tables = read_tables(sampler, [(intervals[k], 0, at[of == k]) for k in ks])
    got = [(k, table) for k, table in zip(ks, tables) if table is not None]
    if not got:
        return None
    names = set.intersection(*(set(table) for _, table in got))
    return (np.concatenate([at[of == k] for k, _ in got]),
            {c: np.concatenate([np.asarray(table[c], dtype=float) if c != "mode" else np.asarray(table[c])
                                for _, table in got]) for c in names})


def thermal_point_reader(source: Source | None, cols, events: pd.DataFrame | None,
                         event_cols: TableColumns | None = None):
    """(read_at, the smooth intervals' ends, the columns it reads, samples(angle column, speed column)) of a finished
    run's thermal columns, as `point_reader` (`_reads_at` on the thermal reader that locates their peaks,
    `thermal_peaks.thermal_reader`, over
    the whole table, its intervals split at the events and the heat input's own switches: the thermal columns
    jump where a contact starts and ends); None where they are not read between rows (no thermal model, a failed
    run)."""
    from mechsim.scenarios.thermal_peaks import heat_breaks, thermal_reader
    t = np.asarray(cols["t_s"], dtype=float)
    if source is None or len(t) < 2 or getattr(source, "thermal", None) is None:
        return None
    mechanics = None
    if source.method == "closed-form":
        mechanics = point_reader(source, cols, events, event_cols)
        if mechanics is None:
            return None
        mechanics = mechanics[2]
    reader = thermal_reader(source, events, float(t[-1]), mechanics)
    if reader is None:
        return None
    lo, hi = float(t[0]), float(t[-1])
    intervals = intervals_of(t, heat_breaks(reader, _breaks(events, event_cols) if events is not None else [], lo, hi),
                             lo, hi, "start", "end")
    if not intervals:
        return None
    def samples(angle_column: str, speed_column: str | None = None):
        return _samples_between_rows(source, reader, intervals, t, cols, angle_column, speed_column)
    return (_reads_at(reader, intervals, t), np.array([intervals[0].lo] + [iv.hi for iv in intervals]),
            frozenset(source.columns) | frozenset(cols.names), samples)


def _intervals(t: np.ndarray, breaks: list[tuple[float, str]], lo: float, hi: float, kinds: tuple[str, str],
               read) -> list[Interval]:
    """The smooth intervals of [lo, hi] between the events' `breaks` (`_breaks`) with the reader's anchors (a DAE
    run: each row's piece and row)."""
    intervals = intervals_of(t, breaks, lo, hi, *kinds)
    if isinstance(read, TrajectoryReader):
        anchors = read.anchors(t)
        held = anchors[:, 0] >= 0
        every = bool(held.all())
        for iv in intervals:
            if every and len(iv.rows) and iv.rows[-1] - iv.rows[0] == len(iv.rows) - 1:    # a run of rows: a view
                iv.anchors = anchors[iv.rows[0]:iv.rows[-1] + 1]
                continue
            keep = iv.rows[held[iv.rows]]
            iv.rows, iv.anchors = keep, anchors[keep]
    return intervals


def _turn_mean_requests(t: np.ndarray, intervals: list[Interval], finest=None, graded: int = 0
                        ) -> list[tuple] | None:
    """The readings `_turn_means` needs, three requests an interval: its one-sided limits at its ends (one request
    each), then the instants between its knots (its ends and rows) in time order: the midpoint of each gap and,
    where `finest` is given (`_rows_finest`'s spacing), the knots added between rows farther apart than that (an
    interval with no row read over evenly then, from the state the run holds before it); with `graded`, knots at
    1/2, 1/4, ... 1/2^graded of the first and last gaps from the interval's ends, and at (k / ONSET_KNOTS)^3 of the
    interval from its start (a column that starts like the square root of the time from its start, as a flash
    temperature where a contact begins, where Simpson's rule loses its order: the gaps grow from the start as the
    column's derivatives fall); None where an interval holds no row and `finest` is not given."""
    if finest is None and any(not len(iv.rows) for iv in intervals):
        return None
    out = []
    for iv in intervals:
        knots = np.r_[iv.lo, t[iv.rows], iv.hi]
        inner = np.zeros(0)
        if finest is not None:
            if not len(iv.rows):
                inner = np.linspace(iv.lo, iv.hi, ROWLESS_READINGS)[1:-1]
                knots = np.r_[iv.lo, inner, iv.hi]
            more = between(knots, finest(knots) if callable(finest) else finest)
            if len(more):
                inner = np.r_[inner, more]
                knots = np.sort(np.r_[knots, more])
        if graded and knots[-1] > knots[0]:
            steps = 0.5 ** np.arange(1, graded + 1)
            first, last = knots[1] - knots[0], knots[-1] - knots[-2]
            more = np.r_[knots[0] + first * steps, knots[-1] - last * steps,
                         knots[0] + (knots[-1] - knots[0]) * (np.arange(1, ONSET_KNOTS) / ONSET_KNOTS) ** 3]
            more = more[(more > knots[0]) & (more < knots[-1])]
            inner = np.r_[inner, more]
            knots = np.unique(np.r_[knots, more])
        mids = 0.5 * (knots[1:] + knots[:-1])
        out += [(iv, 0, np.array([iv.lo])), (iv, max(len(iv.rows) - 1, 0), np.array([iv.hi])),
                (iv, 0, np.sort(np.r_[mids, inner]) if len(inner) else mids)]
    return out


def _turn_means(t: np.ndarray, values: dict[str, np.ndarray], a: float, b: float, intervals: list[Interval],
                tables: list, asked: list[tuple]) -> dict:
    """The mean of each column over the turn [a, b] (its smooth `intervals`): Simpson's rule on each gap between an
    interval's knots (its ends, with the one-sided limits read there, its rows and the knots read between rows
    farther apart than a degree of drive angle), with the reading at the gap's midpoint (`tables`, the readings of
    `_turn_mean_requests` `asked`), so that a jump at an event costs nothing and the error is O(h^4 F^(4)) of the
    knots' spacing h, which no output step coarsens (docs/theory.md §K5: the trapezoidal rule's O(h^2 F^(2)) moved
    the mean by up to 2e-3 of it between grids)."""
    names = list(values)
    if not names:
        return {}
    total = np.zeros(len(names))
    for n, iv in enumerate(intervals):
        first, last, between = tables[3 * n:3 * n + 3]
        at = asked[3 * n + 2][2]                  # the midpoints and the added knots, in time order
        rows = np.asarray(iv.rows, dtype=np.int64)
        if len(rows) and rows[-1] - rows[0] == len(rows) - 1:      # the rows in order, none left out: a view
            rows = slice(int(rows[0]), int(rows[-1]) + 1)
        tt = np.concatenate([[iv.lo], t[rows], at, [iv.hi]])
        ff = np.empty((len(names), len(tt)))
        ff[:, 0] = [first[c][0] for c in names]
        ff[:, 1:len(iv.rows) + 1] = np.array([values[c][rows] for c in names]).reshape(len(names), -1)
        ff[:, len(iv.rows) + 1:-1] = np.array([np.asarray(between[c], dtype=float) for c in names]
                                           ).reshape(len(names), -1)
        ff[:, -1] = [last[c][0] for c in names]
        order = np.argsort(tt, kind="stable")
        tt, ff = tt[order], ff[:, order]
        keep = np.r_[True, tt[1:] != tt[:-1]]     # (a row at an end is its limit: the end's read one kept)
        tt, ff = tt[keep], ff[:, keep]          # knot, midpoint, knot, ..., knot
        total += ((ff[:, 2::2] + 4.0 * ff[:, 1:-1:2] + ff[:, :-2:2]) * (tt[2::2] - tt[:-2:2])).sum(axis=1) / 6.0
    return {c: float(v) / (b - a) for c, v in zip(names, total.tolist())}


#: the thermal means' knots graded toward each interval's ends (`_turn_mean_requests`): a flash rise grows like
#: sqrt(t - t_on) where a contact begins (docs/theory.md §G4.6)
ONSET_GRADING = 6
#: and over each interval from its start, at (k / ONSET_KNOTS)^3 of it: the first gap 1/ONSET_KNOTS^3 of the interval,
#: where Simpson's rule on sqrt(t - t_on) errs by 3e-2 of the gap^1.5 (docs/theory.md §K5)
ONSET_KNOTS = 64


def _thermal_turn_means(reader, t: np.ndarray, cols, columns: list[str], events: pd.DataFrame, a: float,
                        b: float, finest=None) -> dict:
    """`_turn_means` of the thermal columns over the turn [a, b]: its smooth intervals split at the events and at
    the heat input's own switches (the thermal reader's `kinks`: the flash rise follows |slip speed|, and jumps
    where the contact starts and ends), their ends' one-sided limits read by the thermal reader. The trapezoidal
    rule on the rows alone put each jump inside a panel: an error of O(h) of the jump that moved with the output
    step (internal-geneva-motor's mean flash rise by 9e-4 of it between 0.37 and 2.3 ms rows). finest: the knots
    added between rows farther apart, as the mechanical means' (`_turn_mean_requests`)."""
    from mechsim.scenarios.thermal_peaks import heat_breaks
    turn = intervals_of(t, heat_breaks(reader, _breaks(events), a, b), a, b, "turn start", "turn end")
    asked = _turn_mean_requests(t, turn, finest, graded=ONSET_GRADING) if turn else None
    if asked is None:
        return {}
    got = reader.read_many(asked)
    if any(x is None for x in got):
        return {}
    return _turn_means(t, {c: np.asarray(cols[c], dtype=float) for c in columns}, a, b, turn, got, asked)


def turn_mean(t: np.ndarray, f: np.ndarray, a: float, b: float) -> float:
    """The mean of a column over [a, b] by the trapezoidal rule on the rows (the ends interpolated)."""
    inside = (t > a) & (t < b)
    tt = np.r_[a, t[inside], b]
    ff = np.r_[np.interp(a, t, f), f[inside], np.interp(b, t, f)]
    return float(np.trapezoid(ff, tt) / (b - a)) if hasattr(np, "trapezoid") else float(np.trapz(ff, tt) / (b - a))


def located_peaks(df: pd.DataFrame, angle_column: str, peak_columns, events: pd.DataFrame, cols,
                  source: Source | None, speed_column: str | None = None, event_cols: TableColumns | None = None
                  ) -> tuple[dict, dict | None]:
    """({column: {max, min, abs_max, how[, startup, periodic | cycle, singular]}}, the periodic regime or None) for
    each of peak_columns in the table (see the module docstring). Where the run reaches a periodic regime, max and
    min are the periodic regime's and `startup` holds the start-up's (docs/theory.md §K5), `periodic` the mean over
    its last turn; elsewhere `cycle` holds the mean over the last complete drive cycle (`last_drive_cycle`). cols,
    event_cols: the table's and the events' TableColumns (event_cols where at hand)."""
    out: dict = {}
    t = np.asarray(cols["t_s"], dtype=float)
    if not len(t):
        return out, None
    angles = np.asarray(cols[angle_column], dtype=float)
    # (a column no row holds a value of is located all the same where the run's readings hold it: a thermal one
    # defined in contact only, whose engagements lie between rows a turn apart)
    present = [c for c in peak_columns if c in cols and (_valued(np.asarray(cols[c], float)) or (
        source is not None and len(t) > 1 and c not in source.columns))]
    how = HOW_ROWS
    read, coordinates, readable, n = None, (), [], len(t)
    regime = None
    windows = [(float(t[0]), float(t[-1]), "run")]
    kinds = {"run": ("start", "end")}
    if source is not None and len(t) > 1:
        readable = [c for c in present if c in source.columns]
        # a cycle-averaged run's table continues past the simulated window: locate inside the window
        t_end = float(t[-1]) if source.traj is None else float(source.traj.pieces[-1].t[-1])
        n = int(t.searchsorted(t_end, side="right"))
        if source.method == "closed-form":
            angle0 = source.si["initial"][source.mech.initial_keys[0]]
            # the located columns, and the angles (unwrapped from the run's start: a shortened history that counts
            # the turns wrongly shows in them first)
            check = [c for c in readable if c in cols] + [c for c in cols if c.endswith("_angle_rad")
                                                          and c not in readable]
            read, how = _closed_form_reader(source, angle0, t[:n], {c: np.asarray(cols[c], float)[:n]
                                                                   for c in check}, check), HOW_CLOSED
        else:
            read = TrajectoryReader(source.traj, source.mech.angle_coordinates, source.settings)
            how = HOW_DENSE if getattr(source.traj, "dense", None) is not None else HOW_DAE
            model = source.traj.model
            coordinates = tuple(f"{c}_N_m_s" if i in source.mech.angle_coordinates else f"{c}_N_s"
                                for i, c in enumerate(model.coordinates))
    h = _median_step(t[:n]) if n > 1 else 0.0
    speeds = np.asarray(cols[speed_column], float)[:n] if speed_column in cols else None
    values = {c: np.asarray(cols[c], float)[:n] for c in readable}
    # every window's candidates, and the periodic regime's turn, read in one pass of the reader (`read_many`)
    breaks = _breaks(events, event_cols) if read is not None else []
    tn = t[:n]
    raw = read
    read = _Readings(raw) if raw is not None else None
    locate_turns = None                 # where the drive's turns are located on the continuous solution
    if raw is not None and source.method != "closed-form":
        windows = [(float(t[0]), t_end, "run")]
        if speed_column in cols and not source.drive.is_prescribed:
            # the regime's turns located on the continuous solution first: its windows and turn start there
            whole = (_intervals(tn, breaks, float(t[0]), t_end, ("start", "end"), raw)
                     if angle_column in source.columns and speed_column in source.columns else [])
            locate_turns = _located_turns(read, whole, tn, angle_column, speed_column) if whole else None
            regime = periodic_regime(tn, angles[:n], np.asarray(cols[speed_column], float)[:n], locate_turns,
                                     {c: np.asarray(cols[c], float)[:n] for c in cols.names
                                      if c.startswith("work_") and c.endswith("_J") and c in source.columns},
                                     speed_column, _turn_estimates(source, raw, whole, tn, cols, angle_column,
                                                                   speed_column) if whole else None)
    elif source is not None and len(t) > 1:
        windows = [(float(t[0]), t_end, "run")]
    # the turn the means are taken over: the periodic regime's last, else (a prescribed drive, a run that does not
    # settle) the last complete drive cycle, located as the regime's turns are
    mean_over = None if regime is None else regime["last_turn"]
    if regime is None and raw is not None and speed_column in cols:
        cycle = source.mech.drive_cycle()
        if cycle is not None and cycle.column == angle_column:
            mean_over = last_drive_cycle(tn, angles[:n], np.asarray(cols[speed_column], float)[:n], cycle,
                                         locate_turns)
    if regime is not None and regime["startup_turns"] > 0:
        windows = [(regime["from_t_s"], t_end, "periodic"), (float(t[0]), regime["from_t_s"], "startup")]
    kinds = {"run": ("start", "end"), "periodic": ("start of the periodic regime", "end"),
             "startup": ("start", "end of the start-up")}
    if source is not None and source.method == "closed-form" and read is not None:
        breaks = sorted(breaks + _contact_switches(source, tn, cols, breaks))
    spans = [_intervals(tn, breaks, lo, hi, kinds[label], raw) if read is not None and readable else []
             for lo, hi, label in windows]
    # an interval with (almost) no rows is located from readings over it, added to its plan's table (`p.values`);
    # the windows over the same table planned together
    finest = sampler = None
    if source is not None and source.method == "closed-form":
        finest = _finest(source, tn)
    elif read is not None and angle_column.endswith("_rad"):
        # a DAE run's: its dense output's readings, else its states interpolated between its rows
        finest = _rows_finest(tn, angles[:n], speeds)
        sampler = raw.sampler(TRUSTED_RAD) if finest is not None else None
        if sampler is None:
            finest = None
        else:
            how = HOW_DAE_SAMPLED if how == HOW_DAE else HOW_DENSE_SAMPLED
    plans = plan_windows([with_rowless(tn, values, intervals, raw, finest, sampler) if intervals else None
                          for intervals in spans])
    requests = [r for p in plans if p is not None for r in p.requests]
    turn = means_asked = spacing = None
    if mean_over is not None and read is not None:
        turn = _intervals(tn, breaks, *mean_over, ("turn start", "turn end"), raw)
        spacing = finest if finest is not None else _rows_finest(tn, angles[:n], speeds)
        means_asked = _turn_mean_requests(tn, turn, spacing if spacing is not None else np.inf)
    # a dense output's readings cost no integration: the one-sided limits at every end (`stored_limits` ranks the ends
    # by them), those `end_limits` may read and the growth toward the events an extremum may lie next to (what the
    # singular-approach check may read) are read in the same pass (`readings_ahead`, on the rows' lines); other
    # readers read them once the extrema are known
    lines = _end_lines(plans)
    ahead = []
    if how.startswith(HOW_DENSE):
        ahead = [r for ws, x in lines for r in readings_ahead([plans[w] for w in ws], h, x, read.growth)]
        ahead += [r for p in plans if p is not None for r in end_limit_requests(p.intervals, every_end(p.intervals))]
    spanned = [[iv for w in ws for iv in plans[w].intervals] for ws, _ in lines]      # each line group's intervals
    if read is not None and hasattr(read, "stage_limits"):     # the ends `stored_limits` reads, read out with these
        for ivs in spanned:
            read.stage_limits([(ivs[k], side) for k, side, _ in every_end(ivs)])
    tables = read.prefetch(requests + (means_asked or []) + ahead) if read is not None else []
    for (_, x), ivs in zip(lines, spanned) if read is not None else ():      # the limits the reader holds rank the ends
        stored_limits(x, ivs, read)
    means = {}
    if means_asked is not None:
        got = tables[len(requests):len(requests) + len(means_asked)]
        try:
            means = _turn_means(t[:n], values, *mean_over, turn,
                                [x if x is not None else read(*r) for r, x in zip(means_asked, got)], means_asked)
        except ReadingFailed:           # the rows' mean stands (`turn_mean`), and says so (HOW_ROWS_MEAN)
            pass
    located = iter(finish_all([p for p in plans if p is not None], tables[:len(requests)], read))
    located = [next(located) if p is not None else {} for p in plans]
    # the candidates beyond the first that may still beat what these found, refined in a second pass; in a periodic
    # regime, whose turns repeat the same peaks (to its criterion), only those next to an event in its last turn
    # (`second_round`): there the first are the regime's
    if read is not None:
        ends = {w: (x, q if len(ws) > 1 else None) for ws, x in lines if x is not None for q, w in enumerate(ws)}
        refine_further(plans, located, read, [ends.get(w) for w in range(len(plans))],
                       [tuple(regime["last_turn"]) if label == "periodic" else None for _, _, label in windows])
    # each extremum against the one-sided limits at events that may beat it (`end_limits`), read together; not a
    # constant stretch's (exact: a dwell's zero speed, which the limits at the events around it equal only to the
    # integration's tolerance)
    checks = [(p, got, c, name, sense) for p, got in zip(plans, located) if p is not None for c in p.values
              for name, sense in (("max", 1.0), ("min", -1.0))
              if not getattr(got.get(c, {}).get(name), "constant", False)]
    guesses = {}                    # each check's ends to read (`end_guesses`), all of a table's plans' at once
    ranked_by = {}                  # each check's lines and window in them (`end_limits`' further passes)
    for ws, x in lines if read is not None else ():
        mine = [(n, q) for n, check in enumerate(checks) for q, w in enumerate(ws) if check[0] is plans[w]]
        p = plans[ws[0]]
        asks = [(c, sense, getattr(got.get(c, {}).get(name), "value", None))
                for _, got, c, name, sense in (checks[n] for n, _ in mine)]
        if mine:
            guesses.update(zip((n for n, _ in mine), end_guesses(p.t, p.values, p.intervals, asks, p.ties, lines=x,
                                                                 windows=[q for _, q in mine])))
            ranked_by.update((n, (x, q if x is not None and x.window is not None else None)) for n, q in mine)
    guesses = [guesses[n] for n in range(len(checks))] if read is not None else []
    if read is not None and checks:
        read.prefetch([r for (p, *_), g in zip(checks, guesses) for r in end_limit_requests(p.intervals, g)])
    for n, ((p, got, c, name, sense), g) in enumerate(zip(checks, guesses)):
        e = end_limits(got.get(c, {}).get(name), c, sense, p.t, p.values[c], p.intervals, p.intervals, read, p.ties[c],
                       g, *ranked_by.get(n, (None, None)))
        if e is not None:
            got.setdefault(c, {})[name] = e
    # the growth toward an event where an extremum lies next to one: every window's and column's first approach
    # read together (already read on a dense output)
    if read is not None:
        read.prefetch([r for r, _ in growth_requests([x for p, got in zip(plans, located) if p is not None
                                                       for c, e in got.items()
                                                       for x in first_approaches(c, p.values[c], e, p.intervals)], h,
                                                      kept=read.growth)])
    thermal, treader = [c for c in present if c not in readable], None
    if source is not None and thermal and len(t) > 1:
        from mechsim.scenarios.thermal_peaks import thermal_reader
        treader = thermal_reader(source, events, float(t[-1]), read if source.method == "closed-form" else None)
    heats = [{} for _ in windows]
    # (a DAE run's thermal columns sampled as its mechanical ones: `ThermalReader.sampler`, none for a cycle average)
    sampled = ("" if treader is None or sampler is None or source.method == "closed-form" or treader.cycle else
               SAMPLED_DENSE if how == HOW_DENSE_SAMPLED else SAMPLED_STATES)
    if treader is not None:           # the thermal columns over the whole table (a cycle-averaged run's continues)
        from mechsim.scenarios.thermal_peaks import locate_thermal
        heats = locate_thermal(treader, t, cols, thermal, events, [(lo, hi if label == "startup" else float(t[-1]),
                                                                    kinds[label]) for lo, hi, label in windows],
                               finest, TRUSTED_RAD)
        # the growth toward the event next to a thermal column's extremum: every window's and column's first approach
        # read together (the thermal reader keeps them for `singular_approaches`)
        firsts = [x for heat in heats for c, (got, intervals) in heat.items()
                  for x in first_approaches(c, np.asarray(cols[c], dtype=float), got, intervals)]
        if firsts:
            treader.read_many([r for r, _ in growth_requests(list({(id(iv), side): (iv, side)
                                                                   for iv, side in firsts}.values()), h)])
    if treader is not None and mean_over is not None and thermal:
        means.update(_thermal_turn_means(treader, t, cols, thermal, events, *mean_over, spacing))
    table = np.array([np.asarray(cols[c], dtype=float) for c in present]).reshape(len(present), len(t))
    for (lo, hi, label), got, intervals, heat, p in zip(windows, located, spans, heats,
                                                        plans if plans else [None] * len(windows)):
        # rows the unlocated columns are read on: the periodic regime runs to the table's end (a cycle-averaged
        # run's table continues the simulated window periodically)
        inside = (np.ones(len(t), bool) if label == "run" else t >= lo if label == "periodic"
                  else (t >= lo) & (t <= hi))
        bests = _best_rows(table, inside)
        cut = _between_ends(p.t, p.intervals) if p is not None else None
        for c, f, best in zip(present, table, bests):
            mine, own = ((heat[c][0], (treader.how + sampled, heat[c][1], treader)) if c in heat else
                         (got.get(c, {}), (how, intervals, read)))
            # the growth toward an event is judged on the window's table with its samples between the rows where
            # it has them (an interval between events may hold no two rows)
            sampled_rows = (p.t, p.values[c], cut) if c not in heat and p is not None and c in p.values else None
            entry = _column_entry(c, f, t, angles, inside, angle_column, mine, *own, h, events, coordinates, best,
                                  sampled_rows)
            if entry["max"]["at"] == entry["min"]["at"] == "no rows" and not _valued(f):
                continue                    # no row and no reading holds a value of it: no entry
            if label == "startup":
                if c not in out:
                    continue
                out[c]["startup"] = {k: entry[k] for k in ("max", "min") if k in entry}
                if "singular" in entry:
                    out[c].setdefault("singular", []).extend(entry["singular"])
            else:
                if label == "periodic" or (label == "run" and mean_over is not None):
                    a, b = mean_over
                    mean = {"mean": means[c] if c in means else turn_mean(t[:n], f[:n], a, b), "mean_over": [a, b]}
                    if c not in means:
                        mean["how"] = HOW_ROWS_MEAN
                    if _pole_inside(entry.get("singular", ()), a, b):
                        mean.update(mean=None, unbounded=True)
                    elif not math.isfinite(mean["mean"]):       # a column defined only in contact (NaN between)
                        mean["mean"] = None
                    entry["periodic" if regime is not None else "cycle"] = mean
                out[c] = entry
    return out, regime


#: a column that grows like distance^-p toward an event has no finite mean over a turn holding it where p >= 1 (the
#: integral of 1/x diverges); measured exponents of a 1/x pole are 1 to within 1e-3 (`singular_approaches`)
POLE_EXPONENT = 0.95


def _pole_inside(singular, a: float, b: float) -> bool:
    """Whether a column's `singular` events (its entry's) put a pole of order POLE_EXPONENT or more in [a, b]: its
    mean over them is then unbounded."""
    return any(a <= s["t_s"] <= b and (s.get("growth_exponent") or 0.0) >= POLE_EXPONENT for s in singular)


def _finest(source: Source, t: np.ndarray) -> float | None:
    """The time step a closed-form run's columns are sampled at between its rows (`with_rowless`): CLOSED_STEP_RAD of
    drive angle at the prescribed speed, coarser where the run would take more than CLOSED_READINGS samples; None
    without a speed or rows. A peak narrower than the output step (the rolling pair's coupler force near zero, a
    dip of a few degrees) is then among the candidates at every output step (docs/theory.md §K5)."""
    speed = abs(float(getattr(source.drive, "speed", None) or 0.0))
    span = float(t[-1] - t[0]) if len(t) > 1 else 0.0
    if not (speed > 0.0 and math.isfinite(speed) and span > 0.0):
        return None
    return max(CLOSED_STEP_RAD / speed, span / CLOSED_READINGS)


def _rows_finest(t: np.ndarray, angles: np.ndarray, speeds: np.ndarray | None = None):
    """A DAE run's sampling between its rows (`with_rowless`'s `finest`), as a closed form's (`_finest`): the
    spacing in each gap between instants that keeps the drive angle DAE_STEP_RAD apart at the rows' pace there: the
    net turn across the gap, or the drive's speed at either end (`speeds` on the rows, where given) where that is
    faster, since a gap whose ends show little net turning may hold a reversal (a rocking crank through its dead
    points); at most CLOSED_READINGS samples a run; None where no gap needs a sample. Coarser than a closed form's:
    the samples are read-outs of interpolated states, one per sample, and a peak a few degrees wide still has samples
    inside it (docs/theory.md §K5)."""
    if len(t) < 2:
        return None
    h = np.diff(t)
    with np.errstate(invalid="ignore"):
        pace = np.abs(np.diff(angles)) / np.where(h > 0, h, np.inf)
        if speeds is not None:
            fast = np.abs(speeds)
            pace = np.fmax(pace, np.fmax(fast[1:], fast[:-1]))
        step = max(DAE_STEP_RAD, float(np.nansum(pace * h)) / CLOSED_READINGS)
        if not np.nanmax(pace * h, initial=0.0) > step:
            return None

    def spacing(knots: np.ndarray) -> np.ndarray:
        with np.errstate(invalid="ignore", divide="ignore"):
            turn = np.abs(np.diff(np.interp(knots, t, angles))) / np.diff(knots)
            if speeds is not None:
                fast = np.interp(knots, t, np.abs(speeds))
                turn = np.fmax(turn, np.fmax(fast[1:], fast[:-1]))
            return step / turn
    return spacing


def _end_lines(plans: list) -> list[tuple[list[int], object]]:
    """The located plans over one table (t and values the same arrays, as `plan_windows` plans them together) with
    their `end_lines`, made together (each window's ends its own): [(the plans' positions, their lines)]."""
    tables: dict = {}
    for w, p in enumerate(plans):
        if p is not None:
            tables.setdefault((id(p.t), id(p.values)), []).append(w)
    return [(ws, end_lines(plans[ws[0]].t, plans[ws[0]].values, [iv for w in ws for iv in plans[w].intervals],
                           [len(plans[w].intervals) for w in ws])) for ws in tables.values()]


class _Readings:
    """A reader with readings taken ahead (`prefetch`: many requests in one pass of its `read_many`), handed back
    when the same request comes; anything else is the reader's own."""

    def __init__(self, read):
        self.read, self.kept = read, {}
        self.growth: dict = {}          # the growth requests made (`growth_requests`), one h per reader

    @staticmethod
    def _key(iv: Interval, position: int, times: np.ndarray):
        return id(iv), int(position), np.asarray(times, float).tobytes()

    def prefetch(self, requests: list[tuple]) -> list[dict | None]:
        """The readings of `requests` (None where the reader did not read one), kept: those not kept yet read in
        one pass."""
        keys = [self._key(*r) for r in requests]
        new = {k: r for k, r in zip(keys, requests) if k not in self.kept}
        for k, got in zip(new, read_all(self.read, list(new.values()))):
            if got is not None:
                self.kept[k] = got
        return [self.kept.get(k) for k in keys]

    def read_many(self, requests: list[tuple]) -> list[dict | None]:
        """`prefetch`: what a caller reads many at once is kept too (`end_limits`' further passes read their
        requests ahead, then each alone)."""
        return self.prefetch(requests)

    def __call__(self, iv: Interval, position: int, times: np.ndarray) -> dict:
        got = self.kept.get(self._key(iv, position, times))
        return got if got is not None else self.read(iv, position, times)

    @property
    def limits(self):
        """The reader's `limits` (None where it has none), a dense output's readings kept (read again by
        `end_limits`)."""
        inner = getattr(self.read, "limits", None)
        return None if inner is None else (lambda ends, names: inner(ends, names, self.prefetch))

    def __getattr__(self, name):
        return getattr(self.read, name)


def _best_rows(table: np.ndarray, inside: np.ndarray) -> list[dict]:
    """Each column's (a row of `table`) largest and least finite value over the rows `inside` the window, {max, min}
    (None where it has none there): what the rows alone would report, beside each located extremum. The window's
    rows run on (a run, a start-up, a periodic regime to the table's end): read as one slice of them."""
    idx = np.flatnonzero(inside)
    if not len(idx):
        return [{"max": None, "min": None} for _ in table]
    part = table[:, idx[0]:idx[-1] + 1] if idx[-1] - idx[0] == len(idx) - 1 else table[:, idx]
    ok = np.isfinite(part)
    top = part.max(axis=1, where=ok, initial=-np.inf).tolist()
    least = part.min(axis=1, where=ok, initial=np.inf).tolist()
    return [{"max": a if math.isfinite(a) else None, "min": b if math.isfinite(b) else None}
            for a, b in zip(top, least)]


def _between_ends(t: np.ndarray, intervals: list[Interval]) -> list[Interval]:
    """The intervals without their rows at their ends (a plan's table holds an interval's one-sided limits at its
    events as rows: at an event the column grows without bound toward, that limit is a round-off value of either
    sign, which says nothing of the approach the rows before it show)."""
    out = []
    for iv in intervals:
        rows = np.asarray(iv.rows)
        keep = (t[rows] > iv.lo) & (t[rows] < iv.hi) if len(rows) else np.zeros(0, bool)
        out.append(iv if keep.all() else dataclasses.replace(iv, rows=rows[keep]))
    return out


def _column_entry(c, f, t, angles, inside, angle_column, got, how, intervals, read, h, events, coordinates,
                  best: dict, sampled_rows: tuple | None = None) -> dict:
    """One column's {max, min, abs_max, how[, singular]} from its located extrema (or its rows inside the window);
    best: its best rows in the window (`_best_rows`), reported beside a located extremum; sampled_rows: (the times,
    the column, the intervals) of the table the extrema were located on (its samples between rows among its rows),
    on which the growth toward an event is judged (`singular_approaches`) and the other extremum taken where the
    located one is a limit at such an event (`_beside_poles`)."""
    entry: dict = {}
    rows = None                     # the rows inside the window with a value: read where a column is not located
    for name, pick in (("max", np.argmax), ("min", np.argmin)):
        e = got.get(name)
        if e is not None:
            # a constant stretch's row carries the peak columns only: its angle is the table's at that row
            angle = float(e.row[angle_column]) if angle_column in e.row else float(np.interp(e.t, t, angles))
            entry[name] = _entry(e.value, e.t, angle, e.where, best[name], e.limit)
            if "window_t_s" in e.row:     # after a cycle-averaged window: the instant of the turn it repeats
                entry[name]["window_t_s"] = float(e.row["window_t_s"])
            continue
        if rows is None:
            rows = np.flatnonzero(inside & np.isfinite(f))
        if len(rows):
            i = int(rows[pick(f[rows])])
            entry[name] = _entry(f[i], t[i], angles[i], "output row")
        else:
            entry[name] = _entry(np.nan, np.nan, np.nan, "no rows")
    # the larger magnitude; magnitudes equal to the located values' accuracy (a motion symmetric in sign) go to the
    # maximum, so the signed value reported and differentiated follows neither the rounding nor the output rows
    big, small = abs(entry["max"]["value"]), abs(entry["min"]["value"])
    side = "max" if big >= small - SYMMETRIC * max(big, small) or not math.isfinite(small) else "min"
    entry["abs_max"] = dict(entry[side], value=abs(entry[side]["value"]), side=side)
    entry["how"] = how if got else HOW_ROWS
    for name, sense in (("max", 1.0), ("min", -1.0)):
        e = got.get(name)
        # an extremum in the bracket next to an event: does the column grow without bound toward it?
        edge = limit_edge(e)
        if edge is None or read is None:
            continue
        g, ivs = sampled_rows[1:] if sampled_rows is not None else (f, intervals)
        found = singular_approaches(c, g, edge, sense, ivs, read, h, events, coordinates, e.interval)
        if found:
            t_e = found[0]["t_s"]
            angle = _event_angle(events, t_e, angle_column, t, angles)
            entry[name] = dict(entry[name], value=None, unbounded=True, t_s=t_e, drive_angle_rad=angle,
                               drive_angle_wrapped_deg=_wrapped_deg(angle), limit=edge,
                               at=f"grows without bound toward the event at t = {t_e:.9g} s",
                               growth_exponent=found[0]["growth_exponent"])
            entry[name].pop("best_row_value", None)
            entry["abs_max"] = dict(entry[name], side=name)
            entry.setdefault("singular", []).extend(dict(x, extremum=name) for x in found)
            # the other extremum taken as the limit at one of those events from the same side is no value there
            # (the state at the event gives the column to round-off, of either sign): the best of the table without
            # those limits stands
            other = "min" if name == "max" else "max"
            poles = {x["t_s"] for x in found}
            if entry[other].get("limit") == edge and entry[other]["t_s"] in poles:
                entry[other] = _beside_poles(other, entry[other]["t_s"], f, t, angles, inside, edge, poles,
                                             sampled_rows)
    return entry


def _beside_poles(name: str, t_limit: float, f: np.ndarray, t: np.ndarray, angles: np.ndarray, inside: np.ndarray,
                  side: str, poles: set, sampled_rows: tuple | None) -> dict:
    """The entry of a column's extremum `name` ('max' or 'min') where the located one was the limit on `side` at an
    event the column grows without bound toward (`poles`, their times): the best of the table the extrema were
    located on (its rows and its readings between them, `sampled_rows`) without the limits at those events, else
    of the rows inside the window. A reading between rows is the continuous solution's (a dwell's constant value
    between rows a turn apart), which the rows alone miss."""
    pick = np.argmin if name == "min" else np.argmax
    why = (f"the limit at the event at t = {t_limit:.9g} s is no value: the column grows without bound toward it")
    if sampled_rows is not None:
        ts, g, intervals = sampled_rows
        ends = [iv.hi if side == "before" else iv.lo for iv in intervals]
        rows = [np.asarray(iv.rows, dtype=np.int64) for iv in intervals]
        keep = [r[ts[r] != end] if end in poles else r for r, end in zip(rows, ends)]
        idx = np.unique(np.concatenate(keep)) if keep else np.zeros(0, np.int64)
        idx = idx[np.isfinite(g[idx])] if len(idx) else idx
        if len(idx):
            i = int(idx[pick(g[idx])])
            rows = np.flatnonzero(t == ts[i])
            at = "output row" if len(rows) else "reading between the rows"
            angle = float(angles[rows[0]]) if len(rows) else float(np.interp(ts[i], t, angles))
            return _entry(float(g[i]), float(ts[i]), angle, f"{at} ({why})")
    rows = np.flatnonzero(inside & np.isfinite(f))
    if not len(rows):
        return _entry(np.nan, np.nan, np.nan, "no rows")
    i = int(rows[pick(f[rows])])
    return _entry(f[i], t[i], angles[i], f"output row ({why})")


def _event_angle(events: pd.DataFrame | None, t_e: float, angle_column: str, t: np.ndarray,
                 angles: np.ndarray) -> float:
    """The drive angle at an event: the events table's own (`<coordinate>_q`, the state at the event), else
    interpolated between the rows."""
    q = angle_column.removesuffix("_angle_rad") + "_q"
    if events is not None and len(events) and q in events:
        at = events["t_s"].to_numpy(float) == t_e
        if at.any():
            return float(events[q].to_numpy(float)[np.flatnonzero(at)[0]])
    return float(np.interp(t_e, t, angles))


#: a column's largest and least located values whose magnitudes are this close (relative) are equal for its largest
#: magnitude (`abs_max`, the maximum's): a motion symmetric in sign has them equal to its located values' accuracy
#: (a DAE run's, its tolerance: geneva-lc1's wheel acceleration as the sensitivities' DAE, 1.2e-9 apart, the side
#: following the output rows), where a motion that is not differs by far more
SYMMETRIC = 1e-6
