"""The thermal columns' peaks located on the continuous solution, not at the output rows (docs/theory.md §K5,
docs/thermal.md "Reported temperatures").

The thermal finish (thermal/plan.py `ThermalPlan.finish`) computes its columns from each row's mechanical state and
the network's states: the flash rise and the Blok share are algebraic in the contact's state (force, sliding speeds,
time since the contact began), the contact temperature is the share-weighted bulk plus the flash rise. So every
thermal column can be evaluated at any instant from the mechanical state and the network's states there:

- up to the end of the mechanics run (a resolved run, or a cycle-averaged run's mechanics window), a DAE run holds
  the network's states in the same DAE as the mechanics: the mode re-integrated from an output row, or where a
  smooth stretch holds none, from the state its segment started from (dynamics/trajectory_reader.py
  `TrajectoryReader`) gives both, and the finish's own formulas the columns;
- after it (cycle averaging, thermal/cycle.py), the mechanics is the window's last full turn at the instant's
  phase (re-integrated there, not interpolated between its rows) and the network's states the cycle-averaged
  solution at the instant itself (`bulk_response`: the mean curve, exact in the network's modes, plus the
  periodic ripple).

A closed-form run (a prescribed speed) has no DAE: its mechanics is the closed form at any instant (scenarios/peaks.py
`_closed_form_reader`), and its network's states are integrated exactly in the network's modes from the output
row at or before the instant, by the same quadrature of the closed form's heat input that integrated the rows
(thermal/exact.py `ModalNetwork.integrate`, its intervals split at the contact's switches); after a
cycle-averaged window they are the cycle-averaged solution at the instant, as above (`ClosedFormThermalReader`).

`ThermalReader` and `ClosedFormThermalReader` are `dynamics/extrema.py` readers of those columns on the run's
table, so that `locate` finds their extrema as it finds the mechanical ones.
"""
from __future__ import annotations

import copy

from collections.abc import Mapping, MutableMapping

import numpy as np
import pandas as pd

from mechsim.dynamics.extrema import Interval, ReadingFailed, apart, intervals_of, read_all, tie_of
from mechsim.dynamics.tables import TableColumns
from mechsim.dynamics.trajectory_reader import TrajectoryReader

HOW_THERMAL = ("located: the mechanics re-integrated from the nearest output row at 1/10 of the run's tolerances "
               "(the network's states in the same DAE) and the thermal formulas evaluated there")
HOW_THERMAL_CYCLE = ("located: the mechanics re-integrated from the nearest output row at 1/10 of the run's "
                     "tolerances (after the simulated window at the periodic turn's phase), the network's states "
                     "the DAE's, then the cycle-averaged solution at the instant, and the thermal formulas there")
HOW_THERMAL_CLOSED = ("located: the closed form's extremum between output rows (its candidates sampled at most 0.5° "
                      "of drive angle apart, 100 000 samples a run at most), the network's states integrated exactly in its modes "
                      "from the output row before the instant, and the thermal formulas there")
HOW_THERMAL_CYCLE_CLOSED = ("located: the closed form's extremum between output rows, the network's states integrated "
                            "exactly in its modes from the output row before the instant, after the simulated window "
                            "the cycle-averaged solution at the instant, and the thermal formulas there")
#: instants this close to an interval's end (relative to the run's time scale) count as its one-sided limit
ROUNDOFF = 1e-12


def _breaks(events: pd.DataFrame) -> list[tuple[float, str]]:
    if events is None or not len(events):
        return []
    kinds = events["kind"].astype(str).tolist() if "kind" in events else ["event"] * len(events)
    return sorted((float(t), f"event '{k}' at t = {float(t):.9g} s")
                  for t, k in zip(events["t_s"].to_numpy(float), kinds))


def _median(x: np.ndarray) -> float:
    """numpy.median of sorted instants, as it computes it (the middle one, or the mean of the middle two)."""
    m = len(x) // 2
    return float(x[m]) if len(x) % 2 else float(np.mean(x[m - 1:m + 1]))


def _clip(x, lo, hi):
    """numpy.clip(x, lo, hi) (its definition, min(max(x, lo), hi)) without its wrapper's cost."""
    return np.minimum(np.maximum(x, lo), hi)


def _column(v) -> np.ndarray:
    """A reading's column as a frame's column gives it back (`to_numpy`): numpy strings as objects."""
    v = np.asarray(v)
    return v.astype(object) if v.dtype.kind in "US" else v


class _Columns(MutableMapping):
    """Named column arrays in order, each made when first read (`source(name)`) unless set: a reading's columns,
    of which its users read a few (the thermal formulas' inputs, a check's column, an extremum's row)."""

    def __init__(self, names, source, got: dict | None = None):
        self._names, self._source, self._got = list(names), source, dict(got or {})
        self._known = set(self._names)

    def __getitem__(self, name):
        got = self._got.get(name)
        if got is None:
            if name not in self._known:
                raise KeyError(name)
            got = self._got[name] = self._source(name)
        return got

    def __setitem__(self, name, value):
        if name not in self._known:
            self._names.append(name)
            self._known.add(name)
        self._got[name] = value

    def __delitem__(self, name):
        self._names.remove(name)
        self._known.discard(name)
        self._got.pop(name, None)

    def __contains__(self, name) -> bool:
        return name in self._known

    def __iter__(self):
        return iter(self._names)

    def __len__(self) -> int:
        return len(self._names)


class _Mixed(Exception):
    """Readings whose column has different dtypes: their thermal columns are evaluated one reading at a time."""


class _Stacked(Mapping):
    """The readings' columns (mappings with the same names) one after the other, each column joined when first
    read (the thermal formulas read a few); `_Mixed` where a column's dtypes differ (joining would promote it)."""

    def __init__(self, parts: list):
        self._parts, self._got = parts, {}

    def __getitem__(self, name):
        got = self._got.get(name)
        if got is None:
            arrays = [p[name] for p in self._parts]
            if any(a.dtype != arrays[0].dtype for a in arrays[1:]):
                raise _Mixed(name)
            got = self._got[name] = np.concatenate(arrays)
        return got

    def __contains__(self, name) -> bool:
        return name in self._parts[0]

    def __iter__(self):
        return iter(self._parts[0])

    def __len__(self) -> int:
        return len(self._parts[0])


