"""`mechsim bench` (small CI version): every method reaches the reduced-coordinate reference with an error that
follows the requested tolerance; the files, counters and ratios are there; user errors exit 2."""
import json

import numpy as np
import pandas as pd
import pytest
from typer.testing import CliRunner

from mechsim.benchmarks.bench import SMALL_METHODS, SMALL_RTOLS, time_at_error, tracking
from mechsim.benchmarks.bench_methods import METHODS
from mechsim.scenarios.cli import app

runner = CliRunner()


@pytest.fixture(scope="module")
def small_bench(tmp_path_factory):
    out = tmp_path_factory.mktemp("bench") / "b"
    r = runner.invoke(app, ["bench", "--out", str(out), "--quiet"])
    assert r.exit_code == 0, r.output
    return out, r


def test_small_bench_writes_every_file(small_bench):
    out, r = small_bench
    for name in ("work_precision.csv", "output_cost.csv", "summary.json", "work_precision.png"):
        assert (out / name).is_file(), name
    assert "error ~ rtol^slope" in r.stdout


def test_every_method_tracks_the_tolerance(small_bench):
    """Against the reference (DOP853 at 1e-12 on docs/theory.md §G2's reduced equation): each method finishes, its
    error falls when rtol falls by 1000, and stays within 100 rtol (atol = 1e-2 rtol; angles ~ 10 rad)."""
    out, _ = small_bench
    rows = pd.read_csv(out / "work_precision.csv")
    assert set(rows.method) == {m for m in SMALL_METHODS if METHODS[m].available()}
    assert (rows.status == "ok").all(), rows[rows.status != "ok"][["method", "rtol", "failure"]]
    for method, d in rows.groupby("method"):
        d = d.set_index("rtol").error_rad
        loose, tight = d[max(SMALL_RTOLS)], d[min(SMALL_RTOLS)]
        assert tight < loose / 20, method
        assert tight <= 100 * min(SMALL_RTOLS), method
    summary = json.loads((out / "summary.json").read_text())
    # the reference is itself accurate far below every error it judges
    assert summary["reference"]["uncertainty_rad"] < 1e-10 < rows.error_rad.min()


def test_rows_carry_the_solver_statistics(small_bench):
    out, _ = small_bench
    rows = pd.read_csv(out / "work_precision.csv")
    ida = rows[rows.method.str.startswith("ida-")]
    # IDA's own step counters (read past scikit-sundae) and the DAE evaluations are all there
    assert (ida.steps > 0).all() and (ida.rejected_steps >= 0).all()
    assert (ida.residual_evaluations >= ida.steps).all() and (ida.jacobian_evaluations > 0).all()
    # the same mode sequence: entry, slip reversal, exit in the first second (the reduced ODE's slip event,
    # two-sided, may restart once more at the reversal)
    dae = ~rows.method.str.startswith("scipy")
    assert (rows.events[dae] == 3).all() and rows.events[~dae].between(3, 4).all()
    assert (rows.output_points == 1001).all()
    assert (rows.setup_time_s[rows.method.str.startswith(("ida", "casadi"))] > 0).all()
    cost = pd.read_csv(out / "output_cost.csv")
    assert {"ida-index1", "ida-index2"} <= set(cost.method)
    assert np.isfinite(cost.cost_per_output_point_us).all()


def test_unknown_method_and_existing_folder_are_user_errors(tmp_path):
    r = runner.invoke(app, ["bench", "no-such-solver", "--out", str(tmp_path / "x")])
    assert r.exit_code == 2 and "unknown method 'no-such-solver'" in r.stderr
    (tmp_path / "y").mkdir()
    r = runner.invoke(app, ["bench", "--out", str(tmp_path / "y")])
    assert r.exit_code == 2 and "--force" in r.stderr


