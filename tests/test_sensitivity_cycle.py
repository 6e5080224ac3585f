"""Sensitivities of the cycle-averaged temperatures (`thermal.averaging = "cycle"`, docs/sensitivity.md "Cycle
averaging"): the periodic turn's peak contact temperature and flash rise at their last time in the run, against
central finite differences of the IDA path (rtol 1e-12, Richardson-extrapolated), exact identities, and the
closed-form cycle bulk (thermal/cycle_exact.py) against the run's own (thermal/cycle.py `bulk_response`).

The seed's load case 1 with a motor drive for 60 s: the mechanics runs six turns, the bulk is the cycle-averaged
solution at a minute, so every piece of the cycle model is in the derivative (the turn's ends, its mean heat and
share, the network's modes, the periodic ripple, the time t_k + M P), at a fraction of an hour's cost.
"""
from __future__ import annotations

import numpy as np
import pytest

import mechsim
from conftest import assert_matches_finite_differences, richardson_central
from mechsim.scenarios import runner
from mechsim.scenarios.sensitivity import cycle_temperatures, cycle_window, sensitivity
from mechsim.scenarios.units import ScenarioError

NAME = "geneva-seed-lc1-mu015"
SETS = ["duration=60 s", "drive.type=motor", "drive.stall_torque=40 N*m", "drive.no_load_speed=8 rad/s",
        "thermal.averaging=cycle"]
SENS = ["solver.rtol=1e-10", "solver.atol=1e-12"]
FD = ["solver.rtol=1e-12", "solver.atol=1e-14"]
OF = ["peak_temp_contact_C", "peak_temp_flash_rise_K", "heat_per_index_J"]
COLUMNS = {"peak_temp_contact_C": "temp_contact_C", "peak_temp_flash_rise_K": "temp_flash_rise_K"}
#: the first three are checked by finite differences (geometry and mechanics, the motor and with it the period,
#: the material in network and flash); the others serve the exact identities
WRT = ["mechanism.crank_radius", "drive.no_load_speed", "thermal.conductivity", "thermal.density",
       "thermal.specific_heat", "thermal.ambient_temperature", "thermal.convection_pin", "drive.stall_torque"]
CHECKED = 3
#: relative steps 1e-5 and 5e-6: small enough that no event of the turn crosses an output row (asserted: there the
#: turn's piecewise-linear heat input, and the bulk with it, jump by a row's heat), large against rtol 1e-12
H = 1e-5
ELASTICITY_FLOOR = 1e-6


@pytest.fixture(scope="module")
def table():
    return sensitivity(mechsim.load(NAME, set=SETS + SENS), WRT, OF)


def _window(sets):
    """The plan and its mechanics window's run (the run cycle averaging averages), and the turn's temperatures."""
    plan = runner.plan(mechsim.load(NAME, set=SETS + sets))
    result = runner.execute(cycle_window(plan))
    assert result.failure is None
    return plan, result, cycle_temperatures(plan, result.timeseries)


def test_cycle_temperatures_match_finite_differences(table):
    _, nominal, turn = _window(FD)
    modes = nominal.timeseries["mode"].to_numpy()[turn["rows"]]
    rows = {q: int(turn["rows"][np.nanargmax(turn[c])]) for q, c in COLUMNS.items()}
    for q, row in rows.items():         # the sensitivity's peak is this row, at its last time in the run
        k = list(turn["rows"]).index(row)
        assert table.loc[table["quantity"] == q, "t_s"].iloc[0] == pytest.approx(turn["t_s"][k], abs=1e-6)

    def quantities(sets):
        _, result, got = _window(FD + sets)
        assert np.array_equal(result.timeseries["mode"].to_numpy()[got["rows"]], modes), "an event crossed a row"
        return {q: float(got[COLUMNS[q]][list(got["rows"]).index(row)]) for q, row in rows.items()}

    ref0 = quantities([])
    worst = {}
    for key in WRT[:CHECKED]:
        part = table[table["wrt"] == key].set_index("quantity")
        p, unit = float(part["parameter"].iloc[0]), part["wrt_unit"].iloc[0]
        fd = richardson_central(lambda v: quantities([f"{key}={v!r} {unit}".strip()]), p, H)
        mine = {}
        assert_matches_finite_differences(part, ref0, fd, p, key, 1e-7, ELASTICITY_FLOOR, mine)
        print(key, {q: f"{e:.1e}" for q, e in mine.items()})
        worst.update({q: max(e, worst.get(q, 0.0)) for q, e in mine.items()})
    print("largest relative deviation from the finite differences:", {q: f"{e:.1e}" for q, e in worst.items()})


