"""Two designs side by side (`mechsim compare A B`, `mechsim.compare(a, b)`, docs/api.md): the headline table holds
each run's own summary numbers, the differences are b - a and (b - a)/|a|; a design compared with itself differs
by nothing; a load torque changed at a prescribed crank speed changes the load's work per index exactly as its
closed form and leaves the kinematic peaks alone; the cycle figures close the energy balance of a periodic turn;
the overlaid figures draw both runs' values; runs of different mechanisms compare what they share and list the
rest; a folder mechsim did not write and misplaced options are one-line refusals (exit 2)."""
import io
import json
import math

import numpy as np
import pandas as pd
import pytest

import mechsim
from mechsim.scenarios.peaks import PERIODIC_RTOL

from cli_helpers import invoke, one_line_error

SHORT = {"duration": "1.5 s", "output_step": "2 ms"}
TORQUES = (7.0, 10.0)


@pytest.fixture(scope="module")
def saved(tmp_path_factory):
    """geneva-lc1 (crank at a prescribed 5.34 rad/s, 7 N*m on the wheel) run once and saved."""
    folder = tmp_path_factory.mktemp("cmp") / "lc1"
    mechsim.run("geneva-lc1", set=SHORT).save(folder, plots=False)
    return folder


@pytest.fixture(scope="module")
def torques(saved):
    """The saved 7 N*m run (a result folder) against the scenario run with 10 N*m on the wheel."""
    return mechsim.compare(saved, "geneva-lc1", set=SHORT, set_b={"load.wheel_torque": f"{TORQUES[1]} N*m"})


def _row(c, quantity):
    return c.table.set_index("quantity").loc[quantity]


def test_the_table_holds_each_runs_summary_and_its_differences(torques):
    a, b, t = torques.a.summary, torques.b.summary, torques.table.set_index("quantity")
    assert list(torques.table.columns) == ["quantity", "a", "b", "difference", "relative_difference", "resolved"]
    for col in ("contact_force_N", "drive_torque_N_m", "temp_contact_C"):
        for side in ("max", "min"):
            row = t.loc[f"peak_{side}_{col}"]
            assert row.a == a["peaks"][col][side]["value"] and row.b == b["peaks"][col][side]["value"]
    assert (t.difference == t.b - t.a).all()
    nonzero = t.a != 0
    np.testing.assert_array_equal(t.relative_difference[nonzero], (t.difference / t.a.abs())[nonzero])
    assert (t.relative_difference[~nonzero & (t.b == 0)] == 0).all()
    worst = next(c for c in b["validity"]["conditions"] if c["name"] == "hertz_half_width")["worst"]["value"]
    assert t.loc["validity_hertz_half_width_worst", "b"] == worst
    assert t.loc["thermal_heat_generated_J", "b"] == b["thermal"]["heat_balance"]["generated_J"]
    assert torques.names == ("geneva-lc1", f"geneva-lc1 with load.wheel_torque=\"{TORQUES[1]} N*m\"")
    assert torques.only_a == [] and torques.only_b == [] and torques.notes == []


def test_a_load_torque_changes_the_load_work_per_index_and_not_the_kinematics(torques):
    """The crank turns at a prescribed speed: the wheel's motion is the same closed form in both runs (its peaks
    differ by nothing), and the wheel load does W = -T 2 pi / n per index (one index per crank turn)."""
    for col in ("wheel_speed_rad_s", "wheel_accel_rad_s2", "slip_speed_m_s"):
        for side in ("max", "min"):
            assert _row(torques, f"peak_{side}_{col}").difference == 0
    n = torques.a.scenario["mechanism"]["slots"]
    row = _row(torques, "work_load_per_cycle_J")
    # the closed form's work is the trapezoidal rule on the rows: off by h^2/12 x the jump of the wheel's
    # acceleration at entry and at exit, relative to the index angle 2 pi/n
    h, accel = torques.a.scenario["output_step"], _row(torques, "peak_max_wheel_accel_rad_s2").a
    np.testing.assert_allclose([row.a, row.b], [-T * 2 * math.pi / n for T in TORQUES],
                               rtol=2 * h ** 2 / 12 * accel / (2 * math.pi / n))
    # the same rows, the same wheel motion: the works are in the torques' ratio to round-off
    assert row.relative_difference == pytest.approx(-(TORQUES[1] - TORQUES[0]) / TORQUES[0], rel=1e-12)


