"""Extrema of a run's columns in continuous time, not at its output rows (docs/theory.md §K5).

A column F(t) of the result table is smooth between events. Its maximum (and minimum) is sought in three steps:

1. candidates from the output rows: in every smooth interval (between events) each row that is a local maximum
   of the rows, its bracket the rows on either side (an interval's first and last row reach out to the
   interval's ends, so that a maximum at an event is found as the one-sided limit there); the candidates are
   ranked by the vertex of the parabola through the row and its neighbours and the best few refined;
2. a `reader` evaluates every column of the table at any instants of one smooth interval: for a DAE run by
   re-integrating the mode forward from the latest state the run holds before them (an output row, or the state
   its segment started from after the interval's event) at a tenth of the run's tolerances
   (dynamics/trajectory_reader.py); for a closed-form run by the closed form itself; an interval with fewer than
   three rows is also read over its whole length, the readings its candidates too (`with_rowless`);
3. in the bracket, one pass of a grid of readings; the polynomial through the seven readings around the best one
   gives t* and the value (and every column there). At an interval's end the extremum is the one-sided limit
   (the reading at the event instant from that side).

The value, time and drive angle do not depend on the output step beyond the integrator's tolerance: at an
interior extremum a time error dt changes the value by F''dt^2/2 only, and the reading itself carries the
re-integration's error from the row's state (the run's own error at that row).
"""
from __future__ import annotations

from collections.abc import Mapping, MutableMapping
from dataclasses import dataclass, field
from typing import Callable

import numpy as np

#: values closer than this fraction of the column's largest magnitude are equal (round-off): flat rows, ties
TIE_ROUNDOFF = 1e-13
#: readings over a bracket; readings through which the polynomial around the best one is taken (degree + 1)
FIRST_GRID = 33
STENCIL = 7
#: candidates refined per column and sense (the best by the rows' parabola estimate)
CANDIDATES = 2
#: a refined interior value is trusted where the polynomial through the STENCIL readings and the one through the
#: LOWER readings nearest its instant agree to this fraction of the column's largest magnitude (`_refine`); else the
#: bracket is narrowed to the grid's two steps around the best reading and read again, at most NARROWINGS times
AGREE = 1e-9
LOWER = 5
NARROWINGS = 4
#: brackets whose rows lie within this many rows of each other are read together
CLUSTER_ROWS = 8
#: a table of more values than this has its candidates found one column at a time (`_candidates_bounds`): the
#: temporaries of all columns at once (an hour's table: 8 columns of 2.2 million rows) cost more in fresh memory than
#: the per-column calls in Python
JOINT_VALUES = 1 << 20


class ReadingFailed(RuntimeError):
    """A reader could not evaluate the columns between rows (the re-integration failed)."""


@dataclass
class Interval:
    """A smooth stretch of the run: no event inside (lo, hi). lo_kind/hi_kind: 'start', 'end' or the event's kind.
    rows: the table's rows inside [lo, hi] (indices), anchors: what the reader needs to start from each row."""

    lo: float
    hi: float
    lo_kind: str
    hi_kind: str
    rows: np.ndarray
    anchors: list | np.ndarray = field(default_factory=list)

    def inside(self, times: np.ndarray) -> np.ndarray:
        """The instants with the interval's ends moved 1e-12 s (relative to its time scale) inside it, where it is
        longer than that: a reading at an end is the one-sided limit there."""
        eps = 1e-12 * max(1.0, abs(self.hi))
        return np.clip(times, self.lo + eps, self.hi - eps) if self.hi - self.lo > 4 * eps else times


@dataclass
class Extremum:
    """The located extremum of one column: its value, instant, where it lies (interior, or the one-sided limit at
    an interval's end) and every column of the table at that instant (`row`, a mapping; a refined extremum's
    columns are evaluated when read)."""

    value: float
    t: float
    where: str
    row: Mapping
    limit: str | None = None   # at an interval's end: the one-sided limit from 'before' or 'after' that instant
    edge: str | None = None    # the bracket reaches the interval's end ('before' it) or start ('after' it)
    interval: int = -1         # the smooth interval it lies in (the `intervals` list given to `locate`)
    constant: bool = False     # a constant stretch's (its first instant; the value is the rows')


Reader = Callable[[Interval, int, np.ndarray], dict]


@dataclass
class _Job:
    column: str
    sense: float
    interval: int
    anchor: int             # position of the candidate row in the interval's rows
    lo: float
    hi: float
    sampled: float
    t_row: float = np.nan
    best_t: float = np.nan
    best_f: float = -np.inf
    best_row: dict | None = None
    done: bool = False
    where: str = "interior"
    limit: str | None = None
    edge: str | None = None
    tie: float = 0.0
    constant: bool = False
    #: (the best grid instant, the grid's step) where the polynomial's value is not yet to be trusted (`_refine`)
    unsure: tuple[float, float] | None = None


def _estimates(t: np.ndarray, f0: np.ndarray, f1: np.ndarray, f2: np.ndarray, i: np.ndarray) -> np.ndarray:
    """The peak value of the parabola through rows i - 1, i, i + 1 of a series (its values f0, f1, f2 there; each
    row's value where the parabola opens upwards); 0 < i < len(t) - 1."""
    ti = t[i]
    h0, h1 = ti - t[i - 1], t[i + 1] - ti
    with np.errstate(invalid="ignore", divide="ignore", over="ignore"):
        right, left, h = (f2 - f1) / h1, (f1 - f0) / h0, h0 + h1       # the two slopes, each formed once
        d2 = 2.0 * (right - left) / h
        d1 = (right * h0 + left * h1) / h
        gain = np.where(d2 < 0, -0.5 * d1 * d1 / d2, 0.0)
    return f1 + np.where(np.isfinite(gain), gain, 0.0)


def tie_of(f: np.ndarray, finite: bool | None = None) -> float:
    """The round-off tie of a column: TIE_ROUNDOFF of its largest finite magnitude (values closer are equal);
    finite: whether every value is finite, where the caller knows."""
    return float(_ties(np.asarray(f, dtype=float)[None, :], finite)[0])


def _ties(F: np.ndarray, finite: bool | None = None) -> np.ndarray:
    """`tie_of` of each row of F (finite: whether every value of F is finite, where known), a row at a time (an
    hour's temporaries a row's, not the table's). The largest finite magnitude is the larger of the largest finite
    value and the negated least (|x| and -x are exact); 0 where none is finite."""
    out = np.zeros(len(F))
    if not F.shape[-1]:
        return out
    for i, f in enumerate(F):
        if finite or (finite is None and np.isfinite(f).all()):
            out[i] = abs(max(float(f.max()), -float(f.min())))
        else:
            ok = np.isfinite(f)
            if ok.any():
                out[i] = abs(max(float(f.max(where=ok, initial=-np.inf)), -float(f.min(where=ok, initial=np.inf))))
    return TIE_ROUNDOFF * out


def _beats(new: Extremum, old: Extremum | None, sense: float, tie: float) -> bool:
    """Whether `new` is the better extremum: larger (sense +1) by more than the tie, or tied and earlier."""
    if old is None:
        return True
    gain = sense * (new.value - old.value)
    return gain > tie or (gain >= -tie and new.t < old.t)


def _layout(intervals: list[Interval]) -> tuple | None:
    """Every interval's rows side by side (a row's neighbours are its interval's; the ends reach out to its
    ends): (rows, interval, interval's row count, position in it, first, last); None without rows."""
    sizes = np.array([len(iv.rows) for iv in intervals], dtype=int)
    if not sizes.sum():
        return None
    rows = np.concatenate([iv.rows for iv in intervals]).astype(int, copy=False)
    n_of = sizes.repeat(sizes)
    pos = np.arange(len(rows)) - (sizes.cumsum() - sizes).repeat(sizes)
    return rows, np.arange(len(intervals)).repeat(sizes), n_of, pos, pos == 0, pos == n_of - 1


def candidates(t: np.ndarray, f: np.ndarray, intervals: list[Interval], sense: float, limit: int = CANDIDATES,
               layout: tuple | None = None) -> list[tuple[float, int, int, float, float, bool]]:
    """(estimate, interval, position, bracket lo, bracket hi, flat) of the local maxima of sense*f that may hold
    the maximum, the best `limit` of them (and the best constant stretch): a row's bracket may hold up to its parabola estimate plus the estimate's
    gain over the row again (the estimate's error is of the order of its gain), and it is kept where that reaches
    the best candidate's lower bound (its row and its estimate less its gain). flat: the row and its neighbours
    are equal to round-off (a column held constant, e.g. zero in a dwell): the row's value is exact, and the
    stretch's extremum lies at its first instant (lo = hi): the interval's start where the stretch holds the
    interval's first row, else its first row. Values within round-off of each other are ties, and a tie goes to
    the earliest (which dwell's zero speed holds the extremum must not hinge on the BLAS's rounding)."""
    f = np.asarray(f, dtype=float)[None, :]
    return _candidates(t, f, _ties(f), intervals, limit, layout)[0 if sense > 0 else 1]


def _candidates(t: np.ndarray, F: np.ndarray, ties: np.ndarray, intervals: list[Interval],
                limit: int = CANDIDATES, layout: tuple | None = None) -> list[list[tuple]]:
    """`candidates` of every series F[c] (over the table's rows) in both senses, its tie ties[c]: [c max, c min,
    ...] (`_candidates_bounds`)."""
    return _candidates_bounds(t, F, ties, intervals, limit, layout)[0]


#: a series' sign by its parity (`_candidates_bounds`: 2c the column, 2c + 1 the column negated)
_SIGNS = np.array([1.0, -1.0])


