"""Cycle averaging at a prescribed speed (docs/sensitivity.md, "Cycle averaging"): the seed's load case 1 (crank at
5.34 rad/s, lumped bulk) for 60 s with `thermal.averaging = "cycle"`. The run takes the closed form, its two-turn
window and the network's input exact between the contact's switches; the derivatives follow the DAE with the speed
as a constraint over the same window, rows and turn, with the turn's input linear between output rows
(thermal/cycle_exact.py). The table's value is the run's located peak (tested equal), the traced value differs
from it by the input's interpolation (tested against a bound from the run's own input), and the derivatives of the
located peaks (the envelope rule at the peak's phase) match central finite differences of the run's located peaks
(`mechsim.run`, closed form) to 1e-4 relative.
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
#: relative steps h (and h/2) of the finite differences: the located peak is smooth within them (the speed's
#: repetition crossing the run's end is 0.91 % away; the others hold beyond 1 %). Its error, 1e-11 relative (the
#: locating polynomial's), over the smallest change (6e-3 K) is 1e-7 of the derivative; the truncation, O(h^4)
WRT = {"drive.speed": 5e-4, "contact.friction": 5e-4, "mechanism.crank_radius": 5e-4, "thermal.conductivity": 5e-4}
UNITS = {"drive.speed": "rad/s", "contact.friction": "", "mechanism.crank_radius": "m", "thermal.conductivity": "W/(m*K)"}


@pytest.fixture(scope="module")
def table():
    return sensitivity(mechsim.load(NAME, set=SETS + SENS), list(WRT), OF)


def _run(sets):
    r = mechsim.run(mechsim.load(NAME, set=SETS + SENS + sets))
    assert r.failure is None and r.summary["thermal"]["averaging"] == "cycle"
    return r


def _peaks(sets) -> dict:
    """The run's own located cycle-averaged peaks (summary.json peaks, `max`: the continuous solution's extremum,
    the periodic turn's closed form at each instant's phase under the cycle bulk at the instant)."""
    r = _run(sets)
    return {q: r.summary["peaks"][c]["max"] for q, c in COLUMNS.items()}


def test_value_is_the_runs_located_peak(table):
    """The table's value and instant are the run's located peaks (`mechsim run` of the same scenario), not the
    periodic turn's output rows: the located peak lies between rows, above the best row."""
    own = _peaks([])
    for q in OF:
        row = table[table["quantity"] == q].iloc[0]
        assert row["value"] == own[q]["value"] and row["t_s"] == own[q]["t_s"]
        assert own[q]["at"] == "interior" and own[q]["value"] > own[q]["best_row_value"]
    assert not [w for w in table.attrs["warnings"] if "output rows (the rows next to it" in w]


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
    """Central differences of the run's located cycle-averaged peaks (closed form, `_peaks`; steps h, h/2,
    Richardson), against the table's derivatives, to 1e-4 relative: the located peak is smooth in each value up
    to the repetition crossing the run's end (0.91 % of the speed, warned), well beyond the steps. The speed moves
    the contact's switches (entry and exit sit at fixed crank angles, the slip reversal does not): without
    `switch_correction` (what the switches' motion moves in the run's exact input, which the interpolated input
    does not follow) its contact temperature's derivative was 3.1 % off, with the jumps only 1.1e-3 (the slip
    reversal's kink is the rest)."""
    worst = {}
    for key, h in WRT.items():
        p = float(table.loc[table["wrt"] == key, "parameter"].iloc[0])
        unit = UNITS[key]

        def evaluate(v):
            got = _peaks([f"{key}={v!r} {unit}".strip() if unit else f"{key}={v!r}"])
            return {q: e["value"] for q, e in got.items()}
        fd = richardson_central(evaluate, p, h)
        part = table[table["wrt"] == key].set_index("quantity")
        for q in OF:
            worst[(key, q)] = abs(float(part.loc[q, "derivative"]) - fd[q]) / abs(fd[q])
    print({k: f"{v:.2g}" for k, v in worst.items()})
    assert max(worst.values()) <= 1e-4, worst
