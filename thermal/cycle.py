"""Cycle-averaged bulk temperatures for long runs (docs/theory.md §G5: tau >> cycle, so the mean heat drives the bulk).

The mechanics runs, resolved, until its crank turns repeat (`turn_periodicity`: the turn-to-turn change of the
period, the heat per turn and the crank speed over the turn, and how fast it decays); the last full turn [a, a + P)
gives the cycle-mean heat Q_bar and the heat-weighted pin share gamma_bar (exact, from the integrated bookkeeping
energies). From a on the input is that turn repeated, and the network is linear and time-invariant, so its response
from the resolved states T(a) splits exactly into
- the periodic ripple T~_p, the periodic response to the zero-mean remainder u(t) - u_bar, found from one period's
  zero-state response Z by (I - e^{AP}) T~_p(0) = Z(P), and
- the mean curve, the response to the constant mean input from T(a) - T~_p(0), exact in the network's modes
  (`ModalNetwork.constant`), so that an hour costs what a second does.
Fast nodes (the pin, tau ~ 5 s) keep their in-cycle swing this way; slow ones (crank, wheel) are the mean curve.
"""
from __future__ import annotations

import math
from dataclasses import dataclass
from typing import Callable

import numpy as np
import pandas as pd

from mechsim.thermal.exact import ModalNetwork, states_between_rows
from mechsim.thermal.linear import LinearThermalSystem

#: rows of the bulk history table over the whole duration
HISTORY_ROWS = 1001
#: phases within the period are resolved to this fraction of it (bulk_response)
PHASE_RESOLUTION = 1e-10
#: with more distinct phases than HERMITE_ABOVE times (HERMITE_NODES + the input's breaks), as output rows on a grid
#: incommensurate with the period give over a long run, the ripple is interpolated between HERMITE_NODES uniform
#: phases and the breaks (`_ripple_hermite`) instead of integrated to every phase
HERMITE_NODES = 4096
HERMITE_ABOVE = 4
#: up to this many distinct phases (a located peak's readings) each is integrated from the periodic ripple at the
#: start of its piece, kept between calls (`bulk_response`'s cache)
FEW_PHASES = 64
#: rows per block of the elementwise work on an hour of rows (blocks that stay in the cache)
BLOCK = 4096


def turn_boundaries(t: np.ndarray, angle: np.ndarray, angle0: float) -> np.ndarray:
    """Times at which the drive angle passes angle0 + 2 pi m (m = 1, 2, ...), interpolated between rows."""
    if len(t) < 2 or not np.all(np.diff(angle) > 0):
        return np.array([])
    m = np.arange(1, int(np.floor((angle[-1] - angle0) / (2 * np.pi) + 1e-12)) + 1)
    return np.interp(angle0 + 2 * np.pi * m, angle, t)


@dataclass
class CycleMeans:
    """Mean heat, heat-weighted pin share and the period of the last full turn; periodicity against the one before;
    start: the network's states at t_start (the resolved run's, from which the continuation starts)."""

    t_start: float
    period: float
    heat_mean: float
    share_mean: float
    periodicity: float | None     # |Q_bar(last) - Q_bar(previous)| / Q_bar(last), None with one turn only
    start: np.ndarray | None = None


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


#: a turn-to-turn change below this is taken as converged whatever its trend (round-off; callers raise it to the
#: scatter of their rows)
CHANGE_FLOOR = 1e-7


@dataclass
class Periodicity:
    """How periodic the crank turns of a window are. turns: full turns from the start angle; change: the largest
    relative turn-to-turn change of the last full turn against the one before (its period, its heat and the crank
    speed at its start, relative to the turn's mean speed; None with one turn); changes: that change for every pair
    of consecutive turns; rate: the decay of the change per turn, the geometric mean over the last (up to) three
    changes (None with fewer than three turns); error: the last turn's estimated relative distance from the periodic
    limit, the sum of the changes still to come if they keep decaying by `rate`, change * max(1, rate/(1 - rate))
    (inf where they do not decay); ends: the turns' start and end times (the window's start first); period_error:
    the same distance for the period alone (<= error): the continued turns drift in phase by about that times the
    time continued."""

    turns: int
    change: float | None
    changes: np.ndarray
    rate: float | None
    error: float
    ends: np.ndarray
    period_error: float = math.inf

    def turns_needed(self, tolerance: float) -> int | None:
        """Full turns after which `error` is expected to be within `tolerance` (the changes decaying by `rate`),
        None where that cannot be told (fewer than three turns, no decay)."""
        if self.error <= tolerance:
            return self.turns
        if self.rate is None or not 0 < self.rate < 1 or not self.change:
            return None
        factor = max(1.0, self.rate / (1.0 - self.rate))
        more = math.log(tolerance / (self.change * factor)) / math.log(self.rate)
        return self.turns + max(1, int(math.ceil(more)))


