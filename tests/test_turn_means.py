"""The periodic regime's means over its last turn (`periodic.mean`, docs/theory.md §K5): Simpson's rule on each gap
between a smooth interval's instants (its ends, with the one-sided limits there, and its rows), with the column
read at the gap's midpoint, so a jump costs nothing and the error is O(h^4 |F''''|). Checked against what the
integrator itself integrates over the same turn, whose ends lie in a dwell:

- the crank turns once a turn: the mean crank speed is 2 pi / (b - a);
- the wheel turns one index a turn (the ends in a dwell, where it stands): the mean wheel speed is
  (2 pi / slots) / (b - a);
- the heat generated is integrated as a state: the mean heat rate is its change over the turn / (b - a) (no heat
  in the dwell, where the rows are interpolated to a and b).

The run's rtol 1e-7 bounds each speed's error, so the means' too; measured at most 1e-8 (internal-geneva-motor
and geneva-motor, 1 and 2.3 ms rows). The trapezoidal rule before: 1.8e-4 (geneva-torque's wheel speed at 1 ms),
5.8e-5 (internal-geneva-motor's wheel at 2.3 ms), 1.5e-5 (its heat rate), moving with the output step.
"""
import numpy as np
import pytest

import mechsim


@pytest.mark.parametrize("name, step", [("internal-geneva-motor", "1 ms"), ("internal-geneva-motor", "2.3 ms"),
                                        ("geneva-motor", "2.3 ms")])
def test_turn_means_equal_what_the_integrator_integrates(name, step):
    r = mechsim.run(mechsim.load(name, set=["output.plots=false", f'output_step="{step}"']))
    peaks, df = r.summary["peaks"], r.timeseries
    a, b = peaks["crank_speed_rad_s"]["periodic"]["mean_over"]
    slots = r.scenario["mechanism"]["slots"]
    assert peaks["crank_speed_rad_s"]["periodic"]["mean"] == pytest.approx(2 * np.pi / (b - a), rel=1e-7)
    assert peaks["wheel_speed_rad_s"]["periodic"]["mean"] == pytest.approx(2 * np.pi / slots / (b - a), rel=1e-7)
    if "heat_rate_W" in peaks:
        assert peaks["heat_rate_W"]["periodic"]["mean_over"] == [a, b]
        t = df["t_s"].to_numpy()
        generated = np.interp([a, b], t, df["heat_generated_J"].to_numpy())
        assert peaks["heat_rate_W"]["periodic"]["mean"] == pytest.approx((generated[1] - generated[0]) / (b - a),
                                                                          rel=1e-7)


def test_a_flash_rise_mean_hardly_moves_with_the_output_step():
    """The flash rise starts like sqrt(t - t_on) where a contact begins (docs/theory.md §G4.6), where Simpson's rule
    loses its order: the knots graded from each interval's start (`peaks.ONSET_KNOTS`, cubic) and toward its ends
    (`peaks.ONSET_GRADING`) keep its mean over the turn within 1e-6 between 1, 2.3 and 10 ms rows (measured 2e-7;
    1.9e-5 with the end grading alone, 4.5e-4 and 5e-3 of it apart at 2.3 and 10 ms on the rows before)."""
    means = [mechsim.run(mechsim.load("internal-geneva-motor", set=["output.plots=false", f'output_step="{step}"'])
                         ).summary["peaks"]["temp_flash_rise_K"]["periodic"]["mean"]
             for step in ("1 ms", "2.3 ms", "10 ms")]
    assert max(means) - min(means) <= 1e-6 * max(means)


# -- without a periodic regime: the last complete drive cycle ---------------------------------------------------

@pytest.fixture(scope="module")
def prescribed():
    """geneva-lc1 (the crank at a prescribed 5.34 rad/s, so no periodic regime is sought) at 1, 2.3 and 10 ms rows."""
    return {step: mechsim.run(mechsim.load("geneva-lc1", set=["output.plots=false", f'output_step="{step}"',
                                                              "duration=3 s"])) for step in ("1 ms", "2.3 ms", "10 ms")}


