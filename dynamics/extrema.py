"""Extrema of a run's columns in continuous time, not at its output rows (docs/theory.md §K5).

A column F(t) of the result table is smooth between events. Its maximum (and minimum) is sought in three steps:

1. candidates from the output rows: in every smooth interval (between events) each row that is a local maximum
   of the rows, its bracket the rows on either side (an interval's first and last row reach out to the
   interval's ends, so that a maximum at an event is found as the one-sided limit there); the candidates are
   ranked by the vertex of the parabola through the row and its neighbours and the best few refined;
2. a `reader` evaluates every column of the table at any instants of one smooth interval: for a DAE run by
   re-integrating the mode from an output row next to the candidate, forward and backward, at a tenth of the
   run's tolerances (`TrajectoryReader`); for a closed-form run by the closed form itself;
3. in the bracket, one pass of a grid of readings; the polynomial through the seven readings around the best one
   gives t* and the value (and every column there). At an interval's end the extremum is the one-sided limit
   (the reading at the event instant from that side).

The value, time and drive angle do not depend on the output step beyond the integrator's tolerance: at an
interior extremum a time error dt changes the value by F''dt^2/2 only, and the reading itself carries the
re-integration's error from the row's state (the run's own error at that row).
"""
from __future__ import annotations

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
#: brackets whose rows lie within this many rows of each other are read together
CLUSTER_ROWS = 8


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


@dataclass
class Extremum:
    """The located extremum of one column: its value, instant, where it lies (interior, or the one-sided limit at
    an interval's end) and every column of the table at that instant (`row`)."""

    value: float
    t: float
    where: str
    row: dict
    sampled: float          # the best output row's value (for comparison)
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


def _estimates(t: np.ndarray, f: np.ndarray) -> np.ndarray:
    """The peak value of the parabola through each row and its neighbours (the row's value at the ends, and where
    the parabola opens upwards); f may hold several series (along its last axis)."""
    est = f.copy()
    if f.shape[-1] < 3:
        return est
    f0, f1, f2 = f[..., :-2], f[..., 1:-1], f[..., 2:]
    h0, h1 = t[1:-1] - t[:-2], t[2:] - t[1:-1]
    with np.errstate(invalid="ignore", divide="ignore", over="ignore"):
        d2 = 2.0 * ((f2 - f1) / h1 - (f1 - f0) / h0) / (h0 + h1)
        d1 = ((f2 - f1) / h1 * h0 + (f1 - f0) / h0 * h1) / (h0 + h1)
        gain = np.where(d2 < 0, -0.5 * d1 * d1 / d2, 0.0)
    est[..., 1:-1] = f1 + np.where(np.isfinite(gain), gain, 0.0)
    return est


def tie_of(f: np.ndarray) -> float:
    """The round-off tie of a column: TIE_ROUNDOFF of its largest finite magnitude (values closer are equal)."""
    return float(_ties(np.asarray(f, dtype=float)[None, :])[0])


def _ties(F: np.ndarray) -> np.ndarray:
    """`tie_of` of each row of F."""
    if not F.shape[-1]:
        return np.zeros(len(F))
    with np.errstate(invalid="ignore"):
        return TIE_ROUNDOFF * np.where(np.isfinite(F), np.abs(F), 0.0).max(axis=-1)


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
    rows = np.concatenate([iv.rows for iv in intervals]).astype(int)
    n_of = np.repeat(sizes, sizes)
    pos = np.arange(len(rows)) - np.repeat(np.cumsum(sizes) - sizes, sizes)
    return rows, np.repeat(np.arange(len(intervals)), sizes), n_of, pos, pos == 0, pos == n_of - 1


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
    return _candidates(t, f, np.array([sense]), _ties(f), intervals, limit, layout)[0]


