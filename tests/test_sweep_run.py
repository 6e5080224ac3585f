"""Sweeps end to end: the table, local pool vs Dask, resume after an interruption, failing cases, CLI errors.

Physics checks on the table (independent of the code): over one complete index the wheel turns exactly one
pitch (pi/2 for 4 slots), so the load does work -T_L pi/2 whatever the friction; with the crank at constant
speed and the wheel at rest at both ends the kinetic energy is unchanged, so drive + load + friction work = 0;
the last complete revolution of a crank at constant speed w lasts 2 pi / w.
"""
import json

import numpy as np
import pandas as pd
import pytest
from typer.testing import CliRunner

from mechsim.scenarios.cli import app
from mechsim.scenarios.studies.sweep.execute import DaskRunner, PoolRunner
from mechsim.scenarios.studies.sweep.run import run_sweep
from mechsim.scenarios.studies.sweep.spec import build_spec
from cli_helpers import one_line_error

# crank from -180 deg to the end of the first engagement (+45 deg) at 5.34 rad/s takes 0.735 s
ONE_INDEX = ["duration=0.8 s", "output_step=5 ms", "solver.method=dae"]
TIMING = ("case_wall_time_s", "case_cpu_time_s", "solver_wall_time_s", "solver_derive_time_s", "solver_solve_time_s",
          "solver_tables_time_s", "worker", "run_id")
cli = CliRunner()


def grid_2x2():
    return build_spec("geneva-lc1", ["contact.friction=0.1,0.3", "load.wheel_torque=5,9 N*m"], ONE_INDEX, False)


def invoke(*args):
    return cli.invoke(app, ["sweep", *map(str, args)])


@pytest.fixture(scope="module")
def local(tmp_path_factory):
    out = tmp_path_factory.mktemp("sweep") / "local"
    report = run_sweep(grid_2x2(), out, PoolRunner(2))
    return out, report


def test_grid_table_a_row_per_case_with_physics(local):
    out, report = local
    assert report.total == 4 and report.computed == 4 and report.failed == 0 and report.remaining == 0
    df = pd.read_parquet(out / "sweep.parquet")
    csv = pd.read_csv(out / "sweep.csv")
    assert list(csv.columns) == list(df.columns) and len(csv) == 4
    numeric = df.select_dtypes("number").columns
    pd.testing.assert_frame_equal(csv[numeric], df[numeric], check_dtype=False)
    assert list(df["case"]) == [0, 1, 2, 3] and df["success"].all()
    assert list(df["contact.friction"]) == [0.1, 0.1, 0.3, 0.3]
    assert list(df["load.wheel_torque_N_m"]) == [5.0, 9.0, 5.0, 9.0]
    for col in ("peak_max_contact_force_N", "peak_max_contact_force_N_at_t_s",
                "peak_max_contact_force_N_at_drive_angle_deg", "peak_min_drive_torque_N_m",
                "work_drive_J", "solver_residual_evaluations", "case_wall_time_s", "failure"):
        assert col in df
    np.testing.assert_allclose(df["work_load_J"], -df["load.wheel_torque_N_m"] * np.pi / 2, rtol=1e-6)
    np.testing.assert_allclose(df["work_drive_J"] + df["work_load_J"] + df["work_friction_J"], 0.0, atol=1e-5)
    # friction work grows with mu at equal load; the peak normal force sits near mid-engagement
    assert (df["work_friction_J"].iloc[2:].to_numpy() < df["work_friction_J"].iloc[:2].to_numpy()).all()
    assert (df["peak_max_contact_force_N_at_drive_angle_deg"].abs() < 15).all()
    assert len(list((out / "cases").glob("*.json"))) == 4
    plots = {p.name for p in (out / "plots").iterdir()}
    assert {"vs_contact.friction.png", "vs_load.wheel_torque_N_m.png", "heatmap_success.png",
            "heatmap_peak_max_contact_force_N.png"} <= plots
    summary = json.loads((out / "sweep_summary.json").read_text())
    assert summary["complete"] and summary["cases"] == 4 and "not applicable" in summary["batching"]


