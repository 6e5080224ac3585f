"""Cycle-averaged bulk temperatures for long runs (docs/theory.md §G5: tau >> cycle, so the mean heat drives the bulk).

The mechanics runs until it is periodic (a few crank turns); the last full turn gives the cycle-mean heat Q_bar
and the heat-weighted pin share gamma_bar (exact, from the integrated bookkeeping energies). The network is
linear and time-invariant, so with the input taken periodic from t = 0 its response splits exactly into
- the response to the constant mean input, from ambient: exact, as `thermal.integrate_mean_heat` (tested
  equal), evaluated in the network's modes so that an hour costs what a second does, and
- the ripple, the response to the zero-mean remainder u(t) - u_bar from zero: T~(t) = T~_p(t) - e^{At} T~_p(0),
  where T~_p is the periodic solution, found from one period's zero-state response Z by
  (I - e^{AP}) T~_p(0) = Z(P).
Fast nodes (the pin, tau ~ 5 s) keep their in-cycle swing this way; slow ones (crank, wheel) are the mean curve.
"""
from __future__ import annotations

import dataclasses
from dataclasses import dataclass
from typing import Callable

import numpy as np
import pandas as pd

from mechsim.thermal.exact import ModalNetwork
from mechsim.thermal.linear import LinearThermalSystem
from mechsim.thermal.lumped import ambient_temperatures

#: rows of the bulk history table over the whole duration
HISTORY_ROWS = 1001
#: phases within the period are resolved to this fraction of it (bulk_response)
PHASE_RESOLUTION = 1e-10


def turn_boundaries(t: np.ndarray, angle: np.ndarray, angle0: float) -> np.ndarray:
    """Times at which the drive angle passes angle0 + 2 pi m (m = 1, 2, ...), interpolated between rows."""
    if len(t) < 2 or not np.all(np.diff(angle) > 0):
        return np.array([])
    m = np.arange(1, int(np.floor((angle[-1] - angle0) / (2 * np.pi) + 1e-12)) + 1)
    return np.interp(angle0 + 2 * np.pi * m, angle, t)


@dataclass
class CycleMeans:
    """Mean heat, heat-weighted pin share and the period of the last full turn; periodicity against the one before."""

    t_start: float
    period: float
    heat_mean: float
    share_mean: float
    periodicity: float | None     # |Q_bar(last) - Q_bar(previous)| / Q_bar(last), None with one turn only


def cycle_means_from_energies(t: np.ndarray, bounds: np.ndarray, e_gen: np.ndarray, e_pin: np.ndarray) -> CycleMeans:
    """Q_bar = dE_gen/P, gamma_bar = dE_pin/dE_gen over the last full turn (E interpolated at its ends)."""
    a, b = bounds[-2], bounds[-1]
    G = np.interp([a, b], t, e_gen)
    Pn = np.interp([a, b], t, e_pin)
    energy = G[1] - G[0]
    share = (Pn[1] - Pn[0]) / energy if energy > 0 else 0.5
    periodicity = None
    if len(bounds) >= 3:
        prev = np.diff(np.interp(bounds[-3:-1], t, e_gen))[0] / (bounds[-2] - bounds[-3])
        mean = energy / (b - a)
        periodicity = abs(mean - prev) / mean if mean > 0 else 0.0
    return CycleMeans(float(a), float(b - a), float(energy / (b - a)), float(share), periodicity)


