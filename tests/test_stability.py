"""Where the methods fail (docs/stability.md): every failure is detected and reported - exit 3 with a message
that names the cause, or a warning and an event row - never a hang and never silent garbage."""
import json
import importlib.util
import re

import numpy as np
import pandas as pd
import pytest
from typer.testing import CliRunner

from mechsim.scenarios.cli import app
from mechsim.benchmarks.stability import CASES, thermal_mesh_sweep

runner = CliRunner()
CASE = {c.name: c for c in CASES}


def invoke_case(case, out):
    """The case's CLI run without figures (these tests read messages and tables; tests/test_cli.py checks that a
    failed run keeps its figures too)."""
    args = ["run", case.scenario, "--out", str(out), "--quiet", "--set", "output.plots=false"]
    for o in case.overrides:
        args += ["--set", o]
    return runner.invoke(app, args)


def test_index3_on_ida_exits_3_naming_the_formulation(tmp_path):
    r = invoke_case(CASE["index-3 on IDA"], tmp_path / "o")
    assert r.exit_code == 3, r.output
    assert "index-3" in r.stderr and "formulation = 'index2'" in r.stderr
    # where it stopped, with units, each angle also in its turn (where a designer finds it on the drawing): the
    # entry, crank and wheel both at -pi/4, -45 deg
    where = dict((name, (float(rad), float(deg))) for name, rad, deg in
                 re.findall(r"(\w+) = (\S+) rad \((\S+) deg in its turn\)", " ".join(r.stderr.split())))
    assert set(where) == {"crank", "wheel"}
    for rad, deg in where.values():
        assert rad == pytest.approx(-np.pi / 4, abs=1e-5) and deg == pytest.approx(-45.0, abs=0.1)
    # what ran is kept, and it stops at the first restart (entry at crank angle -pi/4, docs/theory.md §K4):
    # the last row is the output step before it
    df = pd.read_csv(tmp_path / "o" / "timeseries.csv")
    gap = -np.pi / 4 - df["crank_angle_rad"].iloc[-1]
    assert 0 <= gap <= 1e-3 * df["crank_speed_rad_s"].iloc[-1] * 1.01


def test_events_off_mode_change_stepped_over(tmp_path):
    """With solver.events = false the crank runs past the entry angle still 'locked': detected after the
    segment, rows after the crossing dropped, so no row is in the wrong mode."""
    r = invoke_case(CASE["events disabled"], tmp_path / "o")
    assert r.exit_code == 3, r.output
    assert "mode change stepped over" in r.stderr and "'entry'" in r.stderr and "solver.events" in r.stderr
    df = pd.read_csv(tmp_path / "o" / "timeseries.csv")
    # geneva-motor starts at -180 deg in the dwell; entry is at -alpha0 = -45 deg (n = 4): every kept row
    # is before it, and the crossing lies within one output step of the last row
    assert (df["mode"] == "dwell").all()
    assert df["crank_angle_rad"].max() < -np.pi / 4
    assert -np.pi / 4 - df["crank_angle_rad"].iloc[-1] < 1e-3 * df["crank_speed_rad_s"].iloc[-1] + 1e-12