def _with_new(columns, new: dict, drop: list[str]) -> _Columns:
    """`columns` without `drop`, those of `new` present replaced in place and the others appended in order (as
    thermal/plan.py `_with_columns` makes a frame of them), the columns read from `columns` when first read."""
    names = [k for k in columns if k not in drop]
    kept = set(names)
    return _Columns(names + [k for k in new if k not in kept], columns.__getitem__, new)


def _reading_columns(reading: Mapping, back: np.ndarray | None) -> _Columns:
    """A window reading's columns at the instants that asked for it: `back` maps each to its distinct instant
    (`ThermalReader._frame_asks`; None: one each)."""
    if back is None:
        return _Columns(reading, lambda k: _column(reading[k]))
    return _Columns(reading, lambda k: _column(reading[k])[back])


def _frame_columns(parts: list[tuple[np.ndarray, Mapping]], n: int) -> Mapping[str, np.ndarray]:
    """The columns of `n` rows put together from `parts` (row positions, their columns' arrays), as one frame of
    the parts concatenated and sorted by row would hold them; a frame is made only where the parts' columns or
    dtypes differ (its concatenation fills and promotes them)."""
    keys = list(parts[0][1])
    if len(parts) == 1:
        return parts[0][1]
    if all(list(p) == keys and all(p[k].dtype == parts[0][1][k].dtype for k in keys) for _, p in parts[1:]):
        out = {}
        for k in keys:
            column = np.empty(n, dtype=parts[0][1][k].dtype)
            for rows, p in parts:
                column[rows] = p[k]
            out[k] = column
        return out
    frames = []
    for rows, p in parts:
        part = pd.DataFrame(dict(p))
        part.index = rows
        frames.append(part)
    frame = pd.concat(frames).sort_index().reset_index(drop=True)
    return {c: frame[c].to_numpy() for c in frame.columns}


class _KeptReadings:
    """A thermal reader's readings kept for the run: a reading depends only on the interval's ends and the instants
    (not on the row position, which these readers do not use), and the columns' end limits ask for the same one
    again (`dynamics/extrema.py` `end_limits`: each column and sense reads the ends that may beat its extremum).
    `read_many` reads many requests in one pass (`_readings`: the thermal columns of all their instants evaluated
    together), `dynamics/extrema.py` `read_all` as it calls it; called, one request (the reader's error raised)."""

    @staticmethod
    def _key(iv: Interval, times: np.ndarray):
        return iv.lo, iv.hi, np.asarray(times, dtype=float).tobytes()

    def __call__(self, iv: Interval, position: int, times: np.ndarray) -> Mapping:
        times = np.asarray(times, dtype=float)
        kept = self.__dict__.setdefault("_kept", {})
        key = self._key(iv, times)
        got = kept.get(key)
        if got is None:
            got = self._readings([(iv, position, times)])[0]
            if isinstance(got, ReadingFailed):
                raise got
            kept[key] = got
        return got

    def read(self, iv: Interval, position: int, times: np.ndarray) -> Mapping:
        return self(iv, position, times)

    def read_many(self, requests: list[tuple[Interval, int, np.ndarray]]) -> list[Mapping | None]:
        """The readings of every (interval, position, times), those not kept read together; None where a reading
        failed (the caller reads it alone, and meets its error)."""
        kept = self.__dict__.setdefault("_kept", {})
        keys = [self._key(iv, times) for iv, _, times in requests]
        new = {}
        for k, (iv, position, times) in zip(keys, requests):
            if k not in kept and k not in new:
                new[k] = (iv, position, np.asarray(times, dtype=float))
        if new:
            for k, got in zip(new, self._readings(list(new.values()))):
                if not isinstance(got, ReadingFailed):
                    kept[k] = got
        return [kept.get(k) for k in keys]

    def _readings(self, requests: list[tuple[Interval, int, np.ndarray]]) -> list:
        """Each request's columns (a mapping of column arrays) or its ReadingFailed: each request's table columns
        read as `_columns` gives them, then the thermal columns of all of them with the same columns evaluated at
        once (the finish's formulas act row by row: each row's values are the same as on its own) and cut back into
        the requests."""
        out = self._columns_many(requests)
        groups: dict = {}
        for i, got in enumerate(out):
            if not isinstance(got, ReadingFailed):
                groups.setdefault(tuple(got[0]), []).append(i)
        for rs in groups.values():
            frames = [out[i] for i in rs]
            try:
                tables = self._thermal(frames)
            except _Mixed:
                tables = [t for f in frames for t in self._thermal([f])]
            for i, table in zip(rs, tables):
                out[i] = table
        return out

    def _columns_many(self, requests: list[tuple[Interval, int, np.ndarray]]) -> list:
        """`_columns` of each request, or its ReadingFailed."""
        out: list = []
        for request in requests:
            try:
                out.append(self._columns(*request))
            except ReadingFailed as error:
                out.append(error)
        return out

    def _thermal(self, frames: list[tuple]) -> list[_Columns]:
        """Each reading's columns with the thermal columns (thermal/plan.py `ThermalPlan.thermal_columns`, as its
        `_add_columns` puts them in a frame), evaluated on all the readings at once."""
        if len(frames) == 1:
            columns, states, since = frames[0]
        else:
            columns = _Stacked([f[0] for f in frames])
            states = None if frames[0][1] is None else np.concatenate([f[1] for f in frames])
            since = np.concatenate([f[2] for f in frames])
        th = self.thermal
        new, drop = th.thermal_columns(columns, self.mech.contact_state(columns), states, since)
        if len(frames) == 1:
            return [_with_new(columns, new, drop)]
        out, a = [], 0
        for f in frames:
            m = len(f[2])
            out.append(_with_new(f[0], {c: v[a:a + m] for c, v in new.items()}, drop))
            a += m
        return out


