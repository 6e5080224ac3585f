"""The thermal columns' peaks located on the continuous solution, not at the output rows (docs/theory.md §K5,
docs/thermal.md "Reported temperatures").

The thermal finish (thermal/plan.py `ThermalPlan.finish`) computes its columns from each row's mechanical state and
the network's states: the flash rise and the Blok share are algebraic in the contact's state (force, sliding speeds,
time since the contact began), the contact temperature is the share-weighted bulk plus the flash rise. So every
thermal column can be evaluated at any instant from the mechanical state and the network's states there:

- up to the end of the mechanics run (a resolved run, or a cycle-averaged run's mechanics window), a DAE run holds
  the network's states in the same DAE as the mechanics: the mode re-integrated from an output row
  (`dynamics/extrema.py` `TrajectoryReader`) gives both, and the finish's own formulas the columns;
- after it (cycle averaging, thermal/cycle.py), the mechanics is the window's last full turn at the instant's
  phase (re-integrated there, not interpolated between its rows) and the network's states the cycle-averaged
  solution at the instant itself (`bulk_response`: the mean curve, exact in the network's modes, plus the
  periodic ripple).

`ThermalReader` is a `dynamics/extrema.py` reader of those columns on the run's table, so that `locate` finds their
extrema as it finds the mechanical ones. A closed-form run's network is integrated exactly between rows by its
own modal solution, which is not re-evaluated between rows: its thermal columns stay the rows' (said in `how`).
"""
from __future__ import annotations

import numpy as np
import pandas as pd

from mechsim.dynamics.extrema import Interval, ReadingFailed, TrajectoryReader, intervals_of

HOW_THERMAL = ("located: the mechanics re-integrated from the nearest output row at 1/10 of the run's tolerances "
               "(the network's states in the same DAE) and the thermal formulas evaluated there")
HOW_THERMAL_CYCLE = ("located: the mechanics re-integrated from the nearest output row at 1/10 of the run's "
                     "tolerances (after the simulated window at the periodic turn's phase), the network's states "
                     "the DAE's, then the cycle-averaged solution at the instant, and the thermal formulas there")
#: instants this close to an interval's end (relative to the run's time scale) count as its one-sided limit
ROUNDOFF = 1e-12


def _breaks(events: pd.DataFrame) -> list[tuple[float, str]]:
    if events is None or not len(events):
        return []
    kinds = events["kind"].astype(str).tolist() if "kind" in events else ["event"] * len(events)
    return sorted((float(t), f"event '{k}' at t = {float(t):.9g} s")
                  for t, k in zip(events["t_s"].to_numpy(float), kinds))


class ThermalReader:
    """Every column of the finished table (mechanical and thermal) at any instants of a smooth interval of it,
    read as module docstring says: `read(interval, position, times)` as `dynamics/extrema.py` readers are (the
    position is not used: each reading starts from the window's output row nearest its instants)."""

    def __init__(self, thermal, traj, window: pd.DataFrame, events: pd.DataFrame, mech, settings, t_table_end: float):
        self.thermal, self.mech = thermal, mech
        self.reader = TrajectoryReader(traj, mech.angle_coordinates, settings)
        t_win = window["t_s"].to_numpy(float)
        self.t_sim_end = float(traj.pieces[-1].t[-1])
        win_events = events if events is None or not len(events) else events[
            events["t_s"].to_numpy(float) <= self.t_sim_end]
        self.windows = intervals_of(t_win, _breaks(win_events), float(t_win[0]), self.t_sim_end)
        anchors = self.reader.anchors(t_win)
        for iv in self.windows:
            keep = [r for r in iv.rows if anchors[r] is not None]
            iv.rows, iv.anchors = np.asarray(keep, dtype=int), [anchors[r] for r in keep]
        self.t_win = t_win
        self.lows = np.array([iv.lo for iv in self.windows])
        self.starts = np.asarray(mech.contact_starts(window, win_events), dtype=float)
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

    def _phase(self, t: np.ndarray) -> np.ndarray:
        """The window instant standing for each instant: itself within the simulated window, else the periodic
        turn's at the same phase."""
        if not self.cycle:
            return t
        a, P = self.solution["t_start"], self.solution["period"]
        return np.where(t <= self.t_sim_end, t, a + np.mod(t - a, P))

    def __call__(self, iv: Interval, position: int, times: np.ndarray) -> dict:
        times = np.asarray(times, dtype=float)
        eps = ROUNDOFF * self.scale
        # the window interval of each instant, found from the instant nudged inside `iv` (an instant at iv's end is
        # its one-sided limit: the window interval on the same side of the event), then the instant clipped into it
        inner = np.clip(times, iv.lo + 1e3 * eps, iv.hi - 1e3 * eps) if iv.hi - iv.lo > 4e3 * eps else times
        which = np.clip(np.searchsorted(self.lows, self._phase(inner), side="right") - 1, 0, len(self.windows) - 1)
        later = times > self.t_sim_end
        out_frames = []
        for w, late in sorted(set(zip(which.tolist(), later.tolist()))):
            pick = (which == w) & (later == late)
            wiv = self.windows[w]
            if not len(wiv.rows):
                raise ReadingFailed(f"no output row between t = {wiv.lo:.9g} and {wiv.hi:.9g} s to read from")
            at = np.clip(self._phase(times[pick]), wiv.lo, wiv.hi)
            order = np.argsort(at, kind="stable")
            mid = float(np.median(at))
            pos = int(np.argmin(np.abs(self.t_win[wiv.rows] - mid)))
            frame = self.reader(wiv, pos, at[order])
            frame = pd.DataFrame({k: np.asarray(v) for k, v in frame.items()})
            back = np.empty(len(order), dtype=int)
            back[order] = np.arange(len(order))
            frame = frame.iloc[back].reset_index(drop=True)
            frame["t_s"] = times[pick]
            if self.cycle:
                frame["window_t_s"] = at
            if late:              # the turns continued: cumulative columns advance by one turn's increase per turn
                turns = np.round((times[pick] - at) / self.solution["period"])
                for c in frame.columns:
                    if c in self.per_turn:
                        frame[c] = frame[c].to_numpy(float) + turns * self.per_turn[c]
            out_frames.append((np.flatnonzero(pick), self._thermal(frame, at, late)))
        n = len(times)
        columns = list(dict.fromkeys(c for _, frame in out_frames for c in frame.columns))
        out = {}
        for c in columns:
            first = next(np.asarray(frame[c]) for _, frame in out_frames if c in frame)
            arr = np.empty(n, dtype=first.dtype if first.dtype.kind in "fiub" else object)
            if arr.dtype.kind == "f":
                arr[:] = np.nan
            for idx, frame in out_frames:
                arr[idx] = np.asarray(frame[c]) if c in frame else np.nan
            out[c] = arr
        return out

    def _thermal(self, frame: pd.DataFrame, at: np.ndarray, late: bool) -> pd.DataFrame:
        """The finish's thermal columns on a frame of mechanical readings (`at`: the window instants they are
        read at; `late`: after the simulated window, where the network's states are the cycle-averaged ones)."""
        th = self.thermal
        ext = th.setup.extension
        states = None
        if ext is not None:
            if late:
                n = th.setup.system.size
                states = np.full((len(frame), n + 3), np.nan)
                states[:, :n] = th.cycle_states(self.solution, frame["t_s"].to_numpy(float))
            else:
                states = frame[list(ext.names)].to_numpy(float)
        t_on_pin = th._time_since(at, self.starts)
        contact = self.mech.contact_state(frame)
        return th._add_columns(frame, contact, states, t_on_pin)


