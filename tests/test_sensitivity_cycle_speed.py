"""Cycle averaging at a prescribed speed (docs/sensitivity.md, "Cycle averaging"): the seed's load case 1 (crank at
5.34 rad/s, lumped bulk) for 60 s with `thermal.averaging = "cycle"`. The run takes the closed form, its two-turn
window and the network's input exact between the contact's switches; the derivatives follow the DAE with the speed
as a constraint over the same window, rows and turn, with the turn's input linear between output rows
(thermal/cycle_exact.py). The table's value is the run's reported peak (tested equal), the traced value differs
from it by the input's interpolation (tested against a bound from the run's own input), and the derivatives match
central finite differences of the run itself (`mechsim.run`, closed form) to 1e-4 relative.
"""
from __future__ import annotations

import dataclasses

import numpy as np
import pytest

import mechsim
from conftest import richardson_central
from mechsim.scenarios import runner
from mechsim.scenarios.studies.sensitivity import cycle_temperatures, cycle_window, sensitivity
from mechsim.scenarios.studies.sensitivity_cycle import closed_form_turn

NAME = "geneva-lc1"
SETS = ["duration=60 s", "thermal.model=lumped", "thermal.averaging=cycle"]
SENS = ["solver.rtol=1e-10", "solver.atol=1e-12"]
OF = ["peak_temp_contact_C", "peak_temp_flash_rise_K"]
COLUMNS = {"peak_temp_contact_C": "temp_contact_C", "peak_temp_flash_rise_K": "temp_flash_rise_K"}
#: relative steps h (and h/2) of the finite differences. drive.speed's are small: the peak's row shares its top with
#: the next row, which takes over after -0.017 % of the speed (the table warns of it); the others hold beyond 1 %
WRT = {"drive.speed": 2e-5, "contact.friction": 5e-4, "mechanism.crank_radius": 5e-4, "thermal.conductivity": 5e-4}
UNITS = {"drive.speed": "rad/s", "contact.friction": "", "mechanism.crank_radius": "m", "thermal.conductivity": "W/(m*K)"}


@pytest.fixture(scope="module")
def table():
    return sensitivity(mechsim.load(NAME, set=SETS + SENS), list(WRT), OF)


def _run(sets):
    r = mechsim.run(mechsim.load(NAME, set=SETS + sets))
    assert r.failure is None and r.summary["thermal"]["averaging"] == "cycle"
    return r


def _peaks(sets) -> dict:
    """The cycle-averaged peaks as the sensitivity defines them: the periodic turn's rows of the closed-form window
    (the run's own, `runner.settled`) at their last repetitions t_k + m_k P in the run, with the run's cycle bulk
    there (thermal/plan.py `cycle_bulk`) under the rows' flash rise and Blok share."""
    from mechsim.thermal.contact_row import KELVIN
    from mechsim.thermal.cycle_exact import TurnLayout
    plan = runner.settled(runner.plan(mechsim.load(NAME, set=SETS + sets)))
    df = runner.execute(cycle_window(plan)).timeseries
    t = df["t_s"].to_numpy(float)
    layout = TurnLayout.of(t, df["crank_angle_rad"].to_numpy(float), 60.0)
    _, bulk = plan.thermal.cycle_bulk(df, t[layout.inner], layout.periods)
    names = list(plan.thermal.setup.system.state_names)
    flash = df["temp_flash_rise_K"].to_numpy(float)[layout.inner]
    share = df["heat_share_pin"].to_numpy(float)[layout.inner]
    contact = (share * bulk[:, names.index("temp_bulk_pin_K")] + (1 - share) * bulk[:, names.index("temp_bulk_wheel_K")]
               + flash - KELVIN)
    return {"peak_temp_contact_C": float(np.nanmax(contact)), "peak_temp_flash_rise_K": float(np.nanmax(flash))}


def test_value_is_the_runs_reported_peak(table):
    """The table's value is the periodic turn's rows at their last repetitions with the run's own cycle bulk
    (`_peaks`); the run reports the largest of its rows on the output grid, the same periodic contact temperature
    in its last turn at phases up to one output step from those: they agree to its change over a step there."""
    run = _run([])
    peak = run.summary["peaks"]["temp_contact_C"]["max"]
    row = table[table["quantity"] == "peak_temp_contact_C"].iloc[0]
    assert row["value"] == pytest.approx(_peaks([])["peak_temp_contact_C"], abs=1e-9)
    ts = run.timeseries
    t, temp = ts["t_s"].to_numpy(), ts["temp_contact_C"].to_numpy()
    step = run.scenario["output_step"]
    near = np.abs(t - row["t_s"]) <= 2 * step
    assert abs(peak["t_s"] - row["t_s"]) <= step
    assert abs(peak["value"] - row["value"]) <= np.nanmax(np.abs(np.diff(temp[near])))


