"""The command line: outputs written atomically, user errors as one line with exit 2, failures exit 3."""
import json
import subprocess
import sys

import pandas as pd
import pytest
import tomli_w
from cli_helpers import invoke, one_line_error


def write(tmp_path, raw, name="case.toml"):
    path = tmp_path / name
    path.write_text(tomli_w.dumps(raw))
    return path


def test_list_and_show():
    r = invoke("list")
    assert r.exit_code == 0 and "geneva-lc1" in r.stdout and "geneva-motor" in r.stdout
    r = invoke("show", "geneva-lc1")
    assert r.exit_code == 0 and 'wheel_torque = "7 N*m"' in r.stdout


def test_run_writes_every_output(tmp_path):
    out = tmp_path / "lc1"
    r = invoke("run", "geneva-lc1", "--out", out, "--quiet", "--set", "duration=1.2 s",
               "--set", "solver.method=dae")
    assert r.exit_code == 0, r.output
    for name in ("timeseries.parquet", "timeseries.csv", "events.csv", "summary.json", "scenario.toml",
                 "motion_vs_time.png", "forces_vs_angle.png", "mechanism.png"):
        assert (out / name).is_file(), name
    df = pd.read_parquet(out / "timeseries.parquet")
    required = ["t_s", "mode", "crank_angle_rad", "crank_speed_rad_s", "crank_accel_rad_s2", "wheel_angle_rad",
                "wheel_speed_rad_s", "wheel_accel_rad_s2", "drive_torque_N_m", "contact_force_N",
                "friction_force_N", "slip_speed_m_s", "friction_power_W", "kinetic_energy_J",
                "constraint_residual_m"]
    assert set(required) <= set(df.columns)
    pd.testing.assert_frame_equal(df, pd.read_csv(out / "timeseries.csv"), check_dtype=False)
    summary = json.loads((out / "summary.json").read_text())
    peak = summary["peaks"]["contact_force_N"]["max"]
    # N = T_L / (x_min - mu R) at mid-engagement plus inertia: docs/theory.md §G2 (225.3 N without friction)
    assert 225 < peak["value"] < 235 and abs(peak["drive_angle_wrapped_deg"]) < 10
    assert summary["model"]["method"] == "dae" and summary["solver"]["residual_evaluations"] > 0
    assert summary["versions"]["scikit-sundae"]
    # the resolved scenario is valid input again and reproduces the same run
    r2 = invoke("run", out / "scenario.toml", "--out", tmp_path / "again", "--quiet", "--set", "output.plots=false")
    assert r2.exit_code == 0, r2.output
    df2 = pd.read_parquet(tmp_path / "again" / "timeseries.parquet")
    pd.testing.assert_frame_equal(df, df2)


def test_existing_output_needs_force(tmp_path):
    out = tmp_path / "o"
    quick = ["--quiet", "--set", "output.plots=false"]
    assert invoke("run", "geneva-lc1", "--out", out, *quick, "--set", "duration=0.1 s").exit_code == 0
    r = invoke("run", "geneva-lc1", "--out", out, *quick, "--set", "duration=0.1 s")
    assert r.exit_code == 2 and "--force" in one_line_error(r)
    assert invoke("run", "geneva-lc1", "--out", out, *quick, "--force", "--set", "duration=0.2 s").exit_code == 0
    assert pd.read_csv(out / "timeseries.csv")["t_s"].iloc[-1] == pytest.approx(0.2)
    assert not [p for p in tmp_path.iterdir() if p.name.startswith(".")]  # no temporary folders left


MALFORMED = [
    ("missing field", lambda r: r["mechanism"].pop("crank_radius"), "mechanism.crank_radius"),
    ("unknown key", lambda r: r["mechanism"].update(crank_raduis="75 mm"),
     "mechanism.crank_raduis: unknown key (did you mean crank_radius?)"),
    ("a section's key at the top", lambda r: r.update(crank_radius="75 mm"),
     "crank_radius: not a top-level key: it belongs in [mechanism]"),
    ("unknown section", lambda r: r.update(motor={"x": 1}), "motor"),
    ("wrong unit", lambda r: r["mechanism"].update(crank_radius="75 kg"), "mechanism.crank_radius"),
    ("missing unit", lambda r: r["mechanism"].update(pin_radius=4), "mechanism.pin_radius"),
    ("negative radius", lambda r: r["mechanism"].update(crank_radius="-75 mm"), "mechanism.crank_radius"),
    ("slots < 3", lambda r: r["mechanism"].update(slots=2), "mechanism.slots"),
    ("unknown drive", lambda r: r["drive"].update(type="steam"), "drive.type"),
    ("non-numeric", lambda r: r["contact"].update(friction="a lot"), "contact.friction"),
    ("unreadable quantity", lambda r: r.update(duration="three seconds"), "duration"),
    ("motor without curve", lambda r: r.update(drive={"type": "motor", "stall_torque": "5 N*m"}),
     "drive.no_load_speed"),
    ("key of another drive type", lambda r: r["drive"].update(torque="5 N*m"), "drive.torque"),
    ("unknown mechanism", lambda r: r["mechanism"].update(type="cam"), "mechanism.type"),
    ("misspelt mechanism", lambda r: r["mechanism"].update(type="genva"), "got 'genva' (did you mean geneva?)"),
    ("no mechanism type", lambda r: r["mechanism"].pop("type"), "mechanism.type: missing (required: one of"),
    ("bad formulation", lambda r: r["solver"].update(formulation="index7"), "solver.formulation"),
    ("misspelt backend", lambda r: r["solver"].update(backend="difrax"), "got 'difrax' (did you mean diffrax?)"),
    ("pin too big", lambda r: r["mechanism"].update(pin_radius="40 mm"), "pin_radius"),
]


