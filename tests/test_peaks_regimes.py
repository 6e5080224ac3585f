"""Start-up apart from the periodic regime, and approaches that grow without bound said as such (docs/theory.md
§K5): the headline peak of a run that settles is the periodic regime's, the start-up's beside it; a force that grows
without bound toward a stop has no peak, and the summary gives the stop's impulse and energy lost instead."""
import numpy as np
import pytest

import mechsim
from mechsim.scenarios import runner


@pytest.fixture(scope="module")
def six_slot():
    return runner.run(mechsim.load("geneva-motor", set=["mechanism.slots=6", "duration=4 s"]))


def test_motor_start_up_is_apart_from_the_periodic_regime(six_slot):
    """The issue's 6-slot motor-driven Geneva: the drive torque at t = 0 is the motor line's T0 - slope w0 =
    40 - 40/8 * 5.34 = 13.3 N*m (the crank starts slow); running, the torque peaks at about 7.2 N*m."""
    r = six_slot
    regime = r.summary["regime"]
    assert regime["startup_turns"] >= 1 and regime["periodic_turns"] >= 2 and regime["turn_spread"] < 1e-3
    torque = r.summary["peaks"]["drive_torque_N_m"]
    assert torque["startup"]["max"]["value"] == pytest.approx(40 - 40 / 8 * 5.34, rel=1e-9)
    assert torque["startup"]["max"]["t_s"] == 0.0
    assert 7.0 < torque["max"]["value"] < 7.3 and torque["max"]["t_s"] >= regime["from_t_s"]
    # the periodic regime's maximum is every periodic turn's: the last turn's own maximum, located alone
    a, b = regime["last_turn"]
    df = r.timeseries
    last = df[(df["t_s"] >= a) & (df["t_s"] <= b)]["drive_torque_N_m"].max()
    assert last <= torque["max"]["value"] < last * (1 + 1e-3)
    # the crank speed is periodic, so its acceleration averages to zero over a turn (trapezoidal rule between the
    # events' one-sided limits: O(h^2 F'') of the value's scale)
    accel = r.summary["peaks"]["crank_accel_rad_s2"]
    assert abs(accel["periodic"]["mean"]) < 1e-4 * accel["abs_max"]["value"]
    assert accel["startup"]["max"]["value"] > 10 * accel["max"]["value"]


def test_a_run_that_does_not_settle_has_no_regime():
    """A constant torque runs the Geneva up from 5.34 to about 40 rad/s in its first second (it settles later,
    against the crank's damping): no two turns alike, the peaks are the whole run's."""
    r = runner.run(mechsim.load("geneva-torque", set=["duration=1 s"]))
    assert r.summary["regime"] is None
    assert all("startup" not in e for e in r.summary["peaks"].values())


def test_coupler_force_through_the_smooth_apex_is_unbounded_not_its_value_at_the_event():
    """chain-mech2-smooth: through the apex on the smooth branch the coupler's force grows like 1/distance on both
    sides, with opposite signs. The run holds its state at the apex (`Trajectory.stops`, `starts`), where the force
    is round-off (-6.2e10 N, its sign either): read as the limit there it would be reported as the minimum. A limit
    against its rows' approach is not taken (`dynamics/extrema.py` `stored_limits`), and the growth toward
    the apex is what is reported, at any output step."""
    for step in ("10 ms", "23 ms"):
        r = runner.run(mechsim.load("chain-mech2-smooth", set=["duration=8 s", f"output_step={step}"]))
        force = r.summary["peaks"]["coupler_force_N"]
        apex = float(r.events.loc[r.events["kind"] == "apex", "t_s"].min())
        for name in ("max", "min"):
            assert force[name]["value"] is None and force[name]["unbounded"], (step, name, force[name])
            assert force[name]["t_s"] == apex, (step, name)
            assert force[name]["growth_exponent"] == pytest.approx(1.0, abs=0.02), (step, name)


