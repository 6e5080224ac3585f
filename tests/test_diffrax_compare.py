"""IDA and diffrax integrate the same derived Geneva model: they must agree to the stated tolerances
(angles 1e-7 rad, speeds 1e-6 relative, contact force 1e-5 relative) over several crank turns, with the same
sequence of events (issue 4, part 2)."""
import numpy as np
import pandas as pd
import pytest
from typer.testing import CliRunner

from mechsim.scenarios.cli import app
from mechsim.scenarios.studies.compare import column_table, compare, tolerance_for

RTOL = 1e-10   # both backends; every test here shares one compiled diffrax solve per mode


@pytest.fixture(scope="module")
def motor_table():
    # motor drive with pin-slot friction (slip reversals) and damping: 3 crank turns at ~5.3 rad/s
    return compare("geneva-motor", ["duration = '3.6 s'", "output_step = '2 ms'"], rtol=RTOL)


def _row(table, column):
    return table.set_index("column").loc[column]


def test_tolerances_as_stated():
    assert tolerance_for("wheel_angle_rad").value == pytest.approx(1e-7) and tolerance_for("wheel_angle_rad").kind == "rel"
    assert tolerance_for("wheel_angle_rad", 1e-8).value == pytest.approx(1e-5)      # scales with the rtol
    assert tolerance_for("crank_speed_rad_s").kind == "rel" and tolerance_for("crank_speed_rad_s").value == pytest.approx(1e-6)
    assert tolerance_for("contact_force_N").value == pytest.approx(1e-5)
    assert tolerance_for("drive_torque_N_m") is None


def test_motor_drive_with_friction_agrees(motor_table):
    t = motor_table
    assert t.attrs["failures"] == {}
    assert t.attrs["same_event_sequence"] and t.attrs["events"]["ida"] >= 9   # 3 turns: entry, slip, exit
    assert t.attrs["event_time_max_diff_s"] < 1e-8
    for col in ("crank_angle_rad", "wheel_angle_rad", "crank_speed_rad_s", "wheel_speed_rad_s",
                "contact_force_N"):
        assert _row(t, col)["passed"], (col, _row(t, col).to_dict())
    assert _row(t, "mode (rows differing)")["max_abs_diff"] == 0
    assert t.attrs["passed"]


def test_torque_drive_agrees():
    # 2 s: about 9 crank turns. The crank accelerates to 45 rad/s, and IDA's global error at rtol 1e-10 grows with
    # it (against the reduced-coordinate reference: 3.5e-8 rad at 2 s, 1.5e-7 rad at 3 s; diffrax 1e-8 rad), so the
    # stated 1e-7 rad agreement is a claim about the first 2 s.
    t = compare("geneva-torque", ["duration = '2 s'", "output_step = '2 ms'"], rtol=RTOL)
    assert t.attrs["passed"], t[t.passed == False].to_dict("records")  # noqa: E712
    assert t.attrs["same_event_sequence"] and t.attrs["events"]["ida"] >= 4


def test_work_columns_agree(motor_table):
    """The integrated works are states of both solves: they agree like the motion does."""
    for col in ("work_drive_J", "work_load_J", "work_friction_J"):
        assert _row(motor_table, col)["max_rel_diff"] < 1e-6, col


def test_cli_compare_passes_and_user_errors_are_one_line():
    runner = CliRunner()
    res = runner.invoke(app, ["compare", "geneva-torque", "--backends", "--set", "duration='0.6 s'",
                              "--rtol", str(RTOL)])
    assert res.exit_code == 0, res.output
    assert "contact_force_N" in res.output
    bad = runner.invoke(app, ["compare", "no-such-scenario", "--backends"])
    assert bad.exit_code == 2
    assert len(bad.output.strip().splitlines()) == 1


def test_column_table_fails_beyond_tolerance():
    """A wheel-angle error of 2e-7 rad fails; one of 5e-8 passes; unbounded columns are only reported."""
    t = np.linspace(0.0, 1.0, 11)
    ida = pd.DataFrame({"t_s": t, "mode": ["engaged"] * 11, "crank_angle_rad": 5 * t, "wheel_angle_rad": np.sin(t),
                        "drive_torque_N_m": np.ones(11)})
    for err, ok in ((2e-7, False), (5e-8, True)):
        other = ida.copy()
        other.loc[7, "wheel_angle_rad"] += err
        other.loc[3, "drive_torque_N_m"] += 1.0
        table = column_table(ida, other, "crank_angle_rad").set_index("column")
        assert table.loc["wheel_angle_rad", "passed"] is ok
        assert table.loc["wheel_angle_rad", "t_s"] == pytest.approx(0.7)
        assert table.loc["wheel_angle_rad", "drive_angle_rad"] == pytest.approx(3.5)
        assert table.loc["drive_torque_N_m", "passed"] is None


def test_cli_compare_exits_1_when_backends_disagree(monkeypatch):
    import mechsim.scenarios.studies.compare as cmp

    def disagreeing(*args, **kwargs):
        table = pd.DataFrame([dict(column="wheel_angle_rad", max_abs_diff=1e-3, max_rel_diff=1e-3, t_s=0.5,
                                   drive_angle_rad=2.0, tolerance="abs <= 1e-07", passed=False)])
        table.attrs.update(passed=False, scenario="x", rtol=1e-10, diffrax_solver="Tsit5", rows={}, events={},
                           event_time_max_diff_s=0.0, failures={}, solver={"ida": {}, "diffrax": {}})
        return table

    monkeypatch.setattr(cmp, "compare", disagreeing)
    res = CliRunner().invoke(app, ["compare", "geneva-torque", "--backends"])
    assert res.exit_code == 1
    assert "NO" in res.output