def _candidates(t: np.ndarray, F: np.ndarray, senses: np.ndarray, ties: np.ndarray, intervals: list[Interval],
                limit: int = CANDIDATES, layout: tuple | None = None) -> list[list[tuple]]:
    """`candidates` of every series F[m] (over the table's rows) in the sense senses[m], its tie ties[m]: the
    comparisons of all series at once, elementwise as for one."""
    if layout is None:
        layout = _layout(intervals)
    if layout is None:
        return [[] for _ in range(len(F))]
    rows, k_of, n_of, pos, first, last = layout
    ti, fi = t[rows], senses[:, None] * F[:, rows]
    ok = np.isfinite(fi)
    fi = np.where(ok, fi, -np.inf)
    edge = np.full((len(fi), 1), -np.inf)
    left = np.where(first, -np.inf, np.concatenate([edge, fi[:, :-1]], axis=1))
    right = np.where(last, -np.inf, np.concatenate([fi[:, 1:], edge], axis=1))
    tie = ties[:, None]
    with np.errstate(invalid="ignore"):
        flat = (((np.abs(fi - left) <= tie) | first) & ((np.abs(fi - right) <= tie) | last) & (n_of > 1) & ok)
    peak = ((fi >= left) & (fi >= right) & ok) | flat
    est = _estimates(ti, fi)
    est = np.where(first | last, fi, est)
    smooth = peak & ~flat
    lower = np.where(peak, fi, -np.inf).max(axis=1)
    level = np.where(flat, fi, -np.inf).max(axis=1)
    with np.errstate(invalid="ignore"):
        kept = smooth & (2 * est - fi >= (lower - ties)[:, None])
    out: list[list[tuple]] = []
    for m in range(len(fi)):
        got: list[tuple] = []
        out.append(got)
        if not peak[m].any():
            continue
        if flat[m].any() and level[m] >= lower[m] - ties[m]:
            # constant stretches are exact: only the best level's earliest can hold the extremum (no refining); it
            # lies at its first instant (the interval's start where it holds the interval's first row)
            i = int(np.argmax(flat[m] & (fi[m] >= level[m] - ties[m])))
            k = int(k_of[i])
            at = float(intervals[k].lo) if first[i] else float(ti[i])
            got.append((float(fi[m, i]), k, int(pos[i]), at, at, True))
        keep = np.flatnonzero(kept[m])
        if len(keep):
            e = est[m, keep]
            best = float(e.max())
            rank = np.where(e >= best - ties[m], best, e)
            keep = keep[np.lexsort((ti[keep], -rank))][:limit]      # by estimate, ties to the earliest
            for i in keep.tolist():
                iv = intervals[int(k_of[i])]
                lo = float(iv.lo) if first[i] else float(ti[i - 1])
                hi = float(iv.hi) if last[i] else float(ti[i + 1])
                got.append((float(est[m, i]), int(k_of[i]), int(pos[i]), lo, hi, False))
    return out


