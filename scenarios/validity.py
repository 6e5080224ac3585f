"""Validity monitors: the conditions a run's model needs (declared as data by the mechanism,
`Mechanism.validity_conditions`, and by the thermal model, `thermal/model_validity.py`), evaluated on every output row.

`section` is the summary's `validity`: per condition the share of the run's time it is violated, its worst value
(and when), the first violation; `stop` cuts a run at the first violating row for `output.on_invalid = "stop"`
(a Failure with code model_invalid: exit 3, what ran written). docs/theory.md, "Validity".
"""
from __future__ import annotations

from collections.abc import Callable, Mapping
from dataclasses import dataclass, field

import numpy as np
import pandas as pd

from mechsim.dynamics.result import Failure, FailureCode
from mechsim.mechanisms.base import ValidityCondition


def conditions(mech, thermal=None) -> list[ValidityCondition]:
    """The mechanism's conditions, then the thermal model's (plain dicts there, made ValidityCondition here)."""
    out = list(mech.validity_conditions())
    if thermal is not None:
        out += [ValidityCondition(**c) for c in thermal.validity_conditions()]
    return out


def _row_weights(t: np.ndarray) -> np.ndarray:
    """Each row's share of the run's time: half the intervals on either side (all equal for a single row)."""
    if len(t) < 2:
        return np.ones(len(t))
    dt = np.diff(t)
    w = np.zeros(len(t))
    w[:-1] += 0.5 * dt
    w[1:] += 0.5 * dt
    return w


def evaluate(conds: list[ValidityCondition], columns: Mapping[str, np.ndarray]) -> dict:
    """The summary's `validity` section of a table (`columns`: name -> array, a DataFrame's TableColumns):
    `valid` (no condition violated on any row), `violated` (their names) and per condition its bound, the time
    share violated, the worst value with its time, and the first violation's time (None if none)."""
    t = np.asarray(columns["t_s"], dtype=float) if "t_s" in columns else np.zeros(0)
    weights = _row_weights(t)
    total = float(weights.sum()) or 1.0
    rows = []
    for c in conds:
        row = {"name": c.name, "description": c.description, "bound": c.bound,
               "sense": "<=" if c.sense == "max" else ">=", "unit": c.unit, "source": c.source}
        missing = [n for n in c.needs if n not in columns]
        if missing or not len(t):
            rows.append({**row, "evaluated": False, "why": f"the table has no {', '.join(missing)}" if missing
                         else "no output rows"})
            continue
        values = np.broadcast_to(np.asarray(c.quantity(columns), dtype=float), t.shape)
        margin = c.margin(values)
        applies = np.isfinite(margin)
        bad = applies & (margin < 0)
        first = int(np.argmax(bad)) if bad.any() else None
        row.update(evaluated=True, how="rows", applies_share=float(weights[applies].sum() / total),
                   violated_share=float(weights[bad].sum() / total), violated_rows=int(bad.sum()),
                   first_violation_t_s=None if first is None else float(t[first]),
                   first_violation_value=None if first is None else float(values[first]), worst=None)
        if applies.any():
            i = int(np.nanargmin(np.where(applies, margin, np.nan)))
            row["worst"] = {"value": float(values[i]), "t_s": float(t[i]), "margin": float(margin[i])}
        rows.append(row)
    violated = [r["name"] for r in rows if r.get("violated_rows")]
    return {"valid": not violated, "violated": violated, "conditions": rows}


def describe(row: dict) -> str:
    """One line of a violated condition: its share of time, worst value and when, the bound."""
    unit = f" {row['unit']}" if row["unit"] else ""
    w = row["worst"]
    worst = (f"unbounded near t = {w['t_s']:.6g} s" if w.get("unbounded") else
             f"worst {w['value']:.4g}{unit} at t = {w['t_s']:.6g} s")
    return (f"{row['name']} violated {100 * row['violated_share']:.3g} % of the time (first at t = "
            f"{row['first_violation_t_s']:.6g} s; {worst}, must be {row['sense']} {row['bound']:g}{unit}): "
            f"{row['description']}")


def violation_lines(section: dict | None) -> list[str]:
    """The console's lines for a run's `validity` section: one warning per violated condition."""
    if not section:
        return []
    return [f"warning: the model leaves its validity: {describe(r)}" for r in section["conditions"]
            if r.get("violated_rows") or r.get("violated_between_rows")]