def test_dask_local_cluster_gives_identical_rows(local, tmp_path):
    pytest.importorskip("distributed")
    out, _ = local
    report = run_sweep(grid_2x2(), tmp_path / "dask", DaskRunner(local_workers=2), plots=False)
    assert report.computed == 4 and report.remaining == 0
    a, b = pd.read_parquet(out / "sweep.parquet"), pd.read_parquet(tmp_path / "dask" / "sweep.parquet")
    keep = [c for c in a.columns if c not in TIMING]
    pd.testing.assert_frame_equal(a[keep], b[keep])


class StopAfter:
    """A progress sink that presses Ctrl-C once `k` cases have finished."""

    def __init__(self, k):
        self.k, self.n = k, 0

    def start(self, total, done, failed):
        pass

    def advance(self, success):
        self.n += 1
        if self.n == self.k:
            raise KeyboardInterrupt


def test_interrupted_sweep_keeps_finished_cases_and_resumes_the_rest(tmp_path):
    args = ["--vary", "contact.friction=0.1,0.2,0.3", "--vary", "load.wheel_torque=5,9 N*m",
            "--set", "duration=0.5 s", "--set", "output_step=5 ms"]
    spec = build_spec("geneva-lc1", [args[1], args[3]], [args[5], args[7]], False)
    out = tmp_path / "sw"
    first = run_sweep(spec, out, PoolRunner(2), progress=StopAfter(2), plots=False)
    kept = first.total - first.remaining
    assert first.interrupted and 2 <= kept < 6
    before = {p.name: (json.loads(p.read_text())["run_id"], p.stat().st_mtime_ns) for p in (out / "cases").iterdir()}
    assert len(before) == kept and {r for r, _ in before.values()} == {first.run_id}
    assert len(pd.read_parquet(out / "sweep.parquet")) == kept

    r = invoke("geneva-lc1", *args, "--out", out, "--workers", 0, "--no-plots", "--quiet")
    assert r.exit_code == 0, r.output
    assert f"({6 - kept} computed, {kept} reused, 0 failed)" in r.stdout
    after = {p.name: json.loads(p.read_text())["run_id"] for p in (out / "cases").iterdir()}
    assert len(after) == 6
    for name, (run_id, mtime) in before.items():     # finished cases were not recomputed nor rewritten
        assert after[name] == run_id and (out / "cases" / name).stat().st_mtime_ns == mtime
    assert len({r for n, r in after.items() if n not in before}) == 1 != first.run_id
    df = pd.read_parquet(out / "sweep.parquet")
    assert len(df) == 6 and list(df["case"]) == list(range(6))

    r = invoke("geneva-lc1", *args, "--out", out, "--workers", 0, "--no-plots", "--quiet")
    assert "(0 computed, 6 reused, 0 failed)" in r.stdout


def test_failing_cases_are_recorded_with_their_reason_and_the_rest_complete(tmp_path):
    out = tmp_path / "fail"
    r = invoke("geneva-torque", "--vary", "drive.torque=1,6 N*m", "--vary", "solver.method=auto,closed-form",
               "--set", "duration=0.5 s", "--set", "output_step=5 ms", "--out", out, "--workers", 2, "--quiet",
               "--timeseries", "--no-plots")
    assert r.exit_code == 0, r.output
    assert "(4 computed, 0 reused, 3 failed)" in r.stdout
    df = pd.read_parquet(out / "sweep.parquet").set_index(["drive.torque_N_m", "solver.method"])
    assert df.loc[(6.0, "auto"), "success"] and df.loc[(6.0, "auto"), "failure"] == ""
    stall = df.loc[(1.0, "auto")]
    assert not stall["success"] and "stalled" in stall["failure"] and stall["failure_kind"] == "physics"
    assert 0 < stall["simulated_time_s"] < 0.5
    for torque in (1.0, 6.0):   # the closed form needs a prescribed speed: an error of that case only
        row = df.loc[(torque, "closed-form")]
        assert not row["success"] and "closed-form" in row["failure"] and row["failure_kind"] == "error"
    series = pd.read_parquet(out / "timeseries" / f"{df.loc[(6.0, 'auto'), 'case_id']}.parquet")
    assert len(series) == 101 and series["t_s"].iloc[-1] == pytest.approx(0.5)