def test_exact_identities(table):
    """(1) The network is linear and starts at the ambient, and the cycle model keeps that (the mean response from
    ambient, a zero-mean ripple): the contact temperature's derivative in T_amb is 1, the flash rise's 0.
    (2) rho and c_p enter only as rho c_p (capacities C = rho c_p V, diffusivity k/(rho c_p)): equal elasticities.
    (3) The flash rise depends on k and rho c_p only through k and the Peclet numbers U b/(2 chi): scaling both keeps
    every Peclet number and scales the rise by 1/k, so its elasticities in k and rho add up to -1
    (docs/theory.md §G4.2-§G4.6). (4) The heat per index is mechanics: no thermal value moves it."""
    t = table.set_index(["quantity", "wrt"])
    assert t.loc[("peak_temp_contact_C", "thermal.ambient_temperature"), "derivative"] == pytest.approx(1.0, abs=1e-9)
    assert t.loc[("peak_temp_flash_rise_K", "thermal.ambient_temperature"), "derivative"] == 0.0
    for q in OF:
        assert t.loc[(q, "thermal.density"), "elasticity"] == pytest.approx(
            t.loc[(q, "thermal.specific_heat"), "elasticity"], rel=1e-12, abs=1e-15)
    flash = "peak_temp_flash_rise_K"
    assert (t.loc[(flash, "thermal.conductivity"), "elasticity"] + t.loc[(flash, "thermal.density"), "elasticity"]
            == pytest.approx(-1.0, abs=1e-10))
    for key in ("thermal.conductivity", "thermal.convection_pin", "thermal.ambient_temperature"):
        assert t.loc[("heat_per_index_J", key), "derivative"] == 0.0


def test_closed_form_cycle_bulk_is_the_runs():
    """The cycle bulk the derivatives go through (thermal/cycle_exact.py: exact for the turn's piecewise-linear
    input) equals the run's (thermal/cycle.py `bulk_response`, Gauss-Legendre on pieces between the turn's rows,
    exact for that input to its quadrature error) at the rows' last times in the run."""
    from mechsim.thermal import cycle as cyc
    plan, result, turn = _window([])
    df = result.timeseries
    t, angle = df["t_s"].to_numpy(float), df["crank_angle_rad"].to_numpy(float)
    bounds = cyc.turn_boundaries(t, angle, angle[0])
    means = cyc.cycle_means_from_energies(t, bounds, df["heat_generated_J"].to_numpy(float),
                                          df["heat_pin_J"].to_numpy(float))
    setup = plan.thermal.setup
    u = setup.extension.inputs_numeric(plan.mechanism.contact_state(df))[0]
    a, P = means.t_start, means.period
    rows = [float(x) - a for x in t[(t > a) & (t < a + P)]]
    _, bulk = cyc.bulk_response(setup.system, means, lambda s: np.array([np.interp(a + s, t, ui) for ui in u]),
                                rows, turn["t_s"])
    assert turn["period"] == pytest.approx(P, rel=1e-14)
    np.testing.assert_allclose(turn["bulk"], bulk, rtol=0, atol=1e-9)
    ripple = bulk - bulk.mean(axis=0)
    assert np.ptp(ripple[:, 0]) > 0.1          # the pin's ripple over the turn is in it (K)


def test_cycle_at_prescribed_speed_is_refused():
    sc = mechsim.load("geneva-seed-lc1-mu015", set=["duration=60 s", "thermal.averaging=cycle"])
    with pytest.raises(ScenarioError) as err:
        sensitivity(sc, ["load.wheel_torque"], OF)
    assert err.value.field == "thermal.averaging"