def turn_spacing(finest, period: float, spans: list[tuple[float, float]]):
    """A cycle-averaged run's sample spacing per gap (`with_rowless`'s `finest`, a time or a function of the
    knots): at most 1/720 of the turn (0.5 degree of drive) on the gaps that reach into one of `spans` (lo, hi),
    none elsewhere (`cycle_finest`)."""
    def spacing(knots: np.ndarray) -> np.ndarray:
        lo, hi = knots[:-1], knots[1:]
        step = np.minimum(finest(knots) if callable(finest) else finest, period / 720.0)
        near = np.zeros(len(lo), dtype=bool)
        for a, b in spans:
            near |= (hi > a) & (lo < b)
        return np.where(near, step, np.inf)
    return spacing


class ThermalReader(_KeptReadings):
    """Every column of the finished table (mechanical and thermal) at any instants of a smooth interval of it,
    read as module docstring says: `read(interval, position, times)` as `dynamics/extrema.py` readers are (the
    position is not used: each reading starts from the window's output row nearest its instants); called or read,
    the reading kept, `read_many` many at once (`_KeptReadings`)."""

    def __init__(self, thermal, traj, window: pd.DataFrame, events: pd.DataFrame, mech, settings, t_table_end: float):
        self.thermal, self.mech = thermal, mech
        self.reader = TrajectoryReader(traj, mech.angle_coordinates, settings)
        #: the mechanics' reader starts where the window has no row (`TrajectoryReader._anchor`: the state the run's
        #: segment started from, or its dense output)
        self.anywhere = bool(getattr(traj, "starts", None)) or getattr(traj, "dense", None) is not None
        columns = TableColumns(window)          # the window's column arrays, each read from the frame once
        t_win = np.asarray(columns["t_s"], dtype=float)
        self.t_sim_end = float(traj.pieces[-1].t[-1])
        win_events = events if events is None or not len(events) else events[
            events["t_s"].to_numpy(float) <= self.t_sim_end]
        self.windows = intervals_of(t_win, _breaks(win_events), float(t_win[0]), self.t_sim_end)
        anchors = self.reader.anchors(t_win)
        for iv in self.windows:       # every row's (piece, row), as `TrajectoryReader.anchors` gives them
            iv.rows = np.asarray(iv.rows, dtype=int)
            iv.anchors = anchors[iv.rows]
        self.t_win = t_win
        self.lows = np.array([iv.lo for iv in self.windows])
        self.highs = np.array([iv.hi for iv in self.windows])
        self.starts = np.asarray(mech.contact_starts(columns, win_events), dtype=float)
        self.solution = None
        self.cycle = t_table_end > self.t_sim_end * (1 + ROUNDOFF) + ROUNDOFF
        if self.cycle:
            self.solution = thermal.cycle_solution(window)
            if self.solution is None:
                raise ValueError("no cycle-averaged solution for the window")
            from mechsim.thermal.cycle import cumulative
            a, P = self.solution["t_start"], self.solution["period"]
            self.per_turn = {c: float(np.diff(np.interp([a, a + P], t_win, window[c].to_numpy(float)))[0])
                             for c in window.columns if cumulative(c)}
        self.scale = max(1.0, abs(t_table_end))
        self.how = HOW_THERMAL_CYCLE if self.cycle else HOW_THERMAL

    def sampler(self, trusted: float | None = None):
        """What samples the thermal columns between rows for the candidates (`locate_thermal`'s `finest`), or None
        (a cycle-averaged run, whose later rows repeat the simulated turns; a run without the states to
        interpolate): this reader itself on a dense output (its readings cost no integration), else a copy of it
        that reads the mechanics and the network's states, DAE states of the run, interpolated between the run's
        own (`TrajectoryReader.sampler`, a gap re-integrated where the interpolation may err by more than
        `trusted`). They rank the candidates; every located value is read by this reader."""
        if self.cycle:
            return self if self.anywhere else None
        states = self.reader.sampler(trusted)
        if states is None or not hasattr(states, "read_many"):
            return None if states is None else self
        clone = copy.copy(self)
        clone.__dict__.pop("_kept", None)           # (its readings are not this reader's)
        clone.reader = states
        return clone

    def cycle_finest(self, finest: float, t_end: float):
        """A cycle-averaged run's sample spacing per gap (`with_rowless`'s `finest`), as a closed form's
        (`ClosedFormThermalReader.cycle_finest`) but only over the turn after the simulated rows and the table's
        last turn: the samples are read on the window's periodic turn (its mechanics re-integrated from the
        window's rows), and the simulated rows are the run's own, located as a resolved run's. internal-geneva-motor
        over 300 s at 0.05 s rows: the contact temperature's maximum was another turn's, 35.1367 C at t = 286.3 s,
        against 35.2099 C at the last exit."""
        P = self.solution["period"]
        return turn_spacing(finest, P, [(self.t_sim_end, self.t_sim_end + P), (t_end - P, np.inf)])

    def read_at(self, times: np.ndarray, spans: list[tuple[Interval, int, int]]) -> Mapping:
        """Every column at `times`, times[a:b] in the interval of each (interval, a, b) of `spans`, read as one
        reading (`dynamics/extrema.py` `with_rowless`'s sampler): the window's columns of all of them in one pass
        of the mechanics' reader, the thermal formulas once."""
        times = np.asarray(times, dtype=float)
        lo, hi = np.empty(len(times)), np.empty(len(times))
        for iv, a, b in spans:
            lo[a:b], hi[a:b] = iv.lo, iv.hi
        at, parts, before = self._window_asks(times, lo, hi, rowless=True)
        asks = [(wiv, pos, distinct) for _, wiv, pos, distinct, _ in parts]
        got = [r if r is not None else self.reader(*ask) for r, ask in zip(self.reader.read_many(asks), asks)]
        return self._thermal([self._framed(times, at, parts, got, before)])[0]

    def _phase(self, t: np.ndarray) -> np.ndarray:
        """The window instant standing for each instant: itself within the simulated window, else the periodic
        turn's at the same phase."""
        if not self.cycle:
            return t
        a, P = self.solution["t_start"], self.solution["period"]
        return np.where(t <= self.t_sim_end, t, a + np.mod(t - a, P))

    def _columns(self, iv: Interval, position: int, times: np.ndarray) -> tuple[dict, np.ndarray | None, np.ndarray]:
        """(the window's columns at the instants, the network's states there, the times since the contact began)
        for the thermal columns (`_KeptReadings._readings`)."""
        got = self._columns_many([(iv, position, times)])[0]
        if isinstance(got, ReadingFailed):
            raise got
        return got

    def _columns_many(self, requests: list[tuple[Interval, int, np.ndarray]]) -> list:
        """`_columns` of each request (or its ReadingFailed), the window readings of all of them read in one pass of
        the mechanics' reader (`TrajectoryReader.read_many`: one read-out per mode, not one per reading)."""
        places, asks = [], []
        for iv, _, times in requests:
            try:
                at, parts, before = self._window_asks(times, iv.lo, iv.hi)
            except ReadingFailed as error:
                places.append(error)
                continue
            places.append((times, at, parts, len(asks), before))
            asks += [(wiv, pos, distinct) for _, wiv, pos, distinct, _ in parts]
        readings = self.reader.read_many(asks) if asks else []
        out: list = []
        for place in places:
            if isinstance(place, ReadingFailed):
                out.append(place)
                continue
            times, at, parts, a, before = place
            try:
                got = [r if r is not None else self.reader(*ask)          # not read together: alone, its error raised
                       for r, ask in zip(readings[a:a + len(parts)], asks[a:a + len(parts)])]
            except ReadingFailed as error:
                out.append(error)
                continue
            out.append(self._framed(times, at, parts, got, before))
        return out

    def _window_asks(self, times: np.ndarray, lo, hi, rowless: bool = False) -> tuple:
        """(the window instants standing for `times` in (lo, hi) (one for all, or each its own), the window readings
        to ask for them (`_frame_asks`), which are limits from before an end (`_before`)); ReadingFailed where a
        window interval has no row, unless `rowless` (a sampler's reader, which reads any instant of the run)."""
        at, which = self._window_instants(times, lo, hi)
        return at, self._frame_asks(at, which, rowless), self._before(at, which)

    def _framed(self, times: np.ndarray, at: np.ndarray, parts: list, got: list, before: np.ndarray) -> tuple:
        """`_columns`' value from the window readings `got` of `_window_asks`' `parts`."""
        return self._finish(times, at, _frame_columns(
            [(pick, _reading_columns(r, back)) for (pick, _, _, _, back), r in zip(parts, got)], len(at)), before)

    def stored_ends(self, ends: list[tuple[Interval, str]]) -> np.ndarray:
        """Whether the one-sided limit at each (interval, side) is read from a state the run holds
        (`TrajectoryReader.stored_ends`): the instant standing for it (`_window_instants`) at the same end of its
        window interval, and the mechanics' reader holding that end."""
        return self._stored(ends)[0]

    def _stored(self, ends: list[tuple[Interval, str]]) -> tuple[np.ndarray, ...]:
        """(`stored_ends`, each end's instant, its window instant, its window interval, whether it is an 'after'
        limit), the window instants of all ends found at once (`_window_instants`)."""
        n = len(ends)
        if not n:
            return np.zeros(0, dtype=bool), np.zeros(0), np.zeros(0), np.zeros(0, dtype=np.int64), np.zeros(0, bool)
        after = np.array([side == "after" for _, side in ends], dtype=bool)
        lo = np.array([iv.lo for iv, _ in ends], dtype=float)
        hi = np.array([iv.hi for iv, _ in ends], dtype=float)
        te = np.where(after, lo, hi)
        at, which = self._window_instants(te, lo, hi)
        edge = np.where(after, self.lows[which], self.highs[which])
        same = np.flatnonzero(np.abs(at - edge) <= 1e-12 * np.maximum(1.0, np.abs(edge)))
        stored = np.zeros(n, dtype=bool)
        stored[same] = self.reader.stored_ends([(self.windows[w], "after" if a else "before")
                                                for w, a in zip(which[same].tolist(), after[same].tolist())])
        return stored, te, at, which, after

    def limits(self, ends: list[tuple[Interval, str]], names: list[str]) -> np.ndarray:
        """The columns `names` (thermal ones included) at each (interval, side) end whose mechanics the run holds
        (`stored_ends`): the mechanics read out there in one pass (`TrajectoryReader.stored_columns`), then the
        thermal formulas on all of them at once, as `_readings` evaluates them; NaN elsewhere (`dynamics/extrema.py`
        `stored_limits`)."""
        out = np.full((len(names), len(ends)), np.nan)
        stored, te, at, which, after = self._stored(ends)
        pick = np.flatnonzero(stored)
        if not len(pick):
            return out
        stacked, read = self.reader.stored_columns([(self.windows[w], "after" if a else "before")
                                                    for w, a in zip(which[pick].tolist(), after[pick].tolist())])
        if stacked is None:
            return out
        pick = pick[read]
        table = self._thermal([self._finish(te[pick], at[pick], _reading_columns(stacked, None), ~after[pick])])[0]
        for m, c in enumerate(names):
            if c in table:
                out[m, pick] = np.asarray(table[c], dtype=float)
        return out

    def _window_instants(self, times: np.ndarray, lo, hi) -> tuple[np.ndarray, np.ndarray]:
        """(the window instant standing for each instant, the window interval it is read in), each instant in the
        interval (lo, hi) (one for all, or each its own)."""
        eps = ROUNDOFF * self.scale
        # the window interval of each instant, found from the instant nudged inside its interval (an instant at its
        # end is its one-sided limit: the window interval on the same side of the event), then clipped into it
        inner = np.where(hi - lo > 4e3 * eps, _clip(times, lo + 1e3 * eps, hi - 1e3 * eps), times)
        which = _clip(np.searchsorted(self.lows, self._phase(inner), side="right") - 1, 0, len(self.windows) - 1)
        return _clip(self._phase(times), self.lows[which], self.highs[which]), which

    def _before(self, at: np.ndarray, which: np.ndarray) -> np.ndarray:
        """Which window instants are the limit from before their window interval's end (at its end, not its start)."""
        eps = 1e-12 * np.maximum(1.0, np.abs(at))
        return (np.abs(self.highs[which] - at) <= eps) & (at - self.lows[which] > eps)

    def _finish(self, times: np.ndarray, at: np.ndarray, frame, before: np.ndarray) -> tuple:
        """`_columns`' value from the window's columns `frame` at the window instants `at` of the instants; `before`:
        those that are the limit from before an event (`_before`), where a contact starting at it has not begun."""
        frame["t_s"] = times
        late = times > self.t_sim_end if self.cycle else np.zeros(len(times), bool)
        if self.cycle:
            frame["window_t_s"] = at
        if late.any():            # the turns continued: cumulative columns advance by one turn's increase per turn
            turns = np.where(late, np.round((times - at) / self.solution["period"]), 0.0)
            for c in list(frame):
                if c in self.per_turn:
                    frame[c] = np.asarray(frame[c], dtype=float) + turns * self.per_turn[c]
        th = self.thermal
        ext = th.setup.extension
        states = None
        if ext is not None:
            states = np.column_stack([np.asarray(frame[name], dtype=float) for name in ext.names])
            if late.any():        # after the window: the cycle-averaged solution's states (no bookkeeping energies)
                n = th.setup.system.size
                states[late] = np.nan
                states[late, :n] = th.cycle_states(self.solution, times[late])
        return frame, states, th._time_since(at, self.starts, before)

    def frame_columns(self, at: np.ndarray, which: np.ndarray) -> Mapping[str, np.ndarray]:
        """The window's columns (mechanics and the network's states) at the window instants `at`, each in the
        window interval `which` (its end: the one-sided limit from inside it), in their order: the mode
        re-integrated from the interval's output row nearest the instants read in it."""
        return _frame_columns([(pick, _reading_columns(self.reader(wiv, pos, distinct), back))
                               for pick, wiv, pos, distinct, back in self._frame_asks(at, which)], len(at))

    def _frame_asks(self, at: np.ndarray, which: np.ndarray, rowless: bool = False) -> list[tuple]:
        """The readings `frame_columns` takes: (the instants' positions, window interval, its output row to read
        from, the distinct window instants in order, each instant's index among them or None where they are the
        instants themselves), per window interval the instants lie in; ReadingFailed where one has no row, unless
        `rowless` (the sampler's reader, its interpolated states or a dense output, starts from no row: row 0)."""
        parts = []
        one = len(which) and which.min() == which.max()
        for w in ([int(which[0])] if one else np.unique(which).tolist()):
            pick = np.arange(len(which)) if one else np.flatnonzero(which == w)
            wiv = self.windows[w]
            if not len(wiv.rows) and not (rowless or self.anywhere):
                raise ReadingFailed(f"no output row between t = {wiv.lo:.9g} and {wiv.hi:.9g} s to read from")
            # each distinct window instant read once (instants a period apart, or clipped to an end, coincide): in
            # increasing order already (as the readings ask), the instants themselves
            x = at if one else at[pick]
            if len(x) < 2 or bool((x[1:] > x[:-1]).all()):
                distinct, back, ordered = x, None, x
            else:
                distinct, back = np.unique(x, return_inverse=True)
                back, ordered = np.ravel(back), np.sort(x)
            pos = int(np.argmin(np.abs(self.t_win[wiv.rows] - _median(ordered)))) if len(wiv.rows) else 0
            parts.append((pick, wiv, pos, distinct, back))
        return parts

    def frame(self, at: np.ndarray, which: np.ndarray) -> pd.DataFrame:
        """`frame_columns` as a frame."""
        return pd.DataFrame(dict(self.frame_columns(at, which)))

    def readings(self):
        """The window's `WindowReadings` (thermal/plan.py) for the cycle averaging: the window's columns at any
        instants of it (at an event: the limit from after it), and its events."""
        from mechsim.thermal.plan import WindowReadings

        def read(times):
            times = np.asarray(times, dtype=float)
            which = np.clip(np.searchsorted(self.lows, times, side="right") - 1, 0, len(self.windows) - 1)
            return self.frame(np.clip(times, self.lows[which], self.highs[which]), which)
        return WindowReadings(read, [iv.lo for iv in self.windows[1:]])