def test_stall_exits_3_where_the_crank_stops(tmp_path):
    """2 N*m cannot carry 7 N*m on the wheel through the engagement: the crank stops, and the slip reversal that
    comes with it (u is proportional to the crank speed) does not hide the stall; no row runs backwards.
    The stall time is where the reduced-coordinate equation (docs/theory.md §G2) brings the crank speed to zero."""
    r = invoke_case(CASE["drive too weak (stall)"], tmp_path / "o")
    assert r.exit_code == 3, r.output
    # the hint names the scenario's keys a user changes
    assert "crank stalled" in r.stderr and "drive.torque" in r.stderr and "load.wheel_torque" in r.stderr
    df = pd.read_csv(tmp_path / "o" / "timeseries.csv")
    assert (df["crank_speed_rad_s"] > 0).all()
    ev = pd.read_csv(tmp_path / "o" / "events.csv")
    assert list(ev["kind"]) == ["entry", "stall"]
    from scipy.integrate import solve_ivp

    import mechsim.mechanisms.geneva.reduced as reduced
    from mechsim.scenarios.loader import build_mechanism, load
    mech = build_mechanism(load("geneva-torque", ["drive.torque=2 N*m"]).si)   # frictionless: no slip sign

    def rhs(_t, s):
        return [s[1], reduced.acceleration(mech, s[0], s[1], 2.0, 0.0, 1.0)]

    def entry(_t, s):
        return s[0] + mech.geometry.engagement_half_angle

    def stop(_t, s):
        return s[1]

    entry.terminal = stop.terminal = True
    first = solve_ivp(rhs, (0, 1), [-np.pi, 5.34], "DOP853", events=entry, rtol=1e-12, atol=1e-12)
    t1, y1 = first.t_events[0][0], first.y_events[0][0] + [1e-15, 0.0]
    second = solve_ivp(rhs, (t1, 1), y1, "DOP853", events=stop, rtol=1e-12, atol=1e-12)
    assert ev["t_s"].iloc[0] == pytest.approx(t1, abs=1e-9)
    assert ev["t_s"].iloc[-1] == pytest.approx(second.t_events[0][0], abs=1e-7)


def test_flank_switch_is_a_warning_and_an_event_row(tmp_path):
    """At 40 rad/s the wheel's deceleration J2 beta'' exceeds the load: N changes sign where the closed form
    (docs/theory.md §G2, flank from the sign of N) says it does; the run goes on (exit 0) on the other flank."""
    r = invoke_case(CASE["pin crosses to the other flank"], tmp_path / "o")
    assert r.exit_code == 0, r.output
    assert r.stderr == ""                               # --quiet: errors only; the warnings are in the summary
    summary = json.loads((tmp_path / "o" / "summary.json").read_text())
    assert any("flank" in g["first"] for g in summary["warning_groups"])
    ev = pd.read_csv(tmp_path / "o" / "events.csv")
    switches = ev[ev["kind"] == "flank switch"]
    assert len(switches) >= 2
    from mechsim.mechanisms.geneva.model import Geneva  # noqa: F401  (the closed form below is the mechanism's own, independent)
    from mechsim.scenarios.loader import build_mechanism, load
    sc = load("geneva-lc1", ["drive.speed=40 rad/s"])
    mech = build_mechanism(sc.si)
    t = np.linspace(0.0, 0.3, 300001)
    cf = mech.closed_form(t, -np.pi, 40.0)
    change = np.flatnonzero(np.diff(cf["flank"]) != 0)
    change = change[(cf["flank"][change] != 0) & (cf["flank"][change + 1] != 0)]
    np.testing.assert_allclose(switches["t_s"].to_numpy()[:2], t[change[:2]], atol=2e-6)


@pytest.mark.skipif(importlib.util.find_spec("diffrax") is None, reason="diffrax not installed")
def test_baumgarte_gains_choke_the_explicit_solver(tmp_path):
    """alpha = beta = 1e6: eigenvalues near -1e6 1/s hold Tsit5's step near 3.5e-6 s; it runs out of steps and
    the message says it is stiffness from the gains, not a mystery."""
    r = invoke_case(CASE["Baumgarte gains on an explicit solver"], tmp_path / "o")
    assert r.exit_code == 3, r.output
    assert "stiff for the explicit Tsit5" in r.stderr and "Baumgarte gains" in r.stderr
    assert "Kvaerno5" in r.stderr and "index2" in r.stderr


