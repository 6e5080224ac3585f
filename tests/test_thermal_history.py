"""The whole history with cycle averaging (docs/thermal.md, "Cycle averaging"): a long lumped-thermal run keeps
its rows over the whole duration — the simulated start-up on the output grid, then the periodic turn's own rows
repeated a whole number of periods later —
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


def test_rows_over_the_whole_duration(motor_120s, tmp_path):
    """The simulated rows on the output grid; after them the turn's rows (t_k in (a, a + P)) at t_k + m P: a row
    step apart inside a turn, (t_first - a) + (a + P - t_last) in (0, 2 step) across the turn's ends; the last row
    within two steps of the end (the turn's rows leave no phase gap of two steps or more)."""
    r = motor_120s
    assert r.success and r.summary["thermal"]["averaging"] == "cycle"
    ts, cycle = r.timeseries, r.summary["thermal"]["cycle"]
    step, P, t_sim = r.scenario["output_step"], cycle["period_s"], cycle["mechanics_simulated_until_s"]
    t = ts["t_s"].to_numpy()
    sim = t[t <= t_sim]
    np.testing.assert_allclose(sim, step * np.arange(len(sim)), rtol=0, atol=1e-9)
    gaps = np.diff(t)
    assert np.all(gaps > 0) and np.all(gaps < 2 * step)
    # per period as many rows as the turn has (one row count per period, up to the rows at the two ends)
    assert abs(len(t) - len(sim) - (120.0 - t_sim) / step) <= (120.0 - t_sim) / P + 2
    assert 120.0 - 2 * step < t[-1] <= 120.0
    r.save(tmp_path / "out", plots=False)
    written = pd.read_parquet(tmp_path / "out" / "timeseries.parquet", columns=["t_s"])
    assert len(written) == len(ts) and written["t_s"].iloc[-1] == t[-1]
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
    # continued rows are the simulated turn's rows: the mechanics columns the same, bit for bit, one period apart,
    # and the crank advances exactly one turn per period
    later = np.flatnonzero(t > t_sim + P)[::997]
    back = np.searchsorted(t, t[later] - P - 1e-9)
    np.testing.assert_allclose(t[back], t[later] - P, rtol=0, atol=1e-9)
    for col in ("crank_speed_rad_s", "contact_force_N", "friction_power_W"):
        assert np.array_equal(ts[col].to_numpy()[later], ts[col].to_numpy()[back], equal_nan=True), col
    # the flash rise is recomputed on every row from those columns (the same formula: to round-off)
    flash = ts["temp_flash_rise_K"].to_numpy()
    np.testing.assert_allclose(flash[later], flash[back], rtol=1e-12, atol=1e-12 * np.nanmax(flash))
    assert (ts["mode"].to_numpy()[later] == ts["mode"].to_numpy()[back]).all()
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