def test_time_at_equal_error_and_tracking_on_exact_lines():
    """Work-precision lines wall = 1e-3 err^-1/4 and err = 0.5 rtol: interpolation and slope are exact."""
    rtol = 10.0 ** -np.arange(3, 11)
    err = 0.5 * rtol
    rows = pd.DataFrame(dict(method="m", status="ok", rtol=rtol, error_rad=err, wall_time_s=1e-3 * err ** -0.25))
    assert time_at_error(rows, "m", 1e-6) == pytest.approx(1e-3 * 1e-6 ** -0.25, rel=1e-12)
    assert np.isnan(time_at_error(rows, "m", 1e-12))
    t = tracking(rows, "m")
    assert t["slope"] == pytest.approx(1.0) and t["max_deviation_decades"] < 1e-12
    assert t["error_over_rtol_at_1"] == pytest.approx(0.5)


@pytest.mark.parametrize("scenario, names, column, label", [
    ("rolling-a-torque", ["ida-index1", "ida-index2"], "rolling_angle_rad", "independent (RollingPairFourBar.reference_solution"),
    ("chain-mech2-smooth", ["ida-index2"], "drive_angle_rad", "self-reference (IDA index2, rtol 1e-12; not independent)"),
])
def test_any_scenario_against_its_mechanism_reference(tmp_path, scenario, names, column, label):
    """`--scenario`: mechsim's own methods on another mechanism, the error on the drive coordinate against the
    mechanism's reference (`Mechanism.reference_solution`: the rolling pair's minimal-coordinate equation) or,
    without one (chain dwell), IDA index2 at rtol 1e-12, labelled as not independent; the Geneva's peers are
    skipped with a note."""
    out = tmp_path / "b"
    r = runner.invoke(app, ["bench", *names, "--scenario", scenario, "--set", "output_step=20 ms",
                            "--out", str(out), "--quiet"])
    assert r.exit_code == 0, r.output
    rows = pd.read_csv(out / "work_precision.csv")
    assert (rows.status == "ok").all() and np.isfinite(rows.error_rad).all()
    assert (rows.error_column == column).all() and rows.reference.str.startswith(label).all()
    assert (rows.output_points == 51).all()
    d = rows[rows.method == "ida-index2"].set_index("rtol").error_rad
    assert d[min(SMALL_RTOLS)] < d[max(SMALL_RTOLS)] / 20
    summary = json.loads((out / "summary.json").read_text())
    assert summary["reference_label"].startswith(label) and summary["error_column"] == column
    assert summary["reference"]["uncertainty_rad"] < 1e-10
    if len(names) == 2:
        assert set(rows.method) == {"ida-index1", "ida-index2"}
        assert summary["reference"]["independent"] is True


def test_geneva_peers_are_skipped_with_a_note_elsewhere(tmp_path):
    r = runner.invoke(app, ["bench", "scipy", "--scenario", "rolling-a-torque", "--out", str(tmp_path / "x")])
    assert r.exit_code == 2 and "none of the chosen methods applies to 'rolling_pair'" in r.stderr
    r = runner.invoke(app, ["bench", "--scenario", "rolling-a-speed", "--out", str(tmp_path / "y")])
    assert r.exit_code == 2 and "torque or motor drive" in r.stderr