def _candidates_bounds(t: np.ndarray, F: np.ndarray, ties: np.ndarray, intervals: list[Interval],
                       limit: int = CANDIDATES, layout: tuple | None = None, groups: list[int] | None = None,
                       finite: bool = False, series: list[int] | None = None, edges: list | None = None
                       ) -> tuple[list[list[tuple]], np.ndarray | None]:
    """(`_candidates`, each series' largest finite row in each sense: [c max, -(c min), ...], -inf where none is
    finite; None without rows). The row-against-neighbour comparisons are made once for both senses on the rows'
    differences (a >= b exactly where a - b >= 0; the negated series' differences are the differences negated,
    exactly), and the series in the minimum's sense (-F, -inf where F is not finite) is formed only where read.
    groups: the intervals of each of several windows, consecutive (their counts; each window with rows), whose
    candidates and bounds are each window's own, all found in one pass: [window 0's series, window 1's, ...], each
    candidate's interval counted in its window's. finite: every value of F is finite (known to the caller).
    series: each window's one series, a row of F (its tie that row's of ties): [window 0's, window 1's, ...], each
    window's candidates and bounds those of that series alone, as if found on its own (windows over one table that
    each locate another column).
    edges: a list that gets, per series as `out`, the candidates at an interval's first or last row that the bound
    drops (their estimate is their row, and what lies between the row and the event is not in it): `second_round`
    bounds them by the one-sided limit at the end."""
    if series is not None and (groups is None or len(groups) == 1):       # one window: its series is the table
        F, ties, series = F[series[0]:series[0] + 1], ties[series[0]:series[0] + 1], None
    if layout is None:
        layout = _layout(intervals)
    if layout is None:
        return [[] for _ in range(2 * (len(F) if series is None else len(series)))], None
    if series is None and len(F) > 1 and F.size > JOINT_VALUES:    # each series alone: the same candidates, bounds
        own_edges = [[] if edges is not None else None for _ in range(len(F))]
        parts = [_candidates_bounds(t, F[c:c + 1], ties[c:c + 1], intervals, limit, layout, groups, finite,
                                    edges=own_edges[c]) for c in range(len(F))]
        n_w = 1 if groups is None else len(groups)
        out = [x for w in range(n_w) for cands, _ in parts for x in cands[2 * w:2 * w + 2]]
        if edges is not None:
            edges.extend(x for w in range(n_w) for got in own_edges for x in got[2 * w:2 * w + 2])
        return out, np.stack([bounds.reshape(n_w, 2) for _, bounds in parts], axis=1).ravel()
    rows, k_of, n_of, pos, first, last = layout
    if groups is None or len(groups) == 1:
        n_w, cuts, w_of, base = 1, None, None, None
    else:                                           # each window's first position in the rows, and each row's
        n_w = len(groups)
        first_iv = np.array([0, *groups[:-1]]).cumsum()
        cuts = k_of.searchsorted(first_iv)
        w_of = first_iv.searchsorted(k_of, side="right") - 1
        base = first_iv
    if series is not None:          # one series: each row its window's (a row's neighbours are in its window)
        of = np.asarray(series, dtype=np.intp)[w_of]
        ti, G = t[rows], F[of, rows][None, :]
        wtie = np.asarray(ties, dtype=float)[np.asarray(series, dtype=np.intp)]
        # a difference's tie: its later row's window's (where the two rows are in different windows, neither
        # reads it: the later row is an interval's first, the earlier one its last)
        ties, tie = wtie.repeat(2), np.append(wtie[w_of], 0.0)[None, :]
    elif rows[-1] - rows[0] == len(rows) - 1 and (rows[1:] > rows[:-1]).all():     # a run of rows: views
        ti, G = t[rows[0]:rows[-1] + 1], F[:, rows[0]:rows[-1] + 1]
    else:
        ti, G = t[rows], F[:, rows]
    ok = None if finite else np.isfinite(G)
    finite = finite or bool(ok.all())
    S = 2 * len(G)                                  # series per window

    def fi(m: np.ndarray, i: np.ndarray) -> np.ndarray:
        """Series m (2c: F[c], 2c + 1: -F[c]; -inf where not finite) at rows i."""
        g = G[m >> 1, i]
        signed = g * _SIGNS[m & 1]                  # exactly -g where m is odd
        return signed if finite else np.where(np.isfinite(g), signed, -np.inf)

    if series is None:
        tie, ties = ties[:, None], ties.repeat(2)
    d = np.empty((len(G), G.shape[1] + 1))                 # d[:, i] = G[:, i] - G[:, i - 1]
    d[:, 0] = d[:, -1] = 0.0
    with np.errstate(invalid="ignore"):
        np.subtract(G[:, 1:], G[:, :-1], out=d[:, 1:-1])
        small, up, down = np.abs(d) <= tie, d >= 0, d <= 0
    # a neighbour in the row's interval with a finite value (else it counts as -inf: below any finite row)
    if finite:               # every row but an interval's first (last) has one: (has & x) | first = x | first
        no_l, no_r = first, last
        flat = (small[:, :-1] | first) & (small[:, 1:] | last) & (n_of > 1)
    else:
        has_l, has_r = np.zeros_like(ok), np.zeros_like(ok)
        has_l[:, 1:], has_r[:, :-1] = ok[:, :-1], ok[:, 1:]
        has_l[:, first], has_r[:, last] = False, False
        no_l, no_r = ~has_l, ~has_r
        flat = ((has_l & small[:, :-1]) | first) & ((has_r & small[:, 1:]) | last) & (n_of > 1)
    rough = ~flat
    smooth = np.empty((len(G), 2, G.shape[1]), dtype=bool)        # [c, sense, row]
    np.logical_and((no_l | up[:, :-1]) & (no_r | down[:, 1:]), rough, out=smooth[:, 0])
    np.logical_and((no_l | down[:, :-1]) & (no_r | up[:, 1:]), rough, out=smooth[:, 1])
    if not finite:
        flat &= ok
        smooth &= ok[:, None]
    ends = [0, G.shape[1]] if cuts is None else [*cuts.tolist(), G.shape[1]]       # each window's rows
    wties = ties if series is not None else np.concatenate([ties] * n_w)       # each window's series' and sense's
    with np.errstate(invalid="ignore"):
        # the best peak's: the largest row is a peak ([window, column, sense]; max and min are exact in any order)
        lower, level = np.empty((n_w, len(G), 2)), np.empty((n_w, len(G), 2))
        big, least = (np.where(ok, G, -np.inf), np.where(ok, G, np.inf)) if not finite else (G, G)
        for w, (a, b) in enumerate(zip(ends[:-1], ends[1:])):
            lower[w, :, 0], lower[w, :, 1] = big[:, a:b].max(axis=1), -least[:, a:b].min(axis=1)
            # each window's constant level: its largest flat row (and negated least), -inf where none
            level[w, :, 0] = G[:, a:b].max(axis=1, where=flat[:, a:b], initial=-np.inf)
            level[w, :, 1] = -G[:, a:b].min(axis=1, where=flat[:, a:b], initial=np.inf)
        lower, level = lower.ravel(), level.ravel()
        # a constant stretch can hold the extremum where its level is within the tie of the best row
        near = level >= lower - wties
    any_peak = lower > -np.inf                      # flat rows and the largest are finite
    # the estimates where they are compared: the smooth peaks (np.nonzero's indices, from the flat ones: far faster)
    ms, ii = np.divmod(smooth.ravel().nonzero()[0], G.shape[1])
    row = fi(ms, ii)
    est = row.copy()
    inner = ~(first[ii] | last[ii])
    mi, ij = ms[inner], ii[inner]
    est[inner] = _estimates(ti, fi(mi, ij - 1), row[inner], fi(mi, ij + 1), ij)
    wm = ms if w_of is None else w_of[ii] * S + ms          # the series in its window
    with np.errstate(invalid="ignore"):
        kept = 2 * est - row >= (lower - wties)[wm]
    # each candidate's interval (counted in its window), position in it and bracket, as numbers
    ivlo, ivhi = np.array([iv.lo for iv in intervals], dtype=float), np.array([iv.hi for iv in intervals], dtype=float)
    local = k_of if base is None else k_of - base[w_of]

    def brackets(i: np.ndarray) -> tuple[list, ...]:
        """Rows i's (interval in its window, position, bracket lo, bracket hi): the neighbouring rows, an
        interval's first (last) row reaching out to its start (end)."""
        return (local[i].tolist(), pos[i].tolist(), np.where(first[i], ivlo[k_of[i]], ti[i - 1]).tolist(),
                np.where(last[i], ivhi[k_of[i]], ti[np.minimum(i + 1, len(ti) - 1)]).tolist())
    if edges is not None:
        edges.extend([] for _ in range(n_w * S))
        dropped = (~kept & (first[ii] | last[ii])).nonzero()[0]
        for m, value, k, p, a, b in zip(wm[dropped].tolist(), est[dropped].tolist(), *brackets(ii[dropped])):
            edges[m].append((value, k, p, a, b, False))
    ms, ii, est, wm = ms[kept], ii[kept], est[kept], wm[kept]
    best = np.full(n_w * S, -np.inf)
    np.maximum.at(best, wm, est)
    rank = np.where(est >= best[wm] - wties[wm], best[wm], est)
    order = np.lexsort((ti[ii], -rank, wm))         # each series' by estimate, ties to the earliest
    ii, est, wm = ii[order], est[order], wm[order]
    nth = np.arange(len(wm)) - wm.searchsorted(wm)
    chosen = nth < limit
    out: list[list[tuple]] = [[] for _ in range(n_w * S)]
    # constant stretches are exact: only the best level's earliest can hold the extremum (no refining); it lies at
    # its first instant (the interval's start where it holds the interval's first row)
    constant = (any_peak & near).nonzero()[0]
    mc = constant % S
    # each one's earliest flat row at its level within the tie, among its window's rows (-g >= x exactly where
    # g <= -x: negation is exact)
    earliest = np.zeros(len(constant), dtype=int)
    with np.errstate(invalid="ignore"):
        for q, (m, w, x) in enumerate(zip(mc.tolist(), (constant // S).tolist(), (level - wties)[constant].tolist())):
            a, b = ends[w], ends[w + 1]
            g = G[m >> 1, a:b]
            earliest[q] = a + (flat[m >> 1, a:b] & (g <= -x if m & 1 else g >= x)).argmax()
    at = np.where(first[earliest], ivlo[k_of[earliest]], ti[earliest])
    for m, value, k, p, x in zip(constant.tolist(), fi(mc, earliest).tolist(), local[earliest].tolist(),
                                 pos[earliest].tolist(), at.tolist()):
        out[m].append((value, k, p, x, x, True))
    for m, value, k, p, a, b in zip(wm[chosen].tolist(), est[chosen].tolist(), *brackets(ii[chosen])):
        out[m].append((value, k, p, a, b, False))
    return out, lower


def locate(t: np.ndarray, values: dict[str, np.ndarray], intervals: list[Interval], read: Reader,
           limit: int = CANDIDATES) -> dict[str, dict[str, Extremum]]:
    """{column: {'max': Extremum, 'min': Extremum}} of the table's `values` (arrays over its rows at times t),
    refined by `read(interval, position, times)` (every column at those instants of the interval, as a dict of
    arrays, read from the interval's row at `position`). Brackets within a few rows of each other are read
    together, from the row before the first of them (one forward integration per reading). The same as
    `plan`, its requests read (`read_all`), then `Plan.finish`: a caller that locates several tables reads all
    their requests together."""
    p = plan(t, values, intervals, limit)
    return p.finish(read_all(read, p.requests), read)


def read_all(read: Reader, requests: list[tuple[Interval, int, np.ndarray]]) -> list[dict | None]:
    """The readings of every (interval, position, times) in one call where the reader reads many at once
    (`read_many`); None for each request it did not read (read alone by the caller)."""
    many = getattr(read, "read_many", None)
    return many(requests) if many is not None and requests else [None] * len(requests)


@dataclass
class Plan:
    """What `locate` does before any reading: the jobs (each column's and sense's candidates), the brackets read
    together (`clusters`, each job's grid) and the requests: each cluster's readings, then each interval's start
    where a constant stretch holds its first row (`starts`); each column's largest and negated least finite row
    over the intervals (`bounds`, as `_candidates_bounds` gives them)."""

    t: np.ndarray
    values: dict
    intervals: list
    jobs: list
    ties: dict
    clusters: list
    grids: list
    starts: dict
    requests: list
    bounds: np.ndarray | None = None
    #: the candidates beyond the first `limit` of each series (`plans`), in rank order, and the window's (values, F,
    #: names, ties): what `second_round` refines where they may beat the located extremum
    reserve: list | None = None
    table: tuple | None = None
    #: per series, the candidates at an interval's first or last row that the rows' bound dropped (`_candidates_bounds`
    #: `edges`): `second_round` bounds them by the limit at the interval's end (`plans`' only: the thermal columns'
    #: `column_plans` have none)
    edges: list | None = None

    def finish(self, tables: list[dict | None], read: Reader) -> dict[str, dict[str, Extremum]]:
        """`locate`'s result from the readings of `requests` (None: read here, alone)."""
        return finish_all([self], tables, read)[0]


def finish_all(plans: list[Plan], tables: list[dict | None], read: Reader) -> list[dict[str, dict[str, Extremum]]]:
    """`Plan.finish` of each plan, from the readings of their requests one plan after another (`tables`), every
    bracket refined in one pass (`_refine`), those whose value is not yet to be trusted narrowed (`_narrowed`)."""
    ready, positions, a = [], [], 0
    for p in plans:
        t, values, intervals = p.t, p.values, p.intervals
        n = len(p.clusters)
        mine = tables[a:a + len(p.requests)]
        a += len(p.requests)
        for (k, group), table in zip(p.starts.items(), mine[n:]):
            _constant_from_start(intervals[k], k, group, read, table)
        for group, grids, request, table in zip(p.clusters, p.grids, p.requests[:n], mine[:n]):
            try:
                ready.append((request[0], group, grids, table if table is not None else read(*request)))
                positions.append(request[1])
            except ReadingFailed:          # the rows' value stands, and says so
                for j in group:
                    r = intervals[j.interval].rows[j.anchor]
                    j.best_f, j.best_t, j.limit = j.sampled, float(t[r]), None
                    j.best_row = {c: v[r] for c, v in values.items()}
                    j.where = "output row (the re-integration between rows failed)"
    _refine(ready)
    _narrowed(ready, positions, read)
    located = []
    for p in plans:
        out: dict[str, dict[str, Extremum]] = {}
        for j in p.jobs:
            slot = out.setdefault(j.column, {})
            name = "max" if j.sense > 0 else "min"
            if j.best_row is None:
                continue
            e = Extremum(j.sense * j.best_f, j.best_t, j.where, j.best_row, j.limit, j.edge, j.interval, j.constant)
            if _beats(e, slot.get(name), j.sense, p.ties[j.column]):
                slot[name] = e
        located.append(out)
    return located


def _narrowed(ready: list[tuple], positions: list[int], read: Reader) -> None:
    """The refined jobs of `ready` whose polynomial is not yet to be trusted (`_Job.unsure`: its value and a lower
    one's differ by more than AGREE of the column's scale, where the bracket's grid is coarse against the peak: a
    bracket spanning a whole interval between events a turn apart), refined again on the grid's two steps around
    their best reading, all of them read in one pass, at most NARROWINGS times; a reading that fails leaves the
    job as it was."""
    for _ in range(NARROWINGS):
        asks = [(iv, pos, j) for (iv, group, _, _), pos in zip(ready, positions) for j in group
                if j.unsure is not None]
        if not asks:
            return
        grids, requests = [], []
        for iv, pos, j in asks:
            centre, step = j.unsure
            lo, hi = max(j.lo, centre - step), min(j.hi, centre + step)
            grid = np.empty(FIRST_GRID + 1)
            grid[:FIRST_GRID] = np.arange(FIRST_GRID) * ((hi - lo) / (FIRST_GRID - 1)) + lo
            grid[FIRST_GRID - 1] = hi
            grid[FIRST_GRID] = centre          # the best reading so far stands as the job's row
            grids.append(grid)
            requests.append((iv, pos, np.unique(grid)))
            j.unsure = None
        again = []
        for (iv, _, j), grid, request, table in zip(asks, grids, requests, read_all(read, requests)):
            try:
                again.append((iv, [j], grid[None, :], table if table is not None else read(*request)))
            except ReadingFailed:
                continue
        _refine(again)


def plan(t: np.ndarray, values: dict[str, np.ndarray], intervals: list[Interval], limit: int = CANDIDATES) -> Plan:
    """`locate`'s candidates, brackets and reading requests (see `Plan`)."""
    return plans([(t, values, intervals)], limit)[0]


def plans(windows: list[tuple | None], limit: int = CANDIDATES) -> list[Plan | None]:
    """`plan` of each window's (t, values, intervals) (None: no plan); the windows over the same table (t and values
    the same objects, as `with_rowless` hands them back without short intervals) planned together: the table's
    ties once, their candidates in one pass of its rows (`_candidates_bounds`), every bracket's grid in another
    (`_grids`)."""
    out: list[Plan | None] = [None] * len(windows)
    tables: dict = {}
    for w, x in enumerate(windows):
        if x is not None:
            tables.setdefault((id(x[0]), id(x[1])), []).append(w)
    for ws in tables.values():
        t, values = windows[ws[0]][:2]
        names = list(values)
        F = np.array([np.asarray(values[c], dtype=float) for c in names]).reshape(len(names), len(t))
        finite = bool(np.isfinite(F).all())
        col_ties = _ties(F, finite)
        ties = {col: float(x) for col, x in zip(names, col_ties.tolist())}
        spans = [windows[w][2] for w in ws]
        held = _held(spans)
        found: list = [[[] for _ in range(2 * len(names))] for _ in spans]
        bounds: list = [None] * len(spans)
        reserve: list = [None] * len(spans)
        more: list = [None] * len(spans)
        if held:
            edges: list = []
            got, lower = _candidates_bounds(t, F, col_ties, [iv for w in held for iv in spans[w]], EVERY,
                                            groups=[len(spans[w]) for w in held], finite=finite, edges=edges)
            S = 2 * len(names)
            for q, w in enumerate(held):
                found[w], reserve[w] = zip(*(_first(x, limit) for x in got[q * S:(q + 1) * S]))
                found[w], bounds[w] = list(found[w]), lower[q * S:(q + 1) * S]
                more[w] = edges[q * S:(q + 1) * S]
        table = (values, F, names, ties)
        for q, (w, plan_) in enumerate(zip(ws, _planned(t, [table] * len(spans), spans, found, bounds))):
            plan_.reserve, plan_.edges, plan_.table = reserve[q], more[q], table
            out[w] = plan_
    return out


#: `_candidates_bounds`'s limit that keeps every candidate
EVERY = 1 << 62
#: candidates refined per column and sense in the second round at most (`second_round`): the largest bounds
SECOND_ROUND = 2
#: a second round's located value within (REPEAT, RIVAL] of the located extremum, relative to the column's largest
#: magnitude, calls for another round (`refine_further`): closer, it is one peak repeated (a run's turns repeat a peak
#: to its located values' own error: the refinement's polynomial, about 1e-10; the readings' tolerance, a tenth of
#: the run's rtol); farther, the bounds that ranked it are loose there (an extremum at an event's limit, far from the
#: located one), where the peaks the bounds rank wrongly differ by 1e-5 to 1e-3 (a bulk temperature rising turn by
#: turn, narrow peaks of a drive that does not repeat)
REPEAT = 1e-6
RIVAL = 1e-2


def _first(got: list[tuple], limit: int) -> tuple[list[tuple], list[tuple]]:
    """(the candidates `_candidates_bounds` gives with `limit`, the rest) of one series' candidates found without a
    limit (constant stretches first, then the others by rank)."""
    flat = [x for x in got if x[5]]
    rest = got[len(flat):]
    return flat + rest[:limit], rest[limit:]


def second_round(plans: list[Plan | None], located: list[dict[str, dict[str, Extremum]]],
                 ends: list[tuple[EndLines, int | None] | None] | None = None,
                 edges_only: list[tuple[float, float] | None] | None = None,
                 taken: list[set] | None = None, series: set | None = None, count: int = SECOND_ROUND
                 ) -> list[Plan | None]:
    """For each plan, a plan of its reserve candidates that may still beat the extremum located from its first ones
    (None where none may): a bracket's extremum may reach its row plus twice its parabola estimate's gain (the
    bound `_candidates_bounds` keeps candidates by), so a candidate whose bound exceeds the located value by more
    than the tie is refined too, the SECOND_ROUND largest bounds first (a run of many turns
    repeats its peaks, each within its bound of the located one). The first ones are the best by the rows' parabola
    estimates, which rank the peaks
    wrongly where a peak is narrow against the output step and the peaks differ (a start-up, whose peaks grow turn
    by turn: geneva-torque's contact force at 2.3 ms rows, 0.1 % low; a drive that is not periodic:
    chain-mech2-detuned's coupler force at its own 10 ms rows, 0.14 % low).

    ends: per plan, its intervals' one-sided limits (`EndLines`, with `stored_limits` applied, and the plan's window
    in them), or None. An interval's first or last row has no neighbour beyond it, so its estimate is its row and
    its bound says nothing of the stretch between it and the event: there the bound is the parabola through the
    row, its inner neighbour and the limit at the end (`_ReserveBounds`), so that an extremum within a step of an event
    that the row does not show is refined (rolling-b-components' crank speed at 23 ms rows, 1.5 % short).
    edges_only: per plan, None, or (a, b): only those within [a, b] are refined (a periodic regime's last turn: its
    turns repeat the same peaks, so its first candidates are the regime's, but an extremum next to an event in every
    turn is in none of them). taken: per plan, the candidates refined already (`refine_further`'s earlier rounds:
    skipped, and those chosen here added); series: the (plan, column, 'max' | 'min') to refine further (None:
    all); count: the candidates refined per column and sense at most."""
    out: list[Plan | None] = []
    for n_plan, (p, got) in enumerate(zip(plans, located)):
        only = edges_only[n_plan] if edges_only is not None else None
        has_ends = p is not None and ends is not None and ends[n_plan] is not None
        edges = p.edges if has_ends and p.edges is not None else None
        if edges is not None and only is not None:
            edges = [[x for x in got if x[3] >= only[0] and x[4] <= only[1]] for got in edges]
        if p is None or (not any(p.reserve or ()) or only is not None) and not any(edges or ()):
            out.append(None)
            continue
        values, F, names, ties = p.table
        found: list[list[tuple]] = [[] for _ in range(2 * len(names))]
        asks = []
        for m, rest in enumerate(p.reserve or [()] * (2 * len(names))):
            c, sense = names[m >> 1], -1.0 if m & 1 else 1.0
            e = got.get(c, {}).get("min" if m & 1 else "max")
            if e is None or (series is not None and (n_plan, c, "min" if m & 1 else "max") not in series):
                continue
            # (not next to an event where a constant stretch holds the extremum: exact, where the limits at the events
            # around it equal it only to the integration's tolerance, as `end_limits` leaves it)
            rest = ([] if only is not None else list(rest or ())) + (list(edges[m]) if edges is not None and
                                                                      not e.constant else [])
            if taken is not None:
                rest = [x for x in rest if (m, *x[1:5]) not in taken[n_plan]]
            if rest:
                asks.append((m, rest))
        every = _ReserveBounds(p.t, p.intervals, *(ends[n_plan] if has_ends else ())).bounds(F, names, asks)
        for (m, rest), bounds in zip(asks, every):
            c, sense = names[m >> 1], -1.0 if m & 1 else 1.0
            v = sense * got[c]["min" if m & 1 else "max"].value
            able = [(-u, n) for n, u in enumerate(bounds) if u > v + ties[c]]
            found[m] = [rest[n] for _, n in sorted(able)[:count]]
            if taken is not None:
                taken[n_plan].update((m, *x[1:5]) for x in found[m])
        if not any(found):
            out.append(None)
            continue
        out.append(_planned(p.t, [p.table], [p.intervals], [found], [p.bounds])[0])
    return out


class _ReserveBounds:
    """`second_round`'s bounds of a window's candidates, all series at once (`bounds`); those whose bracket reaches
    their interval's end at an event (an interval's first or last row, which has no neighbour beyond it: its
    estimate is its own value) from the limit there: the window's intervals, and its ends in `lines` (`window`: its
    number where the lines are several windows', else None; no lines: the rows' bounds alone)."""

    def __init__(self, t: np.ndarray, intervals: list[Interval], lines: EndLines | None = None,
                 window: int | None = None):
        self.t, self.lines = t, lines
        self.lo = np.array([iv.lo for iv in intervals], dtype=float)
        self.hi = np.array([iv.hi for iv in intervals], dtype=float)
        self.n = np.array([len(iv.rows) for iv in intervals], dtype=np.int64)
        self.first = np.cumsum(self.n) - self.n
        self.rows = np.concatenate([np.asarray(iv.rows, dtype=np.int64) for iv in intervals]) if intervals else \
            np.zeros(0, dtype=np.int64)
        # each interval's end positions in the lines (-1: none): [interval, 0 after its start / 1 before its end]; the
        # events inside the window only (the column runs on smoothly across a window's own ends: in a periodic regime
        # the turn after repeats what lies next to its start)
        self.at = np.full((len(intervals), 2), -1, dtype=np.int64)
        for e, (k, side, _) in enumerate(lines.ends if lines is not None else ()):
            inside = (k > 0 or side == "before") and (k < len(intervals) - 1 or side == "after")
            if inside and (window is None or lines.window is None or int(lines.window[e]) == window):
                self.at[k, 1 if side == "before" else 0] = e

    def bounds(self, F: np.ndarray, names: list[str], asks: list[tuple[int, list[tuple]]]) -> list[list[float]]:
        """The bounds of every (series m, its candidates) of `asks` (F: the window's columns `names`, series 2c the
        column c, 2c + 1 it negated): a candidate's row plus twice its estimate's gain. Where its bracket reaches its
        interval's end at an event whose limit the lines hold, and the parabola through the row, its inner neighbour
        and the limit at the end (sense * values) turns between the row and the end: its vertex plus its gain over
        the larger of row and limit again (the estimate's error is of the order of its gain), if more. Where the
        limit is the rows' extrapolation (the reader holds no state there, or its limit does not continue the rows:
        `stored_limits`), the column may reach it plus its margin within the step: that too; where it is the
        reader's, it is `end_limits`' to read."""
        lines = self.lines
        sizes = [len(cands) for _, cands in asks]
        if not sum(sizes):
            return [[] for _ in asks]
        x = np.array([c[:5] for _, cands in asks for c in cands], dtype=float)
        m = np.repeat(np.array([m for m, _ in asks], dtype=np.int64), sizes)
        k, pos, lo, hi = x[:, 1].astype(np.int64), x[:, 2].astype(np.int64), x[:, 3], x[:, 4]
        own = np.where(m & 1, -1.0, 1.0)
        out = 2.0 * x[:, 0] - own * F[m >> 1, self.rows[self.first[k] + pos]]
        cuts = np.cumsum(sizes)[:-1].tolist()
        if lines is None:
            return [part.tolist() for part in np.split(out, cuts)]
        col = np.array([lines.of.get(c, -1) for c in names], dtype=np.int64)[m >> 1]
        before = (pos == self.n[k] - 1) & (hi == self.hi[k])
        after = ~before & (pos == 0) & (lo == self.lo[k])
        inner = np.where(before, pos - 1, pos + 1)
        e = np.where(before, self.at[k, 1], np.where(after, self.at[k, 0], -1))
        use = (before | after) & (e >= 0) & (col >= 0) & (inner >= 0) & (inner < self.n[k])
        use[use] = lines.ok[col[use], e[use]]
        if use.any():
            i = use.nonzero()[0]
            e, k, n, c = e[i], k[i], col[i], m[i] >> 1
            sense = np.where(m[i] & 1, -1.0, 1.0)
            r, q = self.rows[self.first[k] + pos[i]], self.rows[self.first[k] + inner[i]]
            te, fe, margin = lines.te[e], sense * lines.line[n, e], lines.curve[n, e]
            tr, fr, ti, fi = self.t[r], sense * F[c, r], self.t[q], sense * F[c, q]
            with np.errstate(invalid="ignore", divide="ignore"):
                guessed = fe + margin if lines.exact is None else np.where(lines.exact[n, e], -np.inf, fe + margin)
                # the parabola through (ti, fi), (tr, fr), (te, fe) by its divided differences:
                # p(x) = fr + (x - tr) (d1 + c2 (x - ti)), p'(x) = d1 + c2 (2x - tr - ti) = 0 at the vertex
                d1, d2 = (fr - fi) / (tr - ti), (fe - fr) / (te - tr)
                c2 = (d2 - d1) / (te - ti)
                xv = 0.5 * (tr + ti - d1 / c2)
                turns = (c2 < 0) & (np.minimum(tr, te) < xv) & (xv < np.maximum(tr, te))
                top = fr + (xv - tr) * (d1 + c2 * (xv - ti))
                got = np.fmax(guessed, np.where(turns, 2.0 * top - np.maximum(fr, fe) + margin, -np.inf))
            out[i] = np.fmax(out[i], np.where(np.isfinite(got), got, -np.inf))
        return [part.tolist() for part in np.split(out, cuts)]


def merged(located: list[dict[str, dict[str, Extremum]]], more: list[Plan | None], again: list[dict],
           ties: set | None = None) -> set[tuple[int, str, str]]:
    """`located` with each extremum the second round (`more`, its results `again`, in order of the plans that are
    not None) found better in its place (`_beats`: larger by more than the tie, or tied and earlier); the (plan,
    column, 'max' | 'min') whose round found a rival of the located extremum (no repeat of it, and within RIVAL of
    it: a larger one, or only smaller ones; `refine_further`). ties: where given, the (plan, column, 'max' | 'min')
    whose round found the located value again within the tie (a peak repeated to round-off) are added to it."""
    results = iter(again)
    rivals = set()
    for n_plan, (p, got) in enumerate(zip(more, located)):
        if p is None:
            continue
        for c, found in next(results).items():
            for name, e in found.items():
                old = got.get(c, {}).get(name)
                scale = p.ties[c] / TIE_ROUNDOFF
                if old is None or max(p.ties[c], REPEAT * scale) < abs(e.value - old.value) <= RIVAL * scale:
                    rivals.add((n_plan, c, name))
                if ties is not None and old is not None and abs(e.value - old.value) <= p.ties[c]:
                    ties.add((n_plan, c, name))
                if _beats(e, old, 1.0 if name == "max" else -1.0, p.ties[c]):
                    got.setdefault(c, {})[name] = e
    return rivals


def refine_further(plans: list[Plan | None], located: list[dict[str, dict[str, Extremum]]], read: Reader,
                   ends: list[tuple[EndLines, int | None] | None] | None = None,
                   edges_only: list[tuple[float, float] | None] | None = None) -> None:
    """`located` (the plans' `finish_all`) with the second round's candidates (`second_round`, the plans' `ends`,
    `edges_only`) read in one pass of `read` and refined, each better extremum in its place (`merged`). A column
    whose round found a rival of its located extremum (`merged`: neither a repeat of it, REPEAT, nor far from it,
    RIVAL) has its next candidates whose bounds still exceed it refined in another round, until none does (branch
    and bound): the bounds rank the candidates only roughly where peaks are narrow against the rows, so runs whose
    peaks differ by less than their estimates' error are ranked by chance (chain-mech2-detuned's coupler force at
    1 s rows: two candidates of higher bounds, both lower, before its largest peak). A round that finds the located
    extremum again (a run whose turns repeat one peak, each candidate's bound above it), or only values far from it
    (loose bounds: a limit at an event), ends it. Each
    round takes twice the candidates of the one before, so that the passes of `read` grow only like the logarithm
    of the candidates refined."""
    taken: list[set] = [set() for _ in plans]
    series, count = None, SECOND_ROUND
    repeated: set = set()
    while series is None or series:
        more = second_round(plans, located, ends, edges_only, taken, series, count)
        count *= 2
        again = [p for p in more if p is not None]
        if not again:
            break
        series = merged(located, more, finish_all(again, read_all(read, [r for p in again for r in p.requests]),
                                                  read), repeated)
    earliest_ties(plans, located, read, taken, repeated)


#: candidates `earliest_ties` refines per column and sense at most, one a pass
EARLIEST_TRIES = 3


def earliest_ties(plans: list[Plan | None], located: list[dict[str, dict[str, Extremum]]], read: Reader,
                  taken: list[set], repeated: set[tuple[int, str, str]]) -> None:
    """A tie goes to the earliest instant (`_beats`), but only among the candidates refined: where a column repeats
    its extremum to round-off (`repeated`: a prescribed motion's turns, `merged`), which of its turns the first
    rounds refined hangs on where the output rows fall, and so would the reported instant. So the earliest
    candidate before the located instant whose bound (`_ReserveBounds`, the rows': its row plus twice its
    estimate's gain) reaches the located value less the tie is refined, and takes its place where it ties (or where
    it is larger, which the first rounds' bounds should have ruled out); where it is smaller, the next earliest, EARLIEST_TRIES at most (candidates refined already, `taken`, skipped). No
    earlier candidate's bound reaching the value, the located instant is the earliest the rows allow."""
    pending = set(repeated)
    for _ in range(EARLIEST_TRIES):
        more: list[Plan | None] = []
        for n_plan, p in enumerate(plans):
            mine = sorted(x for x in pending if x[0] == n_plan)
            if p is None or not mine or not p.reserve:
                more.append(None)
                continue
            _, F, names, ties = p.table
            asks = []
            for _, c, name in mine:
                m = 2 * names.index(c) + (name == "min")
                e = located[n_plan][c][name]
                rest = [x for x in p.reserve[m] if x[4] <= e.t and (m, *x[1:5]) not in taken[n_plan]]
                if rest and not e.constant and e.limit is None:
                    asks.append((m, rest))
                else:
                    pending.discard((n_plan, c, name))
            found: list[list[tuple]] = [[] for _ in range(2 * len(names))]
            for (m, rest), bounds in zip(asks, _ReserveBounds(p.t, p.intervals).bounds(F, names, asks)):
                c, name = names[m >> 1], "min" if m & 1 else "max"
                v = (-1.0 if m & 1 else 1.0) * located[n_plan][c][name].value
                able = [x for x, u in zip(rest, bounds) if u >= v - ties[c]]
                if able:
                    first = min(able, key=lambda x: x[3])
                    found[m] = [first]
                    taken[n_plan].add((m, *first[1:5]))
                else:
                    pending.discard((n_plan, c, name))
            more.append(_planned(p.t, [p.table], [p.intervals], [found], [p.bounds])[0] if any(found) else None)
        again = [p for p in more if p is not None]
        if not again:
            return
        results = iter(finish_all(again, read_all(read, [r for p in again for r in p.requests]), read))
        for n_plan, p in enumerate(more):
            if p is None:
                continue
            for c, got in next(results).items():
                for name, e in got.items():
                    old = located[n_plan][c][name]
                    if _beats(e, old, 1.0 if name == "max" else -1.0, p.ties[c]):   # tied and earlier, or larger
                        located[n_plan][c][name] = e
                    if abs(e.value - old.value) <= p.ties[c] or located[n_plan][c][name] is e:
                        pending.discard((n_plan, c, name))


def column_plans(t: np.ndarray, values: dict[str, np.ndarray], spans: list[tuple[str, list[Interval]]],
                 limit: int = CANDIDATES) -> list[Plan]:
    """`plan(t, {c: values[c]}, intervals)` of each (column c, intervals) of `spans` (each column searched on
    intervals of its own, over one table): the same plans, every candidate found in one pass of the rows the spans
    hold (`_candidates_bounds`, a series per span), every bracket's grid in another (`_grids`)."""
    names = list(dict.fromkeys(c for c, _ in spans))
    row = {c: i for i, c in enumerate(names)}
    F = np.array([np.asarray(values[c], dtype=float) for c in names]).reshape(len(names), len(t))
    col_ties = _ties(F)           # each column's own (a row's largest finite magnitude: exact in any order)
    own = [({c: values[c]}, F[row[c]:row[c] + 1], [c], {c: float(col_ties[row[c]])}) for c, _ in spans]
    intervals = [ivs for _, ivs in spans]
    held = _held(intervals)
    found: list = [[[], []] for _ in spans]
    bounds: list = [None] * len(spans)
    reserve: list = [None] * len(spans)
    if held:
        got, lower = _candidates_bounds(t, F, col_ties, [iv for w in held for iv in intervals[w]], EVERY,
                                        groups=[len(intervals[w]) for w in held],
                                        series=[row[spans[w][0]] for w in held])
        for q, w in enumerate(held):
            found[w], reserve[w] = (list(x) for x in zip(*(_first(x, limit) for x in got[2 * q:2 * q + 2])))
            bounds[w] = lower[2 * q:2 * q + 2]
    out = _planned(t, own, intervals, found, bounds)
    for p, table, rest in zip(out, own, reserve):
        p.table, p.reserve = table, rest
    return out


def _held(spans: list[list[Interval]]) -> list[int]:
    """The windows with rows in the order of their rows (adjacent windows' rows then run on: views of the table)."""
    return sorted((w for w in range(len(spans)) if any(len(iv.rows) for iv in spans[w])),
                  key=lambda w: next(int(iv.rows[0]) for iv in spans[w] if len(iv.rows)))


def _planned(t: np.ndarray, tables: list[tuple], spans: list[list[Interval]], found: list, bounds: list
             ) -> list[Plan]:
    """Each window's Plan from its candidates (`found`) and bounds: its jobs, brackets and requests, every window's
    grids made in one pass (`_grids`); tables: each window's (values, F, names, ties)."""
    jobs = [_jobs(t, values, F, names, ties, ivs, got)
            for (values, F, names, ties), ivs, got in zip(tables, spans, found)]
    clusters = [_clusters(js) for js, _ in jobs]
    grids, instants = _grids([g for cs in clusters for g in cs])
    out, a = [], 0
    for (values, _, _, ties), intervals, (js, starts), cs, lower in zip(tables, spans, jobs, clusters, bounds):
        mine = slice(a, a + len(cs))
        a += len(cs)
        requests = [(intervals[g[0].interval], max(g[0].anchor - 1, 0), x) for g, x in zip(cs, instants[mine])]
        requests += [(intervals[k], 0, np.array([intervals[k].lo])) for k in starts]
        out.append(Plan(t, values, intervals, js, ties, cs, grids[mine], starts, requests, lower))
    return out


def _jobs(t: np.ndarray, values: dict, F: np.ndarray, names: list[str], ties: dict, intervals: list[Interval],
          found: list[list[tuple]]) -> tuple[list[_Job], dict[int, list[_Job]]]:
    """`plan`'s jobs of each column and sense from its candidates (`found`, as `_candidates_bounds` gives them), in
    order of interval and row, and the constant stretches read at their interval's start (by interval)."""
    jobs: list[_Job] = []
    starts: dict[int, list[_Job]] = {}          # constant stretches from an interval's start (read there)
    for n, col in enumerate(names):
        f = F[n]
        tie = ties[col]
        for sense, got in ((1.0, found[2 * n]), (-1.0, found[2 * n + 1])):
            for est, k, i, lo, hi, flat in got:
                iv = intervals[k]
                r = iv.rows[i]
                j = _Job(col, sense, k, i, lo, hi, sense * float(f[r]), float(t[r]), tie=tie)
                j.edge = "before" if hi == iv.hi else "after" if lo == iv.lo else None
                if flat:             # the row's value is the extremum's, at the stretch's first instant
                    j.best_f, j.best_t, j.done, j.edge, j.constant = j.sampled, lo, True, None, True
                    j.best_row = {c: v[r] for c, v in values.items()}
                    if lo != j.t_row:
                        starts.setdefault(k, []).append(j)
                    elif lo == iv.lo:
                        j.where = f"{iv.lo_kind} (constant from here)"
                    else:
                        j.where = "output row (constant from here)"
                jobs.append(j)
    jobs.sort(key=lambda j: (j.interval, j.anchor))
    return jobs, starts


def _clusters(jobs: list[_Job]) -> list[list[_Job]]:
    """The brackets read together: the jobs still to refine within CLUSTER_ROWS rows of a cluster's first, in its
    interval (`jobs` in order of interval and row)."""
    clusters: list[list[_Job]] = []
    for j in jobs:
        if j.done:
            continue
        if clusters and clusters[-1][0].interval == j.interval and j.anchor - clusters[-1][0].anchor <= CLUSTER_ROWS:
            clusters[-1].append(j)
        else:
            clusters.append([j])
    return clusters


def _constant_from_start(iv: Interval, k: int, group: list[_Job], read: Reader, table: dict | None = None) -> None:
    """Constant stretches that hold their interval's first row lie at the interval's start: every column is read
    there (the one-sided limit after an event; the window's start for the first interval; `table`: that reading
    where already read). The value stays the rows' (exact); if the reading fails, the stretch's first row stands."""
    try:
        table = table if table is not None else read(iv, 0, np.array([iv.lo]))
    except ReadingFailed:
        for j in group:
            j.best_t = j.t_row
        return
    for j in group:
        j.best_row = _Row(table, 0, None)
        j.best_row[j.column] = j.sense * j.best_f
        j.where = (f"{iv.lo_kind} (constant from here, limit from after)" if k > 0
                   else f"{iv.lo_kind} (constant from here)")
        j.limit = "after" if k > 0 else None


def _at_one(v: np.ndarray, pos, w: np.ndarray | None):
    """A column at one instant: the reading at pos, or the polynomial through the readings at pos (weights w; a
    column that is not float: the reading of the largest weight)."""
    if w is None:
        return v[pos]
    if v.dtype.kind == "f":
        return float(w @ v[pos])
    return v[pos[int(np.argmax(w))]]


class _Row(MutableMapping):
    """Every column of a table at one instant (`_at_one`) as a mapping, each column evaluated when first read (a
    summary reads one or two)."""

    def __init__(self, table: dict, pos, w: np.ndarray | None):
        self._table, self._pos, self._w, self._got = table, pos, w, {}

    def __getitem__(self, c):
        if c not in self._got:
            self._got[c] = _at_one(np.asarray(self._table[c]), self._pos, self._w)
        return self._got[c]

    def __setitem__(self, c, value):
        self._got[c] = value

    def __delitem__(self, c):
        raise TypeError("a located row's columns are fixed")

    def __contains__(self, c):
        return c in self._got or c in self._table

    def __iter__(self):
        return iter(dict.fromkeys([*self._table, *self._got]))

    def __len__(self):
        return len(dict.fromkeys([*self._table, *self._got]))

    def __repr__(self):
        return repr(dict(self))


def _stencil_tables(n: int) -> tuple[np.ndarray, np.ndarray]:
    """For n equally spaced nodes 0..n-1: the barycentric weights, and for each node b the inverse of the
    Vandermonde matrix in x - b (the monomial coefficients about b of the polynomial through n values)."""
    nodes = np.arange(n, dtype=float)
    bary = np.array([1.0 / np.prod(x - np.delete(nodes, i)) for i, x in enumerate(nodes)])
    inverse = np.stack([np.linalg.inv(np.vander(nodes - b, increasing=True)) for b in range(n)])
    return bary, inverse


_BARY, _INVERSE = _stencil_tables(STENCIL)
#: instants per grid step at which the interpolant is first searched for its maximum (then Newton's method)
_SEARCH = np.linspace(-1.0, 1.0, 33)


def _stencil_weights(x: np.ndarray) -> np.ndarray:
    """Weights (rows) of the polynomial through the STENCIL nodes 0..STENCIL-1 at each x (barycentric form)."""
    d = np.asarray(x, dtype=float)[:, None] - np.arange(STENCIL, dtype=float)
    hit = d == 0
    with np.errstate(divide="ignore", invalid="ignore"):
        w = _BARY / d
        w = w / w.sum(axis=1, keepdims=True)
    on = hit.any(axis=1)
    w[on] = (hit[on].cumsum(axis=1) == 1) & hit[on]          # the first node it lies on
    return w


def _horner(c: np.ndarray, x: np.ndarray) -> np.ndarray:
    """Each row's polynomial (monomial coefficients c[m], lowest first) at x[m] (a number or a row of them), by
    Horner's rule as numpy's polyval."""
    c = c if x.ndim == 1 else c[:, :, None]
    v = c[:, -1] + x * 0
    for i in range(2, c.shape[1] + 1):
        v = c[:, -i] + v * x
    return v


def _poly_max(f: np.ndarray, b: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """(x*, weights) of each row of f (STENCIL readings, their best at b): the maximum of the polynomial through
    them within a grid step of the best one (x in grid steps from the stencil's first node): sampled, then
    Newton's method on its derivative; the weights give any column at x*."""
    c = np.matmul(_INVERSE[b], f[:, :, None])[:, :, 0]           # coefficients in x - b
    d1 = c[:, 1:] * np.arange(1, STENCIL)
    d2 = d1[:, 1:] * np.arange(1, STENCIL - 1)
    lo, hi = np.maximum(-1.0, -b.astype(float)), np.minimum(1.0, (STENCIL - 1 - b).astype(float))
    xs = np.minimum(np.maximum(_SEARCH[None, :], lo[:, None]), hi[:, None])
    x = xs[np.arange(len(b)), _horner(c, xs).argmax(axis=1)]
    going = np.ones(len(b), dtype=bool)
    # d1 and d2 by Horner's rule stepped together (the same operations as `_horner` of each): d1's coefficients
    # but its lowest beside d2's, one degree below
    n, pair = len(b), np.concatenate([d1[:, 1:], d2])
    with np.errstate(divide="ignore", invalid="ignore"):
        for _ in range(4):
            xx = np.concatenate([x, x])
            v = _horner(pair, xx)
            g, h = d1[:, 0] + v[:n] * x, v[n:]
            going &= h < 0
            x = np.where(going, np.minimum(np.maximum(x - g / h, lo), hi), x)
    x = b + x
    return x, _stencil_weights(x)


def _grids(clusters: list[list[_Job]]) -> tuple[list[np.ndarray], list[np.ndarray]]:
    """Each cluster's jobs' readings over their brackets (FIRST_GRID, as np.linspace spaces them; a bracket of one
    instant: that instant repeated), each job's row after them (a row of FIRST_GRID + 1 instants per job), and the
    instants each cluster reads: those and the jobs' own rows (so that the result is never below the row), in
    order without repeats (as np.unique gives them); all clusters' grids computed at once."""
    jobs = [j for group in clusters for j in group]
    if not jobs:
        return [], []
    lo, hi = np.array([j.lo for j in jobs]), np.array([j.hi for j in jobs])
    t_row = np.array([j.t_row for j in jobs])
    grid = np.empty((len(jobs), FIRST_GRID + 1))
    grid[:, :FIRST_GRID] = np.arange(FIRST_GRID) * ((hi - lo) / (FIRST_GRID - 1))[:, None] + lo[:, None]
    grid[:, FIRST_GRID - 1] = hi
    wide = hi > lo
    grid[~wide, :FIRST_GRID] = lo[~wide, None]
    grid[:, FIRST_GRID] = t_row
    sizes = np.array([len(group) for group in clusters])
    cid = np.arange(len(clusters)).repeat(sizes)
    # every cluster's instants: its wide brackets' grids, its point brackets' one instant, its jobs' rows
    vals = np.concatenate([grid[wide, :FIRST_GRID].ravel(), lo[~wide], t_row])
    of = np.concatenate([cid[wide].repeat(FIRST_GRID), cid[~wide], cid])
    order = np.lexsort((vals, of))
    vals, of = vals[order], of[order]
    new = np.ones(len(vals), dtype=bool)
    new[1:] = (vals[1:] != vals[:-1]) | (of[1:] != of[:-1])
    vals, of = vals[new], of[new]
    cuts = [0, *of.searchsorted(np.arange(1, len(clusters))).tolist(), len(vals)]
    starts = [0, *sizes.cumsum().tolist()]
    return ([grid[a:b] for a, b in zip(starts[:-1], starts[1:])],
            [vals[a:b] for a, b in zip(cuts[:-1], cuts[1:])])


def _refine(ready: list[tuple[Interval, list[_Job], np.ndarray, dict]]) -> None:
    """Each job's maximum in its bracket from one pass of readings (`_grids`, each group's table read from one
    anchor row), all jobs together: the polynomial through the STENCIL readings around the best one gives t* and
    the value, and every column there (its error is of order |F^(STENCIL)| d^STENCIL for the grid's step d, far
    below the tolerance); at an interval's end the one-sided limit there."""
    jobs, tables, ivs, G, A, times, columns = [], [], [], [], [], [], []
    for iv, group, grids, table in ready:
        tt = np.asarray(table["t_s"], dtype=float)
        times.append(tt)
        A.append(tt.searchsorted(grids))      # each job's grid and row (last) among the cluster's readings
        G.append(grids)
        columns += [np.asarray(table[j.column], dtype=float) for j in group]
        jobs += group
        tables += [table] * len(group)
        ivs += [iv] * len(group)
    if not jobs:
        return
    counts, sizes = [len(group) for _, group, _, _ in ready], np.array([len(tt) for tt in times])
    G, A = np.concatenate(G), np.minimum(np.concatenate(A), (sizes - 1).repeat(counts)[:, None])
    TR = np.concatenate(times)[(sizes.cumsum() - sizes).repeat(counts) + A[:, -1]]      # each job's row's instant
    # per job: sense, bracket, tie and its interval's ends
    sense, j_lo, j_hi, sense_tie, lo, hi = np.array([(j.sense, j.lo, j.hi, j.tie, iv.lo, iv.hi)
                                                     for j, iv in zip(jobs, ivs)]).T
    F = np.array([f[a] for f, a in zip(columns, A)]) * sense[:, None]
    G, P, R, F, FR = G[:, :-1], A[:, :-1], A[:, -1], F[:, :-1], F[:, -1]
    n_g = np.where(j_hi > j_lo, FIRST_GRID, 1)       # a bracket of one instant: one reading
    every = np.arange(len(jobs))
    held = np.isfinite(F).any(axis=1)                 # a job none of whose readings is finite keeps no row
    F = np.where(np.isfinite(F), F, -np.inf)
    with np.errstate(invalid="ignore"):
        b = (F >= (F.max(axis=1) - sense_tie)[:, None]).argmax(axis=1)    # the earliest of ties to round-off
        best_f, best_t, best_pos = F[every, b], G[every, b], P[every, b]
        row = FR > best_f + sense_tie                 # the row itself (between grid readings)
    best_f, best_t, best_pos = np.where(row, FR, best_f), np.where(row, TR, best_t), np.where(row, R, best_pos)
    at_lo = (b == 0) & (G[:, 0] == lo)
    at_hi = (b == n_g - 1) & (G[every, n_g - 1] == hi)
    end = at_lo | at_hi | (n_g < STENCIL)            # the one-sided limit at the interval's end
    at_lo, at_hi = at_lo & ~row, at_hi & ~row        # (where the row itself beats them, no limit is the best)
    c0 = np.minimum(np.maximum(b - STENCIL // 2, 0), np.maximum(n_g - STENCIL, 0))
    part = F[every[:, None], np.minimum(c0[:, None] + np.arange(STENCIL), FIRST_GRID - 1)]
    poly = ~end & np.isfinite(part).all(axis=1) & held
    x = np.full(len(jobs), np.nan)
    W = np.full((len(jobs), STENCIL), np.nan)
    value = np.full(len(jobs), -np.inf)
    if poly.any():
        x[poly], W[poly] = _poly_max(part[poly], (b - c0)[poly])
        # each job's dot product (a stack of 1 x n by n x 1 products: numpy's dot of each pair, as w @ f)
        value[poly] = np.matmul(W[poly][:, None, :], part[poly][:, :, None])[:, 0, 0]
    better = poly & (value >= best_f)
    step = G[:, 1] - G[:, 0]
    # the value's error estimate: the polynomial through the LOWER readings nearest x* against the STENCIL one's
    unsure = np.zeros(len(jobs), dtype=bool)
    if better.any():
        m = better.nonzero()[0]
        low = np.clip(np.round(x[m]).astype(int) - LOWER // 2, 0, STENCIL - LOWER)
        nodes = low[:, None] + np.arange(LOWER)
        d = x[m][:, None] - nodes
        w = np.ones((len(m), LOWER))
        for i in range(LOWER):
            for k in range(LOWER):
                if k != i:
                    w[:, i] *= d[:, k] / (i - k)
        lower = (w * part[m[:, None], nodes]).sum(axis=1)
        with np.errstate(invalid="ignore"):
            unsure[m] = ~(np.abs(lower - value[m]) <= AGREE * sense_tie[m] / TIE_ROUNDOFF)
    t_star = (G[every, c0] + x * step).tolist()
    grid_best = G[every, b].tolist()
    unsure, step = unsure.tolist(), step.tolist()
    value, best_f, best_t = value.tolist(), best_f.tolist(), best_t.tolist()
    best_pos, c0, better, end, at_lo, at_hi = (a.tolist() for a in (best_pos, c0, better, end, at_lo, at_hi))
    for m in held.nonzero()[0].tolist():
        j = jobs[m]
        if better[m]:
            j.best_f, j.where, j.best_t = value[m], "interior", t_star[m]
            j.best_row = _Row(tables[m], P[m, c0[m]:c0[m] + STENCIL], W[m])
            j.best_row["t_s"] = j.best_t
            j.unsure = (grid_best[m], step[m]) if unsure[m] else None
            continue
        j.unsure = None
        j.best_f, j.best_t = best_f[m], best_t[m]
        j.best_row = _Row(tables[m], best_pos[m], None)
        if end[m]:
            iv = ivs[m]
            j.where = (f"{iv.lo_kind} (limit from after)" if at_lo[m] else f"{iv.hi_kind} (limit from before)"
                       if at_hi[m] else "output row")
            j.limit = "after" if at_lo[m] else "before" if at_hi[m] else None

def intervals_of(t: np.ndarray, breaks: list[tuple[float, str]], t_start: float, t_end: float,
                 start_kind: str = "start", end_kind: str = "end") -> list[Interval]:
    """The smooth intervals between events within [t_start, t_end]: breaks (time, kind) sorted; rows assigned by
    time (a row exactly at an event belongs to the interval before it)."""
    bounds = [(t_start, start_kind)] + [(b, k) for b, k in breaks if t_start < b < t_end] + [(t_end, end_kind)]
    merged: list[tuple[float, str]] = []
    for b, k in bounds:
        if merged and b == merged[-1][0]:
            if k not in merged[-1][1].split(" + "):
                merged[-1] = (b, merged[-1][1] + " + " + k)
            continue
        merged.append((b, k))
    if len(merged) < 2:
        return []
    ends = np.array([b for b, _ in merged], dtype=float)
    first = t.searchsorted(ends[:-1], side="right").tolist()
    first[0] = int(t.searchsorted(merged[0][0], side="right" if merged[0][0] > t_start else "left"))
    last = t.searchsorted(ends[1:], side="right").tolist()
    return [Interval(lo, hi, lk, hk, np.arange(a, b))
            for (lo, lk), (hi, hk), a, b in zip(merged[:-1], merged[1:], first, last)]


def apart(kinks: list[tuple[float, str]], known: np.ndarray, near: float) -> list[tuple[float, str]]:
    """The kinks (time, kind) farther than `near` from every known instant: the distance to the nearest, found by
    bisection among the known ones in order (a long run has thousands of events and of kinks)."""
    if not len(known) or not kinks:
        return list(kinks)
    known = np.sort(known)
    at = np.array([x for x, _ in kinks], dtype=float)
    i = known.searchsorted(at)
    nearest = np.minimum(np.abs(known[np.maximum(i - 1, 0)] - at), np.abs(known[np.minimum(i, len(known) - 1)] - at))
    return [k for k, far in zip(kinks, (nearest > near).tolist()) if far]


def between(knots: np.ndarray, finest) -> np.ndarray:
    """Instants evenly between consecutive `knots` (in order) farther apart than `finest` (a time, or one per gap),
    as few as leave no two neighbours farther apart than that; the knots themselves not among them."""
    return _between_gaps(knots, finest)[0]


def _between_gaps(knots: np.ndarray, finest) -> tuple[np.ndarray, np.ndarray]:
    """`between`'s instants and the gap each lies in (its knot before)."""
    gaps = knots[1:] - knots[:-1]
    with np.errstate(invalid="ignore", divide="ignore"):
        extra = np.maximum(np.ceil(gaps / finest) - 1.0, 0.0)
    extra = np.where(np.isfinite(extra), extra, 0.0).astype(np.int64)
    if not extra.any():
        return np.zeros(0), np.zeros(0, dtype=np.int64)
    which = np.repeat(np.arange(len(gaps)), extra)
    j = np.arange(len(which)) - np.repeat(np.cumsum(extra) - extra, extra) + 1.0
    return knots[which] + gaps[which] * j / (extra[which] + 1.0), which


def read_tables(read: Reader, requests: list[tuple[Interval, int, np.ndarray]]):
    """Each request's columns read by `read` (its `read_many` where it has one, a request it leaves out read alone),
    in order; None for a request whose reading failed."""
    for request, table in zip(requests, read_all(read, requests)):
        if table is None:
            try:
                table = read(*request)
            except ReadingFailed:
                table = None
        yield table


#: an interval with fewer output rows than this is also read at ROWLESS_READINGS instants over it (its ends included)
SPARSE_ROWS = 3
ROWLESS_READINGS = 9


def sample_instants(t: np.ndarray, intervals: list[Interval], rowless: dict[int, np.ndarray], finest
                    ) -> tuple[np.ndarray, np.ndarray]:
    """(instants, their interval) of `with_rowless`'s samples (and the validity's, scenarios/peaks.py
    `_samples_between_rows`): each interval's instants (its ends, rows and `rowless` readings) spaced by `between`
    at `finest`, every interval's in one pass."""
    ids = [k for k, iv in enumerate(intervals) if iv.hi - iv.lo > 1e-12 * max(1.0, abs(iv.hi))]
    if not ids:
        return np.zeros(0), np.zeros(0, dtype=np.int64)
    rows = [np.asarray(intervals[k].rows, dtype=np.int64) for k in ids]
    extra = [rowless.get(k, np.zeros(0)) for k in ids]
    ks = np.array(ids, dtype=np.int64)
    knots = np.concatenate([np.array([intervals[k].lo for k in ids] + [intervals[k].hi for k in ids]),
                            t[np.concatenate(rows)], *extra])
    of = np.concatenate([ks, ks, np.repeat(ks, [len(r) for r in rows]), np.repeat(ks, [len(x) for x in extra])])
    order = np.lexsort((knots, of))
    knots, of = knots[order], of[order]
    spacing = np.broadcast_to(finest(knots) if callable(finest) else finest, len(knots) - 1).astype(float)
    spacing[of[1:] != of[:-1]] = np.inf             # (no gap from one interval's end to the next one's start)
    times, gap = _between_gaps(knots, spacing)
    return times, of[gap]


def _with_rows(t: np.ndarray, intervals: list[Interval], added: dict[int, np.ndarray], of: np.ndarray,
               first: int) -> list[Interval]:
    """Copies of the intervals that get rows of the table (t: its instants, the new rows' among them): `added`
    (interval -> the rows of its readings) and the samples (their intervals `of`, in order; their rows from `first`
    on), each interval's rows in time order (stably: its own first), the new ones' anchors (-1, -1)."""
    out = list(intervals)
    touched = sorted(set(added) | set(np.unique(of).tolist()))
    if not touched:
        return out
    own = [np.asarray(intervals[k].rows, dtype=np.int64) for k in touched]
    mine = [added.get(k, np.zeros(0, dtype=np.int64)) for k in touched]
    ks = np.array(touched, dtype=np.int64)
    rows = np.concatenate([*own, *mine, np.arange(first, first + len(of))])
    where = np.concatenate([np.repeat(ks, [len(x) for x in own]), np.repeat(ks, [len(x) for x in mine]), of])
    times = t[rows]
    anchors = np.full((len(rows), 2), -1, dtype=int)
    n_own = sum(len(x) for x in own)
    if n_own:
        anchors[:n_own] = np.concatenate(
            [np.asarray(intervals[k].anchors, dtype=int).reshape(len(x), -1) if len(intervals[k].anchors) else
             np.full((len(x), 2), -1) for k, x in zip(touched, own)])
    order = np.lexsort((times, where))
    rows, where, anchors = rows[order], where[order], anchors[order]
    cuts = where.searchsorted(ks[1:]).tolist()
    for k, r, x in zip(touched, np.split(rows, cuts), np.split(anchors, cuts)):
        iv = intervals[k]
        out[k] = Interval(iv.lo, iv.hi, iv.lo_kind, iv.hi_kind, r, x)
    return out


def with_rowless(t: np.ndarray, values: dict[str, np.ndarray], intervals: list[Interval], read: Reader,
                 finest: float | Callable[[np.ndarray], np.ndarray] | None = None, sampler=None
                 ) -> tuple[np.ndarray, dict[str, np.ndarray], list[Interval]]:
    """(t, values, intervals) for `locate` where some smooth intervals hold fewer than SPARSE_ROWS output rows (a
    stretch between events shorter than a few output steps, e.g. a contact episode): each such interval read at
    ROWLESS_READINGS instants evenly over [lo, hi], its ends the one-sided limits at its events, and the readings
    appended to the table as rows of it (their anchors (-1, -1): a reader starts from the latest state the run holds
    before them), so that its extrema are candidates ranked by the rows' parabola estimates as any interval's (a
    lone row's estimate is its value, which says nothing of the interval's peak). The given intervals are not
    changed (copies get the rows); an interval whose reading fails keeps its own. Without such intervals, the
    arguments themselves.

    finest (s): every interval is also sampled between its instants (its ends and rows) farther apart than this
    (a time, or a function of the instants giving one per gap), evenly, so that no two are: the candidates then do
    not depend on the output step (a peak narrower than the rows' step is among them at any step; docs/theory.md
    §K5). The samples are read with the interval's other readings by `read` (a closed form: no integration), or
    by `sampler` where given (`read_at(instants, [(interval, a, b)])`: every column at all the instants, those
    a:b in that interval; `TrajectoryReader.sampler`: a dense output's readings, or a DAE run's states
    interpolated between its rows, whose values rank the candidates only: every located value is still read by
    `read`).
    """
    # (an interval within round-off of an instant has nothing between its ends' one-sided limits to read)
    t = np.asarray(t, dtype=float)
    rowless = {k: np.linspace(iv.lo, iv.hi, ROWLESS_READINGS) for k, iv in enumerate(intervals)
               if len(iv.rows) < SPARSE_ROWS and iv.hi - iv.lo > 1e-12 * max(1.0, abs(iv.hi))}
    at, of = (sample_instants(t, intervals, rowless, finest) if finest is not None else
              (np.zeros(0), np.zeros(0, int)))
    if sampler is None:                    # the samples read with the interval's rowless readings
        cuts = of.searchsorted(np.arange(len(intervals) + 1))      # each interval's samples: at[cuts[k]:cuts[k + 1]]
        asked = {k: np.sort(np.r_[rowless.get(k, ()), at[cuts[k]:cuts[k + 1]]])
                 for k in sorted(set(rowless) | set(of.tolist()))}
        at, of = np.zeros(0), np.zeros(0, dtype=np.int64)
    else:
        asked = rowless
    if not asked and not len(at):
        return t, values, intervals
    requests = [(intervals[k], 0, times) for k, times in asked.items()]
    tables = dict(zip(asked, read_tables(read, requests)))
    if len(at):
        cuts = of.searchsorted(np.arange(len(intervals) + 1))      # each interval's samples: at[cuts[k]:cuts[k + 1]]
        sampled = sampler.read_at(at, [(intervals[k], cuts[k], cuts[k + 1]) for k in np.unique(of).tolist()])
    t_new, v_new, n = [], {c: [] for c in values}, len(t)
    for k, table in tables.items():
        if table is None:
            continue
        times = asked[k]
        t_new.append(times)
        for c in values:
            got = table.get(c)
            v_new[c].append(np.full(len(times), np.nan) if got is None else np.asarray(got, dtype=float))
    added = {}                          # each interval's readings' rows
    for k, table in tables.items():
        if table is not None:
            added[k] = np.arange(n, n + len(asked[k]))
            n += len(asked[k])
    if len(at):
        t_new.append(at)
        for c in values:
            got = sampled.get(c)
            v_new[c].append(np.full(len(at), np.nan) if got is None else np.asarray(got, dtype=float))
    if not t_new:
        return t, values, intervals
    t_all = np.concatenate([t] + t_new)
    return (t_all, {c: np.concatenate([np.asarray(f, dtype=float)] + v_new[c]) for c, f in values.items()},
            _with_rows(t_all, intervals, added, of, n))


#: one-sided limits read per column and sense at most (`end_limits`): the best guesses (the limits themselves where
#: the reader holds the state there: `stored_limits`)
LIMITS = 8
#: at most this many ends read by `end_limits`' further passes and its first together (its resources bounded)
FURTHER_LIMITS = 256


def _end_guesses(e: Extremum | None, sense: float, t: np.ndarray, f: np.ndarray, intervals: list[Interval],
                 tie: float, limit: int | None = LIMITS) -> list[tuple[int, str, float]]:
    """(interval, side, instant) of the intervals' ends whose one-sided limit may beat `e` (`end_limits`), the
    `limit` best guesses first (the earliest of equal ones; None: all)."""
    return end_guesses(t, {None: f}, intervals, [(None, sense, None if e is None else e.value)], {None: tie},
                       limit=limit)[0]


def every_end(intervals: list[Interval]) -> list[tuple[int, str, float]]:
    """(interval, side, instant) of every end whose one-sided limit `end_limits` may read: both ends of each
    interval with two rows or more (`_end_guesses` extrapolates from them), in order."""
    return [(k, side, te) for k, iv in enumerate(intervals) if len(iv.rows) >= 2
            for side, te in (("after", iv.lo), ("before", iv.hi))]


@dataclass
class EndLines:
    """Each column's linear extrapolation to every interval end from its rows there (`end_guesses`): the ends
    (`every_end`), their instants te, and per (column, end) the row nearest the end f0 and the next f1, the
    extrapolated value `line`, its error margin `curve` and whether it can be made (`ok`); over several windows'
    intervals, each end's window (`window`; its interval counted in its window's), else None."""

    ends: list
    te: np.ndarray
    of: dict
    f0: np.ndarray
    f1: np.ndarray
    line: np.ndarray
    curve: np.ndarray
    ok: np.ndarray
    window: np.ndarray | None = None
    #: per (column, end), whether `line` is the limit the reader holds (`stored_limits`), not an extrapolation
    exact: np.ndarray | None = None


def end_lines(t: np.ndarray, values: dict[str, np.ndarray], intervals: list[Interval],
              windows: list[int] | None = None) -> EndLines | None:
    """`EndLines` of every column of `values` at the intervals' ends; None without ends. windows: the intervals of
    each of several windows, consecutive (their counts), whose ends are each window's (`end_guesses` picks an ask's
    among its window's). The limits a reader holds replace the extrapolation where `stored_limits` is applied."""
    ends = every_end(intervals)
    if not ends:
        return None
    # each end's three nearest rows, inward; two rows: the second repeated (the step's own curve)
    near = np.array([(r[0], r[1], r[2] if len(r) > 2 else r[1]) if side == "after" else
                     (r[-1], r[-2], r[-3] if len(r) > 2 else r[-2]) for r, side in
                     ((intervals[k].rows, side) for k, side, _ in ends)], dtype=int)
    te = np.array([x for _, _, x in ends], dtype=float)
    names = list(values)
    F = np.array([np.asarray(values[c], dtype=float)[near] for c in names]).reshape(len(names), len(ends), 3)
    f0, f1, f2 = F[:, :, 0], F[:, :, 1], F[:, :, 2]
    t0, t1 = t[near[:, 0]], t[near[:, 1]]
    with np.errstate(invalid="ignore", divide="ignore"):
        step = f0 - f1
        line = f0 + step * (t0 - te) / (t1 - t0)
        # the extrapolation's error over (at most) one step: its second difference, else the step itself
        curve = np.where(near[:, 2] != near[:, 1], np.abs(step - (f1 - f2)), np.abs(step))
        curve = np.where(np.isfinite(curve), curve, np.abs(step))
    ok = np.isfinite(step) & (t1 != t0)
    window = None
    if windows is not None and len(windows) > 1:        # each end's window, its interval counted there
        first = np.array([0, *windows[:-1]]).cumsum()
        k = np.array([k for k, _, _ in ends])
        window = first.searchsorted(k, side="right") - 1
        ends = [(x, side, te) for x, (_, side, te) in zip((k - first[window]).tolist(), ends)]
    return EndLines(ends, te, {c: n for n, c in enumerate(names)}, f0, f1, line, curve, ok, window)


def stored_limits(lines: EndLines | None, intervals: list[Interval], reader) -> None:
    """`end_lines`' guesses (made over `intervals`), made exact in place where the reader holds the state at an end
    (its `limits`: a segment's start after an event, its end before one, a dense output's interpolant, read there
    in one pass): each column's one-sided limit replaces the extrapolation, with no margin. A column whose value or
    derivative jumps at an event, or grows like a root of the distance toward it (a flash temperature at a slip
    reversal), or changes within a step of it (the flash rise as a contact begins), is extrapolated from its rows
    with an error beyond any margin the rows can give, and its limits ranked so would be read in an order that need
    not hold the best (docs/theory.md §K5). A limit is taken where it continues the rows' change toward the end
    (from the next row to the nearest, per column and end: `EndLines.f1`, `f0`), or equals the nearest row: a
    column unbounded toward the event (a force growing like 1/distance) has at the event itself a value of
    round-off, of either sign; one that continues its rows is checked for growth next to the extremum as any other
    (`scenarios/singular.py` `singular_approaches`), and the others are ranked by the extrapolation, as where the run
    holds no state."""
    limits = getattr(reader, "limits", None)
    if lines is None or limits is None:
        return
    got = limits([(intervals[k], side) for k, side, _ in every_end(intervals)], list(lines.of))
    with np.errstate(invalid="ignore"):
        have = np.isfinite(got) & ((got - lines.f0) * (lines.f0 - lines.f1) >= 0.0)
    lines.line[have] = got[have]
    lines.curve[have] = 0.0
    lines.ok |= have
    lines.exact = have


def end_guesses(t: np.ndarray, values: dict[str, np.ndarray], intervals: list[Interval],
                asks: list[tuple[str, float, float | None]], ties: dict[str, float], limit: int | None = LIMITS,
                lines: EndLines | None = None, windows: list[int] | None = None
                ) -> list[list[tuple[int, str, float]]]:
    """`_end_guesses` of each (column, sense, the extremum's value or None) of `asks` over the same intervals, in
    one array pass: the ends and each column's extrapolation to them (`end_lines`, or `lines` where made already)
    made once for both senses. limit: the best guesses kept per ask (None: every end that may beat the value).
    windows: each ask's window where `lines` are several windows' (its guesses among that window's ends)."""
    if lines is None and asks:
        lines = end_lines(t, {c: values[c] for c in dict.fromkeys(c for c, _, _ in asks)}, intervals)
    if lines is None or not asks:
        return [[] for _ in asks]
    ends, te = lines.ends, lines.te
    m = np.array([lines.of[c] for c, _, _ in asks])
    sense = np.array([s for _, s, _ in asks], dtype=float)[:, None]
    floor = np.array([-np.inf if v is None else s * v + ties[c] for c, s, v in asks], dtype=float)[:, None]
    with np.errstate(invalid="ignore"):
        guess = sense * lines.line[m]
        able = lines.ok[m] & np.isfinite(guess) & (guess + lines.curve[m] > floor)
    if lines.window is not None:
        able &= lines.window == np.array(windows)[:, None]
    # each ask's able ends by guess (largest first), then instant, then position: the best `limit` of them
    a, i = able.nonzero()
    order = np.lexsort((te[i], -guess[a, i], a))
    a, i = a[order], i[order]
    if limit is not None:
        keep = np.arange(len(a)) - a.searchsorted(a) < limit
        a, i = a[keep], i[keep]
    out: list[list[tuple[int, str, float]]] = [[] for _ in asks]
    tes = te.tolist()
    for n, x in zip(a.tolist(), i.tolist()):
        out[n].append((ends[x][0], ends[x][1], tes[x]))
    return out


def end_limit_requests(intervals: list[Interval], guesses: list[tuple[int, str, float]]) -> list[tuple]:
    """The readings `end_limits` may take (interval, position, [instant]) for its `guesses` (`end_guesses`), to be
    read ahead in one pass."""
    return [(intervals[k], 0 if side == "after" else len(intervals[k].rows) - 1, np.array([te]))
            for k, side, te in guesses]


def end_limits(e: Extremum | None, column: str, sense: float, t: np.ndarray, f: np.ndarray, own: list[Interval],
               intervals: list[Interval], reader, tie: float,
               guesses: list[tuple[int, str, float]] | None = None, lines: EndLines | None = None,
               window: int | None = None) -> Extremum | None:
    """The extremum `e` against the one-sided limits at the intervals' ends that may beat it (docs/theory.md §K5):
    `locate` ranks an interval's end by its row next to it, but a column whose value or derivative
    jumps at an event (the contact temperature at a slip reversal: the flash rise follows |slip speed|, the heat
    share jumps; a force at an entry) has its limit up to one row step beyond that row, and the side whose row is
    the better one need not hold the better limit, nor need that row be the column's best. Each end whose limit
    (where the reader holds the state there: `stored_limits`) or linear extrapolation from its two rows, plus their
    second difference for margin (the extrapolation's error over a step), beats `e` is read there (the LIMITS best
    guesses of them); the best limit that beats `e` by more than the tie is returned (`e` where none does). An end
    read that `own` lacks is appended to it (the entry's later checks index the intervals searched). `guesses`:
    those ends where already found (`end_guesses`, on lines with the limits the reader holds: `stored_limits`);
    `lines`: those lines (`end_lines` over `intervals`, or over several windows' with `window` this one's), which
    the further passes rank the ends by (else made here: over an hour's 9 000 intervals, 30 ms a column)."""
    best = e
    if guesses is None:
        guesses = _end_guesses(e, sense, t, f, intervals, tie)
    tried: set[tuple[int, str]] = set()
    batch = list(guesses)
    scale = float(np.nanmax(np.abs(f), initial=0.0))
    while batch:
        values = []
        for k, side, te in batch:
            tried.add((k, side))
            iv = intervals[k]
            if best is not None and te == best.t and best.limit == side:
                continue
            try:
                table = reader(iv, 0 if side == "after" else len(iv.rows) - 1, np.array([te]))
            except ReadingFailed:
                continue
            if column not in table:
                continue
            value = float(np.asarray(table[column], float)[0])
            values.append(value)
            if not np.isfinite(value) or (best is not None and sense * (value - best.value) <= tie):
                continue
            at = next((i for i, x in enumerate(own) if x is iv), None)
            if at is None:
                own.append(iv)
                at = len(own) - 1
            kind = iv.lo_kind if side == "after" else iv.hi_kind
            row = _Row(table, 0, None)
            best = Extremum(value, te, f"{kind} (limit from {side})", row, side, side, at, False)
        gaps = np.abs(np.array(values, dtype=float) - best.value) if best is not None else np.zeros(0)
        if best is None or len(tried) >= FURTHER_LIMITS or not np.any(gaps > REPEAT * scale):
            break
        # a pass that read a limit other than a repeat of the best (more than REPEAT of the column's scale from it,
        # as `refine_further`: a periodic run's repeated peaks stop here): branch and bound, the ends whose guess,
        # with its margin, still beats the best found, the next best twice as many as the pass before (a
        # temperature rising with the bulk over hundreds of exits: the guesses from rows a few degrees apart rank
        # the limits after earlier entries above the last exit's, the largest)
        if lines is None:
            lines = end_lines(t, {column: f}, intervals)
        ranked = end_guesses(t, {column: f}, intervals, [(column, sense, best.value)], {column: tie}, limit=None,
                             lines=lines, windows=None if window is None else [window])[0]
        rest = [g for g in ranked if (g[0], g[1]) not in tried]
        batch = rest[:min(2 * len(batch), FURTHER_LIMITS - len(tried))]
        if batch:
            read_all(reader, end_limit_requests(intervals, batch))
    return best