def test_coupler_force_toward_the_crank_stop_is_unbounded_not_a_row():
    """chain-mech2-torque: at the apex the coupler's constraint loses rank (§K1.5) and its force grows like
    1/(t_stop - t) toward each crank stop; no peak is reported for it at any output step, the stop's impulse and
    energy lost are. The impulse closes the kinetic energy: dKE = (v+ + v-)/2 . impulse (M continuous), against the
    events table's energies before and after (computed by the transition, apart from the reading here)."""
    runs = {step: runner.run(mechsim.load("chain-mech2-torque", set=["duration=8 s", f"output_step={step}"]))
            for step in ("10 ms", "7 ms")}
    r = runs["10 ms"]
    force = r.summary["peaks"]["coupler_force_N"]
    assert force["max"]["value"] is None and force["max"]["unbounded"]
    assert force["abs_max"]["value"] is None
    stops = force["singular"]
    assert len(stops) == (r.events["kind"] == "stop impact").sum() == 2
    first = stops[0]
    assert "stop impact" in first["events"] and first["side"] == "before"
    assert first["growth_exponent"] == pytest.approx(1.0, abs=0.02)
    at = r.events["t_s"].to_numpy(float) == first["t_s"]
    lost = float(r.events.loc[at, "energy_lost_J"].sum())
    assert first["energy_lost_J"] == pytest.approx(lost, rel=1e-12)
    v_minus, v_plus = np.array(first["speeds_before"]), np.array(first["speeds_after"])
    impulse = np.array(list(first["impulse"].values()))
    assert 0.5 * (v_plus + v_minus) @ impulse == pytest.approx(-lost, rel=1e-5)
    # the stops in time order, the impulse the earliest's: not the stop whose nearest row happened to hold the
    # largest force (it was the stop at 11.0, 15.0 or 26.8 s at 1, 7 or 10 ms rows, its impulse 2.8e-4 apart)
    assert [s["t_s"] for s in stops] == sorted(s["t_s"] for s in stops)
    assert first["t_s"] == r.events.loc[r.events["kind"] == "stop impact", "t_s"].min() == force["max"]["t_s"]
    other = runs["7 ms"].summary["peaks"]["coupler_force_N"]["singular"][0]
    assert other["t_s"] == pytest.approx(first["t_s"], abs=1e-6)
    np.testing.assert_allclose(list(other["impulse"].values()), impulse, rtol=0, atol=1e-6 * np.abs(impulse).max())
    assert any("coupler_force_N grows without bound" in w for w in r.summary["warnings"])
    assert runs["7 ms"].summary["peaks"]["coupler_force_N"]["max"]["value"] is None
    # what is bounded stays located: the crank speed's maximum does not move with the output step
    speeds = [x.summary["peaks"]["crank_speed_rad_s"]["max"]["value"] for x in runs.values()]
    assert speeds[0] == pytest.approx(speeds[1], rel=1e-7)


def test_a_limit_at_a_stop_the_column_grows_toward_is_no_extremum():
    """chain-mech1-torque: the coupler force grows without bound toward each crank stop (from before). At 0.5 s rows
    the state held at the stop at 21.74 s gave it as -2.1e8 N (round-off of a singular KKT system), and that limit
    was reported as the minimum; it is no value, so the rows' minimum stands (0 N, the dwell's, as the located one at
    10 ms rows). The maximum's instant is the first stop's, and its drive angle now that stop's own (the events
    table's drive_q there), not the angle of the stop whose bracket held the extremum (7.07 rad against 3.14)."""
    for step in ("10 ms", "0.5 s"):
        r = runner.run(mechsim.load("chain-mech1-torque", set=[f"output_step={step}"]))
        force = r.summary["peaks"]["coupler_force_N"]
        assert force["max"]["value"] is None and force["max"]["unbounded"]
        at = r.events["t_s"].to_numpy(float) == force["max"]["t_s"]
        assert force["max"]["drive_angle_rad"] == float(r.events.loc[at, "drive_q"].iloc[0]), step
        assert force["min"]["value"] == 0.0, (step, force["min"])


def test_where_the_regime_begins_does_not_depend_on_the_output_step():
    """geneva-torque (a constant 6 N*m on IDA) settles at 1.5169 s. The criterion compares each turn's duration and
    starting drive speed with the last turn's to 1e-3; both are read at the turns' ends located on the continuous
    solution. With the speeds interpolated linearly between rows, the regime began at 1.3679 s at 31 ms rows and not
    at all at 80 ms (four rows a turn), where the crank-speed minimum became the start-up's 5.34 rad/s. At 1 s rows
    (seven turns a row) the turns' ends are estimated from the samples between the rows (`_turn_estimates`): from
    the rows the regime was not found there either. The located ends carry the re-integration's error from rows up
    to 1 s back (measured 3e-8 s): 1e-6 s is the margin."""
    runs = {step: mechsim.run(mechsim.load("geneva-torque", set=["output.plots=false", f'output_step="{step}"']))
            for step in ("1 ms", "31 ms", "80 ms", "1 s")}
    own = runs["1 ms"].summary
    for step in ("31 ms", "80 ms", "1 s"):
        other = runs[step].summary
        assert other["regime"] is not None, step
        assert other["regime"]["startup_turns"] == own["regime"]["startup_turns"], step
        assert other["regime"]["from_t_s"] == pytest.approx(own["regime"]["from_t_s"], abs=1e-6), step
        assert other["regime"]["period_s"] == pytest.approx(own["regime"]["period_s"], abs=1e-6), step
        low = own["peaks"]["crank_speed_rad_s"]["min"]
        assert other["peaks"]["crank_speed_rad_s"]["min"]["value"] == pytest.approx(low["value"], rel=1e-6), step