def test_peer_bench_reaches_its_target_and_ratios_come_from_the_curves(tmp_path):
    """`mechsim bench --peer` (small): on case A the CasADi IDAS peer reaches 1e-6 rad against the independent
    reduced reference, with the same 9 mode changes (entry/exit, no slip guard at mu = 0) as the reference's
    boundaries; each reported ratio is the quotient of the two methods' times interpolated on the measured
    (error, median CPU) curves. No timing is asserted."""
    from mechsim.benchmarks.peer_bench import DEFAULT, PEER, PEER_TARGET_ERROR
    out = tmp_path / "p"
    r = runner.invoke(app, ["bench", "--peer", "--out", str(out), "--quiet"])
    assert r.exit_code == 0, r.output
    rows = pd.read_csv(out / "peer.csv")
    summary = json.loads((out / "peer_summary.json").read_text())
    assert (rows.status == "ok").all(), rows[["method", "rtol", "failure"]]
    peer = rows[rows.method == PEER].set_index("rtol")
    assert peer.error_rad.min() <= PEER_TARGET_ERROR
    assert summary["peer_target"]["reached"] and summary["peer_target"]["error_rad"] <= PEER_TARGET_ERROR
    assert (peer.events == 9).all() and (rows.output_points == 5001).all()
    # the peer's error falls with rtol (a tolerance 100x tighter: at least 20x smaller error)
    assert peer.error_rad[min(peer.index)] < peer.error_rad[max(peer.index)] / 20
    for target, entry in summary["ratios_at_equal_error_cpu"]["A"].items():
        t_peer = time_at_error(rows, PEER, float(target), "cpu_time_s")
        for method, ratio in entry["ratio_to_peer"].items():
            t = time_at_error(rows, method, float(target), "cpu_time_s")
            if np.isfinite(t) and np.isfinite(t_peer):
                assert ratio == pytest.approx(t / t_peer, rel=1e-12)
            else:
                assert ratio is None or np.isnan(ratio)
    assert "CPU time / casadi-idas" in r.stdout
    # both target errors lie inside the measured curves of the small run: the ratios are numbers
    assert all(np.isfinite(v) for e in summary["ratios_at_equal_error_cpu"]["A"].values()
               for v in e["ratio_to_peer"].values())
    # end to end: the warm mechsim.run integrates what the solve integrates (the same crank angle, so the same
    # error), and its ratios are its own curve's times over the peer's solve
    d = rows[rows.method == "ida-compiled-index1"]
    assert np.allclose(d.run_error_rad, d.error_rad, rtol=1e-6, atol=0) and np.isfinite(d.run_cpu_time_s).all()
    default = rows[rows.method == DEFAULT].set_index("rtol")
    assert (default.error_rad == default.run_error_rad).all() and default.cpu_time_s.isna().all()
    assert default.error_rad[min(default.index)] < default.error_rad[max(default.index)] / 20
    runs = rows.assign(error_rad=rows.run_error_rad)
    for target, entry in summary["ratios_by_peer"][PEER]["end_to_end"]["A"].items():
        t_peer = time_at_error(rows, PEER, float(target), "cpu_time_s")
        assert set(entry["ratio_to_peer"]) == {"ida-compiled-index1", DEFAULT}
        for method, ratio in entry["ratio_to_peer"].items():
            t = time_at_error(runs, method, float(target), "run_cpu_time_s")
            if np.isfinite(t):      # NaN: its run's curve does not reach the target (index-2 stalls near 1e-8)
                assert ratio == pytest.approx(t / t_peer, rel=1e-12)
            else:
                assert ratio is None or np.isnan(ratio)
        assert np.isfinite(entry["ratio_to_peer"]["ida-compiled-index1"])
    assert "end to end" in r.stdout
    # the located peaks, timed from inside the same end-to-end runs: each round's run less its located peaks is
    # below that round's run, so every order statistic is too (the medians); the ratios without them come from their
    # own curves as the others do
    timed = rows[np.isfinite(rows.run_cpu_time_s)]
    assert (timed.run_peaks_cpu_time_s > 0).all()
    assert (timed.run_less_peaks_cpu_time_s < timed.run_cpu_time_s).all()
    bare = rows.assign(error_rad=rows.run_error_rad)
    for target, entry in summary["ratios_by_peer"][PEER]["end_to_end_without_located_peaks"]["A"].items():
        t_peer = time_at_error(rows, PEER, float(target), "cpu_time_s")
        for method, ratio in entry["ratio_to_peer"].items():
            t = time_at_error(bare, method, float(target), "run_less_peaks_cpu_time_s")
            if np.isfinite(t):
                assert ratio == pytest.approx(t / t_peer, rel=1e-12)
    assert "less peaks" in r.stdout
    if METHODS["diffsol-tsit45"].available():
        assert set(summary["ratios_by_peer"]) == {PEER, "diffsol-tsit45"}
    else:
        assert "diffsol-tsit45: skipped, pydiffsol is not installed" in r.stderr