@pytest.mark.skipif(importlib.util.find_spec("diffrax") is None, reason="diffrax not installed")
def test_explicit_solver_on_a_refined_thermal_mesh_exits_3_and_ida_runs(tmp_path):
    """First cell 2.5 um: the wall's fastest time constant (~dz^2/chi) is about 1e-6 s; Tsit5 runs out of steps
    and the message names the wall temperatures; IDA (BDF) runs the same scenario to the end."""
    case = CASE["explicit solver on a refined 1-D thermal mesh"]
    r = invoke_case(case, tmp_path / "o")
    assert r.exit_code == 3, r.output
    assert "stiff for the explicit Tsit5" in r.stderr and "temp_wall" in r.stderr and "'ida'" in r.stderr
    args = ["run", case.scenario, "--out", str(tmp_path / "ida"), "--quiet", "--set", "output.plots=false"]
    for o in case.overrides:
        args += ["--set", o if not o.startswith("solver.backend") else "solver.backend=ida"]
    r = runner.invoke(app, args)
    assert r.exit_code == 0, r.output


def test_refined_thermal_mesh_stops_the_explicit_solver():
    """The fastest time constant of the 1-D mesh falls like dz^2 (here 2.5e-4 s -> 2.3e-7 s): RK45 exceeds its
    step budget and says so; BDF's cost stays flat, and on the coarse mesh both agree."""
    sweep = thermal_mesh_sweep(first_cells=(8e-5, 2.5e-6), methods=("RK45", "BDF"), duration=0.6, budget=20000)
    rk, bdf = (sweep[sweep.method == m].set_index("first_cell_m") for m in ("RK45", "BDF"))
    assert rk.loc[8e-5, "status"] == "ok" and rk.loc[2.5e-6, "status"].startswith("step budget exceeded: stiff")
    assert (bdf.status == "ok").all()
    assert bdf.loc[2.5e-6, "rhs_evaluations"] < 2 * bdf.loc[8e-5, "rhs_evaluations"]
    assert rk.loc[8e-5, "final_surface_temp_K"] == pytest.approx(bdf.loc[8e-5, "final_surface_temp_K"], rel=1e-4)
    assert sweep.fastest_time_constant_s.min() < 1e-6 < 1e-4 < sweep.fastest_time_constant_s.max()


def test_a_failing_ida_run_through_the_api_prints_nothing(capfd):
    """scikit-sundae prints each IDA failure ("[IDASolve, Error: -22] At t = ...") on stdout; a user of the API
    reads it from the result instead: the failure with its time, and the loop's recoveries before it."""
    import mechsim
    case = CASE["index-3 on IDA"]
    sc = mechsim.load(case.scenario, set=[*case.overrides, "solver.backend=ida", "output.plots=false"])
    r = mechsim.run(sc)
    printed = capfd.readouterr()
    assert printed.out == "" and "IDASolve" not in printed.err
    assert r.summary["failure_code"] in ("max_steps", "integrator_failed")
    # where index-3 breaks down: the first restart, the entry at crank angle -pi/4 (docs/theory.md §K4)
    assert r.summary["solver"]["recoveries"] >= 1
    assert "index-3" in r.summary["failure"] and "crank = -0.785398 rad" in r.summary["failure"]


@pytest.mark.skipif(importlib.util.find_spec("diffrax") is None, reason="diffrax not installed")
def test_a_small_step_budget_is_not_called_stiffness(tmp_path):
    """geneva-motor on Tsit5 with solver.max_steps = 50: the first segment spends its 50 steps in 0.09 s (mean
    1.8 ms, what rtol 1e-8 asks for) while the fastest eigenvalue (250 1/s) would allow 14 ms: the budget ran out,
    stiffness did not hold the steps. The message says to raise solver.max_steps and does not send the user to
    an implicit solver or to lower Baumgarte gains that are already 10."""
    r = runner.invoke(app, ["run", "geneva-motor", "--out", str(tmp_path / "o"), "--quiet", "--set",
                            "output.plots=false", "--set", 'solver.backend="diffrax"', "--set", "solver.max_steps=50"])
    assert r.exit_code == 3, r.output
    assert "raise solver.max_steps" in r.stderr
    assert "stiff" not in r.stderr and "Baumgarte" not in r.stderr