def turn_periodicity(t: np.ndarray, angle: np.ndarray, speed: np.ndarray, energy: np.ndarray,
                     floor: float = CHANGE_FLOOR, accel: np.ndarray | None = None,
                     power: np.ndarray | None = None) -> Periodicity:
    """Periodicity of the window's crank turns (turns from the start angle); energy: the heat generated up to each
    row (J); floor: a change at or below it counts as converged whatever its trend. Each turn is compared by its
    period, its heat and the crank speed at its start, all read where the crank passes the start angle: cubic
    Hermite between the rows around that instant, with the rows' derivatives (the speed for the angle, `accel` for
    the speed, `power` for the energy; linear where not given), so that coarse rows still measure them to
    O(h^4). (A sample of the speed at other angles would meet the contact's kinks between rows, ~1e-3 of the
    speed at 1 ms.)"""
    targets = angle[0] + 2 * np.pi * np.arange(1, int(np.floor((angle[-1] - angle[0]) / (2 * np.pi) + 1e-12)) + 1)
    if len(t) < 2 or not np.all(np.diff(angle) > 0) or len(targets) < 2:
        ends = np.concatenate([[t[0]], turn_boundaries(t, angle, angle[0])])
        return Periodicity(len(ends) - 1, None, np.array([]), None, math.inf, ends, math.inf)
    j = np.clip(np.searchsorted(angle, targets, side="right") - 1, 0, len(t) - 2)
    h = t[j + 1] - t[j]
    x = np.clip((targets - angle[j]) / (angle[j + 1] - angle[j]), 0.0, 1.0)
    for _ in range(4):                                     # Newton on the Hermite cubic of the angle
        value, slope = _hermite(x, angle[j], angle[j + 1], h * speed[j], h * speed[j + 1])
        x = np.clip(x - (value - targets) / np.where(slope > 0, slope, 1.0), 0.0, 1.0)

    def at(y, dy):
        if dy is None:
            return y[j] + x * (y[j + 1] - y[j])
        return _hermite(x, y[j], y[j + 1], h * dy[j], h * dy[j + 1])[0]
    ends = np.concatenate([[t[0]], t[j] + x * h])
    n = len(ends) - 1
    periods = np.diff(ends)
    heat = np.diff(np.concatenate([[energy[0]], at(energy, power)]))
    start_speed = np.concatenate([[speed[0]], at(speed, accel)])[:-1]

    def relative(v, scale):
        return np.abs(np.diff(v)) / np.where(scale[1:] > 0, scale[1:], 1.0)
    changes = np.maximum.reduce([relative(periods, periods), relative(heat, np.abs(heat)),
                                 relative(start_speed, 2 * np.pi / periods)])
    change, rate, error = _distance(changes, floor)
    period_error = _distance(relative(periods, periods), floor)[2]
    return Periodicity(n, change, changes, rate, error, ends, min(period_error, error))


def _distance(changes: np.ndarray, floor: float) -> tuple[float, float | None, float]:
    """(last change, its decay per turn, the estimated distance from the limit) of a sequence of turn-to-turn
    changes (`Periodicity`)."""
    n = len(changes)
    change = float(changes[-1])
    rate = None
    if n >= 2 and changes[-min(n, 3)] > 0:       # the decay per turn over the last (up to) three changes
        k = min(n, 3)
        rate = float((changes[-1] / changes[-k]) ** (1.0 / (k - 1)))
    if change <= floor:
        return change, rate, change
    if rate is not None and rate < 1:
        return change, rate, change * max(1.0, rate / (1.0 - rate))
    return change, rate, math.inf


def _hermite(x, y0, y1, d0, d1):
    """(value, d/dx) of the cubic Hermite on [0, 1] with end values y0, y1 and end slopes d0, d1 (per unit x)."""
    x2, x3 = x * x, x * x * x
    value = (2 * x3 - 3 * x2 + 1) * y0 + (x3 - 2 * x2 + x) * d0 + (3 * x2 - 2 * x3) * y1 + (x3 - x2) * d1
    slope = (6 * x2 - 6 * x) * y0 + (3 * x2 - 4 * x + 1) * d0 + (6 * x - 6 * x2) * y1 + (3 * x2 - 2 * x) * d1
    return value, slope


