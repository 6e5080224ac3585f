"""Whether a column grows without bound toward an event (a pole: a 1-D contact's force as the pin reaches the slot's
end, a closed form's 1/x), judged on readings a decade apart in distance to the event (docs/theory.md §K5): what
an extremum next to an event is then reported as (unbounded, with the growth exponent), and the warnings a run
gives for it.
"""
from __future__ import annotations

import re

import numpy as np
import pandas as pd

from mechsim.dynamics.extrema import Extremum, Interval, ReadingFailed, end_guesses, end_limit_requests

#: decades of distance below the first (the output step, or half the interval) at which the growth toward an event
#: is read
SINGULAR_DECADES = 4
#: growth exponent -dlog|F|/dlog(distance), in every decade, above which an approach counts as unbounded (a
#: bounded column's exponent falls like the distance: |F(d)| = |F(0)| + O(d))
SINGULAR_EXPONENT = 0.25
#: events tested per column once one approach is found unbounded
SINGULAR_EVENTS = 50


def growth_request(iv: Interval, side: str, h: float, decades: int = SINGULAR_DECADES, kept: dict | None = None
                    ) -> tuple:
    """The reading `_growth` takes, (interval, position, times in order), and the order of its distances."""
    return growth_requests([(iv, side)], h, decades, kept)[0]


def growth_requests(ends: list[tuple[Interval, str]], h: float, decades: int = SINGULAR_DECADES,
                     kept: dict | None = None) -> list[tuple]:
    """`growth_request` of each (interval, side), in one array pass; kept: those made already for the same h (by
    interval, side and decades: `peaks._Readings.growth`), the new ones added."""
    if kept is not None:
        keys = [(id(iv), side, decades) for iv, side in ends]
        new = [(k, end) for k, end in zip(keys, ends) if k not in kept]
        kept.update(zip((k for k, _ in new), growth_requests([end for _, end in new], h, decades)))
        return [kept[k] for k in keys]
    if not ends:
        return []
    before = [side == "before" for _, side in ends]
    d = np.multiply.outer([min(h, 0.5 * (iv.hi - iv.lo)) for iv, _ in ends], 10.0 ** -np.arange(decades + 1))
    times = (np.array([iv.hi if b else iv.lo for (iv, _), b in zip(ends, before)])[:, None]
             + np.where(before, -1.0, 1.0)[:, None] * d)          # hi - d before the end, lo + d after the start
    order = times.argsort(axis=1)
    times = times[np.arange(len(ends))[:, None], order]
    return [((iv, len(iv.rows) - 1 if b else 0, x), o) for (iv, _), b, x, o in zip(ends, before, times, order)]


def _growth(read, iv: Interval, side: str, column: str, h: float, sign: float, decades: int = SINGULAR_DECADES
            ) -> float | None:
    """The exponent a of |F| ~ distance^-a toward the interval's end on `side` ('before': its end, 'after': its
    start), from readings a decade apart; None where the column stays bounded there (or changes sign)."""
    request, order = growth_request(iv, side, h, decades, getattr(read, "growth", None))
    try:
        table = read(*request)
    except ReadingFailed:           # the approach cannot be read (a stiff mode re-integrated): no growth claimed
        return None
    f = np.empty(len(order))
    f[order] = sign * np.asarray(table[column], dtype=float)
    if not (np.isfinite(f).all() and (f > 0).all()):
        return None
    decades = np.log10(f)
    slopes = decades[1:] - decades[:-1]            # per decade closer
    return float(slopes[-1]) if (slopes > SINGULAR_EXPONENT).all() else None


def _approached(f: np.ndarray, iv: Interval, side: str, sense: float) -> bool:
    """Whether the column may grow toward the interval's end on `side`: an event there, and its rows' last two
    growing toward it (sense*f positive and not falling)."""
    kind = iv.hi_kind if side == "before" else iv.lo_kind
    if kind in ("start", "end") or len(iv.rows) < 2:
        return False
    near, next_ = (iv.rows[-1], iv.rows[-2]) if side == "before" else (iv.rows[0], iv.rows[1])
    return bool(sense * f[near] > 0 and sense * f[near] >= sense * f[next_])