def test_traced_definition_differs_from_the_run_by_the_input_interpolation():
    """The DAE window (speed as a constraint) has the closed form's rows and turn, and its flash rise to the solver's
    tolerance; its cycle bulk takes the turn's heat input linear between output rows where the run's is exact. The
    two bulks are the responses to inputs that differ by du = u_lin - u (zero at the rows): a linear network with
    capacities C responds to a zero-mean input of L1 norm E with at most E / C per node in its periodic part and
    as much again in its start (the kernel of each mode varies by at most one over a period; docs/thermal.md), so
    |dT| <= 4 (E_pin + E_wheel + |mean du| P) / min(C_pin, C_wheel), E from the exact input sampled 64 times a row."""
    plan = runner.plan(mechsim.load(NAME, set=SETS + SENS))
    window = cycle_window(plan)
    dae = dataclasses.replace(window, method="dae", settings=dataclasses.replace(window.settings, method="dae"),
                              thermal=dataclasses.replace(window.thermal, method="dae"))
    result = runner.execute(dae)
    turn = cycle_temperatures(dae, result.timeseries)
    own = closed_form_turn(plan, turn)
    rows = turn["layout"].t[turn["rows"]]
    assert np.array_equal(own["rows"], turn["rows"])
    np.testing.assert_allclose(own["t_s"], turn["t_s"], rtol=0, atol=1e-9)
    # the bound from the run's exact input over the turn
    cf = runner.execute(window).timeseries
    _, inputs, _ = plan.thermal._window_states(cf)
    a, P = turn["layout"].t[turn["layout"].ia], turn["period"]
    fine = np.linspace(rows[0], rows[-1], 64 * (len(rows) - 1) + 1)
    n_in = plan.thermal.setup.system.input_matrix.shape[1]
    u = np.asarray(inputs(fine))[:n_in].T
    u_rows = np.asarray(inputs(rows))[:n_in].T
    du = np.column_stack([np.interp(fine, rows, u_rows[:, j]) for j in range(n_in)]) - u
    e = np.trapezoid(np.abs(du), fine, axis=0)
    mean = np.abs(np.trapezoid(du, fine, axis=0)).sum()
    capacity = plan.thermal.setup.system.capacity
    names = list(plan.thermal.setup.system.state_names)
    c_min = min(capacity[names.index("temp_bulk_pin_K")], capacity[names.index("temp_bulk_wheel_K")])
    bound = 4 * (e.sum() + mean) / c_min
    diff = np.nanmax(np.abs(own["temp_contact_C"] - own["traced_temp_contact_C"]))
    k = int(np.nanargmax(own["temp_contact_C"]))
    print(f"traced - run: {diff:.3g} K over the turn, {own['traced_temp_contact_C'][k] - own['temp_contact_C'][k]:.3g}"
          f" K at the peak; bound {bound:.3g} K (E {e}, turn from {a:.6g} s, P {P:.9g} s)")
    assert 0 < diff <= bound
    assert int(np.nanargmax(own["traced_temp_contact_C"])) == k        # the same row is the peak in both


def test_derivatives_match_finite_differences_of_the_run(table):
    """Central differences of the run's cycle-averaged peaks at the periodic turn's rows (closed form, `_peaks`;
    steps h, h/2, Richardson), against the table's derivatives, to 1e-4 relative. The speed moves the contact's switches
    (entry and exit sit at fixed crank angles, the slip reversal does not): without `switch_correction` (what the
    switches' motion moves in the run's exact input, which the interpolated input does not follow) its contact
    temperature's derivative was 3.1 % off, with the jumps only 1.1e-3 (the slip reversal's kink is the rest)."""
    worst = {}
    for key, h in WRT.items():
        p = float(table.loc[table["wrt"] == key, "parameter"].iloc[0])
        unit = UNITS[key]

        def evaluate(v):
            return _peaks([f"{key}={v!r} {unit}".strip() if unit else f"{key}={v!r}"])
        fd = richardson_central(evaluate, p, h)
        part = table[table["wrt"] == key].set_index("quantity")
        for q in OF:
            worst[(key, q)] = abs(float(part.loc[q, "derivative"]) - fd[q]) / abs(fd[q])
    print({k: f"{v:.2g}" for k, v in worst.items()})
    assert max(worst.values()) <= 1e-4, worst