def test_a_prescribed_drive_cycle_mean_is_its_closed_form(prescribed):
    """The means of a run without a periodic regime are taken over its last complete drive cycle (a crank turn from
    mid-dwell, `peaks.last_drive_cycle`), located: the cycle lasts 2 pi / w; the wheel turns one index in it, so its
    mean speed is w / slots and its mean acceleration 0; the kinetic energy returns, so the drive's mean power
    w mean(T) is the wheel load's T_L w / slots plus the mean friction power. Read on the closed form with
    Simpson's rule at its 0.5 degree knots (O(h^4)): each to 1e-9, at every output step. The rows' trapezoidal
    rule before: the mean wheel acceleration -0.015 rad/s^2 at 2.3 ms rows, the mean contact force 1.2 % apart
    between 2.3 and 10 ms."""
    for r in prescribed.values():
        peaks, sc = r.summary["peaks"], r.scenario
        w, slots, load = sc["drive"]["speed"], sc["mechanism"]["slots"], sc["load"]["wheel_torque"]
        assert "periodic" not in peaks["crank_speed_rad_s"]
        a, b = peaks["crank_speed_rad_s"]["cycle"]["mean_over"]
        assert b - a == pytest.approx(2 * np.pi / w, rel=1e-12)
        mean = {c: e["cycle"]["mean"] for c, e in peaks.items() if e["cycle"]["mean"] is not None}
        assert mean["wheel_speed_rad_s"] == pytest.approx(w / slots, rel=1e-9)
        assert abs(mean["wheel_accel_rad_s2"]) <= 1e-9 * peaks["wheel_accel_rad_s2"]["max"]["value"]
        assert w * mean["drive_torque_N_m"] == pytest.approx(load * w / slots + mean["friction_power_W"], rel=1e-9)
        assert mean["heat_rate_W"] == pytest.approx(mean["friction_power_W"], rel=1e-9)
        assert peaks["temp_contact_C"]["cycle"]["mean"] is None      # defined only in contact: no mean over the turn


def test_a_prescribed_drive_cycle_mean_does_not_move_with_the_output_step(prescribed):
    """The same means, to 1e-9 (the closed form's quadrature) for the mechanical columns; the thermal ones to 1e-6 of
    their scale: the flash rise, which starts like sqrt(t - t_on) where a contact begins, 4.0283612 K to 2e-7 (4.04,
    4.03 and 4.10 K at 1, 2.3 and 10 ms on the rows)."""
    peaks = [r.summary["peaks"] for r in prescribed.values()]
    for c, entry in peaks[0].items():
        first = entry["cycle"]["mean"]
        if first is None:
            continue
        scale = max(abs(entry["max"]["value"]), abs(entry["min"]["value"]))     # (a mean of 0: the column's scale)
        for other in peaks[1:]:
            assert other[c]["cycle"]["mean"] == pytest.approx(first, abs=(1e-6 if c.startswith("temp_") else 1e-9)
                                                              * scale), c


def test_a_torque_driven_run_that_does_not_settle_takes_its_last_drive_cycle_located():
    """rolling-a-torque accelerates: no periodic regime. Its last complete crank turn is located on the continuous
    solution (Newton's method on the re-integrated angle) and the crank turns 2 pi in it: the mean crank speed is
    2 pi / (b - a) to the run's tolerance, at 1 and 2.3 ms rows alike."""
    got = []
    for step in ("1 ms", "2.3 ms"):
        peaks = mechsim.run(mechsim.load("rolling-a-torque", set=["output.plots=false", f'output_step="{step}"'])
                            ).summary["peaks"]
        a, b = peaks["crank_speed_rad_s"]["cycle"]["mean_over"]
        assert peaks["crank_speed_rad_s"]["cycle"]["mean"] == pytest.approx(2 * np.pi / (b - a), rel=1e-7)
        got.append({c: e["cycle"]["mean"] for c, e in peaks.items()})
    for c, x in got[0].items():
        assert got[1][c] == pytest.approx(x, rel=1e-6), c


