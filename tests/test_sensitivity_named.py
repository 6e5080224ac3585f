"""Quantities named by the extremum they are (docs/sensitivity.md, "Quantities"): `max_<col>`, `min_<col>` are the
run's located maximum and minimum (summary.json peaks.<col>.max / .min, the periodic regime's where the run
settles), `startup_max_<col>`, `startup_min_<col>` the start-up's (peaks.<col>.startup), `peak_<col>` the one of
larger magnitude; their derivatives follow the same envelope rule (the located instant, or the one-sided limit at
an event) as the peaks'. The sweep's rows carry the start-up's extremes beside the headline's
(`startup_peak_max_<col>`, docs/sweeps.md), and a sizing limit may name them.
"""
from __future__ import annotations

import pytest

import mechsim
from conftest import richardson_central
from mechsim.scenarios import runner
from mechsim.scenarios.studies.sensitivity import sensitivity
from mechsim.scenarios.units import ScenarioError

#: geneva-motor (4 slots, motor 40 N*m / 8 rad/s from 5.34 rad/s, wheel load 7 N*m) over its first engagement
SHORT = ["duration=1 s"]
#: the finite differences' runs: far tighter than the sensitivities' (the scenario's rtol 1e-8), so that they are
#: the more accurate side
FD = SHORT + ["solver.rtol=1e-12", "solver.atol=1e-14"]
LOAD = 7.0
#: relative step of the central differences (Richardson with h/2): truncation O(h^4); noise ~ rtol_fd / h
#: amplified by the adaptive steps (measured at rtol 1e-10: 5e-5 of the derivative at h = 1e-4), here ~5e-8
H = 1e-3
#: the sensitivities integrate at rtol 1e-8 through the entry and the slip reversals to t* ~ 0.4-0.5 s: their error
#: is some 1e-7 of the derivative (measured against these differences: 7e-8 for the force, 2.7e-7 for the
#: acceleration); 1e-5 leaves a factor of 30
DERIVATIVE_REL = 1e-5
#: the 6-slot motor-driven Geneva of tests/test_peaks_regimes.py: one start-up turn, then periodic
SETTLING = ["mechanism.slots=6", "duration=4 s"]
T0, W_NL, W0 = 40.0, 8.0, 5.34


@pytest.fixture(scope="module")
def short():
    sc = mechsim.load("geneva-motor", set=SHORT)
    table = sensitivity(sc, ["load.wheel_torque"], ["max_contact_force_N", "min_wheel_accel_rad_s2",
                                                    "peak_wheel_accel_rad_s2"])
    return table.set_index("quantity"), runner.run(mechsim.load("geneva-motor", set=SHORT))


def test_max_and_min_are_the_summary_s_located_extrema(short):
    """The values are summary.json's max and min themselves (the same run), at their instants; the wheel's
    acceleration peaks higher (139 rad/s^2, entering) than it dips (-124 rad/s^2, leaving), so `peak_` is its max
    and `min_` is the other one."""
    table, run = short
    peaks = run.summary["peaks"]
    for q, column, side in (("max_contact_force_N", "contact_force_N", "max"),
                            ("min_wheel_accel_rad_s2", "wheel_accel_rad_s2", "min")):
        assert table.loc[q, "value"] == peaks[column][side]["value"]
        assert table.loc[q, "t_s"] == peaks[column][side]["t_s"]
        assert peaks[column][side]["at"] == "interior"
    accel = peaks["wheel_accel_rad_s2"]
    assert accel["abs_max"]["side"] == "max" and accel["min"]["value"] < 0 < accel["max"]["value"]
    assert table.loc["peak_wheel_accel_rad_s2", "value"] == accel["max"]["value"]
    assert table.loc["min_wheel_accel_rad_s2", "value"] == accel["min"]["value"]


def test_max_and_min_derivatives_match_central_differences(short):
    """d(max contact force)/d(wheel load) and d(min wheel acceleration)/d(wheel load), both interior extrema (the
    envelope rule: dF/dp at the fixed t*), against Richardson central differences of the runs' located max / min."""
    table, _ = short

    def extrema(value):
        r = runner.run(mechsim.load("geneva-motor", set=FD + [f"load.wheel_torque={value!r} N*m"]))
        assert r.failure is None
        p = r.summary["peaks"]
        return {"max_contact_force_N": p["contact_force_N"]["max"]["value"],
                "min_wheel_accel_rad_s2": p["wheel_accel_rad_s2"]["min"]["value"]}
    fd = richardson_central(extrema, LOAD, H)
    for q, d in fd.items():
        assert table.loc[q, "derivative"] == pytest.approx(d, rel=DERIVATIVE_REL), q
    # the contact force grows with the load it carries, the dip of the wheel's acceleration is shallower
    assert fd["max_contact_force_N"] > 0 and fd["min_wheel_accel_rad_s2"] > 0


@pytest.fixture(scope="module")
def settling():
    sc = mechsim.load("geneva-motor", set=SETTLING)
    table = sensitivity(sc, ["drive.stall_torque", "drive.no_load_speed", "load.wheel_torque"],
                        ["startup_max_drive_torque_N_m", "max_drive_torque_N_m"])
    return table, runner.run(mechsim.load("geneva-motor", set=SETTLING))