def window_readings(thermal, traj, window: pd.DataFrame, events: pd.DataFrame, mech, settings):
    """The `WindowReadings` of a DAE run's mechanics window (`ThermalReader.readings`), for thermal/plan.py's cycle
    averaging; None where the window cannot be read (no output rows in it)."""
    try:
        return ThermalReader(thermal, traj, window, events, mech, settings, float(traj.pieces[-1].t[-1])).readings()
    except ValueError:
        return None


class ClosedFormThermalReader(_KeptReadings):
    """Every column of a closed-form run's finished table at any instants of a smooth interval of it (module
    docstring), as `ThermalReader` reads a DAE run's: the closed form's columns (`mechanics`: the run's reader of
    them, scenarios/peaks.py, which reads an interval by its ends), the network's states integrated exactly from the
    window's row at or before each instant (or the cycle-averaged solution after the simulated rows), and the
    finish's thermal columns there; called, the reading kept (`_KeptReadings`)."""

    def __init__(self, thermal, source, window: pd.DataFrame, events: pd.DataFrame, t_table_end: float, mechanics):
        from mechsim.thermal import cycle as cyc
        from mechsim.thermal.exact import ModalNetwork
        self.thermal, self.mech = thermal, source.mech
        mech, si = source.mech, source.si
        t_win = window["t_s"].to_numpy(float)
        self.mechanics = mechanics
        self.states, self.inputs, self.breaks = thermal._window_states(window)
        if self.breaks is None:       # no network (the flash model): the switches alone
            from mechsim.thermal.exact import contact_switches
            self.breaks = contact_switches(mech, si["initial"][mech.initial_keys[0]], thermal.speed, t_win)
        ext = thermal.setup.extension
        self.network = None if self.states is None else ModalNetwork(ext.system, ext.loss)
        self.t_win = t_win
        self.cycle = t_table_end > t_win[-1] * (1 + ROUNDOFF) + ROUNDOFF
        self.t_sim = float(t_win[-1])
        self.solution = None
        win_events = events
        if self.cycle:
            self.t_sim = float(t_win[cyc.simulated_rows(t_win, float(si["duration"]), float(si["output_step"]))[-1]])
            self.solution = thermal.cycle_solution(window)
            if self.solution is None:
                raise ValueError("no cycle-averaged solution for the window")
            if events is not None and len(events):
                win_events = events[events["t_s"].to_numpy(float) <= t_win[-1]]
        self.starts = np.asarray(mech.contact_starts(window, win_events), dtype=float)
        self.how = HOW_THERMAL_CYCLE_CLOSED if self.cycle else HOW_THERMAL_CLOSED

    def sampler(self, trusted: float | None = None):
        """What samples the thermal columns between rows for the candidates (`locate_thermal`'s `finest`): this
        reader itself where the columns need no network states (the flash model) or the run is cycle-averaged (its
        samples next to the run's ends only, `cycle_finest`), else one that reads the closed form at the instants
        and takes the network's states there by linear interpolation between the window's rows. The bulk temperatures
        change slowly against the output step, and the sharp part of a contact temperature, the flash rise, is
        algebraic in the contact read exactly, so the samples rank the candidates; every located value is then
        read as any reading is (`_KeptReadings`). trusted: a DAE sampler's (`ThermalReader.sampler`); the
        mechanics here are exact."""
        if self.cycle:
            return self
        return self if self.states is None else _InterpolatedStates(self)

    def cycle_finest(self, finest: float, t_end: float):
        """A cycle-averaged run's sample spacing per gap (`with_rowless`'s `finest`): 1/720 of the turn (0.5 degree
        of drive) from the run's start to a turn after the simulated rows and over the table's last turn, none
        between. The later turns repeat the window's periodic turn on the cycle-averaged bulk, whose mean rises
        (or falls) monotonically toward its steady state: their largest and least values lie next to those ends,
        which the rows' estimates rank among turns that differ by a fraction of the bulk's rise per turn (an hour
        of geneva-seed-lc1-mu015 at 0.1 s rows: another turn's engagement, 2.2 mK below the last turn's)."""
        P = self.solution["period"]
        return turn_spacing(finest, P, [(-np.inf, self.t_sim + P), (t_end - P, np.inf)])

    def kinks(self, lo: float, hi: float) -> list[tuple[float, str]]:
        """The heat input's switches inside (lo, hi) that are no event of the table (thermal/exact.py
        `switch_times`: a slip reversal, a flank switch), as (time, kind) breaks: the thermal columns kink there
        (the flash rise follows |slip speed|), so an extremum there is read as the one-sided limits; after the
        simulated rows the periodic turn's, every period."""
        found = [b for b in self.breaks if b <= self.t_sim]
        if self.cycle:
            a, P = self.solution["t_start"], self.solution["period"]
            turn = np.array([b for b in self.breaks if a <= b < a + P])
            if len(turn):
                m = np.arange(np.floor((self.t_sim - a) / P), np.ceil((hi - a) / P) + 1)
                later = (turn[None, :] + P * m[:, None]).ravel()
                found += later[later > self.t_sim].tolist()
        return [(float(b), f"switch of the heat input at t = {b:.9g} s") for b in sorted(found) if lo < b < hi]

    def _window_time(self, t: np.ndarray) -> np.ndarray:
        """The window instant at the same phase of the periodic turn (after the simulated rows), else t itself."""
        if not self.cycle:
            return t
        a, P = self.solution["t_start"], self.solution["period"]
        return np.where(t <= self.t_sim, t, a + np.mod(t - a, P))

    def _networks(self, times: list[np.ndarray]) -> list[np.ndarray | None]:
        """The network's states (with the bookkeeping energies; NaN after the simulated rows) at each array of
        instants, every integration from a row run together (`states_between_rows_many`)."""
        if self.states is None:
            return [None] * len(times)
        from mechsim.thermal.exact import states_between_rows_many
        n = self.thermal.setup.system.size
        outs, early, after = [], [], []
        for t in times:
            out = np.full((len(t), self.states.shape[1]), np.nan)
            late = t > self.t_sim if self.cycle else np.zeros(len(t), bool)
            if late.any():
                after.append((out, late, t[late]))
            if not late.all():
                early.append((out, ~late, t[~late]))
            outs.append(out)
        if after:        # the cycle-averaged solution at every request's later instants in one evaluation
            got = self.thermal.cycle_states(self.solution, np.concatenate([t for _, _, t in after]))
            a = 0
            for out, mask, t in after:
                out[mask, :n] = got[a:a + len(t)]
                a += len(t)
        if early:
            got = states_between_rows_many(self.network, self.inputs, self.breaks, self.t_win, self.states,
                                           [t for _, _, t in early], self.thermal.quadrature_piece)
            for (out, mask, _), states in zip(early, got):
                out[mask] = states
        return outs

    def _columns(self, iv: Interval, position: int, times: np.ndarray) -> tuple[dict, np.ndarray | None, np.ndarray]:
        """(the closed form's columns at the instants, the network's states there, the times since the contact
        began) for the thermal columns (`_KeptReadings._readings`)."""
        got = self._columns_many([(iv, position, times)])[0]
        if isinstance(got, ReadingFailed):
            raise got
        return got

    def _columns_many(self, requests: list[tuple[Interval, int, np.ndarray]]) -> list:
        """`_columns` of each request (or its ReadingFailed): the closed form of all of them read together where its
        reader reads many (`read_all`), the network's states of all of them integrated together (`_networks`: one
        evaluation of the heat input)."""
        out: list = []
        for (iv, position, times), reading in zip(requests, read_all(self.mechanics, requests)):
            try:
                reading = reading if reading is not None else self.mechanics(iv, position, times)
                frame = {k: _column(v) for k, v in reading.items()}
            except ReadingFailed as error:
                out.append(error)
                continue
            inner = iv.inside(times)          # the instants the closed form read (`Interval.inside`)
            at = self._window_time(inner)
            if self.cycle:
                frame["window_t_s"] = at
            out.append((frame, inner, at))
        networks = iter(self._networks([got[1] for got in out if not isinstance(got, ReadingFailed)]))
        return [got if isinstance(got, ReadingFailed) else
                (got[0], next(networks), self.thermal._time_since(got[2], self.starts)) for got in out]