def thermal_reader(source, events: pd.DataFrame, t_table_end: float):
    """The `ThermalReader` of a finished run (scenarios/peaks.py Source), or None where its thermal columns are
    not read between rows (no thermal model, a closed-form run, no mechanics window kept)."""
    thermal = getattr(source, "thermal", None)
    window = getattr(source, "window", None)
    if thermal is None or window is None or source.traj is None or not len(window):
        return None
    try:
        return ThermalReader(thermal, source.traj, window, events, source.mech, source.settings, t_table_end)
    except ValueError:
        return None


#: intervals refined per column and sense at most (`_promising`): the best by their rows
PROMISING = 8


def _promising(f: np.ndarray, intervals: list[Interval]) -> list[Interval]:
    """The intervals that may hold the column's maximum or minimum: those whose best row is within twice the
    largest change between neighbouring rows of the interval (the most an extremum between rows, or at an end's
    one-sided limit, can add to its rows: one step at that slope, twice for margin) of the best row, at most
    PROMISING per sense, the best rows first and the earliest of equal ones (a tie goes to the earliest, as in
    `dynamics/extrema.py`). A long cycle-averaged run has thousands of intervals, the periodic columns' equal."""
    finite = np.abs(f[np.isfinite(f)])
    tie = 1e-13 * float(finite.max()) if finite.size else 0.0
    ks = [k for k, iv in enumerate(intervals) if len(iv.rows)]
    if not ks:
        return []
    first = np.array([intervals[k].rows[0] for k in ks])
    last = np.array([intervals[k].rows[-1] for k in ks])
    keep = set()
    for sense in (1.0, -1.0):
        v = np.where(np.isfinite(f), sense * f, -np.inf)
        top = np.maximum.reduceat(v, first)
        top = np.where(last >= first, top, -np.inf)
        step = np.abs(np.diff(f))
        step = np.r_[np.where(np.isfinite(step), step, 0.0), 0.0]
        # the largest change between neighbours inside each interval (the step leaving its last row excluded)
        step[last] = 0.0
        slope = np.maximum.reduceat(step, first)
        ok = np.isfinite(top)
        if not ok.any():
            continue
        floor = float(top[ok].max()) - tie
        able = np.flatnonzero(ok & (top + 2.0 * slope >= floor))
        order = sorted(able.tolist(), key=lambda i: (-(top[i] if top[i] < floor else floor), i))
        keep.update(ks[i] for i in order[:PROMISING])
    return [intervals[k] for k in sorted(keep)]


def locate_thermal(reader: ThermalReader, t: np.ndarray, cols, columns: list[str], events: pd.DataFrame, lo: float,
                   hi: float, kinds: tuple[str, str]) -> dict:
    """{column: ({'max', 'min'} located by `dynamics/extrema.py` `locate` with the reader, the intervals searched)}
    for the thermal columns over [lo, hi] of the table, between its events (a cycle-averaged run's repeated ones
    included), on the intervals that may hold the extremum (`_promising`)."""
    from mechsim.dynamics.extrema import locate
    intervals = intervals_of(t, _breaks(events), lo, hi, *kinds)
    out = {}
    for c in columns:
        f = np.asarray(cols[c], float)
        own = _promising(f, intervals)
        out[c] = (locate(t, {c: f}, own, reader).get(c, {}), own)
    return out
