"""Sensitivities of the temperatures (docs/sensitivity.md, 'Temperatures'): the peak contact temperature, the peak
flash rise and the heat per index of a Geneva with the lumped thermal model, against central finite differences of
the IDA path (rtol 1e-12, Richardson-extrapolated, as tests/test_sensitivity.py), and three exact identities of the
thermal model; the refusals of what is not traced.

geneva-motor for 0.7 s (motor drive, friction 0.15: one engagement with a slip reversal) and geneva-torque with
friction 0.15 for 0.5 s (constant torque with crank damping, running up: two engagements with slip reversals). Both request the same quantities, so the compiled pass
(the model with its thermal states, the same for both drives) serves both cases.
"""
from __future__ import annotations

import numpy as np
import pytest

import mechsim
from conftest import assert_matches_finite_differences, richardson_central
from mechsim.scenarios.units import ScenarioError
from mechsim.scenarios.sensitivity import THERMAL_PEAKS, sensitivity
from test_sensitivity import _work_at

THERMAL = ["thermal.model=lumped", "thermal.averaging=resolved"]
SENS = ["solver.rtol=1e-10", "solver.atol=1e-12"]
FD = ["solver.rtol=1e-12", "solver.atol=1e-14"]
OF = list(THERMAL_PEAKS) + ["heat_per_index_J"]
H = 5e-4
#: an elasticity that is zero (a thermal value cannot move the heat per index; the convection barely moves a
#: temperature over one engagement: its elasticity is ~1e-6) is compared absolutely, as in test_sensitivity.py
ELASTICITY_FLOOR = 1e-6
#: name: (settings, values traced, values also checked by finite differences); the motor case traces three more
#: for the exact identities (test_exact_identities), which check them without re-running
CASES = {
    "geneva-motor": (["duration=0.7 s"],
                     ["load.wheel_torque", "contact.friction", "mechanism.crank_radius", "thermal.conductivity",
                      "thermal.convection_pin", "thermal.density", "thermal.specific_heat",
                      "thermal.ambient_temperature"], 5),
    # the output step is fine here because the finite differences read the heat per index by interpolating the
    # friction work between output rows (tests/test_sensitivity.py `_work_at`), and the friction power changes fast
    # near this run's exits: at 1 ms that reading's own derivative is off by 2e-3, at 0.1 ms by < 1e-6
    "geneva-torque": (["duration=0.5 s", "output_step=0.1 ms", "contact.friction=0.15"],
                      ["drive.torque", "mechanism.pin_radius", "mechanism.thickness", "thermal.E",
                       "mechanism.wheel_inertia", "initial.crank_speed", "thermal.convection_wheel"], 4),
}


def _run(name, sets):
    r = mechsim.run(mechsim.load(name, set=THERMAL + sets))
    assert r.failure is None, r.failure.message()
    return r


def quantities(result, rows: dict) -> dict:
    """The thermal peaks at the given rows, and the heat of the last complete engagement (the friction work from
    entry to exit, as tests/test_sensitivity.py reads it)."""
    df, ev = result.timeseries, result.events
    out = {q: float(df[THERMAL_PEAKS[q]].iloc[i]) for q, i in rows.items()}
    entries = ev.loc[ev["kind"] == "entry", "t_s"].to_numpy(float)
    last_exit = ev.loc[ev["kind"] == "exit", "t_s"].to_numpy(float)[-1]
    out["heat_per_index_J"] = (_work_at(df, entries[entries < last_exit][-1], "friction")
                               - _work_at(df, last_exit, "friction"))
    return out


@pytest.fixture(scope="module")
def tables():
    return {name: sensitivity(mechsim.load(name, set=THERMAL + sets + SENS), wrt, OF)
            for name, (sets, wrt, _) in CASES.items()}


def _literal(si_value, unit):
    return f"{si_value!r} {unit}" if unit else repr(si_value)


