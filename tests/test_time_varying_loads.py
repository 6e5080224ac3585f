"""Time-varying loads and drives through the public API: a wheel torque per station, a piecewise-linear wheel
torque in time, a motor duty cycle (docs/theory.md, 'Time-varying loads and drives').

Physics: a constant profile is the constant load to round-off; each index of a per-station run is the constant-load
run with that station's torque from the same state; the load's work is the integral of T_L(t) w2; with the motor
off in a dwell the crank coasts on its damping alone, w = w0 exp(-c1 t / J1); the breakpoints are events at their
exact instants; IDA and the compiled diffrax run agree. Bad input is one ScenarioError naming the field.
"""
from __future__ import annotations

import numpy as np
import pytest

import mechsim
from mechsim.scenarios.units import ScenarioError
from tests.cli_helpers import invoke, one_line_error

BASE = ["duration=1.5 s"]
PROFILE = 'load.wheel_torque_profile={t = ["0.2 s", "0.45 s", "0.5 s", "1.2 s"], torque = ["7 N*m", "3 N*m", "3 N*m", "9 N*m"]}'
NO_TORQUE = 'load.wheel_torque="0 N*m"'
STATIONS = 'load.wheel_torque_per_station=["7 N*m", "2 N*m", "5 N*m", "0.5 N*m"]'
DUTY = ['drive.duty_on="0.6 s"', 'drive.duty_off="0.3 s"']
#: switched off for 10 ms inside the first index (engaged 0.296 s to 0.557 s): the contact force jumps there
DUTY_ENGAGED = ['drive.duty_on="0.36 s"', 'drive.duty_off="0.01 s"']


def _run(*overrides):
    r = mechsim.run(mechsim.load("geneva-motor", set=[*BASE, *overrides]))
    assert r.success, r.failure
    return r


def _profile_torque(t):
    return np.interp(t, [0.2, 0.45, 0.5, 1.2], [7.0, 3.0, 3.0, 9.0])


# -- bad input: one ScenarioError naming the field --------------------------------------------------------------
@pytest.mark.parametrize("override, field", [
    ('load.wheel_torque_profile={t = ["0 s", "0.5 s", "0.4 s"], torque = ["1 N*m", "2 N*m", "3 N*m"]}',
     "load.wheel_torque_profile.t[2]"),
    ('load.wheel_torque_profile={t = ["0 s", "0.5 s"], torque = ["1 N*m", "2 N"]}',
     "load.wheel_torque_profile.torque[1]"),
    ('load.wheel_torque_profile={t = ["0 m", "0.5 s"], torque = ["1 N*m", "2 N*m"]}',
     "load.wheel_torque_profile.t[0]"),
    ('load.wheel_torque_profile={t = ["0 s"], torque = ["1 N*m", "2 N*m"]}', "load.wheel_torque_profile.torque"),
    ('load.wheel_torque_profile={t = ["0 s"], force = ["1 N*m"]}', "load.wheel_torque_profile"),
    ('load.wheel_torque_per_station=["1 N*m", "2 N*m", "3 N*m"]', "load.wheel_torque_per_station"),
    ('load.wheel_torque_per_station=["1 N*m", "2 N*m", "3 N*m", "4 rad"]', "load.wheel_torque_per_station[3]"),
    ('load.wheel_torque_per_station=["1 N*m", "2 N*m", "-3 N*m", "4 N*m"]', "load.wheel_torque_per_station[2]"),
    ('drive.duty_on="0.5 s"', "drive.duty_off"),
    ('drive.duty_off="0.5 kg"', "drive.duty_off"),
])
def test_bad_input_names_the_field(override, field):
    extra = [] if override.startswith("drive") else [NO_TORQUE]
    with pytest.raises(ScenarioError) as err:
        mechsim.load("geneva-motor", set=[override, *extra])
    assert str(err.value).startswith(field + ":"), str(err.value)
    assert "\n" not in str(err.value)


def test_two_ways_of_giving_the_wheel_torque_and_a_duty_on_a_prescribed_speed_are_refused():
    with pytest.raises(ScenarioError, match=r"^load\.wheel_torque_profile: give the wheel torque one way"):
        mechsim.load("geneva-motor", set=[PROFILE, "load.wheel_torque=7 N*m"])   # both given at once
    # given alone, the profile replaces the file's wheel_torque (Field.replaces)
    assert "wheel_torque" not in mechsim.load("geneva-motor", set=[PROFILE]).raw["load"]
    with pytest.raises(ScenarioError, match=r"^drive\.duty_on: a duty cycle needs drive.type"):
        mechsim.load("geneva-lc1", set=DUTY)


