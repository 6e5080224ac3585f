"""A DAE run's table columns at any instants between its output rows: the reader `dynamics/extrema.py` locates
extrema with (docs/theory.md §K5).

`TrajectoryReader` re-integrates the mode from the latest state the run holds before the instants (an output row,
or the state its segment started from) at a tenth of the run's tolerances, or reads a compiled diffrax run's dense
output; its `sampler` samples the columns between the rows (`_DenseSamples` on a dense output, `_RowInterpolation`
the run's states interpolated between rows elsewhere). The readings are read out as the run's own rows are
(`tables.piece_columns`), one read-out per mode.
"""
from __future__ import annotations

from collections.abc import Mapping
from dataclasses import replace

import numpy as np

from mechsim.dynamics.extrema import Interval, ReadingFailed

class _ReadOut(Mapping):
    """The columns of one mode's readings (`tables.piece_columns` of their pieces, stacked), read out when a column
    is first asked for: readings nobody reads (a one-sided limit its extremum does not need) cost no read-out. The
    same call on the same pieces as reading them out at once, so the same columns."""

    def __init__(self, model, pieces: list, angle_coordinates: tuple[int, ...]):
        self._args, self._columns, self._states = (model, pieces, angle_coordinates), None, {}

    def _table(self) -> dict:
        if self._columns is None:
            from mechsim.dynamics.tables import piece_columns
            self._columns = piece_columns(*self._args, residual=False)
            self._args = None
        return self._columns

    def __getitem__(self, c):
        columns = self._columns
        if columns is None:         # a state column (a position, speed or work) read without the read-out
            got = self._states.get(c)
            if got is None:
                from mechsim.dynamics.tables import state_column
                got = state_column(*self._args, c)
                if got is None:
                    return self._table()[c]
                self._states[c] = got
            return got
        return columns[c]

    def __iter__(self):
        return iter(self._table())

    def __len__(self):
        return len(self._table())

    def __contains__(self, c):
        return c in self._table()


class Gathered(Mapping):
    """Columns of several tables put in one order: (table, its rows taken or None for all, the positions they take)
    per table, each column gathered when first read (one indexing per table); NaN for the rows of a table without
    it. The one-sided limits of many ends read together (`TrajectoryReader.stored_columns`), one table per mode."""

    def __init__(self, groups: list[tuple[Mapping, np.ndarray | None, np.ndarray]]):
        self._groups = groups
        self._order = np.argsort(np.concatenate([np.asarray(at, dtype=np.int64) for _, _, at in groups]),
                                 kind="stable")
        self._names = list(dict.fromkeys(c for table, _, _ in groups for c in table))
        self._got: dict = {}

    @staticmethod
    def of(parts: list) -> "Gathered | None":
        """Readings' columns in their order, or None unless each is one row of a table read for many (`_Part`)."""
        if not parts or not all(isinstance(t, _Part) and t._b - t._a == 1 for t in parts):
            return None
        groups: dict = {}
        for j, part in enumerate(parts):
            group = groups.setdefault(id(part._table), (part._table, [], []))
            group[1].append(part._a)
            group[2].append(j)
        return Gathered([(table, np.array(rows, dtype=np.int64), np.array(js, dtype=np.int64))
                         for table, rows, js in groups.values()])

    def __getitem__(self, c):
        got = self._got.get(c)
        if got is None:
            if c not in self._names:
                raise KeyError(c)
            got = self._got[c] = np.concatenate(
                [(np.asarray(table[c]) if rows is None else np.asarray(table[c])[rows]) if c in table else
                 np.full(len(at), np.nan) for table, rows, at in self._groups])[self._order]
        return got

    def __iter__(self):
        return iter(self._names)

    def __len__(self):
        return len(self._names)


class _Part(Mapping):
    """Rows a:b of a table read for several requests at once (a mapping of column arrays), each column sliced
    when first read (a reading's user reads a few of its columns)."""

    def __init__(self, table: dict, a: int, b: int):
        self._table, self._a, self._b, self._got = table, a, b, {}

    def __getitem__(self, c):
        got = self._got.get(c)
        if got is None:
            got = self._got[c] = self._table[c][self._a:self._b]
        return got

    def __iter__(self):
        return iter(self._table)

    def __len__(self):
        return len(self._table)

    def __contains__(self, c):
        return c in self._table