def test_the_cycle_mean_is_the_mean_over_one_crank_turn(torques):
    """Without a periodic regime (a prescribed drive) the cycle mean is the run's own, over its last complete crank
    turn located on the closed form (`peaks.last_drive_cycle`): at the constant crank speed w the turn lasts
    2 pi / w, and the drive's mean power w x mean torque is the wheel load's T w / slots plus the mean friction
    power (the kinetic energy returns), to the closed form's quadrature (1e-9). The work per turn is the rows'
    trapezoidal rule on the closed form's power (a closed-form run's work columns): off by at most h |jump| / T per
    jump of the drive torque, at entry and exit."""
    h, slots = torques.a.scenario["output_step"], torques.a.scenario["mechanism"]["slots"]
    for side, result, load in zip(("a", "b"), (torques.a, torques.b), TORQUES):
        mean = _row(torques, "cycle_mean_drive_torque_N_m")[side]
        assert mean == result.summary["peaks"]["drive_torque_N_m"]["cycle"]["mean"]
        friction = _row(torques, "cycle_mean_friction_power_W")[side]
        assert 5.34 * mean == pytest.approx(load * 5.34 / slots + friction, rel=1e-9)
        work = _row(torques, "work_drive_per_cycle_J")[side]
        period = _row(torques, "cycle_time_s")[side]
        jump = _row(torques, "peak_max_drive_torque_N_m")[side]
        assert period == pytest.approx(2 * math.pi / 5.34, rel=1e-9)
        assert abs(mean * 2 * math.pi - work) <= 2 * math.pi * 2 * h * jump / period


def test_a_design_against_itself_differs_by_nothing(saved):
    """A saved run against the same scenario run again: every headline quantity and every column the same."""
    c = mechsim.compare(saved, "geneva-lc1", set=SHORT)
    assert len(c.table) > 40 and (c.table.difference == 0).all()
    assert (c.table.relative_difference == 0).all() and not c.table.resolved.any()
    pd.testing.assert_frame_equal(c.a.timeseries, c.b.timeseries)


@pytest.fixture(scope="module")
def motors():
    """A motor-driven Geneva that settles into a periodic regime, against the same with a heavier wheel load."""
    sc = mechsim.load("geneva-motor", set={"duration": "6 s", "output_step": "2 ms"})
    return mechsim.compare(sc, sc.set({"load.wheel_torque": "9 N*m"}))


def test_one_scenario_twice_is_labelled_by_what_differs(motors):
    assert motors.names == ("geneva-motor with load.wheel_torque=7 N*m", "geneva-motor with load.wheel_torque=9 N*m")


def test_a_periodic_regime_gives_its_peaks_start_up_peaks_and_located_means(motors):
    for side, r in (("a", motors.a), ("b", motors.b)):
        assert r.summary["regime"], "the motor run settles (scenario description)"
        peaks = r.summary["peaks"]["contact_force_N"]
        assert _row(motors, "peak_max_contact_force_N")[side] == peaks["max"]["value"]
        assert _row(motors, "startup_peak_max_contact_force_N")[side] == peaks["startup"]["max"]["value"]
        assert (_row(motors, "cycle_mean_drive_torque_N_m")[side]
                == r.summary["peaks"]["drive_torque_N_m"]["periodic"]["mean"])


