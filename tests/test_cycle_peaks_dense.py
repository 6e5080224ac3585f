"""A cycle-averaged DAE run can read its periodic turn on the window's continuous solution, not on its output rows
(`ThermalPlan.read_turn`: thermal/plan.py `WindowReadings`, scenarios/thermal_peaks.py `ThermalReader.readings`;
docs/thermal.md "Reported temperatures"): the turn's ends where the crank passes its start angle, the network's states
and heat energies there, and the heat input on pieces fixed by the turn and its events. The cycle-averaged solution,
and the peaks located on it, then do not depend on the output step beyond the run's tolerance; with the input linear
between the rows (the default, which the design sensitivities trace) they move by about 1e-4 K per ms of output step
(the input jumps at the entries and exits between rows)."""
import dataclasses

import pytest

import mechsim
from mechsim.scenarios import runner

COLUMNS = ("temp_contact_C", "temp_flash_rise_K", "temp_bulk_pin_C", "temp_bulk_wheel_C")
#: geneva-motor (its speed follows from the dynamics) with the lumped network, cycle-averaged after its window
SETS = ["duration=12 s", "thermal.model=lumped", "thermal.averaging=cycle", "solver.rtol=1e-10",
        "solver.atol=1e-12"]


def _run(step, read_turn=True):
    plan = runner.plan(mechsim.load("geneva-motor", set=SETS + [f"output_step={step} ms"]))
    return runner.execute(dataclasses.replace(plan, thermal=dataclasses.replace(plan.thermal, read_turn=read_turn)))


@pytest.fixture(scope="module")
def runs():
    return {step: _run(step) for step in (1, 4)}


def test_cycle_averaged_peaks_do_not_move_with_the_output_step(runs):
    """1 and 4 ms: the periodic turn, its mean heat and every located thermal peak equal to 100 times the run's
    rtol (relative; measured: 1e-10 on the pin's bulk peak, 2e-11 on the contact temperature's), the peaks after the
    window; the same run with the turn's input linear between its 4 ms rows misses by a hundred times that."""
    one, four = runs[1].summary, runs[4].summary
    for r in (one, four):
        assert r["thermal"]["averaging"] == "cycle"
    a, b = one["thermal"]["cycle"], four["thermal"]["cycle"]
    assert b["periodic_turn_s"] == pytest.approx(a["periodic_turn_s"], rel=1e-8)
    assert b["mean_heat_rate_W"] == pytest.approx(a["mean_heat_rate_W"], rel=1e-8)
    for col in COLUMNS:
        for side in ("max", "min"):
            assert four["peaks"][col][side]["value"] == pytest.approx(one["peaks"][col][side]["value"], rel=1e-8), \
                (col, side)
    peak = one["peaks"]["temp_contact_C"]["max"]
    assert peak["t_s"] > a["mechanics_simulated_until_s"]
    rows = _run(4, read_turn=False).summary["peaks"]
    for col in ("temp_contact_C", "temp_bulk_pin_C"):
        assert abs(rows[col]["max"]["value"] - one["peaks"][col]["max"]["value"]) > 1e2 * 1e-8 * peak["value"], col
