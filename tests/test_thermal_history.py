"""The whole history with cycle averaging (docs/thermal.md, "Cycle averaging"): a long lumped-thermal run keeps
its rows over the whole duration on the output grid — the simulated start-up, then the periodic turn interpolated
at the phase of every later grid time — with the bulk temperatures of the averaged solution on every row; events
continue with the turn; the per-cycle temperature figure covers the run."""
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
    """Every row on the output grid k * step, the last at the end time (120 000 steps: 120 001 rows)."""
    r = motor_120s
    assert r.success and r.summary["thermal"]["averaging"] == "cycle"
    ts = r.timeseries
    step = r.scenario["output_step"]
    t = ts["t_s"].to_numpy()
    assert len(t) == 120001 and t[-1] == 120.0
    np.testing.assert_allclose(t, step * np.arange(len(t)), rtol=0, atol=1e-9)
    r.save(tmp_path / "out", plots=False)
    written = pd.read_parquet(tmp_path / "out" / "timeseries.parquet", columns=["t_s"])
    assert len(written) == len(ts) and written["t_s"].iloc[-1] == t[-1]
    assert (tmp_path / "out" / "thermal_history.csv").exists()


def test_the_start_up_is_simulated_and_the_rest_is_the_periodic_turn(motor_120s):
    r = motor_120s
    ts, cycle = r.timeseries, r.summary["thermal"]["cycle"]
    P, t_sim = cycle["period_s"], cycle["mechanics_simulated_until_s"]
    a = cycle["periodic_turn_s"][0]
    t = ts["t_s"].to_numpy()
    assert 0 < a < a + P <= t_sim < 10 and cycle["rows_continued_periodically"] == int((t > t_sim).sum())
    # the motor starts from rest-ish speed and settles: the first turn is slower than the periodic one
    w = ts["crank_speed_rad_s"].to_numpy()
    assert abs(w[0] - w[t < t_sim][-1]) > 0.1
    # a continued row is the periodic turn (simulated rows [a, a + P)) at its phase, linear between the turn's rows
    # where no event lies between them (across an event: from the rows on its side, test_cycle_settling.py)
    later = np.flatnonzero(t > t_sim)[::997]
    phase_t = a + np.mod(t[later] - a, P)
    sim = t <= t_sim
    j = np.searchsorted(t[sim], phase_t) - 1
    te = r.events["t_s"].to_numpy()
    clear = np.array([not np.any((te > t[i]) & (te < t[i + 1])) for i in j])
    for col in ("crank_speed_rad_s", "contact_force_N", "friction_power_W"):
        expected = np.interp(phase_t, t[sim], ts[col].to_numpy()[sim])
        np.testing.assert_allclose(ts[col].to_numpy()[later][clear], expected[clear], rtol=1e-12, atol=1e-12,
                                   err_msg=col)
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
    from figure_images import titles_outside
    assert not titles_outside(fig)              # the title within the figure (its detail on a line of its own)


def test_the_period_means_stretches_are_numpys_linspaces_to_the_bit():
    """`_linspaces` (the period mean's quadrature pieces, all stretches at once) gives every point np.linspace gives
    stretch by stretch, to the last bit: the mean the cycle continuation subtracts must not move."""
    from mechsim.thermal.cycle import _linspaces
    rng = np.random.default_rng(1)
    for trial in range(300):
        period = float(rng.uniform(0.1, 3.0))
        breaks = np.sort(rng.uniform(0.0, period, int(rng.integers(1, 60))))
        edges = np.unique(np.concatenate([[0.0, period], np.round(breaks, 4) if trial % 3 == 0 else breaks]))
        pieces = int(rng.choice([1, 7, 512]))
        counts = np.maximum(1, np.ceil(pieces * np.diff(edges) / period)).astype(np.intp)
        expected = np.concatenate([np.linspace(a, b, n + 1) for a, b, n in zip(edges[:-1], edges[1:], counts)])
        got = _linspaces(edges, counts)
        assert got.shape == expected.shape and np.array_equal(got.view(np.int64), expected.view(np.int64)), trial


def test_a_continued_row_is_read_between_adjacent_rows_of_the_turn():
    """`_event_sides` reads every phase between rows lo and lo + 1 of the window, beside an event as between rows
    (thermal/cycle.py `continue_periodically` gathers each column's difference of adjacent rows at lo): both rows
    exist, and the row whose discrete values hold is one of them."""
    from mechsim.thermal.cycle import _event_sides
    rng = np.random.default_rng(7)
    for trial in range(200):
        t = np.cumsum(rng.uniform(0.5, 1.5, int(rng.integers(4, 40))))
        events = np.sort(np.concatenate([rng.uniform(t[0], t[-1], int(rng.integers(0, 6))),
                                         rng.choice(t, int(rng.integers(0, 3)))]))    # some on rows
        at = rng.uniform(t[0] - 0.1, t[-1] + 0.1, 500)
        lo, side = _event_sides(t, at, events if len(events) else None)
        assert lo.min() >= 0 and lo.max() + 1 < len(t), trial
        assert np.all((side == lo) | (side == lo + 1)), trial
