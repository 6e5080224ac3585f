"""The drive's turns in continuous time: the instants the drive angle passes angle0 + 2 pi m.

From the rows, each crossing is the root of the cubic Hermite interpolant of the angle and its speed (the speed
is the angle's time derivative) in the gap that holds it, O(h^4) in the output step h where the linear
interpolation is O(h^2); on a run with a reader (a DAE run's re-integration or dense output), Newton's method on
the angle read there makes it the crossing of the continuous solution (docs/theory.md §K5, "The drive's turns").
"""
from __future__ import annotations

import numpy as np

#: Newton passes on the readings at most (from the rows' estimate one pass is enough at output steps of a few
#: degrees of drive angle; the rest is for coarse rows)
PASSES = 4
#: a Newton move below this (relative to the instant) ends the passes: the moved instant is then the crossing to
#: O(move^2), about 1e-17 of it, and a column read before the move is carried over it by its rows' slope
#: (`carried`), to O(move h) of the output step h
CONVERGED = 1e-9


def hermite_crossings(t: np.ndarray, angle: np.ndarray, speed: np.ndarray, levels: np.ndarray) -> np.ndarray:
    """The instants the angle reaches `levels` (ascending, inside the rows' range; the angle increasing), each the
    root of the cubic Hermite interpolant of (angle, speed) on the rows' gap that holds it (Newton's method on the
    cubic from the linear interpolation, kept inside the gap; the linear estimate where the cubic has no root
    there, as on a gap wider than the angle's curvature allows)."""
    levels = np.asarray(levels, dtype=float)
    j = np.clip(angle.searchsorted(levels, side="left"), 1, len(t) - 1)
    t0, h, a0 = t[j - 1], t[j] - t[j - 1], angle[j - 1]
    d, m0, m1 = angle[j] - a0, h * speed[j - 1], h * speed[j]      # the cubic in the gap, from its first row
    rise = levels - a0
    with np.errstate(invalid="ignore", divide="ignore"):
        linear = np.where(d != 0, rise / d, 1.0)
        s = linear.copy()
        for _ in range(12):
            s2 = s * s
            f = (3 * s2 - 2 * s2 * s) * d + (s2 * s - 2 * s2 + s) * m0 + (s2 * s - s2) * m1 - rise
            df = (6 * s - 6 * s2) * d + (3 * s2 - 4 * s + 1) * m0 + (3 * s2 - 2 * s) * m1
            step = np.where(df > 0, f / df, 0.0)
            s = np.clip(s - step, 0.0, 1.0)
            if not np.any(np.abs(step) > 1e-14):
                break
        s2 = s * s
        residual = (3 * s2 - 2 * s2 * s) * d + (s2 * s - 2 * s2 + s) * m0 + (s2 * s - s2) * m1 - rise
        ok = np.isfinite(s) & (np.abs(residual) <= 1e-9 * np.maximum(np.abs(d), 1e-300))
    return t0 + np.where(ok, s, linear) * h


def crossings(t: np.ndarray, angle: np.ndarray, speed: np.ndarray | None, angle0: float) -> np.ndarray:
    """The instants the drive angle (increasing) passes angle0 + 2 pi m, m = 1, 2, ... within the rows:
    `hermite_crossings` where the speed is at hand, else linear between rows; none where the angle is not
    increasing."""
    if len(t) < 2 or not np.all(np.diff(angle) > 0):
        return np.array([])
    m = np.arange(1, int(np.floor((angle[-1] - angle0) / (2 * np.pi) + 1e-12)) + 1)
    levels = angle0 + 2 * np.pi * m
    if speed is None or not np.all(np.isfinite(speed)):
        return np.interp(levels, angle, t)
    return hermite_crossings(t, angle, speed, levels)


def cubic_at(t: np.ndarray, f: np.ndarray, x: np.ndarray) -> np.ndarray:
    """The cubic through the four rows around each of `x` (two on each side where there are), O(h^4) on a smooth
    column where the linear interpolation is O(h^2): a column without its derivative at the rows (a work)."""
    x = np.asarray(x, dtype=float)
    if len(t) < 4:
        return np.interp(x, t, f)
    k = np.clip(t.searchsorted(x, side="right") - 2, 0, len(t) - 4)
    idx = k[..., None] + np.arange(4)
    tt, ff = t[idx], f[idx]
    out = np.zeros(x.shape)
    for i in range(4):
        w = np.ones(x.shape)
        for m in range(4):
            if m != i:
                w = w * (x - tt[..., m]) / (tt[..., i] - tt[..., m])
        out = out + w * ff[..., i]
    return out


def newton_passes(read_at, times: np.ndarray, levels: np.ndarray, angle_column: str, speed_column: str):
    """Newton's method on the angle read at `times` (the rows' estimates of where it reaches `levels`): each pass
    reads every crossing not yet converged (`read_at(times)`: a column table per instant, or None where it could
    not be read) and moves it by -(angle - level)/speed, until the move is below CONVERGED of the instant or
    PASSES passes. Returns (the instants, each moved by its last Newton step; the tables read in its last pass,
    None where a reading failed (the estimate kept); the instants those were read at)."""
    times = np.asarray(times, dtype=float).copy()
    tables: list = [None] * len(times)
    read = times.copy()
    todo = np.arange(len(times))
    for _ in range(PASSES):
        got = read_at(times[todo])
        nxt = []
        for k, table in zip(todo.tolist(), got):
            tables[k] = table
            if table is None:
                continue
            read[k] = times[k]
            a, w = float(np.asarray(table[angle_column])[0]), float(np.asarray(table[speed_column])[0])
            move = -(a - levels[k]) / w if w > 0 and np.isfinite(a) else 0.0
            times[k] += move
            if abs(move) > CONVERGED * max(1.0, abs(times[k])):
                nxt.append(k)
        todo = np.array(nxt, dtype=np.int64)
        if not len(todo):
            break
    return times, tables, read


def carried(t: np.ndarray, f: np.ndarray, value: float, at: float, to: float) -> float:
    """A column's `value` read at `at` carried to the nearby instant `to` by the slope of its rows' gap holding
    `at` (the move is a Newton step's, far below the output step: the slope's O(h) error costs O(h (to - at)))."""
    if to == at or len(t) < 2:
        return value
    j = int(np.clip(t.searchsorted(at, side="right"), 1, len(t) - 1))
    slope = (f[j] - f[j - 1]) / (t[j] - t[j - 1]) if t[j] > t[j - 1] else 0.0
    return value + slope * (to - at)