def stop(section: dict, df: pd.DataFrame, events: pd.DataFrame, failure: Failure | None, mode_column: str = "mode"):
    """(table, events, failure) cut after the first row that violates a condition, that violation the run's
    failure (code model_invalid) unless an earlier failure stands; unchanged where every condition holds. The
    violating row is kept: it is a valid solution of the model that shows where the model stops holding."""
    firsts = [(r["first_violation_t_s"], r) for r in section["conditions"] if r.get("first_violation_t_s") is not None]
    if not firsts:
        return df, events, failure
    t_v, row = min(firsts, key=lambda item: item[0])
    if failure is not None and failure.time <= t_v:
        return df, events, failure
    t = df["t_s"].to_numpy(float)
    keep = t <= t_v
    mode = str(df[mode_column].to_numpy()[np.flatnonzero(keep)[-1]]) if mode_column in df and keep.any() else "?"
    unit = f" {row['unit']}" if row["unit"] else ""
    failure = Failure(time=t_v, mode=mode, reason=(
        f"the model leaves its validity: {row['name']} = {row['first_violation_value']:.4g}{unit}, must be "
        f"{row['sense']} {row['bound']:g}{unit} ({row['description']})"), kind="physics",
        code=FailureCode.MODEL_INVALID,
        hint="output.on_invalid = 'warn' runs on and lists every violation in summary.json (validity)")
    df = df[keep].reset_index(drop=True)
    if len(events):
        events = events[events["t_s"].to_numpy(float) <= t_v].reset_index(drop=True)
    return df, events, failure


#: readings per bracket and pass (`located`): each pass narrows a bracket to two of its spacings
SAMPLES = 64
#: passes at most; a bracket narrower than LOCATED of its instant ends them
PASSES = 8
LOCATED = 1e-12
#: the next bracket around an interpolated answer spans this fraction of a spacing either side (`_refine`)
GUESS_SHRINK = 64.0
#: a least value settled when a pass changes it by less than this (relative, `_settled`)
SETTLED = 1e-13
#: row minima of a condition's margin refined (`located`), the lowest first
CANDIDATES = 4
#: other row minima that hold but may dip below the bound between their neighbours refined at most (`located`), those
#: that may reach deepest first: a run's resources stay bounded however many turns it has
DIPS = 256
#: the worst value counts as unbounded where its magnitude grew by more than this in each of the last two passes
UNBOUNDED_GROWTH = 3.0


@dataclass
class _Job:
    """A bracket [lo, hi] of one condition narrowed on readings (`_refine`): to its least margin (`first` False) or
    to where the margin, times `sign`, first turns negative (a crossing from the left). Its result: the instant, the
    reading's table and the instant's place in it, the best score of each pass."""

    lo: float
    hi: float
    margin: Callable
    quantity: Callable
    sign: float = 1.0
    first: bool = False
    found: tuple | None = None
    scores: list = field(default_factory=list)
    root: float | None = None          # a crossing's instant, interpolated between the samples around it
    value: float | None = None         # the quantity there, interpolated the same way
    decides: bool = False              # only whether the least passes the bound (a dip's, a rise's): `_decided`

    def __post_init__(self):
        self.end = self.hi                 # the bracket's end as given (the search narrows hi)


@dataclass
class _Edge:
    """A gap between rows with an event inside where the condition starts or stops applying, or where it applies only
    between the rows (a smooth interval without rows): its pieces between the smooth intervals' ends, the crossing
    searched in the first and the last where that row's side applies and its status may change before the event
    (None: it applies throughout at the row's status, or does not apply), each rowless piece's least margin, and
    after those (`_Condition.between_jobs`) each rowless violation's crossings and the instant a violation begins at
    the event, where one does."""

    g: int
    pieces: list
    first: _Job | None = None
    last: _Job | None = None
    middle: list = field(default_factory=list)      # (least margin's job, (a, b)) of each rowless piece searched
    pairs: list = field(default_factory=list)        # (into, out) of each rowless piece's violation
    begins: _Job | None = None                       # the last piece's start, violated there, read