def bulk_response(system: LinearThermalSystem, means: CycleMeans, u_of_phase: Callable[[np.ndarray], np.ndarray],
                  phase_breaks: list[float], times: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """(mean response, mean + ripple) of the network states at `times` (s from the start, from ambient)."""
    times = np.asarray(times, dtype=float)
    n = system.size
    u_bar = np.array([means.share_mean * means.heat_mean, (1.0 - means.share_mean) * means.heat_mean])
    mean, _ = ModalNetwork(system).constant(ambient_temperatures(system), u_bar, times, energy=False)
    P = means.period
    s0 = (-means.t_start) % P                      # phase of t = 0 within the periodic turn
    # output rows a whole number of steps apart repeat the same few phases, up to the round-off of `t mod P`
    # (and of P itself); phases are snapped to PHASE_RESOLUTION * P so that an hour of rows integrates the
    # period once over those few phases, not over a million that differ in their last digits (the ripple then
    # moves by at most PHASE_RESOLUTION * P * |dT/dt|: ~1e-9 K at the seed's rates)
    phase = np.round((times % P) / (PHASE_RESOLUTION * P)) * (PHASE_RESOLUTION * P)
    phase = np.minimum(phase, P)
    tau = np.unique(np.concatenate([[0.0, P], phase]))
    breaks = sorted({(b - s0) % P for b in list(phase_breaks) + [0.0]} - {0.0})
    # the remainder must integrate to zero over the period to the quadrature's own accuracy: (I - e^{AP}) is
    # nearly singular for the slow modes (P/tau ~ 1e-3), so its mean is taken with the same quadrature
    u_own = _period_mean(u_of_phase, P, sorted(set(phase_breaks) | {0.0}))

    def ripple_input(x):
        return np.asarray(u_of_phase((s0 + np.asarray(x)) % P), dtype=float) - u_own[:, None]

    homogeneous = ModalNetwork(system, source=False)            # the ripple has no ambient source
    Z = homogeneous.integrate(ripple_input, tau, np.zeros(n + 3), breaks)[:, :n]
    start = homogeneous.resolvent_periodic(Z[-1], P)
    periodic = homogeneous.exp(tau, start) + Z
    ripple = periodic[np.searchsorted(tau, phase)] - homogeneous.exp(times, start)
    return mean, mean + ripple


def _period_mean(u_of_phase, period: float, breaks: list[float], nodes: int = 8, pieces: int = 64) -> np.ndarray:
    """(1/P) int_0^P u(s) ds by Gauss-Legendre on `pieces` sub-intervals of each smooth stretch between breaks."""
    x, w = np.polynomial.legendre.leggauss(nodes)
    edges = np.unique(np.concatenate([[0.0, period], [b for b in breaks if 0.0 < b < period]]))
    fine = np.unique(np.concatenate([np.linspace(a, b, pieces + 1) for a, b in zip(edges[:-1], edges[1:])]))
    h = np.diff(fine)
    s = (fine[:-1, None] + 0.5 * h[:, None] * (x[None, :] + 1.0)).ravel()
    weights = (0.5 * h[:, None] * w[None, :]).ravel()
    return np.asarray(u_of_phase(s), dtype=float) @ weights / period


def history_table(system: LinearThermalSystem, means: CycleMeans, u_of_phase, phase_breaks, duration: float,
                  kelvin: float) -> pd.DataFrame:
    """Bulk temperatures over the whole run (mean + ripple and mean only), HISTORY_ROWS rows."""
    times = np.linspace(0.0, duration, HISTORY_ROWS)
    mean, full = bulk_response(system, means, u_of_phase, phase_breaks, times)
    out = {"t_s": times, "heat_generated_J": means.heat_mean * times}
    for j, name in enumerate(system.state_names):
        if name.startswith("temp_bulk_"):
            base = name[:-2]
            out[f"{base}_C"] = full[:, j] - kelvin
            out[f"{base}_mean_C"] = mean[:, j] - kelvin
    return pd.DataFrame(out)


def output_times(duration: float, step: float) -> np.ndarray:
    """The run's output grid: 0, step, 2 step, ... and the end itself when it is not a multiple (as the runner's)."""
    n = int(np.floor(duration / step + 1e-9))
    t = np.minimum(step * np.arange(n + 1), duration)
    return t if t[-1] >= duration - 1e-12 else np.append(t, duration)


def cumulative(column: str) -> bool:
    """Columns that grow by a fixed amount per periodic turn (unwrapped angles, works) rather than repeat."""
    return column.endswith("_angle_rad") or (column.startswith("work_") and column.endswith("_J"))


def last_repetitions(t_rows: np.ndarray, period: float, duration: float) -> np.ndarray:
    """m_k = floor((duration - t_k)/P): how many whole periods after the periodic turn's row t_k its last repetition
    t_k + m_k P in the run lies (t_k + m_k P <= duration, to 1e-12 of a period). One rule for the run's continuation
    (`continue_periodically`) and the sensitivities' rows (thermal/cycle_exact.py `TurnLayout`)."""
    return np.floor((duration - np.asarray(t_rows, dtype=float)) / period + 1e-12).astype(np.int64)


def turn_rows(t: np.ndarray, t_start: float, period: float) -> np.ndarray:
    """Indices of the rows strictly inside the periodic turn (t_start, t_start + period): the rows it repeats."""
    return np.flatnonzero((t > t_start) & (t < t_start + period))


def continue_periodically(df: pd.DataFrame, events: pd.DataFrame, t_start: float, period: float, duration: float,
                          step: float) -> tuple[pd.DataFrame, pd.DataFrame, float]:
    """The whole run: the simulated rows on the output grid up to the last simulated one, then the periodic turn's
    own rows t_k (t_start < t_k < t_start + period) repeated at t_k + m P (m = 1, 2, ..., up to
    `last_repetitions`), the rows after the simulated window (the mechanics is periodic there: cycle averaging
    checks it). No interpolation in phase: a continued row is a simulated row, so the largest of the run's rows is
    the largest of the turn's rows at their last repetition (docs/thermal.md, "Cycle averaging"); those rows are a
    row step apart within a turn and (t_k,first + P - t_k,last) across its ends, not on multiples of `step`.
    Cumulative columns advance by their increase over one turn per period. Events of the turn repeat the same way
    (`message` says so). Returns (table, events, the last simulated time)."""
    t = df["t_s"].to_numpy(float)
    grid = output_times(duration, step)
    on_grid = np.isin(np.round(t / step, 6), np.round(grid / step, 6))
    simulated = df[on_grid]
    t_sim = float(simulated["t_s"].iloc[-1])
    own = turn_rows(t, t_start, period)
    own = own[on_grid[own]]
    if not len(own):
        return df, events, float(t[-1])
    last = last_repetitions(t[own], period, duration)
    m = np.arange(1, max(int(last.max()), 0) + 1)
    reps = (m[:, None] * np.ones((1, len(own)), dtype=np.int64)).ravel()      # period-major: times ascend
    idx = np.tile(own, len(m))
    new_t = t[idx] + reps * period
    keep = (reps <= np.tile(last, len(m))) & (new_t > t_sim + 1e-9 * step)
    idx, reps, new_t = idx[keep], reps[keep], new_t[keep]
    if not len(new_t):
        return df, events, float(t[-1])
    new = {}
    for col in df.columns:
        column = df[col]
        if col == "t_s":
            new[col] = new_t
        elif cumulative(col):
            values = column.to_numpy().astype(float)
            per_turn = float(np.diff(np.interp([t_start, t_start + period], t, values))[0])
            new[col] = values[idx] + reps * per_turn
        elif isinstance(column.dtype, np.dtype):
            new[col] = column.to_numpy()[idx]
        else:       # the mode's strings: taken as they are stored (an hour's rows as Python objects cost ~0.5 s)
            new[col] = column.array.take(idx)
    table = pd.concat([simulated, pd.DataFrame(new, columns=df.columns)], ignore_index=True)
    return table, _repeat_events(df, events, t_start, period, t_sim, duration), t_sim


def _repeat_events(df, events, t_start, period, t_sim, duration) -> pd.DataFrame:
    """The turn's events repeated every period after t_sim up to duration; `<coordinate>_q` advances like the
    coordinate's angle column (all copies built at once: a long run repeats the turn thousands of times)."""
    if events is None or not len(events):
        return events
    te = events["t_s"].to_numpy(float)
    turn = events[(te >= t_start) & (te < t_start + period)]
    if turn.empty:
        return events
    t = df["t_s"].to_numpy(float)
    turns = int(np.ceil((duration - t_start) / period))
    m = np.repeat(np.arange(1, turns + 1), len(turn))
    copies = turn.iloc[np.tile(np.arange(len(turn)), turns)].reset_index(drop=True)
    copies["t_s"] = copies["t_s"] + m * period
    for col in turn.columns:
        angle = f"{col[:-2]}_angle_rad"
        if col.endswith("_q") and angle in df:
            per_turn = float(np.diff(np.interp([t_start, t_start + period], t, df[angle].to_numpy(float)))[0])
            copies[col] = copies[col].astype(float) + m * per_turn
    if "message" in copies:
        copies["message"] = "periodic continuation of the last simulated turn"
    copies = copies[(copies["t_s"] > t_sim) & (copies["t_s"] <= duration + 1e-12)]
    return pd.concat([events, copies], ignore_index=True) if len(copies) else events