def test_cli_refuses_a_decreasing_profile_with_exit_2_and_one_line(tmp_path):
    bad = 'load.wheel_torque_profile={t = ["1 s", "0.5 s"], torque = ["1 N*m", "2 N*m"]}'
    result = invoke("run", "geneva-motor", "--set", bad, "--set", NO_TORQUE, "--out", tmp_path / "out")
    assert result.exit_code == 2
    line = one_line_error(result)
    assert "load.wheel_torque_profile.t[1]" in line and "strictly increasing" in line


def test_sensitivities_through_a_time_varying_load_are_refused():
    sc = mechsim.load("geneva-motor", set=[*BASE, PROFILE, NO_TORQUE])
    with pytest.raises(ScenarioError, match=r"^load\.wheel_torque_profile: sensitivities through a time-varying"):
        mechsim.sensitivity(sc, wrt=["contact.friction"])


# -- physics ---------------------------------------------------------------------------------------------------
def test_a_constant_profile_is_the_constant_load_to_round_off():
    """One point, or several on one level: no breakpoint, the same computation as wheel_torque = 7 N*m."""
    ref = _run()
    for profile in ('{t = ["0.3 s"], torque = ["7 N*m"]}', '{t = ["0 s", "0.4 s", "1 s"], torque = ["7 N*m", "7 N*m", "7 N*m"]}'):
        r = _run(f"load.wheel_torque_profile={profile}", NO_TORQUE)
        assert "load breakpoint" not in set(r.events["kind"])
        for col in ("crank_angle_rad", "wheel_speed_rad_s", "contact_force_N", "work_load_J"):
            np.testing.assert_array_equal(r.timeseries[col].to_numpy(), ref.timeseries[col].to_numpy())


def test_profile_breakpoints_are_exact_events_and_the_load_work_is_its_integral():
    r = _run(PROFILE, NO_TORQUE, "output_step=0.1 ms")
    ev = r.events[r.events["kind"] == "load breakpoint"]
    # 0.2 s is where the hold before the first point ends (the first segment's slope begins); 0.5 s ends the
    # flat piece; the knot at 0.45 s and the end of the profile at 1.2 s bend it too
    assert ev["t_s"].tolist() == [0.2, 0.45, 0.5, 1.2]
    assert (ev["from_mode"] == ev["to_mode"]).all()
    df = r.timeseries
    t, w2 = df["t_s"].to_numpy(), df["wheel_speed_rad_s"].to_numpy()
    engaged = (df["mode"] == "engaged").to_numpy()
    power = np.where(engaged, -_profile_torque(t) * w2, 0.0)
    integral = np.concatenate([[0.0], np.cumsum(0.5 * (power[1:] + power[:-1]) * np.diff(t))])
    work = df["work_load_J"].to_numpy()
    # trapezoidal rule at 0.1 ms: error O(dt^2 |P''|), about 1e-7 of the load's work here
    np.testing.assert_allclose(work, integral, atol=1e-6 * np.abs(work).max())
    balance = r.summary["energy"]
    assert abs(balance["closure_error_relative"]) < 1e-6, balance


def test_each_index_of_a_per_station_run_is_the_constant_load_run_from_the_same_state():
    r = _run(STATIONS, NO_TORQUE)
    df = r.timeseries
    entries = r.events[r.events["kind"] == "entry"]["t_s"].to_numpy()
    exits = r.events[r.events["kind"] == "exit"]["t_s"].to_numpy()
    assert len(entries) >= 2
    torques = [7.0, 2.0, 5.0, 0.5]
    for k, t_entry in enumerate(entries[:2]):
        # a row in the dwell before the entry: the state (crank angle, speed; the wheel locked) starts a run
        i = int(np.searchsorted(df["t_s"].to_numpy(), t_entry - 0.05))
        row = df.iloc[i]
        t_row = float(row["t_s"])
        end = exits[exits > t_entry][0] if (exits > t_entry).any() else 1.5
        station = k % 4            # crank angle -180 deg: slot 0 enters first
        one = mechsim.run(mechsim.load("geneva-motor", set=[
            f"duration={end - t_row:.12g} s", f'load.wheel_torque="{torques[station]} N*m"',
            f'initial.crank_angle="{float(row["crank_angle_rad"])!r} rad"',
            f'initial.crank_speed="{float(row["crank_speed_rad_s"])!r} rad/s"']))
        assert one.success
        t_one = one.timeseries["t_s"].to_numpy() + t_row
        mine = df[(df["t_s"] > t_row + 1e-9) & (df["t_s"] < end)]
        for col in ("crank_angle_rad", "crank_speed_rad_s", "wheel_angle_rad", "contact_force_N"):
            theirs = np.interp(mine["t_s"].to_numpy(), t_one, one.timeseries[col].to_numpy())
            scale = np.abs(one.timeseries[col]).max()
            # same rows (the 1 ms grid shifted by a whole number of steps), both at rtol 1e-8
            np.testing.assert_allclose(mine[col].to_numpy(), theirs, atol=1e-6 * scale, err_msg=col)