def test_the_work_per_periodic_turn_closes_the_energy_balance(motors):
    """Over one turn of a periodic regime the kinetic energy returns to its value: the works of drive, load,
    friction and damping sum to zero, to the regime's measured periodicity (its turns' spread, at least the
    solver's rtol), ten times over (about 1e-8 of the drive's work here)."""
    for side, r in (("a", motors.a), ("b", motors.b)):
        works = [_row(motors, f"work_{w}_per_cycle_J")[side] for w in ("drive", "load", "friction", "damping")]
        spread = max(r.summary["regime"]["turn_spread"], r.scenario["solver"]["rtol"])
        assert spread < PERIODIC_RTOL
        assert abs(sum(works)) <= 10 * spread * abs(works[0])


def test_a_mean_that_vanishes_over_a_periodic_turn_has_no_relative_difference(motors):
    """Over a periodic turn each speed returns to its value, so its mean acceleration, the speed's change over the
    turn divided by T, is zero exactly: what a run reports is its integrator's error (here below ten times the
    regime's periodicity or rtol, times the speed's scale, per turn), and (b - a)/|a| would be a ratio of two
    errors. It is NaN and the notes name it; a mean that does not vanish (the drive torque's) keeps its ratio."""
    r = motors.a.summary
    period = r["regime"]["period_s"]
    accuracy = 10 * max(r["regime"]["turn_spread"], motors.a.scenario["solver"]["rtol"])
    for body in ("crank", "wheel"):
        row = _row(motors, f"cycle_mean_{body}_accel_rad_s2")
        speed = r["peaks"][f"{body}_speed_rad_s"]["max"]["value"]
        assert 0 < abs(row.a) * period <= accuracy * speed
        assert math.isnan(row.relative_difference) and row.difference == row.b - row.a
        assert f"cycle_mean_{body}_accel_rad_s2 (|A| = " in next(n for n in motors.notes if n.startswith("zero at A"))
    row = _row(motors, "cycle_mean_drive_torque_N_m")
    assert row.relative_difference == row.difference / abs(row.a) and row.relative_difference > 0.1


def test_a_figure_both_designs_share_differs_only_within_the_runs_accuracy(motors):
    """In every dwell the crank runs free on the motor curve and settles where it meets the crank damping: the least
    drive torque is T* = c Ts / (Ts/w0 + c) whatever the wheel load (docs/theory.md, the motor drive). Both runs
    locate it to their integration's error of the torque's scale (10 x rtol x the stall torque they reach at
    start-up), so b - a is that error, not a difference between the designs: `resolved` is False and the notes
    say so, while the contact force's peak, which the load does change, is resolved."""
    sc = motors.a.scenario
    stall, free, c = sc["drive"]["stall_torque"], sc["drive"]["no_load_speed"], sc["mechanism"]["crank_damping"]
    rtol = max(sc["solver"]["rtol"], motors.b.scenario["solver"]["rtol"])
    equilibrium = c * stall / (stall / free + c)
    row = _row(motors, "peak_min_drive_torque_N_m")
    np.testing.assert_allclose([row.a, row.b], equilibrium, rtol=0, atol=10 * rtol * stall)
    scale = max(abs(r.summary["peaks"]["drive_torque_N_m"][k]["value"]) for r in (motors.a, motors.b)
                for k in ("max", "min"))
    assert 0 < abs(row.difference) <= 10 * rtol * scale and not row.resolved
    assert "peak_min_drive_torque_N_m" in next(n for n in motors.notes if n.startswith("equal within the runs'"))
    force = _row(motors, "peak_max_contact_force_N")
    assert force.resolved and abs(force.difference) > 1e3 * 10 * rtol * abs(force.a)
    assert _row(motors, "work_load_per_cycle_J").resolved