class TrajectoryReader:
    """Every table column of a DAE run at any instants of a smooth interval: the mode re-integrated forward from the
    latest state the run holds before them (`_anchor`: an output row, or the state a segment started from) by IDA at
    `tighten` times the run's tolerances, its rows read out as the run's own (`tables.timeseries`). The anchors of an
    interval are (piece, row) of its table rows.

    An index-1 IDA run's row, and an index-2 one read on the compiled callbacks, is IDA's own (y, y'), the state
    its next steps would have continued from: a reading starts there as it is, so that it continues the run's own
    solution (a projection onto the constraints first moves the start by the run's drift, within its tolerance, and
    costs a Gauss-Newton and KKT solve per row). Other rows are made consistent first
    (`consistent.consistent_state`): diffrax's, the index-3 form's, the index-2 form's on scikit-sundae, and a row
    IDA fails from at the tighter tolerances (its constraints hold to the run's tolerance only, a jump IDA's error
    test at the tighter tolerances can reject).

    The tighter try has a step budget of its own (`TIGHT_STEPS`): a reading spans less than about one output step,
    which the run crossed in a few steps; where IDA at the tighter tolerances needs a thousand steps for it, it is
    not resolving the solution but stalling at the event the mode ends at (tolerances the residual cannot meet
    there, which would otherwise cost the whole `max_steps` per reading), and the run's own tolerances read it, as
    on any failure of the tighter try; on scikit-sundae's IDA a start's stall is kept, and a later reading from it
    that reaches as far goes to the run's own tolerances at once (`_stalls`). A reading asked for again (several columns' limits at one end) is the kept
    one: the same start, instants and tries give the same states."""

    #: steps the tighter try may take per output instant (the run's own try keeps `settings.max_steps`)
    TIGHT_STEPS = 1000

    def __init__(self, traj, angle_coordinates: tuple[int, ...], settings, tighten: float = 1e-1):
        import dataclasses
        self.traj, self.angle_coordinates = traj, angle_coordinates
        rtol = max(settings.rtol * tighten, 1e-13)
        own = dataclasses.replace(settings, multiplier_atol=settings.lam_atol, events=False)
        #: the tighter tolerances first, the run's own where IDA cannot meet those
        self.tries = (dataclasses.replace(own, rtol=rtol, atol=settings.atol * rtol / settings.rtol,
                                          max_steps=min(settings.max_steps, self.TIGHT_STEPS)), own)
        #: an index-1/2 IDA run's rows are IDA's own states (y, y'): a reading starts from them as they are (index-2
        #: on the compiled readings only: IDA fails from some of its rows at the tighter tolerances, and the
        #: scikit-sundae binding prints each failure on stdout)
        self._own_rows = (settings.backend in ("auto", "ida", "ida-compiled")
                          and settings.formulation in ("index1", "index2"))
        self._own_compiled_only = settings.formulation == "index2"
        self.reintegrations = self.dense_readings = 0
        self._starts: dict = {}
        self._own_failed: set = set()        # (piece, row) whose own state IDA failed from
        self._stalls: dict = {}              # a start's (mode, parameters, t0, y0) -> how far its tighter try got
        self._solvers: dict = {}
        self._compiled: list | None = None       # per try: the compiled IDA backend (a compiled run's readings)
        self._anchors = None
        self._segments = self._rows = self._stop_times = None
        self._keep: list = []
        self._read: dict = {}        # (start, instants) -> `_from_row`'s (t, y, y'), or its ReadingFailed
        self._ahead: dict = {}       # `_read`'s key -> the first try's (t, y, y'), or None, read ahead
        self._staged: list = []      # the ends `stage_limits` staged, until the next read-out
        self._limit_parts: dict = {}  # (id(interval), side) -> (interval, its stored state's read-out or None)

    def anchors(self, t_rows: np.ndarray) -> np.ndarray:
        """(piece index, row index) of each table time (the last piece that holds it, as the table keeps it), as
        rows of an (n, 2) array; (-1, -1) for a time no piece holds. Kept for the reader's life (one table)."""
        if self._anchors is not None and np.array_equal(self._anchors[0], t_rows):
            return self._anchors[1]
        all_t, kr = self._row_order()
        if len(all_t) == len(t_rows) and np.array_equal(all_t, t_rows) and bool((all_t[1:] > all_t[:-1]).all()):
            self._anchors = (t_rows, kr)          # the table's rows are the pieces' rows, each time once
            return kr
        last = np.searchsorted(all_t, t_rows, side="right") - 1
        at = np.clip(last, 0, None)
        hit = (last >= 0) & (all_t[at] == t_rows)
        out = np.where(hit[:, None], kr[at], -1)
        self._anchors = (t_rows, out)
        return out

    def __call__(self, iv: Interval, position: int, times: np.ndarray) -> dict:
        table = self.read_many([(iv, position, times)])[0]
        if table is not None:
            return table
        from mechsim.dynamics.tables import piece_columns
        return piece_columns(self.traj.model, self._reading(iv, position, times), self.angle_coordinates,
                             residual=False)

    def _reading(self, iv: Interval, position: int, times: np.ndarray, anchor: tuple | None = None):
        """The re-integrated states at `times` (ordered) as a Piece of the row's mode; ReadingFailed if IDA fails.
        `anchor`: `_anchor`'s tuple for the reading where the caller has it already."""
        from mechsim.dynamics.hybrid import Piece
        first = float(times.min())
        if anchor is None:
            anchor = self._anchor(iv, position, first)
        piece, t0 = anchor[0], anchor[2]
        # every reading starts from the row's own state: a restart from an earlier reading's state (projected back
        # onto the constraints) was cheaper but added its own error, which a finite difference of the peak shows
        if first >= t0:          # the usual reading: every instant at or after the start, one integration
            t, y, yp = self._from_row(anchor, times)
            if len(t) == len(times) and (len(t) == 1 or bool(np.all(t[1:] >= t[:-1]))):       # rows in order
                return Piece(piece.mode, piece.params, t, y, yp, piece.offset)
        ts, ys, yps = [], [], []
        for part in (times[times < t0][::-1], times[times >= t0]):
            if not len(part):
                continue
            tt, yy, yyp = self._from_row(anchor, part)
            ts.append(tt)
            ys.append(yy)
            yps.append(yyp)
        t = np.concatenate(ts)
        if len(t) != len(times):          # every caller indexes the reading by the instants it asked for
            raise ReadingFailed(f"re-integration between rows gave {len(t)} of {len(times)} instants "
                                f"({float(np.min(times)):.9g} to {float(np.max(times)):.9g} s)")
        order = np.argsort(t, kind="stable")
        return Piece(piece.mode, piece.params, t[order], np.concatenate(ys)[order], np.concatenate(yps)[order],
                     piece.offset)

    def read_many(self, requests: list[tuple[Interval, int, np.ndarray]]) -> list[dict | None]:
        """The columns of each (interval, position, times) from the run's own dense output where the integrator
        keeps one (the compiled diffrax run: the interpolant its output rows come from), else re-integrated, all
        read out together: one read-out per mode, made when a column of it is first read (`_ReadOut`); None for a
        request the dense output does not hold (read by re-integration) or whose re-integration failed."""
        from mechsim.dynamics.hybrid import Piece
        dense = getattr(self.traj, "dense", None)
        if dense is not None:
            got = [None if g is None else Piece(g[0], g[1], np.asarray(times, float), g[3], None, g[2])
                   for g, (_, _, times) in zip(dense.read_many([(np.asarray(times, float), iv.lo, iv.hi)
                                                                for iv, _, times in requests]), requests)]
        else:                  # re-integrated, each request on its own; read out together (None where IDA failed)
            stored = [self._stored_limit(*r) for r in requests] if self._limit_parts else []
            if any(x is not None for x in stored):          # a limit read out with the first readings is that one
                rest = iter(self.read_many([r for r, x in zip(requests, stored) if x is None]))
                return [x if x is not None else next(rest) for x in stored]
            got = []
            anchors, ready = self._read_ahead(requests)
            try:
                for request, anchor, hit in zip(requests, anchors, ready):
                    if hit is not None and hit[0] not in self._read and hit[1] not in self._own_failed:
                        # `_reading` as it goes on such a reading: the first try's rows, kept (`_from_row`)
                        key, _, piece, t, y, yp = hit
                        self.reintegrations += 1
                        self._read[key] = self._ahead.pop(key)
                        got.append(Piece(piece.mode, piece.params, t, y, yp, piece.offset))
                        continue
                    try:
                        got.append(self._reading(*request, anchor=anchor))
                    except ReadingFailed:
                        got.append(None)
            finally:
                self._ahead.clear()
        return self._read_out(got)

    def sampler(self, trusted: float | None = None):
        """What samples the columns between the rows (`with_rowless`'s `sampler`): on a dense output its own
        readings (`_DenseSamples`: exact, and costing no integration), else the run's states interpolated between
        its own (`_RowInterpolation`, a gap re-integrated where the interpolation's estimated error exceeds
        `trusted`); None where a piece keeps no y' to interpolate with, or the run no segment starts."""
        traj = self.traj
        if getattr(traj, "dense", None) is not None:
            return _DenseSamples(self)
        if not traj.starts or any(p.yp is None for p in traj.pieces + traj.starts):
            return None
        return _RowInterpolation(self, trusted)

    def _stored_limit(self, iv: Interval, position: int, times: np.ndarray) -> Mapping | None:
        """The read-out of the state the run holds at the interval's end (`stage_limits`) where a request asks for
        just that one-sided limit (its one instant the end, from the end's own row), else None."""
        if len(times) != 1:
            return None
        side = ("after" if position == 0 and times[0] == iv.lo else
                "before" if position == len(iv.rows) - 1 and times[0] == iv.hi else None)
        kept = self._limit_parts.get((id(iv), side)) if side is not None else None
        return kept[1] if kept is not None and kept[0] is iv else None

    def stage_limits(self, ends: list[tuple[Interval, str]]) -> None:
        """Read out the states the run holds at `ends` (`stored_columns`) with the next `read_many`'s readings, in
        its read-out of each mode: a read-out has a fixed cost of its own (the generated functions' calls), and
        the limits are read right after the first readings (`stored_limits`). A dense output reads them anyway."""
        if getattr(self.traj, "dense", None) is None:
            self._staged += [(iv, side) for iv, side in ends if (id(iv), side) not in self._limit_parts]

    def _read_out(self, readings: list) -> list[dict | None]:
        """Each reading's columns (None where there is none): one read-out per mode of all its readings, stacked
        (`_ReadOut`, parameters and offsets per row), each reading its rows of it; with them the states staged
        (`stage_limits`), whose read-outs are kept for `stored_columns`."""
        n, staged = len(readings), self._staged
        if staged:
            self._staged = []
            readings = readings + self._stored_states(staged)
        groups: dict = {}
        for r, piece in enumerate(readings):
            if piece is not None:
                if not isinstance(piece.params, tuple):       # (the read-out compares parameters as tuples)
                    readings[r] = replace(piece, params=tuple(np.asarray(piece.params, float).tolist()))
                groups.setdefault(piece.mode, []).append(r)
        out: list[dict | None] = [None] * len(readings)
        for rs in groups.values():
            table = _ReadOut(self.traj.model, [readings[r] for r in rs], self.angle_coordinates)
            a = 0
            for r in rs:
                rows = len(readings[r].t)
                out[r] = _Part(table, a, a + rows)
                a += rows
        self.dense_readings += len(groups) if getattr(self.traj, "dense", None) is not None else 0
        for (iv, side), part in zip(staged, out[n:]):
            self._limit_parts[id(iv), side] = (iv, part)
        return out[:n]

    def _read_ahead(self, requests: list) -> tuple[list, list]:
        """Each request's `_anchor` (None where it has none), and on the compiled callbacks the first (tighter) try of
        every reading `_reading` starts forward from its anchor, run ahead in one compiled call per mode
        (`IdaCompiledBackend.read_many`): the same IDA calls from the same states as one reading at a time, so the
        same rows (a reading whose every instant is within round-off of its start is that start, as `_integrate`
        reads it). Each such reading's rows (or None where IDA failed) are kept in `_ahead` for `_integrate` to
        take; per request, (key, row, piece, t, y, y') where that is the whole reading (every instant, in order),
        else None. A reading from a row IDA failed from before it (`_own_failed`, also found while the requests are
        then read in order) is not run ahead: it starts from the consistent state, as one at a time."""
        n = len(requests)
        times = [np.asarray(r[2], dtype=float) for r in requests]
        sizes = np.fromiter(map(len, times), dtype=np.int64, count=n)
        ready: list = [None] * n
        if not n or not sizes.all():
            return [None] * n, ready
        all_t = np.concatenate(times)
        starts = np.cumsum(sizes) - sizes
        firsts = np.minimum.reduceat(all_t, starts).tolist()        # each request's times.min()
        anchors = [None if isinstance(a, ReadingFailed) else a
                   for a in self._anchors_of([(iv, position, f) for (iv, position, _), f in zip(requests, firsts)])]
        if not self._compiled_tries() or np.isnan(all_t).any():
            return anchors, ready
        # the instants within round-off of the start (`_integrate`'s), for all requests at once (t0 NaN: none)
        starts_t: list = [np.nan] * n
        keys: list = [None] * n
        seen = set(self._read)
        for i, (anchor, f, ti) in enumerate(zip(anchors, firsts, times)):
            if anchor is None or f < anchor[2] or anchor[5] in self._own_failed:
                continue
            key = self._key(anchor, ti)
            if key in seen:                 # read before, or again in these requests: the kept reading
                continue
            seen.add(key)
            keys[i], starts_t[i] = key, anchor[2]
        t0 = np.array(starts_t, dtype=float)
        near = 1e-12 * np.maximum(1.0, np.abs(t0))
        at_start = np.abs(all_t - np.repeat(t0, sizes)) <= np.repeat(near, sizes)
        leads = np.add.reduceat(at_start, starts, dtype=np.int64)
        for i in np.flatnonzero(~np.isnan(t0) & (leads == sizes)).tolist():      # every instant at the start
            n0, y0, yp0 = int(sizes[i]), anchors[i][3], anchors[i][4]
            got = self._ahead[keys[i]] = (times[i][at_start[starts[i]:starts[i] + n0]],
                                          np.repeat(y0[None, :], n0, axis=0), np.repeat(yp0[None, :], n0, axis=0))
            if n0 == 1 or bool(np.all(got[0][1:] >= got[0][:-1])):
                ready[i] = (keys[i], anchors[i][5], anchors[i][0]) + got
        groups: dict = {}           # the readings with an instant to integrate to, by mode
        group_of = np.full(n, -1, dtype=np.int64)
        for i in np.flatnonzero(~np.isnan(t0) & (leads < sizes)).tolist():
            self._ahead[keys[i]] = None         # IDA failed, unless its rows replace this
            number, members = groups.setdefault(id(anchors[i][1]), (len(groups), []))
            group_of[i] = number
            members.append(i)
        if not groups:
            return anchors, ready
        # every group's instants, reading after reading, each reading's instants at t0 first
        in_group = np.repeat(group_of, sizes)
        rows = np.flatnonzero(in_group >= 0)
        rows = rows[np.lexsort((~at_start[rows], np.repeat(np.arange(n), sizes)[rows], in_group[rows]))]
        end = 0
        for _, members in groups.values():
            mf = anchors[members[0]][1]
            counts = sizes[members]
            group_rows, end = rows[end:end + int(counts.sum())], end + int(counts.sum())
            bounds = np.empty((len(members), 3), dtype=np.int64)
            bounds[:, 2] = np.cumsum(counts)
            bounds[:, 0] = bounds[:, 2] - counts
            bounds[:, 1] = bounds[:, 0] + leads[members]
            t, y, yp, ok = self._compiled[0].read_many(
                mf, t0[members], np.array([anchors[i][3] for i in members]),
                np.array([anchors[i][4] for i in members]),
                np.array([anchors[i][0].params for i in members], dtype=float).reshape(len(members), -1),
                all_t[group_rows], bounds)
            # rows k whose next row is not later (a reading's last row where the next reading starts earlier), and the
            # readings that hold one before their last row (lo <= k < hi - 1): their rows are not in time order
            falls = np.flatnonzero(~(t[1:] >= t[:-1]))
            first = falls.searchsorted(bounds[:, 0])          # each reading's first such row at or after its start
            unordered = first < len(falls)
            unordered[unordered] = falls[first[unordered]] < bounds[unordered, 2] - 1
            for i, (lo, _, hi), whole, out_of_order in zip(members, bounds.tolist(), ok.tolist(), unordered.tolist()):
                if not whole:
                    continue
                got = self._ahead[keys[i]] = (t[lo:hi], y[lo:hi], yp[lo:hi])
                if not out_of_order:             # in time order (`_reading`'s)
                    ready[i] = (keys[i], anchors[i][5], anchors[i][0]) + got
        return anchors, ready

    def momentum(self, iv: Interval, position: int, t: float) -> tuple[np.ndarray, np.ndarray]:
        """(M(q) v, v) at instant t of the interval (its one-sided limit at an end), from the row at `position`:
        the generalized momentum, whose jump across an event is the impulse the event delivers."""
        anchor = self._anchor(iv, position, t)
        piece, mf = anchor[0], anchor[1]
        _, y, _ = self._from_row(anchor, np.array([t]))
        q, v = y[0, mf.index["q"]], y[0, mf.index["v"]]
        M = np.atleast_2d(np.asarray(mf.mass(q, piece.params), dtype=float))
        return M @ v, v

    def _anchor(self, iv: Interval, position: int, first: float | None = None, own: bool = True):
        """(piece, its mode's functions, t0, y0, y'0, row): the state a reading of the interval starts from: the
        interval's row `position`, or where the reading's `first` instant lies before that row (or the interval has
        no row there), the latest state the run holds at or before `first` (`_anchors_of`), so that every reading runs
        forward in time: backward, a damped stiff mode (a compliant contact) is unstable. The row itself only where
        the run holds no earlier state (its segments' starts not kept). A row's state is `_row_state`'s; `row` is
        (piece, row) where it is an IDA run's own (y, y'), else None (a consistent state). ReadingFailed where there
        is none."""
        got = self._anchors_of([(iv, position, first)], own)[0]
        if isinstance(got, ReadingFailed):
            raise got
        return got

    def _anchors_of(self, items: list, own: bool = True) -> list:
        """`_anchor` of each (interval, position, first), or its ReadingFailed; the rows' times and the searches for
        earlier states made for all at once. An earlier state is the latest one at or before `first` in the smooth
        stretch that holds it (ending at the interval's end): an output row of the run's segment there, else the
        state that segment started from (`Trajectory.starts`, after the event that opened it); none where the run
        kept no segment starts (the compiled diffrax run). A reading at the interval's end, where the run ended a
        segment there, starts from that state (`_stops_at`): the one-sided limit the run itself reached."""
        n = len(items)
        k, r = np.array([iv.anchors[position] if 0 <= position < len(iv.anchors) else (-1, 0)
                         for iv, position, _ in items], dtype=np.int64).reshape(n, 2).T
        kr = zip(k.tolist(), r.tolist())
        first = np.array([np.nan if f is None else f for _, _, f in items], dtype=float)
        asked = np.array([f is not None for _, _, f in items], dtype=bool)
        hi = np.array([iv.hi for iv, _, _ in items], dtype=float)
        t_flat, offsets = self._row_times()
        t_row = t_flat[np.where(k >= 0, offsets[k] + r, 0)] if len(t_flat) else np.full(n, np.nan)
        earlier = asked & ((k < 0) | (first < t_row))
        starts = getattr(self.traj, "starts", None)
        seg = row = np.full(n, -1, dtype=np.int64)
        stop = self._stops_at(first, hi) if own else seg
        if starts and earlier.any():
            ts = self._segment_times()
            eps = 1e-12 * np.maximum(1.0, np.abs(first))
            # the last segment started at or before `first` (of several at one instant, the one the run went on
            # from), not one started at the stretch's end (after its closing event)
            seg = np.where(earlier, ts.searchsorted(np.minimum(first + eps, hi - eps), side="right") - 1, -1)
            t_rows, rows = self._row_order()
            i = t_rows.searchsorted(first + eps, side="right") - 1
            # an output row of that segment, nearer than its start
            row = np.where((seg >= 0) & (i >= 0) & (t_rows[np.maximum(i, 0)] > ts[np.maximum(seg, 0)]), i, -1)
        out: list = []
        for (ki, ri), s, i, e, (iv, _, _) in zip(kr, seg.tolist(), row.tolist(), stop.tolist(), items):
            if e >= 0:                  # the interval's end, where its segment ended: the run's state there
                end = self.traj.stops[e]
                out.append((end, self.traj.model.modes[end.mode], float(end.t[0]), end.y[0], end.yp[0], None))
            elif s >= 0:
                if i >= 0:
                    try:
                        out.append(self._row_state(int(rows[i, 0]), int(rows[i, 1]), own))
                        continue
                    except ReadingFailed:
                        pass
                start = starts[s]
                out.append((start, self.traj.model.modes[start.mode], float(self._segments[s]), start.y[0],
                            start.yp[0], None))
            elif ki < 0:
                out.append(ReadingFailed(f"no state to read the interval ({iv.lo:.9g}, {iv.hi:.9g}) s from"))
            else:
                try:
                    out.append(self._row_state(ki, ri, own))
                except ReadingFailed as exc:
                    out.append(exc)
        return out

    def _segment_times(self) -> np.ndarray:
        """The instant each segment of the run started at (`Trajectory.starts`), kept."""
        if self._segments is None:
            self._segments = np.array([float(p.t[0]) for p in self.traj.starts])
        return self._segments

    def _stops_at(self, first: np.ndarray, hi: np.ndarray) -> np.ndarray:
        """Per reading (its first instant, its interval's end): the segment whose end state is the reading's start,
        where the reading is the one-sided limit at the interval's end and the run ended a segment there
        (`Trajectory.stops`: the state before the event's transition); -1 elsewhere."""
        stops = getattr(self.traj, "stops", None)
        if not stops or not len(hi):
            return np.full(len(hi), -1, dtype=np.int64)
        if self._stop_times is None:
            self._stop_times = np.array([np.nan if p is None else float(p.t[0]) for p in stops])
        eps = 1e-12 * np.maximum(1.0, np.abs(hi))
        s = self._segment_times().searchsorted(hi - eps, side="right") - 1       # the segment running into the end
        with np.errstate(invalid="ignore"):
            ok = (np.abs(first - hi) <= eps) & (s >= 0) & (np.abs(self._stop_times[np.maximum(s, 0)] - hi) <= eps)
        return np.where(ok, s, -1)

    def stored_ends(self, ends: list[tuple[Interval, str]]) -> np.ndarray:
        """Whether the one-sided limit at each (interval, side: 'after' its start, 'before' its end) is a state the
        run holds, read without integrating: the segment's start after an event, its end before one
        (`Trajectory.starts`, `stops`); every end of a dense output (an interpolation)."""
        if getattr(self.traj, "dense", None) is not None:
            return np.ones(len(ends), dtype=bool)
        return np.array([p is not None for p in self._stored_states(ends)], dtype=bool)

    def _stored_states(self, ends: list[tuple[Interval, str]]) -> list:
        """The state the run holds at each (interval, side) end, as a one-row Piece (`stored_ends`), or None."""
        if not getattr(self.traj, "starts", None) or not ends:
            return [None] * len(ends)
        after = np.array([side == "after" for _, side in ends], dtype=bool)
        te = np.array([iv.lo if a else iv.hi for (iv, _), a in zip(ends, after)], dtype=float)
        ts = self._segment_times()
        eps = 1e-12 * np.maximum(1.0, np.abs(te))
        s = ts.searchsorted(te + eps, side="right") - 1      # the segment started there (the last of several)
        started = np.where((s >= 0) & (np.abs(ts[np.maximum(s, 0)] - te) <= eps), s, -1)
        ended = self._stops_at(te, te)
        starts, stops = self.traj.starts, self.traj.stops
        return [(starts[a] if a >= 0 else None) if x else (stops[b] if b >= 0 else None)
                for x, a, b in zip(after.tolist(), started.tolist(), ended.tolist())]

    def limits(self, ends: list[tuple[Interval, str]], names: list[str], read_many=None) -> np.ndarray:
        """The columns `names` at each (interval, side) end the run holds the state of (`stored_ends`), read out in
        one pass (`stored_columns`): (column, end) values, NaN where the run holds none or the column has none
        (`stored_limits`). read_many: what reads a dense output there (default its own; a caller's that keeps the
        readings, for the limits read again later)."""
        out = np.full((len(names), len(ends)), np.nan)
        columns, read = self.stored_columns(ends, read_many)
        if columns is not None:
            for m, c in enumerate(names):
                if c in columns:
                    out[m, read] = np.asarray(columns[c], dtype=float)
        return out

    def stored_columns(self, ends: list[tuple[Interval, str]], read_many=None) -> tuple[Mapping | None, np.ndarray]:
        """(the columns at the ends the run holds the state of (`stored_ends`), in the ends' order, those ends'
        positions): the states read out together, one read-out per mode (`tables.piece_columns` of the stacked
        one-row pieces, as a reading's), or the dense output read there (by `read_many`, default `read_many`);
        (None, none) where there is none."""
        if getattr(self.traj, "dense", None) is not None:
            tables = (read_many or self.read_many)([(iv, 0 if side == "after" else len(iv.rows) - 1,
                                      np.array([iv.lo if side == "after" else iv.hi])) for iv, side in ends])
            read = np.array([j for j, table in enumerate(tables) if table is not None], dtype=np.int64)
            return Gathered.of([tables[j] for j in read.tolist()]), read
        kept = self._limit_parts
        if ends and all(kept.get((id(iv), side), (None,))[0] is iv for iv, side in ends):   # (`stage_limits`)
            parts = [kept[id(iv), side][1] for iv, side in ends]
            read = np.array([j for j, part in enumerate(parts) if part is not None], dtype=np.int64)
            return (Gathered.of([parts[j] for j in read.tolist()]) if len(read) else None), read
        modes: dict = {}
        for j, piece in enumerate(self._stored_states(ends)):
            if piece is not None:
                if not isinstance(piece.params, tuple):       # (the read-out compares parameters as tuples)
                    piece = replace(piece, params=tuple(np.asarray(piece.params, float).tolist()))
                modes.setdefault(piece.mode, ([], []))
                modes[piece.mode][0].append(piece)
                modes[piece.mode][1].append(j)
        if not modes:
            return None, np.zeros(0, dtype=np.int64)
        groups = [(_ReadOut(self.traj.model, pieces, self.angle_coordinates), None, np.array(at, dtype=np.int64))
                  for pieces, at in modes.values()]
        return Gathered(groups), np.sort(np.concatenate([at for _, _, at in groups]))

    def _row_state(self, k: int, r: int, own: bool = True):
        """`_anchor`'s tuple at row r of piece k: the run's own (y, y') there where `_owns` says so (own=True),
        else the consistent state made from its positions and speeds (`_start`)."""
        piece = self.traj.pieces[k]
        t0 = float(piece.t[r])
        if own and self._owns(piece):
            return piece, self.traj.model.modes[piece.mode], t0, piece.y[r], piece.yp[r], (k, r)
        try:
            y0, yp0 = self._start(k, r)
        except (ValueError, np.linalg.LinAlgError) as exc:
            raise ReadingFailed(f"no consistent state at the row t = {t0:.9g} s: {exc}") from None
        return piece, self.traj.model.modes[piece.mode], t0, y0, yp0, None

    def _from_row(self, anchor: tuple, times):
        """`_integrate` from an `_anchor` state. From the run's own (y, y') at the tighter tolerances only: where IDA
        fails from it there, the reading starts from the consistent state made at that row (both tries), and so do the
        later readings from that row (kept)."""
        times = np.asarray(times, dtype=float)
        key = self._key(anchor, times)
        got = self._read.get(key)
        if got is None:
            try:
                got = self._from_row_once(anchor, times, key)
            except ReadingFailed as exc:
                got = exc
            self._read[key] = got
        if isinstance(got, ReadingFailed):
            raise got
        return got

    @staticmethod
    def _key(anchor: tuple, times: np.ndarray) -> tuple:
        """What a reading is kept under: its start (the row, or the state itself) and instants."""
        piece, _, t0, y0, yp0, row = anchor
        return ((row,) if row is not None else (id(piece), t0, y0.tobytes(), yp0.tobytes())) + (times.tobytes(),)

    def _from_row_once(self, anchor: tuple, times: np.ndarray, key: tuple | None = None):
        piece, mf, t0, y0, yp0, row = anchor
        if row is None:
            return self._integrate(mf, piece.params, t0, y0, yp0, times, key=key)
        if row not in self._own_failed:
            try:
                return self._integrate(mf, piece.params, t0, y0, yp0, times, self.tries[:1], key)
            except ReadingFailed:
                self._own_failed.add(row)
        _, _, t0, y0, yp0, _ = self._row_state(*row, own=False)
        return self._integrate(mf, piece.params, t0, y0, yp0, times)

    def _row_times(self):
        """Every piece's output times, piece after piece, and where each piece's rows begin there."""
        return self._row_order(flat=True)

    def _row_order(self, flat: bool = False):
        """Every piece's output rows in time order: (times, (piece, row) of each) as rows of an (n, 2) array; with
        `flat`, `_row_times` (the same rows in piece order)."""
        if self._rows is None:
            pieces = self.traj.pieces
            sizes = np.array([len(p.t) for p in pieces], dtype=np.int64)
            starts = np.cumsum(sizes) - sizes
            all_t = np.concatenate([p.t for p in pieces])
            kr = np.stack([np.repeat(np.arange(len(pieces)), sizes), np.arange(len(all_t)) - np.repeat(starts, sizes)],
                          axis=1)
            flat_t = all_t
            if np.any(all_t[1:] < all_t[:-1]):       # not in time order already (as the pieces come): sorted, stably
                order = np.argsort(all_t, kind="stable")
                all_t, kr = all_t[order], kr[order]
            self._rows = (all_t, kr, flat_t, starts)
        return self._rows[2:] if flat else self._rows[:2]

    def _owns(self, piece) -> bool:
        """Whether readings from this piece's rows start from the run's own (y, y') (`_own_rows`)."""
        return (self._own_rows and piece.yp is not None
                and (not self._own_compiled_only or self._compiled_tries()))

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
        scikit-sundae's binding, without a Python call per residual); one backend per try, kept for the thread's
        later readers (`ida_compiled.reusable`)."""
        if self._compiled is None:
            from mechsim.dynamics.backends.ida_compiled import reusable, runs_compiled
            self._compiled = ([reusable(s) for s in self.tries]
                              if runs_compiled(self.tries[-1], self.traj.model) else [])
        return bool(self._compiled)

    def _integrate(self, mf, p, t0, y0, yp0, times, tries: tuple | None = None, key: tuple | None = None):
        """(t, y, yp) at `times` (all on one side of t0, ordered away from it) from the consistent (y0, yp0), with
        the first of `tries` (default: all the reader's tolerance tries) that IDA meets; the tighter try's result
        read ahead (`_read_ahead`) where `key` names one."""
        self.reintegrations += 1
        n_tries = len(tries if tries is not None else self.tries)
        done = 0
        if key is not None and key in self._ahead:        # the first try's result, read ahead
            got = self._ahead.pop(key)
            if got is not None:
                return got
            done = 1
        # instants within round-off of t0 are read at t0 (IDA cannot step that little; F' dt is below round-off)
        near = 1e-12 * max(1.0, abs(t0))
        gap = np.abs(times - t0)
        at_start = gap <= near if gap.min() <= near else None
        out_t = times if at_start is None else times[~at_start]
        if len(out_t) and self._compiled_tries():       # the instants at t0 in the same arrays (`read`)
            lead = None if at_start is None else times[at_start]
            for backend in self._compiled[done:n_tries]:
                got = backend.read(mf, p, t0, y0, yp0, out_t, lead)
                if got is not None:
                    return got
            raise ReadingFailed("re-integration between rows failed: IDA failed on the compiled callbacks")
        rows_t, rows_y, rows_yp = [], [], []
        if at_start is not None:
            n0 = int(at_start.sum())
            rows_t.append(times[at_start])
            rows_y.append(np.repeat(y0[None, :], n0, axis=0))
            rows_yp.append(np.repeat(yp0[None, :], n0, axis=0))
        if len(out_t):
            from sksundae.ida import IDA

            from mechsim.dynamics.backends.ida import atol_vector, solve_quietly
            tspan = np.concatenate([[t0], out_t])
            if len(tspan) == 2:
                tspan = np.array([t0, 0.5 * (t0 + out_t[0]), out_t[0]])
            # a tighter try that stalled from this start (its step budget spent short of an instant: at the event
            # the mode ends at, `TIGHT_STEPS`) stalls again on any reading from it that reaches as far: such a
            # reading goes to the run's own tolerances at once (rows a turn apart read many instants from one start)
            start = (id(mf), np.asarray(p, dtype=float).tobytes(), float(t0), y0.tobytes())
            stalled = self._stalls.get(start)
            first = 1 if stalled is not None and n_tries > 1 and abs(out_t[-1] - t0) >= stalled else 0
            for n, s in enumerate(self.tries[:n_tries]):
                if n < first:
                    continue
                # one solver per mode, parameter values and try, re-initialised at each solve
                key = (id(mf), np.asarray(p, dtype=float).tobytes(), n)
                solver = self._solvers.get(key)
                if solver is None:
                    solver = self._solvers[key] = IDA(
                        mf.residual, userdata=p, rtol=s.rtol, atol=atol_vector(mf, s),
                        algebraic_idx=mf.algebraic or None, jacfn=mf.jacobian if s.jacobian == "exact" else None,
                        max_num_steps=s.max_steps, linsolver="dense")
                    self._keep.append(mf)          # the id stays this mode's while the reader lives
                # a tighter try's failure falls back to the next, the last try's is the ReadingFailed below (its
                # message), which the peaks handle (another start, or the rows, said in their `at`)
                sol = solve_quietly(solver, tspan, y0, yp0)
                if sol.success:
                    break
                if n == 0:
                    reached = np.asarray(sol.t, dtype=float)
                    far = float(np.abs(reached - t0).max()) if len(reached) else 0.0
                    self._stalls[start] = min(far, self._stalls.get(start, np.inf))
            else:
                raise ReadingFailed(f"re-integration between rows failed: {sol.message}")
            keep = np.isin(np.asarray(sol.t), out_t)
            rows_t.append(np.asarray(sol.t)[keep])
            rows_y.append(np.asarray(sol.y)[keep])
            rows_yp.append(np.asarray(sol.yp)[keep])
        if len(rows_t) == 1:          # one block (the usual reading): as it is, not copied
            return rows_t[0], rows_y[0], rows_yp[0]
        return np.concatenate(rows_t), np.vstack(rows_y), np.vstack(rows_yp)


class _RowInterpolation:
    """A DAE run's columns between its output rows: each segment's states (its start, its rows, its end: y and y' as
    the integrator left them) joined by cubic Hermite interpolation, read out as the rows are
    (`TrajectoryReader._read_out`: one read-out per mode). A state's error is of order h^4 |y^(4)| / 384 over rows
    h apart, while a column's narrow peak comes from the read-out's sharp dependence on a smooth state (a contact
    force through an engagement), so the samples rank the candidates; every located value is then read by
    re-integration (docs/theory.md §K5). Where rows lie so far apart that the interpolation cannot be trusted to
    rank (a reversal within one gap: `gap_errors` above `trusted`), that gap's samples are re-integrated as a
    reading is; trusted None: none is."""

    def __init__(self, reader: TrajectoryReader, trusted: float | None = None):
        traj = reader.traj
        self.reader, self.trusted = reader, trusted
        self.start_t = np.array([float(p.t[0]) for p in traj.starts])
        parts: list[list] = [[p] for p in traj.starts]           # each segment's states in time order
        for piece in traj.pieces:
            if len(piece.t):
                k = int(self.start_t.searchsorted(piece.t[0], side="left")) - 1
                if k >= 0:                     # (the run's first row is its first segment's start)
                    parts[k].append(piece)
        for k, stop in enumerate(traj.stops):
            if stop is not None and stop.t[0] > parts[k][-1].t[-1]:
                parts[k].append(stop)
        sizes = np.array([sum(len(p.t) for p in part) for part in parts], dtype=np.int64)
        self.first = np.cumsum(sizes) - sizes                     # each segment's first state
        self.size = sizes
        every = [p for part in parts for p in part]
        self.t = np.concatenate([p.t for p in every])
        # the states of every segment in one array, each mode's layout padded to the widest (NaN beyond its own)
        self.width = [p.y.shape[1] for p in traj.starts]
        if min(self.width) == max(self.width):
            self.y, self.yp = np.concatenate([p.y for p in every]), np.concatenate([p.yp for p in every])
        else:
            self.y, self.yp = np.full((len(self.t), max(self.width)), np.nan), np.full((len(self.t), max(self.width)),
                                                                                      np.nan)
            row = 0
            for p in every:
                rows, width = p.y.shape
                self.y[row:row + rows, :width], self.yp[row:row + rows, :width] = p.y, p.yp
                row += rows
        self.starts = traj.starts

    def read_many(self, requests: list[tuple[Interval, int, np.ndarray]]) -> list[Mapping]:
        """Each (interval, position, times)'s columns, as a reader's (`read_at` of every request's instants at
        once, each in its interval, each request its rows of it): a thermal reader's mechanics between rows
        (scenarios/thermal_peaks.py `ThermalReader.sampler`)."""
        sizes = [len(times) for _, _, times in requests]
        if not sizes:
            return []
        ends = np.cumsum(sizes).tolist()
        table = self.read_at(np.concatenate([np.asarray(times, dtype=float) for _, _, times in requests]),
                             [(iv, e - n, e) for (iv, _, _), n, e in zip(requests, sizes, ends)])
        return [_Part(table, e - n, e) for n, e in zip(sizes, ends)]

    def __call__(self, iv: Interval, position: int, times: np.ndarray) -> Mapping:
        return self.read_many([(iv, position, times)])[0]

    def gap_errors(self, j: np.ndarray) -> np.ndarray:
        """The estimated error of the interpolation over each gap j (between states j and j + 1), its largest over
        the coordinates: in radians for an angle coordinate, relative to the largest magnitude the run holds of any
        other. Two estimates: the cubic's error in q from the quintic through q, v and a at both ends (their
        difference at mid-gap, h (v0 - v1)/32 + h^2 (a0 + a1)/64, is the cubic's leading error h^4 q^(4)/384), and
        the cubic in v integrated against q1 - q0 (the Hermite-corrected trapezoidal rule
        h (v0 + v1)/2 + h^2 (a0 - a1)/12, exact to h^5 q^(5)/720); docs/theory.md §K5."""
        nq = len(self.reader.traj.model.coordinates)
        k = np.minimum(j + 1, len(self.t) - 1)
        h = (self.t[k] - self.t[j])[:, None]
        q0, q1 = self.y[j, :nq], self.y[k, :nq]
        v0, v1 = self.y[j, nq:2 * nq], self.y[k, nq:2 * nq]
        a0, a1 = self.yp[j, nq:2 * nq], self.yp[k, nq:2 * nq]
        scale = np.ones(nq)
        other = [i for i in range(nq) if i not in self.reader.angle_coordinates]
        if other:
            scale[other] = np.maximum(np.nanmax(np.abs(self.y[:, other]), axis=0, initial=0.0), 1e-300)
        with np.errstate(invalid="ignore"):
            cubic = np.abs(h * (v0 - v1) / 32 + h * h * (a0 + a1) / 64)
            moved = np.abs(q1 - q0 - h * (v0 + v1) / 2 - h * h * (a0 - a1) / 12)
            return np.nanmax(np.maximum(cubic, moved) / scale, axis=1, initial=0.0)

    def read_at(self, times: np.ndarray, spans: list[tuple[Interval, int, int]]) -> Mapping:
        """Every column at `times` (in order; NaN where no segment's states bracket one), each in the segment
        started last at or before it; the instants of a gap whose interpolation cannot be trusted (`gap_errors` above
        `trusted`) re-integrated from the latest row of its interval (`spans`: the interval of each stretch
        times[a:b]; without them, none is)."""
        from mechsim.dynamics.hybrid import Piece
        times = np.asarray(times, dtype=float)
        seg = self.start_t.searchsorted(times, side="right") - 1
        ok = (seg >= 0) & (self.size[np.maximum(seg, 0)] > 1)
        seg = np.maximum(seg, 0)
        a = self.first[seg]
        # the state at or before each instant within its segment (its last gap where it lies beyond: NaN below)
        j = np.clip(self.t.searchsorted(times, side="right") - 1, a, a + self.size[seg] - 2)
        found = self._reintegrated(times, j, ok, spans) if spans and self.trusted is not None else []
        if found:
            keep = np.ones(len(times), dtype=bool)
            for _, _, at in found:
                keep[at] = False
            if not keep.any():
                return Gathered(found)
            inner = self.read_at(times[keep], [])
            return Gathered(found + [(inner, None, np.flatnonzero(keep))])
        t0, t1 = self.t[j], self.t[np.minimum(j + 1, len(self.t) - 1)]
        h = (t1 - t0)[:, None]
        with np.errstate(invalid="ignore", divide="ignore"):
            s = (times[:, None] - t0[:, None]) / h
        s2, s3 = s * s, s * s * s
        y = ((2 * s3 - 3 * s2 + 1) * self.y[j] + (s3 - 2 * s2 + s) * h * self.yp[j]
             + (3 * s2 - 2 * s3) * self.y[np.minimum(j + 1, len(self.t) - 1)]
             + (s3 - s2) * h * self.yp[np.minimum(j + 1, len(self.t) - 1)])
        y[~(ok & (times >= t0) & (times <= t1) & (h[:, 0] > 0))] = np.nan
        # one piece a run of instants in one segment (its mode, parameters and offset); one read-out a mode, each
        # column put in the instants' order when first read (`Gathered`)
        bounds = np.r_[0, np.flatnonzero(np.diff(seg)) + 1, len(times)].tolist()
        modes: dict = {}
        for i, e, k in zip(bounds[:-1], bounds[1:], seg[bounds[:-1]].tolist()):
            start = self.starts[k]
            params = (start.params if isinstance(start.params, tuple) else
                      tuple(np.asarray(start.params, float).tolist()))
            pieces, at = modes.setdefault(start.mode, ([], []))
            pieces.append(Piece(start.mode, params, times[i:e], y[i:e, :self.width[k]], None, start.offset))
            at.append(np.arange(i, e))
        model, angles = self.reader.traj.model, self.reader.angle_coordinates
        return Gathered([(_ReadOut(model, pieces, angles), None, np.concatenate(at)) for pieces, at in modes.values()])

    def _reintegrated(self, times: np.ndarray, j: np.ndarray, ok: np.ndarray, spans: list[tuple[Interval, int, int]]
                      ) -> list[tuple[Mapping, None, np.ndarray]]:
        """(columns, None, their instants' positions) of the stretches of each span whose gap's interpolation cannot
        be trusted (`gap_errors`), each re-integrated from the latest row of its interval at or before it (one
        reading per gap, read together by the reader); a reading that fails keeps the interpolation."""
        gaps = np.unique(j[ok])
        bad = gaps[self.gap_errors(gaps) > self.trusted]
        if not len(bad):
            return []
        untrusted = ok & np.isin(j, bad)
        requests, where = [], []
        t_flat, offsets = self.reader._row_times()
        for iv, lo, hi in spans:
            mine = lo + np.flatnonzero(untrusted[lo:hi])
            if not len(mine):
                continue
            anchors = np.asarray(iv.anchors, dtype=np.int64).reshape(-1, 2)
            # each row's instant (a reading's row, anchor (-1, -1), none: the one before it stands), non-decreasing
            own = anchors[:, 0] >= 0
            rows_t = np.full(len(anchors), -np.inf)
            rows_t[own] = t_flat[offsets[anchors[own, 0]] + anchors[own, 1]]
            rows_t = np.maximum.accumulate(rows_t) if len(rows_t) else rows_t
            cuts = np.r_[0, np.flatnonzero(np.diff(j[mine])) + 1, len(mine)]
            for c0, c1 in zip(cuts[:-1], cuts[1:]):
                at = mine[c0:c1]
                position = max(int(rows_t.searchsorted(times[at[0]], side="right")) - 1, 0)
                requests.append((iv, position, times[at]))
                where.append(at)
        got = self.reader.read_many(requests) if requests else []
        return [(table, None, at) for table, at in zip(got, where) if table is not None]


class _DenseSamples:
    """A dense output's readings at many instants of many intervals, their columns in one order (`Gathered`): the
    samples between the rows of a compiled diffrax run."""

    def __init__(self, reader: TrajectoryReader):
        self.reader = reader

    def read_at(self, times: np.ndarray, spans: list[tuple[Interval, int, int]]) -> Mapping:
        """Every column at `times`, times[a:b] in the interval of each (interval, a, b) of `spans` (NaN where the
        dense output does not hold a stretch)."""
        parts = self.reader.read_many([(iv, 0, times[a:b]) for iv, a, b in spans])
        groups: dict = {}
        missing = []
        for (_, a, b), part in zip(spans, parts):
            if part is None:
                missing.append(np.arange(a, b))
                continue
            table = part._table
            group = groups.setdefault(id(table), (table, [], []))
            group[1].append(np.arange(part._a, part._b))
            group[2].append(np.arange(a, b))
        found = [(table, np.concatenate(rows), np.concatenate(at)) for table, rows, at in groups.values()]
        if missing:
            found.append(({}, None, np.concatenate(missing)))
        return Gathered(found)