@pytest.mark.parametrize("label,mutate,field", MALFORMED, ids=[m[0] for m in MALFORMED])
def test_malformed_scenario_exits_2_with_one_line(tmp_path, lc1_raw, label, mutate, field):
    mutate(lc1_raw)
    r = invoke("run", write(tmp_path, lc1_raw), "--out", tmp_path / "out", "--quiet")
    assert r.exit_code == 2, r.output
    assert field in one_line_error(r)
    assert not (tmp_path / "out").exists()


def test_malformed_toml_and_missing_file(tmp_path):
    bad = tmp_path / "bad.toml"
    bad.write_text("name = 'x'\n[mechanism\n")
    r = invoke("run", bad, "--quiet")
    assert r.exit_code == 2 and "malformed TOML" in one_line_error(r)
    r = invoke("run", tmp_path / "nope.toml", "--quiet")
    assert r.exit_code == 2 and "not found" in one_line_error(r)
    r = invoke("run", "geneva-lc", "--quiet", "--out", tmp_path / "o")      # a built-in's name, misspelt
    assert r.exit_code == 2 and "(did you mean geneva-lc1?)" in one_line_error(r)
    r = invoke("run", "geneva-lc1", "--set", "solver.rtol=abc", "--quiet", "--out", tmp_path / "o")
    assert r.exit_code == 2 and "solver.rtol" in one_line_error(r)


def test_stall_exits_3_and_keeps_what_ran(tmp_path, lc1_raw):
    lc1_raw["drive"] = {"type": "torque", "torque": "1 N*m"}
    lc1_raw["load"]["wheel_torque"] = "20 N*m"
    lc1_raw["initial"] = {"crank_angle": "-60 deg", "crank_speed": "2 rad/s"}
    out = tmp_path / "stall"
    r = invoke("run", write(tmp_path, lc1_raw), "--out", out, "--quiet")
    assert r.exit_code == 3, r.output
    assert "stalled" in r.stderr and "t =" in r.stderr
    summary = json.loads((out / "summary.json").read_text())
    assert summary["success"] is False and "stalled" in summary["failure"]
    assert summary["failure_code"] == "physical_stop"
    df = pd.read_csv(out / "timeseries.csv")
    assert 0 < df["t_s"].iloc[-1] < 3.0
    # the figures of what ran are kept too (tests/test_stability.py runs its failure cases without them)
    for name in ("motion_vs_time.png", "forces_vs_time.png", "thermal_vs_time.png", "report.html"):
        assert (out / name).stat().st_size > 1000, name


def test_solver_failure_exits_3(tmp_path):
    out = tmp_path / "tiny"
    r = invoke("run", "geneva-motor", "--out", out, "--quiet", "--set", "solver.max_steps=3")
    assert r.exit_code == 3
    assert "IDA failed" in r.stderr
    # the hint names the budget that ran out and its value, what a user changes first
    assert "raise solver.max_steps" in r.stderr and "solver.max_steps = 3 steps" in r.stderr
    assert json.loads((out / "summary.json").read_text())["failure_code"] == "max_steps"


def test_console_script_user_error_has_no_traceback(tmp_path):
    """The real entry point in a fresh process: one line on stderr, exit 2."""
    proc = subprocess.run([sys.executable, "-m", "mechsim.scenarios.cli", "run", "no-such-scenario"], capture_output=True,
                          text=True, cwd=tmp_path)
    assert proc.returncode == 2
    assert proc.stderr.strip().startswith("error: scenario:") and "Traceback" not in proc.stderr
    assert len(proc.stderr.strip().splitlines()) == 1


def test_unforeseen_backend_error_is_one_line_exit_3(tmp_path, monkeypatch):
    import mechsim.dynamics.hybrid as hybrid_module      # the runner imports the DAE loop from here when it runs one

    def broken(*args, **kwargs):
        raise RuntimeError("saveat.ts must be increasing\nmore lines of jax noise")

    monkeypatch.setattr(hybrid_module, "simulate", broken)
    r = invoke("run", "geneva-motor", "--out", tmp_path / "o", "--quiet")
    assert r.exit_code == 3
    line = one_line_error(r)
    assert "internal error" in line and "RuntimeError" in line and "jax noise" not in line