def _refine(read_at, jobs: list[_Job]) -> None:
    """Every job's bracket narrowed on readings, all jobs in one pass of `read_at` (with groups) per step: SAMPLES
    instants evenly over it (its ends included); the next bracket is 1/GUESS_SHRINK of a spacing either side of the
    interpolated answer (the secant's root between the samples around a crossing, the parabola's vertex through the
    three around the least score), so that a smooth margin needs two or three passes, and where that bracket turns
    out not to hold the answer (a kink, a pole), the two spacings around it as found by the samples; until
    narrower than LOCATED of its instant or PASSES passes. A job whose reading fails keeps what it had."""
    live = list(jobs)
    plain: dict[int, tuple[float, float]] = {}          # a job's bracket by the samples alone, if its guess fails
    for _ in range(PASSES):
        live = [job for job in live if job.root is None
                and (job.hi - job.lo > LOCATED * max(1.0, abs(job.hi)) or job.found is None)]
        if not live:
            return
        grids = [np.linspace(job.lo, job.hi, SAMPLES) if job.hi > job.lo else np.array([job.lo]) for job in live]
        failed = []
        for job, grid, table in zip(live, grids, read_at(grids, groups=True)):
            if table is None:
                failed.append(job)
                continue
            f = job.sign * np.broadcast_to(np.asarray(job.margin(table), dtype=float), grid.shape)
            n = len(grid)
            if job.first:
                below = np.flatnonzero(f < 0)
                j = int(below[0]) if len(below) else n - 1
                held = len(below) and j > 0               # the crossing inside this bracket
            else:
                j = int(np.argmin(np.where(np.isfinite(f), f, np.inf)))
                held = 0 < j < n - 1 or n == 1            # the least inside, not at an edge
            if not held and id(job) in plain:             # the guess missed: the samples' bracket before it
                job.lo, job.hi = plain.pop(id(job))
                continue
            if job.first and held and id(job) in plain:
                # a crossing inside its guessed bracket: the secant's root there is the crossing to O(spacing^2)
                x = _guess(grid, f, j, True)
                if x is not None:
                    job.root = x
                    job.value = float(np.interp(x, grid[j - 1:j + 1], job.quantity(table)[j - 1:j + 1]))
            job.found = (float(grid[j]), table, j)
            job.scores.append(float(f[j]))
            lo, hi = float(grid[max(j - 1, 0)]), float(grid[min(j + (0 if job.first else 1), n - 1)])
            plain[id(job)] = (lo, hi)
            guess = _guess(grid, f, j, job.first) if held else None
            if guess is None:
                job.lo, job.hi = lo, hi
            else:
                w = (grid[1] - grid[0]) / GUESS_SHRINK
                job.lo, job.hi = max(lo, guess - w), min(hi, guess + w)
        live = [job for job in live if job not in failed and (job.first or not (_unbounded(job.scores)
                                                                                 or _settled(job.scores)
                                                                                 or job.scores[-1] == np.inf
                                                                                 or job.decides and _decided(job)))]


def _decided(job: _Job) -> bool:
    """Whether a dip's or rise's search has its answer: a sample past the bound (its crossings are searched from
    there, `_Condition.between_jobs`), or a least that cannot get there: it came closer in the last pass by less
    than half its distance (each pass narrows the bracket 32-fold: what a smooth extremum or a kink still gains
    falls at least twofold a pass)."""
    s = job.scores
    return s[-1] < 0 or (len(s) >= 2 and s[-1] > 2.0 * (s[-2] - s[-1]))


def _crossing(jobs: list[_Job]) -> _Job | None:
    """Of one gap's crossing searches, one per smooth interval in time order: the first that found its sign change
    before its interval's end (inside it, or at its start: a change at the event before it, its one-sided limit
    there), else the last (none read: None)."""
    found = [job for job in jobs if job.found is not None]
    for job in found:
        if _instant(job) < job.end:
            return job
    return found[-1] if found else None


def _instant(job: _Job) -> float:
    """A crossing's instant: the interpolated root where its last pass found one, else its sample."""
    return job.root if job.root is not None else job.found[0]


def _settled(scores: list[float]) -> bool:
    """A least value that no longer changes from pass to pass (to SETTLED of it): its instant may still move along a
    minimum flat to round-off, its value does not."""
    return len(scores) >= 2 and abs(scores[-1] - scores[-2]) <= SETTLED * max(1.0, abs(scores[-1]))


def _guess(grid: np.ndarray, f: np.ndarray, j: int, first: bool) -> float | None:
    """The answer interpolated between the samples: the secant's root between samples j - 1 and j (a crossing), or
    the vertex of the parabola through j - 1, j, j + 1 (a least value); None where it is not defined."""
    if first:
        a, b = f[j - 1], f[j]
        return float(grid[j - 1] + (grid[j] - grid[j - 1]) * a / (a - b)) if np.isfinite(a - b) and a != b else None
    y0, y1, y2 = f[j - 1], f[j], f[j + 1]
    curve = y0 - 2.0 * y1 + y2
    if not (np.isfinite(curve) and curve > 0):
        return None
    return float(grid[j] + 0.5 * (grid[1] - grid[0]) * (y0 - y2) / curve)