def bulk_response(system: LinearThermalSystem, means: CycleMeans, u_of_phase: Callable[[np.ndarray], np.ndarray],
                  phase_breaks: list[float], times: np.ndarray, cache: dict | None = None
                  ) -> tuple[np.ndarray, np.ndarray]:
    """(mean curve, mean curve + ripple) of the network states at `times` (s from the run's start, >= t_start):
    continued from the states means.start at means.t_start with the turn's input u_of_phase (phase 0 = t_start)
    repeated every period (module docstring). cache: a dict kept between calls for the same turn (the located
    peaks' many small readings): the input's mean and the periodic ripple at the turn's fixed pieces' ends, from
    which each phase is integrated exactly over its own piece."""
    times = np.asarray(times, dtype=float)
    n = system.size
    u_bar = np.array([means.share_mean * means.heat_mean, (1.0 - means.share_mean) * means.heat_mean])
    P = means.period
    since = np.maximum(times - means.t_start, 0.0)
    # output rows a whole number of steps apart repeat the same few phases, up to the round-off of `t mod P`
    # (and of P itself); phases are snapped to PHASE_RESOLUTION * P so that an hour of rows integrates the
    # period once over those few phases, not over a million that differ in their last digits (the ripple then
    # moves by at most PHASE_RESOLUTION * P * |dT/dt|: ~1e-9 K at the seed's rates)
    phase = np.round((since % P) / (PHASE_RESOLUTION * P)) * (PHASE_RESOLUTION * P)
    phase = np.minimum(phase, P)
    breaks = sorted({b for b in phase_breaks if 0.0 < b < P})
    # the ripple is integrated over the turn on pieces fixed by the turn (HERMITE_NODES uniform phases and the
    # input's breaks) and the phases asked for: so that its value at a phase does not depend on which other phases
    # (which output grid) are asked for with it, as a few phases alone would make the pieces long
    nodes = np.unique(np.concatenate([[0.0, P], breaks, np.linspace(0.0, P, HERMITE_NODES + 1)]))
    # with more distinct phases (tau) than `above` the ripple is the Hermite's: the first rows' phases often tell
    # already; else the distinct phases by hashing (an hour of rows repeats a few phases: sorting them all is the
    # slow way to the same set), each row's phase its code among them
    above = (HERMITE_ABOVE + 1) * (HERMITE_NODES + len(breaks))
    hermite = len(np.unique(np.concatenate([nodes, phase[:2 * above]]))) > above
    if not hermite:
        codes, distinct = pd.factorize(phase)
        tau = np.unique(np.concatenate([nodes, distinct]))
        hermite = len(tau) > above
    cache = {} if cache is None else cache
    # the remainder must integrate to zero over the period to the quadrature's own accuracy: (I - e^{AP}) is
    # nearly singular for the slow modes (P/tau ~ 1e-3), so its mean is taken with the same quadrature
    if "u_own" not in cache:
        cache["u_own"] = _period_mean(u_of_phase, P, breaks)
    u_own = cache["u_own"]

    def ripple_input(x):
        return np.asarray(u_of_phase(np.asarray(x) % P), dtype=float) - u_own[:, None]

    homogeneous = ModalNetwork(system, source=False)            # the ripple has no ambient source
    if hermite:
        ripple, periodic0 = _ripple_hermite(homogeneous, ripple_input, P, breaks, phase)
    elif len(distinct) <= FEW_PHASES:          # a few phases: each from its piece's start
        if "nodes" not in cache:
            Z = homogeneous.integrate(ripple_input, nodes, np.zeros(n + 3), breaks)
            cache["nodes"] = homogeneous.exp(nodes, homogeneous.resolvent_periodic(Z[-1, :n], P)) + Z[:, :n]
        at = cache["nodes"]
        ripple = states_between_rows(homogeneous, ripple_input, breaks, nodes, np.c_[at, np.zeros((len(at), 3))],
                                     phase)[:, :n]
        periodic0 = at[0]
    else:
        Z = homogeneous.integrate(ripple_input, tau, np.zeros(n + 3), breaks)[:, :n]
        start = homogeneous.resolvent_periodic(Z[-1], P)
        periodic = homogeneous.exp(tau, start) + Z
        ripple, periodic0 = periodic[np.searchsorted(tau, distinct)[codes]], periodic[0]
    T0 = np.asarray(means.start, dtype=float) - periodic0
    mean, _ = ModalNetwork(system).constant(T0, u_bar, since, energy=False)
    return mean, mean + ripple