class _InterpolatedStates:
    """`ClosedFormThermalReader.sampler` where the columns need the network's states: the closed form read at the
    instants, the states interpolated linearly between the window's rows and the heat input's switches (a contact's
    start and end: the states kink there, a bulk temperature peaks as a contact ends; integrated exactly there, so
    no sample interpolates across one), the finish's thermal columns there."""

    def __init__(self, reader: ClosedFormThermalReader):
        self.reader = reader
        self._nodes = None

    def _states(self, times: np.ndarray) -> np.ndarray:
        """The network's states at the instants, interpolated linearly between the nodes (`_nodes`: the rows and the
        switches inside the simulated window, made at the first call)."""
        r = self.reader
        if self._nodes is None:
            breaks = np.asarray(r.breaks, dtype=float)
            breaks = breaks[(breaks > r.t_win[0]) & (breaks < r.t_sim)]
            breaks = breaks[~np.isin(breaks, r.t_win)]
            t, states = r.t_win, r.states
            if len(breaks):
                at = r._networks([breaks])[0]
                t = np.concatenate([t, breaks])
                order = np.argsort(t, kind="stable")
                t, states = t[order], np.concatenate([states, at])[order]
            self._nodes = (t, states)
        t, states = self._nodes
        return np.column_stack([np.interp(times, t, states[:, j]) for j in range(states.shape[1])])

    def read_many(self, requests: list[tuple[Interval, int, np.ndarray]]) -> list[Mapping | None]:
        """Each request's columns, or None where its closed form could not be read."""
        r = self.reader
        frames, out = [], []
        for (iv, position, times), reading in zip(requests, read_all(r.mechanics, requests)):
            try:
                reading = reading if reading is not None else r.mechanics(iv, position, times)
            except ReadingFailed:
                out.append(None)
                continue
            inner = iv.inside(times)
            states = self._states(inner)
            frames.append(({k: _column(v) for k, v in reading.items()}, states, r.thermal._time_since(inner, r.starts)))
            out.append(len(frames) - 1)
        tables = r._thermal(frames) if frames else []
        return [None if k is None else tables[k] for k in out]