def locate(t: np.ndarray, values: dict[str, np.ndarray], intervals: list[Interval], read: Reader,
           limit: int = CANDIDATES) -> dict[str, dict[str, Extremum]]:
    """{column: {'max': Extremum, 'min': Extremum}} of the table's `values` (arrays over its rows at times t),
    refined by `read(interval, position, times)` (every column at those instants of the interval, as a dict of
    arrays, read from the interval's row at `position`). Brackets within a few rows of each other are read
    together, from the row before the first of them (one forward integration per reading)."""
    jobs: list[_Job] = []
    ties: dict[str, float] = {}
    starts: dict[int, list[_Job]] = {}          # constant stretches from an interval's start (read there)
    layout = _layout(intervals)
    names = list(values)
    F = np.array([np.asarray(values[c], dtype=float) for c in names]).reshape(len(names), len(t))
    col_ties = _ties(F)
    found = _candidates(t, np.repeat(F, 2, axis=0), np.tile([1.0, -1.0], len(names)), np.repeat(col_ties, 2),
                        intervals, limit, layout)
    for n, col in enumerate(names):
        f = F[n]
        ties[col] = tie = float(col_ties[n])
        for sense, got in ((1.0, found[2 * n]), (-1.0, found[2 * n + 1])):
            for est, k, i, lo, hi, flat in got:
                j = _Job(col, sense, k, i, lo, hi, sense * float(f[intervals[k].rows[i]]), tie=tie)
                j.t_row = float(t[intervals[k].rows[i]])
                j.edge = "before" if hi == intervals[k].hi else "after" if lo == intervals[k].lo else None
                if flat:             # the row's value is the extremum's, at the stretch's first instant
                    r = intervals[k].rows[i]
                    j.best_f, j.best_t, j.done, j.edge, j.constant = j.sampled, lo, True, None, True
                    j.best_row = {c: v[r] for c, v in values.items()}
                    if lo != j.t_row:
                        starts.setdefault(k, []).append(j)
                    elif lo == intervals[k].lo:
                        j.where = f"{intervals[k].lo_kind} (constant from here)"
                    else:
                        j.where = "output row (constant from here)"
                jobs.append(j)
    for k, group in starts.items():
        _constant_from_start(intervals[k], k, group, read)
    jobs.sort(key=lambda j: (j.interval, j.anchor))
    clusters: list[list[_Job]] = []
    for j in jobs:
        if j.done:
            continue
        if clusters and clusters[-1][0].interval == j.interval and j.anchor - clusters[-1][0].anchor <= CLUSTER_ROWS:
            clusters[-1].append(j)
        else:
            clusters.append([j])
    plans = [_grids(group) for group in clusters]
    requests = [(intervals[g[0].interval], max(g[0].anchor - 1, 0), p[1]) for g, p in zip(clusters, plans)]
    many = getattr(read, "read_many", None)
    tables = many(requests) if many is not None else [None] * len(requests)
    for group, (grids, _), request, table in zip(clusters, plans, requests, tables):
        try:
            _refine(request[0], group, grids, table if table is not None else read(*request))
        except ReadingFailed:          # the rows' value stands, and says so
            for j in group:
                r = intervals[j.interval].rows[j.anchor]
                j.best_f, j.best_t, j.limit = j.sampled, float(t[r]), None
                j.best_row = {c: v[r] for c, v in values.items()}
                j.where = "output row (the re-integration between rows failed)"
    out: dict[str, dict[str, Extremum]] = {}
    for j in jobs:
        slot = out.setdefault(j.column, {})
        name = "max" if j.sense > 0 else "min"
        if j.best_row is None:
            continue
        e = Extremum(j.sense * j.best_f, j.best_t, j.where, j.best_row, j.sense * j.sampled, j.limit, j.edge,
                     j.interval, j.constant)
        if _beats(e, slot.get(name), j.sense, ties[j.column]):
            slot[name] = e
    return out


def _constant_from_start(iv: Interval, k: int, group: list[_Job], read: Reader) -> None:
    """Constant stretches that hold their interval's first row lie at the interval's start: every column is read
    there (the one-sided limit after an event; the window's start for the first interval). The value stays the
    rows' (exact); if the reading fails, the stretch's first row stands."""
    try:
        row = _at(read(iv, 0, np.array([iv.lo])), 0)
    except ReadingFailed:
        for j in group:
            j.best_t = j.t_row
        return
    for j in group:
        j.best_row = dict(row)
        j.best_row[j.column] = j.sense * j.best_f
        j.where = (f"{iv.lo_kind} (constant from here, limit from after)" if k > 0
                   else f"{iv.lo_kind} (constant from here)")
        j.limit = "after" if k > 0 else None


def _at(table: dict, pos, w: np.ndarray | None = None) -> dict:
    """Every column at one instant: the reading at pos, or the polynomial through the readings at pos (weights
    w; a column that is not float: the reading of the largest weight)."""
    out = {}
    for c, v in table.items():
        v = np.asarray(v)
        if w is None:
            out[c] = v[pos]
        elif v.dtype.kind == "f":
            out[c] = float(w @ v[pos])
        else:
            out[c] = v[pos[int(np.argmax(w))]]
    return out


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