def _case_a():
    from mechsim.benchmarks.bench import BenchConfig, make_problem, reference
    from mechsim.benchmarks.peer_bench import CASE_A
    problem = make_problem(BenchConfig(scenario="geneva-motor", duration=5.0, overrides=CASE_A))
    return problem, reference(problem)


@pytest.mark.parametrize("name", ["diffsol-tsit45", "diffsol-bdf", "diffsol-tsit45-index1"])
def test_diffsol_peer_matches_the_reference(name):
    """The diffsol peer (the crank angle per mode in DiffSL, restarted at each located boundary) on case A: the
    reference's 9 boundary crossings, every output, and an error that follows the tolerance (100x tighter:
    at least 20x smaller), below 1e-6 rad at rtol 1e-7 (angles ~ 25 rad)."""
    method = METHODS[name]
    if not method.available():
        pytest.skip("pydiffsol not installed")
    problem, ref = _case_a()
    errors = {}
    for rtol in (1e-7, 1e-9):
        handle = method.setup(problem, rtol, rtol * 1e-2)[0]
        run = method.run(handle, problem, rtol, rtol * 1e-2)
        assert run.failure is None and len(run.t) == 5001 and run.stats["events"] == 9
        errors[rtol] = np.max(np.abs(run.angle - ref["angle"]))
    assert errors[1e-7] < 1e-6 and errors[1e-9] < errors[1e-7] / 20


def test_diffsol_peer_covers_the_external_geneva_without_friction_only():
    """Friction makes slip reversals mode changes and the lumped model adds states: neither is in the peer's
    program, so the bench skips it there, saying why."""
    from mechsim.benchmarks.bench import BenchConfig, make_problem
    from mechsim.benchmarks.peer_bench import CASES
    method = METHODS["diffsol-tsit45"]
    for case, supported in (("A", True), ("A-mu0.15", False), ("A-mu0.15-lumped", False)):
        problem = make_problem(BenchConfig(scenario="geneva-motor", duration=1.0, overrides=CASES[case]))
        assert method.supports_problem(problem) is supported, case
        if not supported:
            assert "without friction" in method.skip_reason(problem) or "thermal" in method.skip_reason(problem)


def test_geneva_peers_refuse_a_time_varying_load():
    """The peers' equations hold one constant wheel torque and a drive always on: per-station torques (or a
    profile, or a duty cycle) are skipped with the reason, mechsim's own methods run."""
    from mechsim.benchmarks.bench import BenchConfig, make_problem
    from mechsim.benchmarks.peer_bench import CASE_A
    problem = make_problem(BenchConfig(scenario="geneva-motor", duration=1.0, overrides=CASE_A + (
        'load.wheel_torque="0 N*m"', 'load.wheel_torque_per_station=["7 N*m", "2 N*m", "5 N*m", "0.5 N*m"]')))
    for name in ("casadi-idas", "casadi-idas-events", "scipy-LSODA", "diffsol-tsit45"):
        assert not METHODS[name].supports_problem(problem), name
        assert "constant wheel torque" in METHODS[name].skip_reason(problem)
    assert METHODS["ida-index1"].supports_problem(problem)


def test_casadi_event_support_variant_matches_the_reference():
    """CasADi's own event support (`casadi-idas-events`) on case A: the same 9 mode changes as the reduced
    reference's boundaries, and the crank angle within 10 rtol of it over 5 s (angles ~ 25 rad)."""
    from mechsim.benchmarks.bench import BenchConfig, make_problem, reference
    from mechsim.benchmarks.peer_bench import CASE_A
    method = METHODS["casadi-idas-events"]
    if not method.available():
        pytest.skip("casadi not installed")
    problem = make_problem(BenchConfig(scenario="geneva-motor", duration=5.0, overrides=CASE_A))
    ref = reference(problem)
    handle, setup, _ = method.setup(problem, 1e-7, 1e-9)
    run = method.run(handle, problem, 1e-7, 1e-9)
    assert run.failure is None and len(run.t) == 5001
    assert run.stats["events"] == 9
    assert np.max(np.abs(run.angle - ref["angle"])) < 1e-6