@pytest.mark.parametrize("args, fragment", [
    (["--vary", "contact.friction=0.1:0.4"], "--vary contact.friction: cannot read"),
    (["--vary", "contact.frikshun=0.1,0.2"], "contact.frikshun: unknown key"),
    (["--vary", "load.wheel_torque=5,9 kg"], "load.wheel_torque: wrong unit"),
    (["--vary", "contact.friction=0.1,-0.2"], "(sweep case 2: contact.friction=-0.2)"),
    (["--vary", "contact.friction=0.1,0.2", "--vary", "load.wheel_torque=1:3:3 N*m", "--zip"], "equal lengths"),
    (["--vary", "contact.friction=0.1", "--dask-local", "2", "--scheduler", "tcp://x:1"], "not both"),
    ([], "nothing to sweep"),
])
def test_bad_specs_exit_2_with_one_line_before_anything_runs(tmp_path, args, fragment):
    r = invoke("geneva-lc1", *args, "--out", tmp_path / "never")
    assert r.exit_code == 2
    assert fragment in one_line_error(r)
    assert not (tmp_path / "never").exists()


def test_a_different_sweep_needs_force(tmp_path):
    out = tmp_path / "sw"
    base = ["--set", "duration=0.2 s", "--out", out, "--workers", 0, "--no-plots", "--quiet"]
    assert invoke("geneva-lc1", "--vary", "contact.friction=0.1,0.2", *base).exit_code == 0
    r = invoke("geneva-lc1", "--vary", "contact.friction=0.1,0.3", *base)
    assert r.exit_code == 2 and "holds a different sweep (2 cases, 1 in common" in one_line_error(r)
    r = invoke("geneva-lc1", "--vary", "contact.friction=0.1,0.3", *base, "--force")
    assert r.exit_code == 0 and "(2 computed, 0 reused" in r.stdout
    # the same cases written in other units are the same sweep: values are resolved to SI before hashing
    assert invoke("geneva-lc1", "--vary", "load.wheel_torque=5,9 N*m", *base, "--force").exit_code == 0
    r = invoke("geneva-lc1", "--vary", "load.wheel_torque=5000,9000 N*mm", *base)
    assert r.exit_code == 0 and "(0 computed, 2 reused" in r.stdout, r.output


def test_the_cli_reports_the_whole_commands_time_beside_the_cases(tmp_path):
    """`mechsim sweep` ends with the time the user waited, split into the cases (the account's, sweep_summary.json's
    wall_time_s) and the rest: start-up, tables and figures (as `run` and `sensitivity` do)."""
    import re
    from cli_helpers import durations, invoke
    r = invoke("sweep", "geneva-lc1", "--vary", "contact.friction=0.1,0.3", "--set", "output.plots=false",
               "--workers", "0", "--out", tmp_path / "s")
    assert r.exit_code == 0, r.output
    line = r.output.strip().splitlines()[-1]
    assert re.fullmatch(r"time: [0-9.]+ s in all \(cases [0-9.]+ m?s, start-up, tables and figures [0-9.]+ m?s\)",
                        line), r.output
    total, shown_cases, rest = durations(line)
    cases = json.loads((tmp_path / "s" / "sweep_summary.json").read_text())["wall_time_s"]
    # each part to its last digit shown: 0.1 ms below a tenth of a second, else 0.01 s
    assert shown_cases == pytest.approx(cases, abs=0.5e-4 if cases < 0.1 else 0.5e-2)
    assert abs(total - shown_cases - rest) <= 0.011