@pytest.mark.parametrize("name", CASES)
def test_temperatures_match_finite_differences(tables, name):
    sets, wrt, checked = CASES[name]
    table = tables[name]
    nominal = _run(name, sets + FD)
    df = nominal.timeseries
    rows = {q: int(np.nanargmax(np.abs(df[c].to_numpy(float)))) for q, c in THERMAL_PEAKS.items()}
    for q, i in rows.items():       # the sensitivity's peak is the run's (same row)
        assert table.loc[table["quantity"] == q, "t_s"].iloc[0] == pytest.approx(float(df["t_s"].iloc[i]))
    ref0 = quantities(nominal, rows)
    worst = {}
    for key in wrt[:checked]:
        part = table[table["wrt"] == key].set_index("quantity")
        p, unit = float(part["parameter"].iloc[0]), part["wrt_unit"].iloc[0]
        fd = richardson_central(lambda value: quantities(_run(name, sets + FD + [f"{key}={_literal(value, unit)}"]),
                                                         rows), p, H)
        mine = {}
        assert_matches_finite_differences(part, ref0, fd, p, key, 1e-7, ELASTICITY_FLOOR, mine)
        print(name, key, {q: f"{e:.1e}" for q, e in mine.items()})
        worst.update({q: max(e, worst.get(q, 0.0)) for q, e in mine.items()})
    print(name, "largest relative deviation from the finite differences:", {q: f"{e:.1e}" for q, e in worst.items()})


def test_exact_identities(tables):
    """(1) rho and c_p enter only as rho c_p: equal elasticities. (2) The flash rise is (Q/l) R_p R_w/(R_p + R_w),
    R_i = theta(L_i)/(2k) with L_i = U_i b/(2 chi), chi = k/(rho c_p) (docs/theory.md §G4.2-§G4.6): scaling k and
    rho c_p together keeps every L_i and scales the rise by 1/k, so its elasticities in k and rho add up to -1.
    (3) The bulk network is linear, C T' = -K T + h A T_amb + B u, and starts at T_amb (docs/theory.md §G5): T - T_amb
    does not depend on T_amb, so d(contact temperature)/d T_amb = 1 and the flash rise does not depend on it."""
    t = tables["geneva-motor"].set_index(["quantity", "wrt"])
    for q in OF:
        assert t.loc[(q, "thermal.density"), "elasticity"] == pytest.approx(
            t.loc[(q, "thermal.specific_heat"), "elasticity"], rel=1e-12, abs=1e-15)
    flash = "peak_temp_flash_rise_K"
    assert (t.loc[(flash, "thermal.conductivity"), "elasticity"] + t.loc[(flash, "thermal.density"), "elasticity"]
            == pytest.approx(-1.0, abs=1e-10))
    assert t.loc[("peak_temp_contact_C", "thermal.ambient_temperature"), "derivative"] == pytest.approx(1.0, abs=1e-9)
    assert t.loc[(flash, "thermal.ambient_temperature"), "derivative"] == 0.0
    assert t.loc[("heat_per_index_J", "thermal.conductivity"), "derivative"] == 0.0


@pytest.mark.parametrize("sets, field", [
    (["thermal.model=1d"], "thermal.model"),                               # the wall-track mesh: not traced
    (["thermal.flash=seed-blok"], "thermal.flash"),                        # the seed's formula: not traced
])
def test_refused_thermal_options(sets, field):
    sc = mechsim.load("geneva-motor", set=["thermal.model=lumped"] + sets)
    with pytest.raises(ScenarioError) as err:
        sensitivity(sc, ["load.wheel_torque"], OF)
    assert err.value.field == field


def test_unset_thermal_geometry_is_refused():
    sc = mechsim.load("geneva-motor", set=["thermal.model=lumped"])
    with pytest.raises(ScenarioError) as err:
        sensitivity(sc, ["thermal.wheel_radius"], OF)
    assert err.value.field == "thermal.wheel_radius"


def test_band_table_in_jax_is_the_table():
    """The band rise the flash derivatives go through (`band_theta_table_xp` in jax) is the run's table, values and
    slope, inside the table and on both asymptotes (docs/theory.md §G4.3)."""
    import jax
    import jax.numpy as jnp
    from mechsim.thermal.band_source import band_theta_table, band_theta_table_xp
    L = np.logspace(-5, 5, 301)
    np.testing.assert_array_equal(band_theta_table_xp(L), band_theta_table(L))
    np.testing.assert_allclose(np.asarray(band_theta_table_xp(jnp.asarray(L), xp=jnp)), band_theta_table(L),
                               rtol=1e-15)
    slope = np.asarray(jax.vmap(jax.grad(lambda x: band_theta_table_xp(x, xp=jnp)))(jnp.asarray(L)))
    h = 1e-6
    fd = (band_theta_table(L * (1 + h)) - band_theta_table(L * (1 - h))) / (2 * h * L)
    inside = (L > 1.1e-4) & (L < 0.9e4)        # away from the table's ends, where the pieces meet the asymptotes
    np.testing.assert_allclose(slope[inside], fd[inside], rtol=1e-7)