def thermal_reader(source, events: pd.DataFrame, t_table_end: float, mechanics=None):
    """The `ThermalReader` (a closed-form run: `ClosedFormThermalReader`, its closed form read by `mechanics`, the
    run's reader of it) of a finished run (scenarios/peaks.py Source), or None where its thermal columns are not read
    between rows (no thermal model, no mechanics window kept, no full turn to average)."""
    thermal = getattr(source, "thermal", None)
    window = getattr(source, "window", None)
    if thermal is None or window is None or not len(window):
        return None
    if source.method == "closed-form":
        if mechanics is None:
            return None
        try:
            return ClosedFormThermalReader(thermal, source, window, events, t_table_end, mechanics)
        except ValueError:
            return None
    if source.traj is None:
        return None
    try:
        return ThermalReader(thermal, source.traj, window, events, source.mech, source.settings, t_table_end)
    except ValueError:
        return None


def _interval_rows(intervals: list[Interval]) -> tuple[list[int], np.ndarray, np.ndarray]:
    """(the intervals with rows, their first rows, their last rows): what `_promising` reads of the intervals."""
    ks = [k for k, iv in enumerate(intervals) if len(iv.rows)]
    return (ks, np.array([intervals[k].rows[0] for k in ks], dtype=np.intp),
            np.array([intervals[k].rows[-1] for k in ks], dtype=np.intp))