def limit_edge(e: Extremum | None) -> str | None:
    """The side of the event next to a located extremum whose growth toward it is checked, or None."""
    if e is None or e.constant or e.where.startswith(("start", "end")):
        return None
    return e.limit if e.limit is not None else e.edge


def readings_ahead(plans: list, h: float, lines, kept: dict | None = None) -> list[tuple]:
    """The readings `end_limits` and `first_approaches` may take for located plans over one table
    (`dynamics/extrema.py` `plans`; `lines`: their `end_lines`, made together), before their extrema are known,
    plan after plan: the growth toward each event a bracket reaches, on that side; the one-sided limits at the ends
    whose guesses may beat each column's best row in the window, in each sense (its located extremum is at least
    that row, but for round-off: a guess beyond these is read once the extrema are known), and the growth toward
    each of those ends the column approaches (`_approached`, here for every column, sense and end at once, from
    the rows `lines` hold: an end's nearest row and the next). kept: the growth requests made (`growth_requests`)."""
    if lines is None:            # no interval with two rows: nothing is approached (`_approached`), no end guessed
        return []
    window = lines.window if lines.window is not None else np.zeros(len(lines.ends), dtype=int)
    at = {(q, k, side): e for e, (q, (k, side, _)) in enumerate(zip(window.tolist(), lines.ends))}
    event = np.array([(plans[q].intervals[k].hi_kind if side == "before" else plans[q].intervals[k].lo_kind)
                      not in ("start", "end") for q, (k, side, _) in zip(window.tolist(), lines.ends)])
    with np.errstate(invalid="ignore"):      # `_approached` of each column (row), sense and end (column)
        up = (event & (lines.f0 > 0) & (lines.f0 >= lines.f1), event & (-lines.f0 > 0) & (-lines.f0 >= -lines.f1))
    ends: list[list] = [[] for _ in plans]
    asks, of = [], []
    for q, p in enumerate(plans):
        for j in p.jobs:
            if j.done:
                continue
            iv = p.intervals[j.interval]
            for side, reaches in (("after", j.lo == iv.lo), ("before", j.hi == iv.hi)):
                e = at.get((q, j.interval, side)) if reaches else None
                if e is not None and up[j.sense < 0][lines.of[j.column], e]:
                    ends[q].append((iv, side))
        # each column's best rows over the plan's intervals, as its candidates found them (`end_lines` are made
        # on the plan's values and need rows at the ends, so the plan has its bounds)
        top, bottom = p.bounds[0::2].tolist(), (-p.bounds[1::2]).tolist()
        mine = [(c, sense, v) for c, hi, lo in zip(lines.of, top, bottom) if np.isfinite(hi)
                for sense, v in ((1.0, hi), (-1.0, lo))]
        asks += mine
        of += [q] * len(mine)
    p = plans[0]
    limits: list[dict] = [{} for _ in plans]        # each plan's ends to read, each once (in order)
    for q, (c, sense, _), guesses in zip(of, asks, end_guesses(p.t, p.values, p.intervals, asks, p.ties, limit=None,
                                                                lines=lines, windows=of)):
        intervals = plans[q].intervals
        limits[q].update(dict.fromkeys(guesses))
        near = up[0 if sense > 0 else 1][lines.of[c]]
        ends[q] += [(intervals[k], side) for k, side, _ in guesses if near[at[(q, k, side)]]]
    return [r for q in range(len(plans)) for r in end_limit_requests(plans[q].intervals, list(limits[q])) + [
        x for x, _ in growth_requests(list({(id(iv), side): (iv, side) for iv, side in ends[q]}.values()), h,
                                       kept=kept)]]


def first_approaches(column: str, f: np.ndarray, got: dict, intervals: list[Interval]) -> list[tuple]:
    """(interval, side) of the readings `singular_approaches` takes first for the column's located extrema `got`
    (max, min; `growth_requests`): the growth toward the event next to each, in its own interval."""
    out = []
    for name, sense in (("max", 1.0), ("min", -1.0)):
        e = got.get(name)
        side = limit_edge(e)
        if side is not None and _approached(f, intervals[e.interval], side, sense):
            out.append((intervals[e.interval], side))
    return out


