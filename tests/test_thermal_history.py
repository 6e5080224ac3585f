"""The whole history with cycle averaging (docs/thermal.md, "Cycle averaging"): a long lumped-thermal run keeps
one row per output step over the whole duration — the simulated start-up, then the periodic turn continued —
with the bulk temperatures of the averaged solution on every row; events continue with the turn; the
per-cycle temperature figure covers the run."""
import math

import numpy as np
import pandas as pd
import pytest

import mechsim
from mechsim.scenarios.output.figures import cycle_table, thermal_cycle_figure


@pytest.fixture(scope="module")
def motor_120s():
    return mechsim.run("geneva-motor", set={"thermal.model": "lumped", "duration": "120 s"})


def test_one_row_per_output_step_over_the_whole_duration(motor_120s, tmp_path):
    r = motor_120s
    assert r.success and r.summary["thermal"]["averaging"] == "cycle"
    ts = r.timeseries
    step = r.scenario["output_step"]
    assert len(ts) == round(120.0 / step) + 1
    np.testing.assert_allclose(ts["t_s"].to_numpy(), step * np.arange(len(ts)), rtol=0, atol=1e-9)
    r.save(tmp_path / "out", plots=False)
    written = pd.read_parquet(tmp_path / "out" / "timeseries.parquet", columns=["t_s"])
    assert len(written) == len(ts) and written["t_s"].iloc[-1] == pytest.approx(120.0)
    assert (tmp_path / "out" / "thermal_history.csv").exists()


def test_the_start_up_is_simulated_and_the_rest_is_the_periodic_turn(motor_120s):
    r = motor_120s
    ts, cycle = r.timeseries, r.summary["thermal"]["cycle"]
    P, t_sim = cycle["period_s"], cycle["mechanics_simulated_until_s"]
    t = ts["t_s"].to_numpy()
    assert 0 < t_sim < 10 and cycle["rows_continued_periodically"] == int((t > t_sim).sum())
    # the motor starts from rest-ish speed and settles: the first turn is slower than the periodic one
    w = ts["crank_speed_rad_s"].to_numpy()
    assert abs(w[0] - w[t < t_sim][-1]) > 0.1
    # continued rows repeat the simulated turn: same speed one period apart (to the interpolation between
    # output rows, ~ max|dw/dt| x step), and the crank advances exactly one turn per period
    later = np.flatnonzero(t > t_sim + P)[::997]
    back = np.interp(t[later] - P, t, w)
    accel = np.abs(ts["crank_accel_rad_s2"]).max()
    assert np.max(np.abs(w[later] - back)) <= accel * r.scenario["output_step"]
    theta = ts["crank_angle_rad"].to_numpy()
    i = np.flatnonzero(t > t_sim)[0]
    advance = np.interp(t[-1] - P, t, theta)
    assert theta[-1] - advance == pytest.approx(2 * math.pi, abs=1e-3)
    assert theta[i:].min() >= theta[i - 1]                     # unwrapped, never restarts


def test_bulk_temperatures_on_every_row_are_the_averaged_solution(motor_120s):
    r = motor_120s
    ts, history = r.timeseries, r.extra_tables["thermal_history"]
    for body in ("pin", "crank", "wheel"):
        col = f"temp_bulk_{body}_C"
        assert ts[col].notna().all()
        np.testing.assert_allclose(np.interp(history["t_s"], ts["t_s"], ts[col]), history[col], atol=2e-3)
    # the pin heats up over the whole run (never a cut at the last turn)
    assert ts["temp_bulk_pin_C"].iloc[-1] > ts["temp_bulk_pin_C"].iloc[len(ts) // 2] > ts["temp_bulk_pin_C"].iloc[0]


def test_events_continue_with_the_turn(motor_120s):
    r = motor_120s
    ev, t_sim = r.events, r.summary["thermal"]["cycle"]["mechanics_simulated_until_s"]
    entries = ev.loc[ev["kind"] == "entry", "t_s"].to_numpy()
    P = r.summary["thermal"]["cycle"]["period_s"]
    assert entries[-1] > 120.0 - P
    np.testing.assert_allclose(np.diff(entries[entries > t_sim]), P, rtol=1e-9)
    assert (ev.loc[ev["t_s"] > t_sim, "message"] == "periodic continuation of the last simulated turn").all()


def test_the_per_cycle_figure_covers_the_run(motor_120s):
    r = motor_120s
    ts = r.timeseries
    table = cycle_table(ts)
    turns = (ts["crank_angle_rad"].iloc[-1] - ts["crank_angle_rad"].iloc[0]) / (2 * math.pi)
    assert len(table) == math.ceil(turns)
    fig = thermal_cycle_figure(r)
    ax = fig.axes[0]
    assert ax.get_xlabel() == "time (s)" and ax.get_ylabel() == "temperature (°C)"
    contact = ax.get_lines()[0].get_ydata()
    assert len(contact) == len(table)
    touched = ~np.isnan(contact)
    assert touched.sum() >= len(table) - 1                  # every whole turn has an engagement
    assert np.all(contact[touched] > table["temp_bulk_pin_mean_C"].to_numpy()[touched])   # hotter than the pin