def _stencil_weights(x: float) -> np.ndarray:
    """Weights of the polynomial through the STENCIL nodes 0..STENCIL-1 at x (barycentric form)."""
    d = x - np.arange(STENCIL, dtype=float)
    hit = np.flatnonzero(d == 0)
    if len(hit):
        w = np.zeros(STENCIL)
        w[hit[0]] = 1.0
        return w
    w = _BARY / d
    return w / w.sum()


def _poly_max(f: np.ndarray, b: int) -> tuple[float, np.ndarray]:
    """(x*, weights): the maximum of the polynomial through the STENCIL readings f within a grid step of the best
    one b (x in grid steps from the stencil's first node): sampled, then Newton's method on its derivative; the
    weights give any column at x*."""
    c = _INVERSE[b] @ f                       # coefficients in x - b
    d1 = c[1:] * np.arange(1, STENCIL)
    d2 = d1[1:] * np.arange(1, STENCIL - 1)
    lo, hi = max(-1.0, -float(b)), min(1.0, float(STENCIL - 1 - b))
    xs = np.clip(_SEARCH, lo, hi)
    x = float(xs[np.argmax(np.polynomial.polynomial.polyval(xs, c))])
    for _ in range(4):
        g, h = np.polynomial.polynomial.polyval(x, d1), np.polynomial.polynomial.polyval(x, d2)
        if not h < 0:
            break
        x = min(max(x - g / h, lo), hi)
    x = b + x
    return x, _stencil_weights(x)


def _grids(group: list[_Job]) -> tuple[list[np.ndarray], np.ndarray]:
    """Each job's readings over its bracket (FIRST_GRID), and the instants the group reads: those and the jobs'
    own rows (so that the result is never below the row)."""
    grids = [np.linspace(j.lo, j.hi, FIRST_GRID) if j.hi > j.lo else np.array([j.lo]) for j in group]
    return grids, np.unique(np.concatenate(grids + [np.array([j.t_row for j in group])]))


def _refine(iv: Interval, group: list[_Job], grids: list[np.ndarray], table: dict) -> None:
    """Each job's maximum in its bracket from one pass of readings (`_grids`, read from one anchor row): the
    polynomial through the STENCIL readings around the best one gives t* and the value, and every column there
    (its error is of order |F^(STENCIL)| d^STENCIL for the grid's step d, far below the tolerance)."""
    tt = np.asarray(table["t_s"], dtype=float)
    for j, g in zip(group, grids):
        got = _refine_one(iv, j, g, tt, table)
        if got is not None:                     # every column at the best instant, read out once
            j.best_row = _at(table, *got)
            if got[1] is not None:
                j.best_row["t_s"] = j.best_t