def _promising(F: np.ndarray, intervals: list[Interval]) -> list[list[Interval]]:
    """For each column (a row of F): the intervals that may hold its maximum or minimum: those whose best row is
    within twice the largest change between neighbouring rows of the interval (the most an extremum between rows,
    or at an end's one-sided limit, can add to its rows: one step at that slope, twice for margin) of the best row;
    a column at a time (an hour's temporaries a column's, not the table's). Every such interval, not the best few
    by their rows: where the rows under-sample a peak its interval ranks low (geneva-torque with friction 0.15 and
    lumped temperatures at 2.3 ms rows: the contact temperature's maximum, 134.985 C, lay in an interval below the
    best 8, and 134.589 C was reported); the brackets refined among them are bounded by `dynamics/extrema.py`
    (CANDIDATES and its second round), however many intervals a long cycle-averaged run has."""
    ks, first, last = _interval_rows(intervals)
    if not ks:
        return [[] for _ in F]
    keep: list[set] = [set() for _ in F]
    for c, f in enumerate(F):         # a column at a time: an hour's temporaries are a column's, not the table's
        valued = np.isfinite(f)
        every = bool(valued.all())
        tie = tie_of(f, every)
        step = np.zeros(len(f))                 # |f[i+1] - f[i]|, 0 where not finite, and 0 after the last row
        with np.errstate(invalid="ignore"):     # (inf - inf: not finite, so 0 below)
            np.subtract(f[1:], f[:-1], out=step[:-1])
        np.abs(step, out=step)
        if not every or not np.isfinite(step).all():
            step[~np.isfinite(step)] = 0.0
        # the largest change between neighbours inside each interval (the step leaving its last row excluded)
        step[last] = 0.0
        slope = np.maximum.reduceat(step, first)
        for sense in (1.0, -1.0):           # (the largest of -f is minus the least of f, exactly)
            if every:
                top = np.maximum.reduceat(f, first) if sense > 0 else -np.minimum.reduceat(f, first)
            else:
                top = np.maximum.reduceat(np.where(valued, sense * f, -np.inf), first)
            top = np.where(last >= first, top, -np.inf)
            ok = np.isfinite(top)
            if not ok.any():
                continue
            floor = float(top[ok].max()) - tie
            keep[c].update(ks[i] for i in np.flatnonzero(ok & (top + 2.0 * slope >= floor)).tolist())
    return [[intervals[k] for k in sorted(mine)] for mine in keep]