def test_a_pole_inside_the_turn_has_no_mean():
    """chain-mech1-torque's coupler force grows like 1/distance toward each stop impact (growth exponent 1): its
    integral over a turn holding one diverges, so its mean is unbounded (None), as its maximum is; the rows'
    trapezoid gave -5.7e4, -1.5e5 and -1.5e6 N at 1, 2.3 and 10 ms rows. The bounded columns keep theirs."""
    peaks = mechsim.run(mechsim.load("chain-mech1-torque", set=["output.plots=false"])).summary["peaks"]
    coupler = peaks["coupler_force_N"]
    a, b = coupler["cycle"]["mean_over"]
    assert any(a <= s["t_s"] <= b and s["growth_exponent"] > 0.99 for s in coupler["singular"])
    assert coupler["cycle"]["mean"] is None and coupler["cycle"]["unbounded"] is True
    assert coupler["max"]["value"] is None
    assert peaks["crank_speed_rad_s"]["cycle"]["mean"] == pytest.approx(2 * np.pi / (b - a), rel=1e-7)


def test_the_console_and_the_report_show_the_mean_over_the_turn(prescribed):
    """What a designer reads first carries the mean beside the peaks: the console's peaks line and report.html's peaks
    table each show the summary's located mean of the contact force over the last drive cycle, and its span."""
    from mechsim.scenarios.output.report_html import report_html
    from mechsim.scenarios.console import console_lines
    r = prescribed["1 ms"]
    cycle = r.summary["peaks"]["contact_force_N"]["cycle"]
    assert f"mean {cycle['mean']:.5g} over the last turn" in console_lines(r.summary)[0]
    html = report_html(r, {})
    a, b = cycle["mean_over"]
    assert "mean over the last drive cycle" in html and f"{a:.6g} .. {b:.6g}" in html


def test_a_sweep_row_carries_the_located_means():
    """A sweep's table has each case's located means (`cycle_mean_<col>`, as mechsim compare names them): at the
    prescribed crank speed w the drive's mean power equals the wheel load's T_L w / slots plus the mean friction
    power, case by case, to 1e-9; a contact-only column has none (empty)."""
    table = mechsim.sweep("geneva-lc1", {"load.wheel_torque": "5,9 N*m"}, set={"duration": "1.5 s"})
    assert table["success"].all() and len(table) == 2
    w = 5.34
    np.testing.assert_allclose(w * table["cycle_mean_drive_torque_N_m"],
                               table["load.wheel_torque_N_m"] * w / 4 + table["cycle_mean_friction_power_W"], rtol=1e-9)
    assert table["cycle_mean_temp_contact_C"].isna().all()


def test_the_console_shows_a_closed_form_zero_as_zero():
    """chain-mech2-kinematic's drive torque is zero in a dwell (the crank held, the chain unloaded): its located
    minimum is -3.3e-19 N m, the round-off of the inverse dynamics' terms, and the console shows 0 for it (the
    summary keeps the number); a value above round-off of the column's scale keeps its digits."""
    from mechsim.scenarios.console import ROUNDOFF_SHOWN, console_lines
    r = mechsim.run(mechsim.load("chain-mech2-kinematic", set=["output.plots=false"]))
    torque = r.summary["peaks"]["drive_torque_N_m"]
    assert 0.0 < abs(torque["min"]["value"]) <= ROUNDOFF_SHOWN * torque["max"]["value"]
    line = console_lines(r.summary)[0]
    assert f"drive_torque_N_m 0 .. {torque['max']['value']:.5g} (max at" in line
    # where in its turn: the drive angle, which every turn shares
    assert f"drive angle {torque['max']['drive_angle_wrapped_deg']:.4g}°, mean" in line
    assert f"mean {torque['cycle']['mean']:.5g} over the last turn" in line
    from mechsim.scenarios.output.report_html import report_html
    html = report_html(r, {})                         # report.html's peaks table alike
    assert f"{torque['min']['value']:.6g}" not in html and f"{torque['max']['value']:.6g}" in html
    start = r.summary["peaks"]["crank_speed_rad_s"]["min"]    # at the run's start: drive angle 1.35e-10 deg
    assert 0.0 < abs(start["drive_angle_wrapped_deg"]) < 1e-9 and f"{start['drive_angle_wrapped_deg']:.6g}" not in html