def _ripple_hermite(homogeneous: ModalNetwork, ripple_input, period: float, breaks: list[float], phase: np.ndarray
                    ) -> tuple[np.ndarray, np.ndarray]:
    """(the periodic ripple at the phases, at phase 0) from its exact values at HERMITE_NODES uniform phases and the
    input's breaks, cubic Hermite between them with its exact slopes z' = lambda z + B_m (u - u_bar) in the modes
    (one-sided at the nodes: the input may jump at a break). Between breaks the ripple is smooth, so the error is
    h^4 max|d^4z/dt^4| / 384 with h = P / HERMITE_NODES."""
    nodes = np.unique(np.concatenate([[0.0, period], breaks, np.linspace(0.0, period, HERMITE_NODES + 1)]))
    n, m = homogeneous.n, homogeneous.Bm.shape[1]
    Z = homogeneous.integrate(ripple_input, nodes, np.zeros(n + 3), breaks)[:, :n]
    values = homogeneous.exp(nodes, homogeneous.resolvent_periodic(Z[-1], period)) + Z
    z = values @ homogeneous.Vinv.T
    eps = 1e-12 * period
    lam, Bm = homogeneous.lam[None, :], homogeneous.Bm
    slope_lo = lam * z[:-1] + np.asarray(ripple_input(nodes[:-1] + eps))[:m].T @ Bm.T
    slope_hi = lam * z[1:] + np.asarray(ripple_input(nodes[1:] - eps))[:m].T @ Bm.T
    out = np.empty((len(phase), z.shape[1]))
    for b in range(0, len(phase), BLOCK):       # in blocks that stay in the cache (the same operations per element)
        p = phase[b:b + BLOCK]
        k = np.clip(np.searchsorted(nodes, p, side="right") - 1, 0, len(nodes) - 2)
        h = (nodes[k + 1] - nodes[k])[:, None]
        x = ((p - nodes[k]) / h[:, 0])[:, None]
        x2, x3 = x * x, x * x * x
        out[b:b + BLOCK] = ((2 * x3 - 3 * x2 + 1) * z[k] + (x3 - 2 * x2 + x) * h * slope_lo[k]
                            + (3 * x2 - 2 * x3) * z[k + 1] + (x3 - x2) * h * slope_hi[k])
    return out @ homogeneous.V.T, values[0]


def _period_mean(u_of_phase, period: float, breaks: list[float], nodes: int = 8, pieces: int = 512) -> np.ndarray:
    """(1/P) int_0^P u(s) ds by Gauss-Legendre on each smooth stretch between breaks, split into its share of
    `pieces` sub-intervals over the period (at least one)."""
    x, w = np.polynomial.legendre.leggauss(nodes)
    edges = np.unique(np.concatenate([[0.0, period], [b for b in breaks if 0.0 < b < period]]))
    fine = np.unique(_linspaces(edges, np.maximum(1, np.ceil(pieces * np.diff(edges) / period)).astype(np.intp)))
    h = np.diff(fine)
    s = (fine[:-1, None] + 0.5 * h[:, None] * (x[None, :] + 1.0)).ravel()
    weights = (0.5 * h[:, None] * w[None, :]).ravel()
    return np.asarray(u_of_phase(s), dtype=float) @ weights / period


def _linspaces(edges: np.ndarray, counts: np.ndarray) -> np.ndarray:
    """np.linspace(edges[i], edges[i + 1], counts[i] + 1) of every stretch, one after the other, computed as
    linspace computes each (j * ((b - a) / n) + a, the last point b itself) for all stretches at once (a turn of
    1 ms rows has a thousand of them)."""
    a, b = edges[:-1], edges[1:]
    sizes = counts + 1
    stretch = np.repeat(np.arange(len(a)), sizes)
    j = (np.arange(int(sizes.sum())) - np.repeat(np.cumsum(sizes) - sizes, sizes)).astype(float)
    out = j * ((b - a) / counts)[stretch] + a[stretch]
    out[np.cumsum(sizes) - 1] = b
    return out