def heat_breaks(reader, breaks: list[tuple[float, str]], lo: float, hi: float) -> list[tuple[float, str]]:
    """The events' `breaks` with the heat input's own switches inside (lo, hi) that are no event (within round-off
    of none): the reader's `kinks`, where it knows them (the thermal columns kink there)."""
    kinks = getattr(reader, "kinks", None)
    if kinks is None:
        return breaks
    near = ROUNDOFF * max(1.0, abs(hi)) * 1e3
    return sorted(breaks + apart(kinks(lo, hi), np.array([b for b, _ in breaks], dtype=float), near))


def locate_thermal(reader: ThermalReader, t: np.ndarray, cols, columns: list[str], events: pd.DataFrame,
                   windows: list[tuple[float, float, tuple[str, str]]], finest: float | None = None,
                   trusted: float | None = None) -> list[dict]:
    """For each window (lo, hi, the kinds of its ends) of the table: {column: ({'max', 'min'} located by
    `dynamics/extrema.py` `locate` with the reader, the intervals searched)} for the thermal columns over [lo, hi],
    between its events (a cycle-averaged run's repeated ones included) and the heat input's own switches where the
    reader knows them (`kinks`), on the intervals that may hold the extremum (`_promising`), then against the
    one-sided limits at the intervals' ends that may beat it (`dynamics/extrema.py` `end_limits`). Every window's and
    column's readings are read in one pass of the reader (`read_many`), then every one-sided limit the checks may
    read in another. finest: the columns are also sampled between the rows at most this far apart (a time, or one
    per gap: `with_rowless`), by the reader's `sampler`, as the mechanical columns are (scenarios/peaks.py
    `_finest`, `_rows_finest`), the samples candidates beside the rows (`trusted`: the sampler's, scenarios/peaks.py
    TRUSTED_RAD); the intervals handed back are the table's own."""
    from mechsim.dynamics.extrema import (column_plans, end_guesses, end_limit_requests, end_limits, end_lines,
                                          finish_all, refine_further, stored_limits, with_rowless)
    values = {c: np.asarray(cols[c], float) for c in columns}
    ties = {c: tie_of(f) for c, f in values.items()}
    events_breaks = _breaks(events)
    tables = [intervals_of(t, heat_breaks(reader, events_breaks, lo, hi), lo, hi, *kinds) for lo, hi, kinds in windows]
    if finest is not None and getattr(reader, "cycle", False) and hasattr(reader, "cycle_finest"):
        finest = reader.cycle_finest(finest, float(t[-1]))
    sampler = getattr(reader, "sampler", None) if finest is not None else None
    sampler = sampler(trusted) if sampler is not None else None
    own = [iv for intervals in tables for iv in intervals]              # the table's intervals, every window's
    back = {id(iv): iv for iv in own}
    if sampler is not None and own:
        # a DAE run's sampler reads all the samples at once (`read_at`), the rowless intervals read by the reader
        t, values, sampled = (with_rowless(t, values, own, reader, finest, sampler) if hasattr(sampler, "read_at")
                              else with_rowless(t, values, own, sampler, finest))
        if sampled is not own:
            # the samples put in time order among the rows, so that each interval's rows run on (`_promising` reads
            # an interval's rows as one stretch of the table)
            order = np.argsort(t, kind="stable")
            at = np.empty(len(order), dtype=np.int64)
            at[order] = np.arange(len(order))
            t, values = t[order], {c: v[order] for c, v in values.items()}
            sampled = [Interval(iv.lo, iv.hi, iv.lo_kind, iv.hi_kind, np.sort(at[iv.rows])) for iv in sampled]
            back = {id(b): a for a, b in zip(own, sampled)}
            sizes = np.cumsum([0] + [len(ivs) for ivs in tables]).tolist()
            tables = [sampled[a:b] for a, b in zip(sizes[:-1], sizes[1:])]
    F = np.array(list(values.values())).reshape(len(values), len(t))
    spans = [(intervals, dict(zip(values, _promising(F, intervals)))) for intervals in tables]
    # `locate` of each column on its own intervals: every window's and column's plan made together, the readings of
    # all of them at once, then their finish
    planned = iter(column_plans(t, values, [(c, own) for _, owns in spans for c, own in owns.items()]))
    spans = [(intervals, owns, {c: next(planned) for c in owns}) for intervals, owns in spans]
    every = [p for _, _, plans in spans for p in plans.values()]
    # every window's and column's brackets refined in one pass (`finish_all`)
    results = finish_all(every, read_all(reader, [r for p in every for r in p.requests]), reader)
    # the candidates beyond the first that may still beat them, in every window: a temperature rises with the bulk
    # through a periodic regime of the motion, so its turns do not repeat the same peaks
    refine_further(every, results, reader)
    done = iter(results)
    founds = [{c: next(done).get(c, {}) for c in plans} for _, _, plans in spans]
    # the one-sided limits that may beat each extremum, every window's read at once, then checked in order
    checks, ahead = [], []
    for (intervals, owns, _), found in zip(spans, founds):
        asks = [(c, sense, getattr(found[c].get(name), "value", None))
                for c in values for name, sense in (("max", 1.0), ("min", -1.0))]
        lines = end_lines(t, values, intervals)
        stored_limits(lines, intervals, reader)
        guesses = end_guesses(t, values, intervals, asks, ties, lines=lines) if asks else []
        for (c, sense, _), g in zip(asks, guesses):
            e = found[c].get("max" if sense > 0 else "min")
            ahead += end_limit_requests(intervals, [x for x in g if e is None or x[2] != e.t or e.limit != x[1]])
        checks.append((intervals, owns, found, asks, guesses, lines))
    read_all(reader, ahead)
    out = []
    for intervals, owns, found, asks, guesses, lines in checks:
        located = {}
        for (c, sense, _), g in zip(asks, guesses):
            name = "max" if sense > 0 else "min"
            got = found[c]
            e = end_limits(got.get(name), c, sense, t, values[c], owns[c], intervals, reader, ties[c], g, lines)
            if e is not None:
                got[name] = e
            located[c] = (got, [back[id(iv)] for iv in owns[c]])
        out.append(located)
    return out