def test_the_station_is_the_slot_count_modulo_the_slots_rebased_counts_included():
    """The entry rule sets T_L from slot + slot_base (the re-based frame's count, `Geneva.rebase`) modulo n."""
    from mechsim.scenarios.loader import build_mechanism
    mech = build_mechanism(mechsim.load("geneva-motor", set=[STATIONS, NO_TORQUE]).si)
    values = dict(mech.parameter_values(), slot=1.0, slot_base=8.0)     # the 10th index: station 9 mod 4 = 1
    g = mech.geometry
    q = np.array([2 * np.pi * 1 - g.engagement_half_angle, 0.5 * g.pitch])
    tr = mech.on_guard("dwell", "entry", values, 0.0, q, np.array([5.0, 0.0]))
    assert tr.mode == "engaged" and tr.updates["T_L"] == 2.0
    assert mech.transition_rules()[("dwell", "entry")][0].python_only      # the compiled run hands it back
    assert mech.initial_state(-np.pi, 5.0).updates["T_L"] == 7.0 and mech.initial_state(2 * np.pi * 3, 5.0).updates[
        "T_L"] == 0.5


def test_motor_off_in_a_dwell_coasts_on_the_crank_damping_alone():
    """geneva-motor: the drive switches off at 0.6 s inside the dwell (0.551 s to 1.14 s); the crank then obeys
    J1 w' = -c1 w, so w = w(0.6) exp(-c1 (t - 0.6) / J1) until 0.9 s."""
    r = _run(*DUTY)
    ev = r.events
    switches = ev[ev["kind"].isin(["drive off", "drive on"])]
    # exact: off at m (on + off) + on, on again at (m + 1) (on + off), as floats compute them
    assert switches["t_s"].tolist() == [0.6, 0.6 + 0.3, (0.6 + 0.3) + 0.6][:len(switches)] and len(switches) >= 2
    assert switches["kind"].tolist()[:2] == ["drive off", "drive on"]
    df = r.timeseries
    off = df[(df["t_s"] >= 0.6) & (df["t_s"] <= 0.9)]
    assert (off["mode"] == "dwell").all()
    w0 = float(off["crank_speed_rad_s"].iloc[0])
    c1, J1 = 0.002, 0.02
    expected = w0 * np.exp(-c1 * (off["t_s"].to_numpy() - 0.6) / J1)
    np.testing.assert_allclose(off["crank_speed_rad_s"].to_numpy(), expected, rtol=1e-7)
    # the row at 0.6 s is the left limit (the motor still on); after it no torque at all
    np.testing.assert_allclose(off["drive_torque_N_m"].to_numpy()[1:], 0.0, atol=1e-12)
    on = df[(df["t_s"] > 0.9) & (df["t_s"] < 1.0)]
    np.testing.assert_allclose(on["drive_torque_N_m"].to_numpy(), 40.0 * (1 - on["crank_speed_rad_s"] / 8.0),
                               rtol=1e-9)
    balance = r.summary["energy"]
    assert abs(balance["closure_error_relative"]) < 1e-6, balance


@pytest.mark.parametrize("overrides", [(PROFILE, NO_TORQUE, *DUTY_ENGAGED), (STATIONS, NO_TORQUE)],
                         ids=["profile+duty", "stations"])
def test_ida_ida_compiled_and_the_compiled_diffrax_run_agree(overrides):
    ida = _run(*overrides)
    dfx = _run(*overrides, 'solver.backend="diffrax"')
    a, b = ida.events, dfx.events
    assert a["kind"].tolist() == b["kind"].tolist()
    np.testing.assert_allclose(a["t_s"].to_numpy(), b["t_s"].to_numpy(), atol=1e-7)
    brk = a["kind"].isin(["load breakpoint", "drive off", "drive on"]).to_numpy()
    np.testing.assert_array_equal(a["t_s"].to_numpy()[brk], b["t_s"].to_numpy()[brk])   # both exact
    for col in ("crank_angle_rad", "wheel_angle_rad", "work_load_J", "work_drive_J"):
        scale = np.abs(ida.timeseries[col]).max()
        np.testing.assert_allclose(dfx.timeseries[col], ida.timeseries[col], atol=1e-6 * scale, err_msg=col)
    assert "compiled whole-run" in dfx.summary["solver"]["notes"]["segments"]
    if STATIONS not in overrides:
        compiled = _run(*overrides, 'solver.backend="ida-compiled"')
        assert compiled.events["kind"].tolist() == a["kind"].tolist()
        np.testing.assert_array_equal(compiled.events["t_s"].to_numpy()[brk], a["t_s"].to_numpy()[brk])
        scale = np.abs(ida.timeseries["crank_angle_rad"]).max()
        np.testing.assert_allclose(compiled.timeseries["crank_angle_rad"], ida.timeseries["crank_angle_rad"],
                                   atol=1e-6 * scale)