def _unbounded(scores: list[float]) -> bool:
    """A worst value that keeps growing as its bracket narrows: its magnitude up by UNBOUNDED_GROWTH in each of the
    last two passes (a quantity with a pole inside the run, such as a friction demand |F_t|/|N| where N passes
    zero, grows like the bracket shrinks, a hundredfold a pass and more; a bounded one settles)."""
    a = np.abs(np.asarray(scores[-3:], dtype=float))
    return len(a) == 3 and bool(np.all(a[1:] > UNBOUNDED_GROWTH * a[:-1]))


def locatable(section: dict, conds: list[ValidityCondition], readable) -> list[bool]:
    """Which conditions `located` reads: evaluated, not located yet (by another reader), and every column they need
    among the reader's (`readable`)."""
    return [bool(row.get("evaluated")) and row.get("how") != "located" and all(n in readable for n in c.needs)
            for c, row in zip(conds, section["conditions"])]


def _with_samples(t: np.ndarray, columns: Mapping[str, np.ndarray], ts: np.ndarray, table: Mapping,
                  needs: set[str]) -> tuple[np.ndarray, dict[str, np.ndarray], np.ndarray]:
    """(instants, columns, which are output rows) of the rows and the samples between them together, in time order
    (the columns the conditions need, and the instants): every crossing, dip, rise and least margin the samples
    show between two rows is then searched as one between rows is, however many a gap between rows holds
    (docs/theory.md, "Validity"). A column the samples lack is NaN there (the condition does not apply)."""
    order = np.argsort(np.concatenate([t, ts]), kind="stable")
    merged = {}
    for n in (n for n in needs if n in columns):
        rows = np.asarray(columns[n])
        rows = rows if rows.dtype == object else rows.astype(float)       # (a mode's name stays a string)
        more = np.asarray(table[n]) if n in table else np.full(len(ts), None if rows.dtype == object else np.nan)
        merged[n] = np.concatenate([rows, more.astype(rows.dtype)])[order]
    merged["t_s"] = np.concatenate([t, np.asarray(ts, dtype=float)])[order]
    return merged["t_s"], merged, order < len(t)


def located(section: dict, conds: list[ValidityCondition], columns: Mapping[str, np.ndarray], reader,
            readable, samples: Callable | None = None) -> None:
    """The section's numbers (`evaluate`, on the rows) located on the run's continuous solution, in place, for each
    condition whose columns the reader reads (`readable`; `scenarios/peaks.py` `point_reader`: (read_at, the smooth
    intervals' ends), the mechanics'; then `thermal_point_reader`, the thermal columns', for those left; a
    condition neither reads stays on the rows, `how` says which): its worst value the extremum of the
    quantity (the least margin, refined on readings around the CANDIDATES lowest row minima, within the smooth
    interval holding each), or unbounded (`_unbounded`: value None); its first violation the instant the margin
    crosses zero (between the last row that holds and the first that does not); its violated share with every
    crossing between rows located (the rows' half-gap weights elsewhere); a violation between two rows that hold,
    which the worst or a dip reveals, counted as well, and a return to holding between two rows that violate, which a
    rise reveals, taken off (a dip or rise: a row extremum that may reach the bound between its neighbours, or a
    gap where the condition's signed quantity changes sign, `ValidityCondition.signed`); where it starts or stops
    applying at an event between rows, its applying and violated shares counted to the event (`_Edge`). Every
    condition's brackets are narrowed together (`_refine`). samples: where given, () -> (instants, columns) of the
    run sampled between rows that lie far apart (`peaks._samples_between_rows`) or None: the samples join the rows
    (`_with_samples`), so that every excursion between rows they show is searched (docs/theory.md, "Validity")."""
    read_at, ends = reader
    t = np.asarray(columns["t_s"], dtype=float)
    if len(t) < 2:
        return
    chosen = [(c, row) for c, row, ok in zip(conds, section["conditions"], locatable(section, conds, readable)) if ok]
    got = samples() if samples is not None and chosen else None
    # the samples between far-apart rows searched as rows are (`_with_samples`), for each condition they hold
    sampled = [got is not None and all(n in got[1] for n in c.needs) for c, _ in chosen]
    merged = (_with_samples(t, columns, *got, {n for (c, _), s in zip(chosen, sampled) if s for n in c.needs})
              if any(sampled) else None)
    work = [_Condition(c, row, *(merged if s else (t, columns, None)), ends) for (c, row), s in zip(chosen, sampled)]
    work = [w for w in work if w.applies.any()]
    _refine(read_at, [job for w in work
                      for job in w.worst_jobs + w.dip_jobs + w.rise_jobs + [j for jobs in w.crossing_jobs for j in jobs]
                      + w.edge_jobs()])
    _refine(read_at, [job for w in work for job in w.between_jobs()])
    for w in work:
        w.report()
    section["violated"] = [r["name"] for r in section["conditions"]
                           if r.get("violated_rows") or r.get("violated_between_rows")]
    section["valid"] = not section["violated"]


