"""The drive's turns in continuous time (scenarios/turns.py, docs/theory.md §K5 "The drive's turns").

- the rows' estimate is the root of the cubic Hermite interpolant of (angle, speed): exact for a cubic angle,
  O(h^4) otherwise (the error falls 16-fold when the step halves, where the linear interpolation's falls 4-fold);
- Newton's method on readings of the continuous solution reaches the crossing to round-off in two passes;
- a run's periodic regime and the sweep's cycle figures do not move with the output step: geneva-torque (a
  constant 6 N·m drive) turns in the same period at 1, 10 and 37 ms rows, its drive work over the last turn is
  6 N·m x 2 pi, and the contact force's mean over it is the same where the rows had left intervals between events
  without a row (the trapezoidal rule on the rows: 1 % off at 10 ms, 13 % at 37 ms).
"""
import math

import numpy as np
import pandas as pd
import pytest

import mechsim
from mechsim.scenarios.studies.sweep.rows import cycle_figures
from mechsim.scenarios.turns import CONVERGED, cubic_at, hermite_crossings, newton_passes


def test_a_cubic_angle_crosses_where_its_hermite_interpolant_does():
    t = np.linspace(0.0, 2.0, 9)
    angle, speed = 3.0 * t + 0.4 * t ** 3, 3.0 + 1.2 * t ** 2
    levels = np.array([0.7, 2.5, 6.1, 9.0])
    got = hermite_crossings(t, angle, speed, levels)
    assert 3.0 * got + 0.4 * got ** 3 == pytest.approx(levels, abs=1e-13)


def test_the_rows_estimate_is_fourth_order():
    def angle(t):
        return 5.0 * t + 0.8 * np.sin(3.0 * t)

    def speed(t):
        return 5.0 + 2.4 * np.cos(3.0 * t)
    levels = np.linspace(0.5, 14.0, 40)
    lo, hi = np.zeros(len(levels)), np.full(len(levels), 3.0)
    for _ in range(100):                            # the crossings by bisection on the function itself
        mid = 0.5 * (lo + hi)
        below = angle(mid) < levels
        lo, hi = np.where(below, mid, lo), np.where(below, hi, mid)
    root = 0.5 * (lo + hi)
    errors, linear = [], []
    for n in (40, 80, 160):
        t = np.linspace(0.0, 3.0, n + 1)
        errors.append(np.abs(hermite_crossings(t, angle(t), speed(t), levels) - root).max())
        linear.append(np.abs(np.interp(levels, angle(t), t) - root).max())
    assert errors[0] / errors[1] == pytest.approx(16.0, rel=0.3)
    assert errors[1] / errors[2] == pytest.approx(16.0, rel=0.3)
    assert linear[1] / linear[2] == pytest.approx(4.0, rel=0.3)
    assert errors[2] < 1e-3 * linear[2]


def test_a_cubic_through_four_rows_is_exact_on_a_cubic():
    t = np.array([0.0, 0.3, 0.5, 1.1, 1.4, 2.0])
    f = 1.0 - 2.0 * t + 0.5 * t ** 2 + 0.25 * t ** 3
    x = np.array([0.05, 0.71, 1.9])
    assert cubic_at(t, f, x) == pytest.approx(1.0 - 2.0 * x + 0.5 * x ** 2 + 0.25 * x ** 3, abs=1e-13)


def test_newton_on_readings_reaches_the_crossing():
    calls = []

    def read_at(times):
        calls.append(len(times))
        return [{"a": np.array([5.0 * x + 0.8 * math.sin(3.0 * x)]), "w": np.array([5.0 + 2.4 * math.cos(3.0 * x)])}
                for x in times.tolist()]
    levels = np.array([2 * np.pi, 4 * np.pi])
    t = np.linspace(0.0, 3.0, 31)                     # the rows' estimates at 0.1 s rows, about 1e-4 s off
    guess = hermite_crossings(t, 5.0 * t + 0.8 * np.sin(3.0 * t), 5.0 + 2.4 * np.cos(3.0 * t), levels)
    times, tables, _ = newton_passes(read_at, guess, levels, "a", "w")
    # the passes end once a move is below CONVERGED of the instant: the instant is then the crossing to round-off,
    # the angle read within its speed times that
    tol = 7.4 * CONVERGED * 3.0
    assert [float(tb["a"][0]) for tb in tables] == pytest.approx(levels.tolist(), abs=tol)
    assert 5.0 * times + 0.8 * np.sin(3.0 * times) == pytest.approx(levels, abs=1e-13)
    assert len(calls) <= 3


def test_cycle_figures_between_rows_are_fourth_order():
    def frame(n):
        t = np.linspace(0.0, 4.0, n + 1)
        return pd.DataFrame({"t_s": t, "crank_angle_rad": 4.0 * t + 0.5 * np.sin(2.0 * t),
                             "crank_speed_rad_s": 4.0 + np.cos(2.0 * t), "work_drive_J": 3.0 * t + np.sin(t)})
    fine = cycle_figures(frame(20000), "crank_angle_rad", None, "crank_speed_rad_s")
    for n in (50, 100):
        got = cycle_figures(frame(n), "crank_angle_rad", None, "crank_speed_rad_s")
        assert got["cycles"] == fine["cycles"] == 2
        assert got["cycle_time_s"] == pytest.approx(fine["cycle_time_s"], rel=2e-6)
        assert got["work_drive_per_cycle_J"] == pytest.approx(fine["work_drive_per_cycle_J"], rel=2e-6)


@pytest.fixture(scope="module")
def torque_runs():
    return {step: mechsim.run(mechsim.load("geneva-torque", set=["output.plots=false", f'output_step="{step}"']))
            for step in ("1 ms", "10 ms", "37 ms")}


def test_the_regime_and_its_means_do_not_move_with_the_output_step(torque_runs):
    fine = torque_runs["1 ms"].summary
    tol = 1e-8 * 10          # the run's rtol 1e-8, a reading's path from its own row
    for step, r in torque_runs.items():
        regime = r.summary["regime"]
        assert regime["period_s"] == pytest.approx(fine["regime"]["period_s"], rel=tol)
        assert regime["last_turn"][1] == pytest.approx(fine["regime"]["last_turn"][1], rel=tol)
        assert regime["last_turn_work_J"]["drive"] == pytest.approx(6.0 * 2 * np.pi, rel=tol)
        mean = r.summary["peaks"]["contact_force_N"]["periodic"]["mean"]
        assert mean == pytest.approx(fine["peaks"]["contact_force_N"]["periodic"]["mean"], rel=1e-7)


def test_a_sweep_row_takes_the_located_turn(torque_runs):
    for r in torque_runs.values():
        got = cycle_figures(r.timeseries, "crank_angle_rad", r.summary["regime"], "crank_speed_rad_s")
        assert got["cycle_time_s"] == r.summary["regime"]["period_s"]
        assert got["work_drive_per_cycle_J"] == r.summary["regime"]["last_turn_work_J"]["drive"]