def history_table(system: LinearThermalSystem, means: CycleMeans, u_of_phase, phase_breaks, duration: float,
                  kelvin: float, window: tuple[np.ndarray, np.ndarray], t_sim: float) -> pd.DataFrame:
    """Bulk temperatures over the whole run, HISTORY_ROWS rows: up to t_sim the resolved window's (window = (its
    times, its network states), linear between rows), after it the continuation (mean curve + ripple, and the mean
    curve alone; NaN in the resolved part)."""
    times = np.linspace(0.0, duration, HISTORY_ROWS)
    later = times > t_sim
    t_w, states = window
    full = np.column_stack([np.interp(times, t_w, states[:, j]) for j in range(system.size)])
    mean = np.full_like(full, np.nan)
    if later.any():
        mean[later], full[later] = bulk_response(system, means, u_of_phase, phase_breaks, times[later])
    out = {"t_s": times, "heat_generated_J": _heat_generated(times, window, means, t_sim)}
    for j, name in enumerate(system.state_names):
        if name.startswith("temp_bulk_"):
            base = name[:-2]
            out[f"{base}_C"] = full[:, j] - kelvin
            out[f"{base}_mean_C"] = mean[:, j] - kelvin
    return pd.DataFrame(out)


def _heat_generated(times, window, means, t_sim) -> np.ndarray:
    """The heat generated up to each time: the window's (its bookkeeping state E_gen) up to t_sim, then the cycle
    mean's rate."""
    t_w, states = window
    n = states.shape[1] - 3
    at_end = float(np.interp(t_sim, t_w, states[:, n]))
    return np.where(times <= t_sim, np.interp(times, t_w, states[:, n]), at_end + means.heat_mean * (times - t_sim))


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
    t_k + m_k P in the run lies (t_k + m_k P <= duration, to 1e-12 of a period): the times at which the design
    sensitivities read the turn's rows (thermal/cycle_exact.py `TurnLayout`)."""
    return np.floor((duration - np.asarray(t_rows, dtype=float)) / period + 1e-12).astype(np.int64)


def turn_rows(t: np.ndarray, t_start: float, period: float) -> np.ndarray:
    """Indices of the rows strictly inside the periodic turn (t_start, t_start + period)."""
    return np.flatnonzero((t > t_start) & (t < t_start + period))


def simulated_rows(t: np.ndarray, duration: float, step: float) -> np.ndarray:
    """Indices of the window's rows at times t that lie on the run's output grid (`output_times`): the simulated rows
    a cycle-averaged table keeps (`continue_periodically`); the last of them is where its continuation starts."""
    t = np.asarray(t, float)
    grid = output_times(duration, step)
    if len(t):        # grid times a step beyond the last row cannot match it (the rounding is monotone)
        grid = grid[:np.searchsorted(grid, t.max() + step, side="right")]
    return np.flatnonzero(np.isin(np.round(t / step, 6), np.round(grid / step, 6)))