def _refine_one(iv: Interval, j: _Job, g: np.ndarray, tt: np.ndarray, table: dict) -> tuple | None:
    """`_refine` of one job: sets its value, instant and where; returns (positions, weights or None) of the
    readings that give every column at its instant (`_at`), None where no reading is finite."""
    pos = np.clip(np.searchsorted(tt, g), 0, len(tt) - 1)
    column = np.asarray(table[j.column], dtype=float)
    f = j.sense * column[pos]
    if not np.isfinite(f).any():
        return None
    f = np.where(np.isfinite(f), f, -np.inf)
    b = int(np.argmax(f >= f.max() - j.tie))          # the earliest of readings tied to round-off
    j.best_f, j.best_t, best = float(f[b]), float(g[b]), (pos[b], None)
    r = int(np.clip(np.searchsorted(tt, j.t_row), 0, len(tt) - 1))
    if j.sense * column[r] > j.best_f + j.tie:        # the row itself (between grid readings)
        j.best_f, j.best_t, best = float(j.sense * column[r]), float(tt[r]), (r, None)
    at_lo, at_hi = b == 0 and g[0] == iv.lo, b == len(g) - 1 and g[-1] == iv.hi
    if at_lo or at_hi or len(g) < STENCIL:           # the one-sided limit at the interval's end
        j.where = (f"{iv.lo_kind} (limit from after)" if at_lo else f"{iv.hi_kind} (limit from before)"
                   if at_hi else "output row")
        j.limit = "after" if at_lo else "before" if at_hi else None
        return best
    c0 = min(max(b - STENCIL // 2, 0), len(g) - STENCIL)
    part = f[c0:c0 + STENCIL]
    if not np.isfinite(part).all():
        return best
    x, w = _poly_max(part, b - c0)
    value = float(w @ part)
    if value >= j.best_f:
        j.best_f, j.best_t, j.where = value, float(g[c0] + x * (g[1] - g[0])), "interior"
        best = (pos[c0:c0 + STENCIL], w)
    return best


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
    out = []
    for (lo, lk), (hi, hk) in zip(merged[:-1], merged[1:]):
        first = np.searchsorted(t, lo, side="right" if lo > t_start else "left")
        last = np.searchsorted(t, hi, side="right")
        out.append(Interval(lo, hi, lk, hk, np.arange(first, last)))
    return out


class TrajectoryReader:
    """Every table column of a DAE run at any instants of a smooth interval: the mode re-integrated from the state
    at an output row (forward and backward) by IDA at `tighten` times the run's tolerances, its rows read out as
    the run's own (`tables.timeseries`). The anchors of an interval are (piece, row) of its table rows."""

    def __init__(self, traj, angle_coordinates: tuple[int, ...], settings, tighten: float = 1e-1):
        import dataclasses
        self.traj, self.angle_coordinates = traj, angle_coordinates
        rtol = max(settings.rtol * tighten, 1e-13)
        own = dataclasses.replace(settings, multiplier_atol=settings.lam_atol, events=False)
        #: the tighter tolerances first, the run's own where IDA cannot meet those
        self.tries = (dataclasses.replace(own, rtol=rtol, atol=settings.atol * rtol / settings.rtol), own)
        self.reintegrations = self.dense_readings = 0
        self._starts: dict = {}
        self._solvers: dict = {}
        self._compiled: list | None = None       # per try: the compiled IDA backend (a compiled run's readings)
        self._anchors = None
        self._keep: list = []

    def anchors(self, t_rows: np.ndarray) -> np.ndarray:
        """(piece index, row index) of each table time (the last piece that holds it, as the table keeps it), as
        rows of an (n, 2) array; (-1, -1) for a time no piece holds. Kept for the reader's life (one table)."""
        if self._anchors is not None and np.array_equal(self._anchors[0], t_rows):
            return self._anchors[1]
        pieces = self.traj.pieces
        all_t = np.concatenate([p.t for p in pieces])
        all_k = np.concatenate([np.full(len(p.t), k) for k, p in enumerate(pieces)])
        all_r = np.concatenate([np.arange(len(p.t)) for p in pieces])
        order = np.argsort(all_t, kind="stable")
        st = all_t[order]
        at = np.searchsorted(st, t_rows, side="right") - 1
        hit = (at >= 0) & (st[np.clip(at, 0, None)] == t_rows)
        ks, rs = all_k[order][np.clip(at, 0, None)], all_r[order][np.clip(at, 0, None)]
        out = np.where(hit[:, None], np.stack([ks, rs], axis=1), -1)
        self._anchors = (t_rows, out)
        return out

    def __call__(self, iv: Interval, position: int, times: np.ndarray) -> dict:
        table = self.read_many([(iv, position, times)])[0]
        if table is not None:
            return table
        from mechsim.dynamics.tables import piece_columns
        return piece_columns(self.traj.model, self._reading(iv, position, times), self.angle_coordinates,
                             residual=False)

    def _reading(self, iv: Interval, position: int, times: np.ndarray):
        """The re-integrated states at `times` (ordered) as a Piece of the row's mode; ReadingFailed if IDA fails."""
        from mechsim.dynamics.hybrid import Piece
        piece, mf, t0, y0, yp0 = self._anchor(iv, position)
        # every reading starts from the row's own state: a restart from an earlier reading's state (projected back
        # onto the constraints) was cheaper but added its own error, which a finite difference of the peak shows
        ts, ys, yps = [], [], []
        for part in (times[times < t0][::-1], times[times >= t0]):
            if not len(part):
                continue
            tt, yy, yyp = self._integrate(mf, piece.params, t0, y0, yp0, part)
            ts.append(tt)
            ys.append(yy)
            yps.append(yyp)
        t = np.concatenate(ts)
        order = np.argsort(t, kind="stable")
        return Piece(piece.mode, piece.params, t[order], np.concatenate(ys)[order], np.concatenate(yps)[order],
                     piece.offset)

    def read_many(self, requests: list[tuple[Interval, int, np.ndarray]]) -> list[dict | None]:
        """The columns of each (interval, position, times) from the run's own dense output where the integrator
        keeps one (the compiled diffrax run: the interpolant its output rows come from), else re-integrated, all
        read out together: one read-out per mode and parameters; None for a request the dense output does not hold
        (read by re-integration) or whose re-integration failed."""
        from mechsim.dynamics.hybrid import Piece
        from mechsim.dynamics.tables import piece_columns
        dense = getattr(self.traj, "dense", None)
        if dense is not None:
            got = dense.read_many([(np.asarray(times, float), iv.lo, iv.hi) for iv, _, times in requests])
        else:                  # re-integrated, each request on its own; read out together (None where IDA failed)
            got = []
            for request in requests:
                try:
                    p = self._reading(*request)
                except ReadingFailed:
                    got.append(None)
                    continue
                got.append((p.mode, p.params, p.offset, p.y, p.t, p.yp))
        groups: dict = {}
        for r, g in enumerate(got):
            if g is not None:
                key = (g[0], np.asarray(g[1], float).tobytes(), np.asarray(g[2], float).tobytes())
                groups.setdefault(key, []).append(r)
        out: list[dict | None] = [None] * len(requests)
        for rs in groups.values():
            mode, params, offset = got[rs[0]][:3]
            if dense is not None:
                t, yp = np.concatenate([np.asarray(requests[r][2], float) for r in rs]), None
            else:
                t, yp = np.concatenate([got[r][4] for r in rs]), np.vstack([got[r][5] for r in rs])
            table = piece_columns(self.traj.model, Piece(mode, params, t, np.vstack([got[r][3] for r in rs]), yp,
                                                         offset), self.angle_coordinates, residual=False)
            a = 0
            for r in rs:
                n = len(got[r][3])
                out[r] = {c: v[a:a + n] for c, v in table.items()}
                a += n
        self.dense_readings += len(groups) if dense is not None else 0
        return out

    def momentum(self, iv: Interval, position: int, t: float) -> tuple[np.ndarray, np.ndarray]:
        """(M(q) v, v) at instant t of the interval (its one-sided limit at an end), from the row at `position`:
        the generalized momentum, whose jump across an event is the impulse the event delivers."""
        piece, mf, t0, y0, yp0 = self._anchor(iv, position)
        _, y, _ = self._integrate(mf, piece.params, t0, y0, yp0, np.array([t]))
        q, v = y[0, mf.index["q"]], y[0, mf.index["v"]]
        M = np.atleast_2d(np.asarray(mf.mass(q, piece.params), dtype=float))
        return M @ v, v

    def _anchor(self, iv: Interval, position: int):
        """(piece, its mode's functions, t0, y0, y'0): the consistent state at the interval's row `position`, where
        every reading of it starts."""
        k, r = (int(x) for x in iv.anchors[position])
        piece = self.traj.pieces[k]
        t0 = float(piece.t[r])
        try:
            y0, yp0 = self._start(k, r)
        except (ValueError, np.linalg.LinAlgError) as exc:
            raise ReadingFailed(f"no consistent state at the row t = {t0:.9g} s: {exc}") from None
        return piece, self.traj.model.modes[piece.mode], t0, y0, yp0

    def _start(self, k: int, r: int):
        """The consistent (y, y') at row r of piece k (the compiled diffrax run keeps states only), kept."""
        from mechsim.dynamics.consistent import consistent_state
        got = self._starts.get((k, r))
        if got is None:
            piece = self.traj.pieces[k]
            mf = self.traj.model.modes[piece.mode]
            ix, y = mf.index, piece.y[r]
            y0, yp0, _ = consistent_state(mf, float(piece.t[r]), y[ix["q"]], y[ix["v"]], y[ix["work"]],
                                          y[ix["ext"]], piece.params)
            got = self._starts[(k, r)] = (y0, yp0)
        return got

    def _compiled_tries(self) -> bool:
        """Whether the readings run on the compiled IDA callbacks, as the run did (the same algorithm as
        scikit-sundae's binding, without a Python call per residual); builds one backend per try."""
        if self._compiled is None:
            from mechsim.dynamics.backends.ida_compiled import IdaCompiledBackend, runs_compiled
            self._compiled = ([IdaCompiledBackend(s) for s in self.tries]
                              if runs_compiled(self.tries[-1], self.traj.model) else [])
        return bool(self._compiled)

    def _integrate(self, mf, p, t0, y0, yp0, times):
        """(t, y, yp) at `times` (all on one side of t0, ordered away from it) from the consistent (y0, yp0)."""
        from sksundae.ida import IDA

        from mechsim.dynamics.backend import End, Request
        from mechsim.dynamics.backends.ida import atol_vector
        self.reintegrations += 1
        # instants within round-off of t0 are read at t0 (IDA cannot step that little; F' dt is below round-off)
        at_start = np.abs(times - t0) <= 1e-12 * max(1.0, abs(t0))
        out_t = times[~at_start]
        rows_t, rows_y, rows_yp = [], [], []
        if at_start.any():
            n0 = int(at_start.sum())
            rows_t.append(times[at_start])
            rows_y.append(np.repeat(y0[None, :], n0, axis=0))
            rows_yp.append(np.repeat(yp0[None, :], n0, axis=0))
        if len(out_t) and self._compiled_tries():
            for backend in self._compiled:
                seg = backend.integrate(Request(self.traj.model, "", mf, p, t0, y0, yp0, out_t, float(out_t[-1])))
                if seg.end is End.END and len(seg.t) == len(out_t):
                    break
            else:
                raise ReadingFailed(f"re-integration between rows failed: {seg.message}")
            rows_t.append(seg.t)
            rows_y.append(seg.y)
            rows_yp.append(seg.yp)
        elif len(out_t):
            tspan = np.concatenate([[t0], out_t])
            if len(tspan) == 2:
                tspan = np.array([t0, 0.5 * (t0 + out_t[0]), out_t[0]])
            for n, s in enumerate(self.tries):
                # one solver per mode, parameter values and try, re-initialised at each solve
                key = (id(mf), np.asarray(p, dtype=float).tobytes(), n)
                solver = self._solvers.get(key)
                if solver is None:
                    solver = self._solvers[key] = IDA(
                        mf.residual, userdata=p, rtol=s.rtol, atol=atol_vector(mf, s),
                        algebraic_idx=mf.algebraic or None, jacfn=mf.jacobian if s.jacobian == "exact" else None,
                        max_num_steps=s.max_steps, linsolver="dense")
                    self._keep.append(mf)          # the id stays this mode's while the reader lives
                sol = solver.solve(tspan, y0, yp0)
                if sol.success:
                    break
            else:
                raise ReadingFailed(f"re-integration between rows failed: {sol.message}")
            keep = np.isin(np.asarray(sol.t), out_t)
            rows_t.append(np.asarray(sol.t)[keep])
            rows_y.append(np.asarray(sol.y)[keep])
            rows_yp.append(np.asarray(sol.yp)[keep])
        return np.concatenate(rows_t), np.vstack(rows_y), np.vstack(rows_yp)