class _Condition:
    """One condition's rows, its brackets to narrow (`_Job`) and what it reports from them (`located`)."""

    def __init__(self, c: ValidityCondition, row: dict, t: np.ndarray, columns, is_row: np.ndarray | None,
                 ends: np.ndarray):
        """t, columns: the output rows', or the rows and the samples between them together (`_with_samples`), is_row
        saying which are rows (None: all)."""
        self.c, self.row, self.t, self.ends, self.is_row = c, row, t, ends, is_row
        values = np.broadcast_to(np.asarray(c.quantity(columns), dtype=float), t.shape)
        m = c.margin(values)
        self.applies = applies = np.isfinite(m)
        self.bad = applies & (m < 0)

        def quantity(table):
            return np.broadcast_to(np.asarray(c.quantity(table), dtype=float), np.asarray(table["t_s"]).shape)

        def margin(table):
            return c.margin(quantity(table))
        self.margin, self.quantity = margin, quantity
        # the worst: the least margin near each of the lowest row minima
        mm = np.where(applies, m, np.inf)
        lower = np.r_[True, mm[1:] <= mm[:-1]] & np.r_[mm[:-1] <= mm[1:], True] & applies
        rows = np.flatnonzero(lower)
        rows = rows[np.argsort(mm[rows], kind="stable")][:CANDIDATES]
        # a later one only where it may dip below the least row between its neighbours: by no more than the rise
        # to the higher of them (a smooth minimum between rows lies within a quarter of it)
        near = np.maximum(mm[np.maximum(rows - 1, 0)], mm[np.minimum(rows + 1, len(t) - 1)])
        rise = np.where(np.isfinite(near), near - mm[rows], np.inf)
        rows = rows[(mm[rows] - rise <= mm[rows[0]]) | (np.arange(len(rows)) == 0)] if len(rows) else rows
        self.worst_jobs = [_Job(*self._within(int(i), max(int(i) - 1, 0), min(int(i) + 1, len(t) - 1)), margin,
                                quantity) for i in rows]
        # every other row minimum that holds, between rows that hold, and may dip below the bound between them: by
        # no more than its rise to the higher neighbour (a violation narrower than a row, that no row sees)
        every = np.flatnonzero(lower)
        up = np.maximum(mm[np.maximum(every - 1, 0)], mm[np.minimum(every + 1, len(t) - 1)])
        reach = mm[every] - (up - mm[every])           # the least a dip between the neighbours may reach
        dips = every[(mm[every] >= 0) & np.isfinite(up) & (reach < 0) & ~np.isin(every, rows)]
        dips = dips[np.argsort(reach[np.searchsorted(every, dips)], kind="stable")][:DIPS]   # the deepest first
        self.dip_jobs = [_Job(*self._within(int(i), max(int(i) - 1, 0), min(int(i) + 1, len(t) - 1)), margin,
                              quantity, decides=True) for i in dips]
        # the converse: every row maximum that violates, between rows that violate, and may rise to the bound between
        # them, by no more than its fall to the lower neighbour (a return to holding narrower than a row); its job
        # narrows to the greatest margin (the least of the negated one)
        nn = np.where(applies, m, -np.inf)
        tops = np.flatnonzero(np.r_[True, nn[1:] >= nn[:-1]] & np.r_[nn[:-1] >= nn[1:], True] & self.bad)
        down = np.minimum(nn[np.maximum(tops - 1, 0)], nn[np.minimum(tops + 1, len(t) - 1)])
        high = nn[tops] + (nn[tops] - down)             # the most a rise between the neighbours may reach
        able = np.isfinite(down) & (high >= 0)
        tops = tops[able][np.argsort(-high[able], kind="stable")][:DIPS]                 # the highest first
        self.rise_jobs = [_Job(*self._within(int(i), max(int(i) - 1, 0), min(int(i) + 1, len(t) - 1)), margin,
                               quantity, -1.0, decides=True) for i in tops]
        # where the condition's signed quantity changes sign between two rows of a smooth interval, the quantity
        # passes zero between them (`ValidityCondition.signed`): a return to holding there between two rows that
        # violate, or a violation between two that hold, whatever the rows show; the gap searched as a rise or dip
        self.signs, self.holds_at_zero = None, bool(c.margin(0.0) >= 0)
        if c.signed is not None:
            s = self.signs = np.broadcast_to(np.asarray(c.signed(columns), dtype=float), t.shape)
            with np.errstate(invalid="ignore"):
                change = applies[:-1] & applies[1:] & (s[:-1] * s[1:] < 0)
            change &= (self.bad[:-1] & self.bad[1:]) if self.holds_at_zero else ~(self.bad[:-1] | self.bad[1:])
            change &= ends.searchsorted(t[:-1], side="right") == ends.searchsorted(t[1:], side="left")  # no event
            for g in np.flatnonzero(change)[:DIPS].tolist():
                self._search_gap(g, 0.5 * float(t[g] + t[g + 1]), self.holds_at_zero)
        # every sign change of the margin between two applying rows: into a violation (the margin's first
        # negative sample) or out of one (the negated margin's), each smooth interval between the two rows searched
        # in time order (a sign change at an event between them: its one-sided limits, `_crossing`)
        both = applies[:-1] & applies[1:]
        bad = self.bad
        self.gaps = [(int(g), bool(bad[g])) for g in np.flatnonzero(both & (bad[:-1] != bad[1:]))]
        self.crossing_jobs = [[_Job(lo, hi, margin, quantity, -1.0 if was_bad else 1.0, True)
                               for lo, hi in self._pieces(float(t[g]), float(t[g + 1]))] for g, was_bad in self.gaps]
        self.m = m
        self.edges = self._edges()
        self.extra: list[tuple[list[_Job], list[_Job]]] = []      # (`between_jobs`)
        self.holds: list[tuple[list[_Job], list[_Job]]] = []

    def _search_gap(self, g: int, at: float, rise: bool) -> None:
        """The gap between rows g and g + 1, within the smooth interval holding the instant `at`, searched as a rise
        (its greatest margin: `rise_jobs`) or a dip (its least: `dip_jobs`), to decide whether it passes the bound."""
        t = self.t
        job = _Job(*self._clipped(at, float(t[g]), float(t[g + 1])), self.margin, self.quantity,
                   -1.0 if rise else 1.0, decides=True)
        (self.rise_jobs if rise else self.dip_jobs).append(job)

    def _edges(self) -> list[_Edge]:
        """The gaps between rows with an event inside where the condition starts or stops applying, or where neither
        row applies and a smooth interval lies wholly inside (it may apply there, as a brief contact no row sees):
        each an `_Edge` with its searches (at most DIPS rowless pieces a condition)."""
        t, applies, bad, ends = self.t, self.applies, self.bad, self.ends
        # the ends in each gap, its rows' instants included (a row at an event reads one side of it)
        held = ends.searchsorted(t[1:], side="right") - ends.searchsorted(t[:-1], side="left")
        edges, rowless = [], 0
        for g in np.flatnonzero((held > 0) & (applies[:-1] != applies[1:]) | (held > 1) & ~applies[:-1]
                                & ~applies[1:]).tolist():
            a, b = float(t[g]), float(t[g + 1])
            cuts = [a, *ends[(ends >= a) & (ends <= b)].tolist(), b]
            pieces = list(zip(cuts[:-1], cuts[1:]))     # (a piece of no length where a row is at an event)
            edge = _Edge(g, pieces)
            (lo, hi), (lo_m, hi_m) = pieces[0], pieces[-1]
            if applies[g] and hi > lo and not self._steady(g, g - 1, hi - lo):
                edge.first = _Job(lo, hi, self.margin, self.quantity, -1.0 if bad[g] else 1.0, True)
            if applies[g + 1] and hi_m > lo_m and (bad[g + 1] or not self._steady(g + 1, g + 2, hi_m - lo_m)):
                edge.last = _Job(lo_m, hi_m, self.margin, self.quantity, 1.0 if bad[g + 1] else -1.0, True)
            for a, b in pieces[1:-1]:
                if rowless < DIPS and b > a:
                    edge.middle.append((_Job(a, b, self.margin, self.quantity), (a, b)))
                    rowless += 1
            edges.append(edge)
        return edges

    def _steady(self, i: int, j: int, length: float) -> bool:
        """Whether row i's status (holding or violating) surely lasts `length` beyond it toward the event: its margin
        further from zero than twice its slope from its neighbour j (in the same smooth interval, applying) over
        that length; False where j is no such neighbour."""
        t, ends = self.t, self.ends
        if not (0 <= j < len(t)) or not self.applies[j] or \
                ends.searchsorted(min(t[i], t[j]), side="right") != ends.searchsorted(max(t[i], t[j]), side="left"):
            return False
        slope = abs(self.m[i] - self.m[j]) / abs(t[i] - t[j])
        return bool(abs(self.m[i]) > 2.0 * slope * length)

    def edge_jobs(self) -> list[_Job]:
        """The edges' searches of the first pass (`_edges`)."""
        return [job for e in self.edges for job in (e.first, e.last, *(j for j, _ in e.middle)) if job is not None]

    def _pieces(self, a: float, b: float) -> list[tuple[float, float]]:
        """[a, b] split at the smooth intervals' ends inside it, in time order."""
        inside = self.ends[(self.ends > a) & (self.ends < b)].tolist()
        cuts = [a, *inside, b]
        return list(zip(cuts[:-1], cuts[1:]))

    def _within(self, centre: int, i: int, j: int) -> tuple[float, float]:
        """[t_i, t_j] clipped to the smooth interval holding row `centre` (a row at an event: the one before)."""
        return self._clipped(float(self.t[centre]), float(self.t[i]), float(self.t[j]))

    def _clipped(self, at: float, lo: float, hi: float) -> tuple[float, float]:
        """[lo, hi] clipped to the smooth interval holding the instant `at` (one at an event: the one before)."""
        ends = self.ends
        k = int(np.clip(ends.searchsorted(at, side="left"), 1, len(ends) - 1))
        return max(lo, float(ends[k - 1])), min(hi, float(ends[k]))

    def _best(self):
        """(the job holding the least margin, whether it is unbounded): the earliest unbounded one the searches found
        where there are several (a friction demand at each instant its normal force passes zero); which ones the
        searches hold still depends on the rows' ranking of the candidates."""
        best, unbounded = None, None
        for job in self.worst_jobs + [j for e in self.edges for j, _ in e.middle]:
            if job.found is None or job.scores[-1] == np.inf:       # (a rowless piece where it does not apply)
                continue
            if _unbounded(job.scores):
                if unbounded is None or job.found[0] < unbounded.found[0]:
                    unbounded = job
            elif best is None or job.scores[-1] < best.scores[-1]:
                best = job
        return (unbounded, True) if unbounded is not None else (best, False)

    def between_jobs(self) -> list[_Job]:
        """Each least margin below zero between two rows that hold (the worst's, a dip's): the crossings into and out
        of it; each greatest margin above zero between two rows that violate (a rise's): the crossings out of and back
        into the violation (`_pairs`)."""
        self.extra = self._pairs(self.worst_jobs + self.dip_jobs, holding=True)
        self.holds = self._pairs(self.rise_jobs, holding=False)
        more = []
        for e in self.edges:            # a rowless piece's violation: its crossings; a violation from the event on
            for job, (a, b) in e.middle:
                if job.found is not None and job.scores and job.scores[-1] < 0 and not _unbounded(job.scores):
                    at = job.found[0]
                    e.pairs.append((_Job(a, at, self.margin, self.quantity, 1.0, True),
                                    _Job(at, b, self.margin, self.quantity, -1.0, True)))
            if e.last is not None and not self.bad[e.g + 1] and e.last.found is not None and \
                    _instant(e.last) > e.pieces[-1][0]:         # violated from the event on: read there
                e.begins = _Job(e.pieces[-1][0], _instant(e.last), self.margin, self.quantity, 1.0, True)
            more += [job for pair in e.pairs for job in pair] + ([e.begins] if e.begins is not None else [])
        return [job for pair in self.extra + self.holds for side in pair for job in side] + more

    def _pairs(self, found_by: list[_Job], holding: bool) -> list[tuple[list[_Job], list[_Job]]]:
        """For each job whose extremum lies beyond the bound between two rows that hold (`holding`) or that violate:
        the searches for the crossing before it and the one after it, each side's stretch between the extremum and
        the row split at the smooth intervals' ends (`_pieces`; `_crossing` picks, so a stretch that runs on across
        an event, a dead point's, is followed into the next interval); one gap between rows counted once."""
        t, gaps, out = self.t, set(), []
        sign = 1.0 if holding else -1.0         # the first crossing: into the violation, or out of it
        for job in found_by:
            if job.found is None or not job.scores or job.scores[-1] >= 0 or _unbounded(job.scores):
                continue
            at = job.found[0]
            g = int(np.clip(t.searchsorted(at, side="right") - 1, 0, len(t) - 2))
            rows_alike = (self.applies[g] and self.applies[g + 1] and not (self.bad[g] or self.bad[g + 1])
                          if holding else self.bad[g] and self.bad[g + 1])
            if g in gaps or not rows_alike:
                continue
            gaps.add(g)
            out.append(([_Job(lo, hi, self.margin, self.quantity, sign, True)
                         for lo, hi in self._pieces(float(t[g]), at)],
                        [_Job(lo, hi, self.margin, self.quantity, -sign, True)
                         for lo, hi in self._pieces(at, float(t[g + 1]))]))
        return out

    def _between_rows(self) -> None:
        """`violated_between_rows` (`held_between_rows`) where a sample violates (holds) between two output rows that
        hold (violate) and apply: what the rows do not show, as a dip (rise) between them says (`report`)."""
        if self.is_row is None or self.is_row.all():
            return
        rows = np.flatnonzero(self.is_row)
        k = np.clip(rows.searchsorted(np.arange(len(self.t)), side="right") - 1, 0, len(rows) - 1)
        before, after = rows[k], rows[np.minimum(k + 1, len(rows) - 1)]
        inside = ~self.is_row & (before < np.arange(len(self.t))) & (np.arange(len(self.t)) < after)
        both = self.applies[before] & self.applies[after] & inside & self.applies
        if np.any(both & self.bad & ~self.bad[before] & ~self.bad[after]):
            self.row["violated_between_rows"] = True
        if np.any(both & ~self.bad & self.bad[before] & self.bad[after]):
            self.row["held_between_rows"] = True

    def report(self) -> None:
        row, t = self.row, self.t
        row["how"] = "located"
        best, unbounded = self._best()
        if best is not None:
            at, table, j = best.found
            row["worst"] = ({"value": None, "t_s": at, "margin": None, "unbounded": True} if unbounded else
                            {"value": float(best.quantity(table)[j]), "t_s": at, "margin": best.scores[-1]})
        weights = _row_weights(t)
        total = float(weights.sum()) or 1.0
        violated = float(weights[self.bad].sum())
        starts = []
        for (g, was_bad), jobs in zip(self.gaps, self.crossing_jobs):
            job = _crossing(jobs)
            if job is None:
                continue
            x = _instant(job)
            violated += (x - t[g] if was_bad else t[g + 1] - x) - 0.5 * (t[g + 1] - t[g])
            if not was_bad:
                starts.append(job)
        for held, (before, after) in [(False, pair) for pair in self.extra] + [(True, pair) for pair in self.holds]:
            first, second = _crossing(before), _crossing(after)
            if first is None or second is None:
                continue
            violated += (_instant(first) - _instant(second)) if held else (_instant(second) - _instant(first))
            row["held_between_rows" if held else "violated_between_rows"] = True
            if not held:
                starts.append(first)
        applied = float(weights[self.applies].sum())
        for e in self.edges:                # each edge's pieces located, in place of its rows' half gaps
            g, half = e.g, 0.5 * (t[e.g + 1] - t[e.g])
            (lo, hi), (lo_m, hi_m) = e.pieces[0], e.pieces[-1]
            applied -= half * (self.applies[g] + self.applies[g + 1])
            violated -= half * (self.bad[g] + self.bad[g + 1])
            for side, job, was_bad, a, b in ((0, e.first, self.bad[g], lo, hi),
                                             (1, e.last, self.bad[g + 1], lo_m, hi_m)):
                if not self.applies[g + side]:
                    continue
                applied += b - a
                if job is None:
                    violated += (b - a) * was_bad
                elif job.found is None:             # its reading failed: the rows' half gap
                    violated += half * was_bad
                else:
                    x = _instant(job)
                    # the first piece: row g's status until x; the last: row g + 1's from x
                    violated += ((x - a) if was_bad else (b - x)) if side == 0 else ((b - x) if was_bad else (x - a))
                    if (side == 1 and was_bad) or (side == 0 and not was_bad and x < job.end):     # one begins
                        starts.append(job)
            if e.begins is not None and e.begins.found is not None:
                starts.append(e.begins)
            for job, (a, b) in e.middle:
                if job.found is not None and job.scores and job.scores[-1] < np.inf:
                    applied += b - a
            for into, out in e.pairs:
                if into.found is not None and out.found is not None:
                    violated += _instant(out) - _instant(into)
                    row["violated_between_rows"] = True
                    starts.append(into)
        row["applies_share"] = float(applied / total)
        row["violated_share"] = float(violated / total)
        self._between_rows()
        # the first violation: the earliest crossing into it, or the first violating row where none lies before it
        # (the run's first row, or a row after one the condition does not apply to)
        first = min(starts, key=_instant) if starts else None
        if self.bad.any():
            r = int(np.argmax(self.bad))
            if first is None or t[r] < _instant(first):
                row["first_violation_t_s"] = float(t[r])          # (the rows' own value stays)
                return
        if first is not None:
            at, table, j = first.found
            row["first_violation_t_s"] = _instant(first)
            row["first_violation_value"] = first.value if first.root is not None else float(first.quantity(table)[j])