def test_start_up_maximum_and_its_derivatives_in_closed_form(settling):
    """The start-up's drive torque peaks at t = 0 on the motor line T = T0 (1 - w0 / w_nl) = 13.3 N*m (the crank
    starts slow): dT/dT0 = 1 - w0/w_nl, dT/dw_nl = T0 w0 / w_nl^2, and the wheel load does not enter (the start's
    speed is given). No integration lies between the seed and t = 0: the derivatives are exact to round-off, 1e-12
    leaves four orders. `max_` is the periodic regime's (7.15 N*m, after the start-up), as summary.json's max."""
    table, run = settling
    start = table[table["quantity"] == "startup_max_drive_torque_N_m"].set_index("wrt")
    entry = run.summary["peaks"]["drive_torque_N_m"]
    assert start["value"].iloc[0] == entry["startup"]["max"]["value"] == pytest.approx(T0 * (1 - W0 / W_NL),
                                                                                        rel=1e-12)
    assert (start["t_s"] == 0.0).all()
    assert start.loc["drive.stall_torque", "derivative"] == pytest.approx(1 - W0 / W_NL, rel=1e-12)
    assert start.loc["drive.no_load_speed", "derivative"] == pytest.approx(T0 * W0 / W_NL**2, rel=1e-12)
    assert start.loc["load.wheel_torque", "derivative"] == 0.0
    periodic = table[table["quantity"] == "max_drive_torque_N_m"]
    assert (periodic["value"] == entry["max"]["value"]).all() and 7.0 < entry["max"]["value"] < 7.3
    assert periodic["t_s"].iloc[0] >= run.summary["regime"]["from_t_s"]
    # running, the torque peak follows the load it drives (elasticity ~1), not the motor's line
    assert periodic.set_index("wrt").loc["load.wheel_torque", "elasticity"] == pytest.approx(1.0, abs=0.01)


def test_a_run_that_does_not_settle_has_no_start_up_quantity():
    """geneva-motor's 4-slot wheel over 1 s completes no periodic turn: the start-up quantity is left out with a
    warning naming it (the run's headline peaks are the whole run's)."""
    table = sensitivity(mechsim.load("geneva-motor", set=SHORT), ["load.wheel_torque"],
                        ["startup_max_drive_torque_N_m"])
    assert table.empty
    assert any(w.startswith("startup_max_drive_torque_N_m: the run does not settle") for w in table.attrs["warnings"])


@pytest.mark.parametrize("name", ["max_contact_force", "max_temp_contact_C", "largest_contact_force_N",
                                  "startup_peak_max_drive_torque_N_m"])
def test_unknown_names_are_refused_naming_the_valid_ones(name):
    with pytest.raises(ScenarioError) as err:
        mechsim.sensitivity("geneva-motor", "load.wheel_torque", [name], set=SHORT)
    assert err.value.field == "--of"
    message = str(err.value)
    assert "\n" not in message and "peak_contact_force_N" in message
    assert "max_/min_/startup_max_/startup_min_" in message
    assert "contact_force_N, drive_torque_N_m" in message
    if name == "max_contact_force":            # the likely name suggested
        assert "(did you mean max_contact_force_N?)" in message


def test_sweep_rows_carry_the_start_up_extremes():
    """A sweep over the wheel load of the settling Geneva: the start-up columns beside the headline's. The start-up
    torque is the motor line's at t = 0, T0 (1 - w0/w_nl) = 13.3 N*m whatever the load; the periodic peak rises
    with it (about 1 N*m per N*m, `test_start_up_maximum_and_its_derivatives_in_closed_form`). A heat map reduces
    a start-up minimum by its minimum."""
    from mechsim.scenarios.studies.sweep.plots import aggregate_for
    df = mechsim.sweep("geneva-motor", ["load.wheel_torque=5,7 N*m"], set=SETTLING)
    assert df["success"].all()
    assert list(df["startup_peak_max_drive_torque_N_m"]) == pytest.approx([T0 * (1 - W0 / W_NL)] * 2, rel=1e-12)
    assert list(df["startup_peak_max_drive_torque_N_m_at_t_s"]) == [0.0, 0.0]
    assert (df["startup_peak_max_drive_torque_N_m_at_drive_angle_deg"] == -180.0).all()
    headline = df["peak_max_drive_torque_N_m"].to_numpy()
    assert 7.0 < headline[1] < 7.3 and headline[1] - headline[0] == pytest.approx(2.0, rel=0.05)
    assert (df["peak_max_drive_torque_N_m_at_t_s"] > df["startup_peak_max_drive_torque_N_m_at_t_s"]).all()
    assert "startup_peak_min_drive_torque_N_m" in df
    assert aggregate_for("startup_peak_min_drive_torque_N_m") == "min"
    assert aggregate_for("startup_peak_max_drive_torque_N_m") == "max"


def test_a_sizing_limit_on_an_unknown_name_is_refused():
    with pytest.raises(ScenarioError) as err:
        mechsim.size("geneva-motor", vary=["mechanism.crank_radius=60:90 mm"], minimize="mechanism.crank_radius",
                     subject_to=["max_contact_force <= 300"], set=SHORT)
    assert err.value.field == "--subject-to" and "max_/min_/startup_max_/startup_min_" in err.value.problem