def test_the_documented_example_loads_and_its_resolved_form_reads_back():
    """docs/examples/geneva_duty_profile.toml (docs/geneva.md) is valid, and its resolved scenario in SI text (the
    run folder's record) validates back to the same values."""
    from pathlib import Path

    import tomllib

    from mechsim.scenarios import loader
    from mechsim.scenarios.output.writer import resolved_scenario_toml
    path = Path(__file__).resolve().parents[1] / "docs" / "examples" / "geneva_duty_profile.toml"
    sc = mechsim.load(str(path))
    assert sc["drive.duty_on"] == 0.6 and sc["load.wheel_torque_profile"]["torque"] == [7.0, 3.0, 3.0, 9.0]
    again = loader.validate(tomllib.loads(resolved_scenario_toml(sc.si)))
    assert again["load"] == sc.si["load"] and again["drive"] == sc.si["drive"]
    # report.html's scenario table: the profile's two lists on rows of their own, each with its unit
    from mechsim.scenarios.output.report_html import scenario_rows
    rows = {r[1]: r for r in scenario_rows(sc.si) if r[0] == "load"}
    assert rows["wheel_torque_profile.t"][2:] == ["0.2, 0.45, 0.5, 1.2", "s"]
    assert rows["wheel_torque_profile.torque"][2:] == ["7, 3, 3, 9", "N·m"]


def test_cycle_averaged_temperatures_need_a_steady_load():
    """Cycle averaging stands one periodic crank turn for all later ones: refused under a time-varying load (one
    line naming thermal.averaging); 'auto' resolves every cycle instead."""
    from mechsim.scenarios import runner
    varying = [PROFILE, NO_TORQUE]
    with pytest.raises(ScenarioError, match=r"^thermal\.averaging: 'cycle' needs a steady load"):
        runner.plan(mechsim.load("geneva-seed-lc1-mu015", set=[*varying, 'thermal.averaging="cycle"']))
    plan = runner.plan(mechsim.load("geneva-seed-lc1-mu015", set=varying))
    assert plan.thermal.averaging == "resolved" and "varies in time" in plan.thermal.averaging_why


def test_motor_off_mid_index_follows_the_reduced_equation_to_a_stall():
    """Off at 0.35 s inside the first index, the crank carries the 7 N*m load on its kinetic energy alone: the DAE
    follows the independent one-coordinate equation (mechanisms/geneva/reduced.py, T_in = 0, DOP853 at 1e-12)
    from the switch's state, and stops with a stall (exit 3, a physics stop)."""
    from mechsim.mechanisms.geneva import reduced
    from mechsim.scenarios.loader import build_mechanism
    sc = mechsim.load("geneva-motor", set=[*BASE, 'drive.duty_on="0.35 s"', 'drive.duty_off="0.2 s"'])
    r = mechsim.run(sc)
    assert r.failure is not None and r.failure.kind == "physics" and "stalled" in r.failure.reason
    assert r.events["kind"].tolist() == ["entry", "drive off", "stall"]
    assert r.events["t_s"].tolist()[1] == 0.35
    df = r.timeseries
    after = df[(df["t_s"] >= 0.35) & (df["t_s"] <= r.failure.time - 2e-3)]
    assert (after["mode"] == "engaged").all() and len(after) > 10
    theta0, omega0 = float(after["crank_angle_rad"].iloc[0]), float(after["crank_speed_rad_s"].iloc[0])
    theta, omega = reduced.integrate(build_mechanism(sc.si), 0.0, 0.0, theta0, omega0, after["t_s"].to_numpy())
    np.testing.assert_allclose(after["crank_angle_rad"].to_numpy(), theta, rtol=0, atol=1e-7)
    np.testing.assert_allclose(after["crank_speed_rad_s"].to_numpy(), omega, rtol=0, atol=1e-6 * omega0)