def continue_periodically(df: pd.DataFrame, events: pd.DataFrame, t_start: float, period: float, duration: float,
                          step: float, given: Callable[[np.ndarray], dict] | None = None
                          ) -> tuple[pd.DataFrame, pd.DataFrame, float, np.ndarray]:
    """The whole run on the output grid (`output_times`: k step, and the end time): the simulated rows on it up to the
    last simulated one, t_sim, then the periodic turn [t_start, t_start + period) interpolated at the phase (t -
    t_start) mod period of every later grid time (the mechanics is periodic there: cycle averaging checks it),
    linear between the window's rows, and across an event (a mode change, where columns jump or kink) from the two
    rows on the phase's side of it (`_event_sides`). Cumulative columns advance by their increase over one turn per
    period; a discrete column (the mode) is that of the row on the phase's side. Events of the turn repeat every
    period (`message` says so). given: the columns' own values at the later grid times where known (a closed form's,
    exact at any time), which replace the continued ones. Returns (table, events, t_sim, the indices into df of the
    simulated rows kept)."""
    t = df["t_s"].to_numpy(float)
    grid = output_times(duration, step)
    kept = simulated_rows(t, duration, step)
    simulated = df.iloc[kept]
    t_sim = float(t[kept[-1]])
    new_t = grid[grid > t_sim + 1e-9 * step]
    if not len(new_t):
        return simulated.reset_index(drop=True), events, t_sim, kept
    m = np.floor((new_t - t_start) / period + 1e-12)
    at = np.clip(t_start + (new_t - t_start - m * period), t_start, t_start + period)
    lo, side = _event_sides(t, at, None if events is None or not len(events) else events["t_s"].to_numpy(float))
    hi = lo + 1
    weight = (at - t[lo]) / (t[hi] - t[lo])
    own = {} if given is None else {k: v for k, v in given(new_t).items() if k in df and k != "t_s"}
    new, out = {}, {}
    for col in df.columns:
        column = df[col]
        exact = own.get(col)
        if col == "t_s":
            new[col] = new_t
        elif (exact is not None and isinstance(column.dtype, np.dtype) and column.dtype.kind == "f"
              and np.asarray(exact).dtype == float):       # taken as assigning it over the continued rows would
            new[col] = np.asarray(exact)
            own.pop(col)
        elif exact is not None and not isinstance(column.dtype, np.dtype):
            # the mode's strings in the column's own dtype, as assigning them over the continued rows converts them:
            # each distinct value converted once (an hour's rows of Python strings converted one by one are slow)
            codes, uniques = pd.factorize(np.asarray(exact, dtype=object), use_na_sentinel=True)
            new[col] = pd.array(np.asarray(uniques, dtype=object), dtype=column.dtype).take(codes, allow_fill=True)
            own.pop(col)
        elif column.dtype == np.float64:      # in blocks that stay in the cache, the same operations per element
            values = column.to_numpy()
            joined = np.empty(len(kept) + len(new_t))
            joined[:len(kept)] = values[kept]
            per_turn = (float(np.diff(np.interp([t_start, t_start + period], t, values))[0]) if cumulative(col)
                        else None)
            # values[hi] - values[lo] is the window's own difference at lo: formed once per window row, gathered with
            # values[lo] per later row (the same numbers: each the same subtraction)
            rise = values[1:] - values[:-1]
            for b in range(0, len(new_t), BLOCK):
                j = slice(b, b + BLOCK)
                at_lo = lo[j]
                value = values[at_lo] + weight[j] * rise[at_lo]
                joined[len(kept) + b:len(kept) + b + BLOCK] = value if per_turn is None else value + m[j] * per_turn
            out[col] = joined
            continue
        elif isinstance(column.dtype, np.dtype) and column.dtype.kind in "fc":
            values = column.to_numpy().astype(float)
            new[col] = values[lo] + weight * (values[hi] - values[lo])
            if cumulative(col):
                per_turn = float(np.diff(np.interp([t_start, t_start + period], t, values))[0])
                new[col] = new[col] + m * per_turn
        elif isinstance(column.dtype, np.dtype):
            new[col] = column.to_numpy()[side]
        else:       # the mode's strings: taken as they are stored (as Python objects, an hour's rows would be slow)
            new[col] = column.array.take(side)
        # the simulated rows and the continued ones joined column by column, as concatenating the frames would
        if isinstance(column.dtype, np.dtype) and isinstance(new[col], np.ndarray):
            out[col] = np.concatenate([column.to_numpy()[kept], new[col]])
        else:
            out[col] = pd.concat([column.iloc[kept], pd.Series(new[col])], ignore_index=True)
    table = pd.DataFrame(out, columns=df.columns, copy=False)        # every column made here: no copy needed
    if own:                 # the other given columns (the mode's strings) assigned over the continued rows
        later = np.arange(len(table)) >= len(kept)
        for col, values in own.items():
            table.loc[later, col] = values
    return table, _repeat_events(df, events, t_start, period, t_sim, duration), t_sim, kept


def _event_sides(t: np.ndarray, at: np.ndarray, t_events: np.ndarray | None):
    """(lo, side): the rows lo and lo + 1 to interpolate the times `at` between (linear, extrapolating where `at` is
    outside [t_lo, t_lo+1]) and the row whose discrete values hold there. Between rows with no event: the rows
    around; where an event lies between them, the two rows on the same side of the event as `at` (a one-sided
    limit: the columns jump or kink at events, and the rows straddling one would smear it)."""
    j = np.clip(np.searchsorted(t, at, side="right") - 1, 0, len(t) - 2)
    lo, side = j.copy(), np.where(at - t[j] <= t[j + 1] - at, j, j + 1)
    if t_events is None or not len(t_events) or len(t) < 4:
        return lo, side
    te = np.sort(t_events)
    k = np.clip(np.searchsorted(te, t[j], side="right"), 0, len(te) - 1)
    crossed = (te[k] > t[j]) & (te[k] < t[j + 1])
    before = crossed & (at < te[k]) & (j >= 1)
    after = crossed & (at >= te[k]) & (j + 2 < len(t))
    lo[before] = j[before] - 1
    lo[after] = j[after] + 1
    side = np.where(crossed, np.where(at < te[k], j, j + 1), side)
    return lo, side


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