def test_a_temperatures_accuracy_is_of_the_absolute_temperature():
    """A temperature in degrees Celsius is integrated as the absolute temperature: a run at rtol resolves it to
    rtol x its value in kelvin, not in degrees Celsius (scenarios/studies/resolution.py); a count is exact."""
    from types import SimpleNamespace

    from mechsim.scenarios.studies.compare_designs import difference_floor, run_scales
    run = SimpleNamespace(scenario=None, summary={"model": {"rtol": 1e-6}, "peaks": {"temp_bulk_pin_C": {
        "max": {"value": 26.85}, "min": {"value": 20.0}}}})
    scales = run_scales(run)
    assert difference_floor("peak_max_temp_bulk_pin_C", 26.85, 26.86, scales, scales) == pytest.approx(10 * 1e-6 * 300)
    assert difference_floor("validity_violated_conditions", 1, 2, scales, scales) == 0.0


def test_the_figures_overlay_both_runs(torques):
    """A's lines solid and B's dashed in one colour: each line's data are its run's column; folded per crank turn
    both lie within one turn."""
    fig = torques.plot("contact_force_N")
    lines = {ln.get_gid(): ln for ax in fig.axes for ln in ax.get_lines()}
    for gid, r in (("contact_force_N", torques.a), ("B:contact_force_N", torques.b)):
        np.testing.assert_array_equal(lines[gid].get_xdata(), r["t_s"].to_numpy())
        np.testing.assert_array_equal(lines[gid].get_ydata(), r["contact_force_N"].to_numpy())
    assert lines["B:contact_force_N"].get_linestyle() == "--"
    assert lines["B:contact_force_N"].get_color() == lines["contact_force_N"].get_color()
    folded = torques.plot(["contact_force_N"], x="angle")
    xs = [ln.get_xdata() for ax in folded.axes for ln in ax.get_lines() if ln.get_gid().startswith("B:")]
    assert xs and np.ptp(np.concatenate(xs)) <= 360.0 + 1e-9
    figs = torques.plot()
    assert {"motion_vs_time", "forces_vs_time", "forces_vs_angle", "thermal_vs_time"} <= set(figs)
    with pytest.raises(KeyError, match="'nope'"):
        torques.plot("nope")


def test_different_mechanisms_compare_what_they_share(saved):
    """A Geneva against an internal Geneva: the common columns and quantities compared, the rest listed."""
    c = mechsim.compare(saved, "internal-geneva-speed", set={"duration": "1.2 s", "output_step": "2 ms"})
    ca, cb = set(c.a.timeseries.columns), set(c.b.timeseries.columns)
    assert set(c.only_a) >= ca - cb and set(c.only_b) >= cb - ca
    assert set(c.common_columns()) == ca & cb
    assert any(n.startswith("different mechanisms") for n in c.notes)
    assert _row(c, "peak_max_contact_force_N").a == c.a.summary["peaks"]["contact_force_N"]["max"]["value"]


def test_cli_writes_the_table_and_figures(saved, tmp_path):
    out = tmp_path / "cmp"
    res = invoke("compare", saved, saved, "--out", out, "--format", "csv")
    assert res.exit_code == 0, res.output
    table = pd.read_csv(out / "compare.csv")
    assert (table.difference == 0).all()
    pd.testing.assert_frame_equal(pd.read_csv(io.StringIO(res.stdout)), table)
    facts = json.loads((out / "compare.json").read_text())
    assert facts["a"] == facts["b"] == "geneva-lc1" and len(facts["quantities"]) == len(table)
    assert (out / "forces_vs_angle.png").is_file() and (out / ".mechsim-output").is_file()
    again = invoke("compare", saved, saved, "--out", out)
    assert again.exit_code == 2 and "--force" in one_line_error(again)


@pytest.mark.parametrize("args, words", [
    (("{saved}",), "two designs"),
    (("{tmp}", "{saved}"), "A: "),
    (("{saved}", "{saved}", "--set", "duration=1 s"), "scenarios only"),
    (("{saved}", "{saved}", "--rtol", "1e-9"), "--backends"),
    (("{saved}", "{saved}", "--backends"), "one scenario"),
])
def test_cli_refusals_are_one_line(saved, tmp_path, args, words):
    res = invoke("compare", *(a.format(saved=saved, tmp=tmp_path) for a in args))
    assert res.exit_code == 2
    assert words in one_line_error(res)