def _impulse(reader, intervals: list[Interval], k: int, coordinates) -> tuple[dict, list, list] | None:
    """(impulse, speeds before, speeds after) of the event between intervals k and k+1: the generalized impulse is
    the jump of M(q) v (N*m*s per angle coordinate); None where the reader has no states (a closed form) or a side
    has no rows. The kinetic energy's change is (v+ + v-)/2 . impulse (M is continuous across the event)."""
    if not hasattr(reader, "momentum") or not 0 <= k < len(intervals) - 1:
        return None
    before, after = intervals[k], intervals[k + 1]
    if not (len(before.rows) and len(after.rows)):
        return None
    p_minus, v_minus = reader.momentum(before, len(before.rows) - 1, before.hi)
    p_plus, v_plus = reader.momentum(after, 0, after.lo)
    return ({name: float(x) for name, x in zip(coordinates, p_plus - p_minus)}, v_minus.tolist(), v_plus.tolist())


def singular_approaches(column: str, f: np.ndarray, side: str, sense: float, intervals: list[Interval], read,
                        h: float, events: pd.DataFrame, coordinates, first: int) -> list[dict]:
    """Every event the column's `sense` (+1 max, -1 min) grows without bound toward, on `side` of it: the event's
    time and kind, the growth exponent, the impulse it delivers and the energy it loses (the events table), in time
    order. The extremum's own interval `first` is read first; only if its approach is unbounded are the others read.
    The impulse is the earliest event's: which event holds the located extremum depends on the output rows."""
    found, where = [], []
    order = [first] + [k for k in range(len(intervals)) if k != first]
    for k in order:
        iv = intervals[k]
        if k != first and not found:
            break
        if not _approached(f, iv, side, sense):
            continue
        kind = iv.hi_kind if side == "before" else iv.lo_kind
        # the first approach is read over SINGULAR_DECADES decades, the others (the same event of later cycles) over
        # two: a bounded column's exponent is already ~1e-2 there
        a = _growth(read, iv, side, column, h, sense, SINGULAR_DECADES if not found else 2)
        if a is None:
            continue
        t_e = iv.hi if side == "before" else iv.lo
        at = events["t_s"].to_numpy(float) == t_e if len(events) else np.zeros(0, bool)
        lost = float(np.nansum(events.loc[at, "energy_lost_J"].to_numpy(float))) if "energy_lost_J" in events \
            else None
        found.append({"t_s": t_e, "events": re.findall(r"event '([^']*)'", kind) or [kind], "side": side,
                      "growth_exponent": a, "impulse": None, "energy_lost_J": lost})
        where.append(k)
        if k == first and hasattr(read, "prefetch"):      # the others approached, read together
            others = [(intervals[j], side) for j in order[1:] if _approached(f, intervals[j], side, sense)]
            read.prefetch([r for r, _ in growth_requests(others[:SINGULAR_EVENTS], h, 2,
                                                          getattr(read, "growth", None))])
        if len(found) >= SINGULAR_EVENTS:
            break
    if found:                                  # the impulse of the earliest (a stop of a periodic motion repeats it)
        by_time = sorted(range(len(found)), key=lambda i: found[i]["t_s"])
        found, k = [found[i] for i in by_time], where[by_time[0]]
        try:
            got = _impulse(read, intervals, k if side == "before" else k - 1, coordinates)
        except ReadingFailed:
            got = None
        if got is not None:
            found[0]["impulse"], found[0]["speeds_before"], found[0]["speeds_after"] = got
    return found


def singular_warnings(peaks: dict) -> list[str]:
    """One warning per column with an unbounded approach: the events, the growth, the impulse and energy lost."""
    out = []
    for col, entry in peaks.items():
        found = entry.get("singular")
        if not found:
            continue
        first = found[0]
        kinds = sorted({f"'{k}'" for x in found for k in x["events"]})
        impulse = ("" if not first["impulse"] else ", impulse " + ", ".join(
            f"{k} {v:.4g}" for k, v in first["impulse"].items() if v != 0.0))
        lost = "" if first["energy_lost_J"] is None else f", energy lost {first['energy_lost_J']:.4g} J"
        out.append(f"t = {first['t_s']:.6g} s: {col} grows without bound toward {len(found)} event(s) "
                   f"{', '.join(kinds)} (|F| ~ (distance in time)^-{first['growth_exponent']:.2g}): no peak is "
                   f"reported for its {first['extremum']}imum (summary.json peaks.{col}.singular); at the first"
                   f"{impulse}{lost}")
    return out
