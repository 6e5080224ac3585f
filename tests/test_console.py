"""A calm console: warnings grouped by kind, native solver output captured, --quiet prints only errors."""
import ctypes
import json
import os
import warnings

from cli_helpers import invoke

from mechsim.scenarios.console import group_line, group_warnings, native_output


def test_warnings_group_by_kind_with_count_and_time_span():
    msgs = [f"t = {t} s: normal force changed sign at crank angle {a} deg (local): the pin crossed to the "
            f"{side} flank" for t, a, side in ((0.5, 6.75, "trailing"), (0.54, 20.6, "driving"), (4.2, 5.9, "trailing"))]
    msgs.append("thermal: the pin's Biot number h(V/A)/k = 0.2 >= 0.1, so it is not lumped")
    groups = group_warnings(msgs)
    assert [g["count"] for g in groups] == [3, 1]
    assert groups[0]["first_t_s"] == 0.5 and groups[0]["last_t_s"] == 4.2 and groups[0]["first"] == msgs[0]
    assert groups[1]["first_t_s"] is None
    line = group_line(groups[0])
    assert "\n" not in line and line.startswith("warning: 3 x normal force changed sign at crank angle 5.9 .. 20.6 "
                                                 "deg (local) between t = 0.5 s and 4.2 s")
    assert group_line(groups[1]) == f"warning: {msgs[3]}"
    assert groups[1]["kind"] == "thermal: the pin's Biot number h(V/A)/k = 0.2 >= 0.1, so it is not lumped"


def test_grouped_warning_keeps_the_numbers_its_messages_share():
    """A formula's "= 0" is the same in every message: the grouped line keeps it; the measured angles become the
    range they span, least to largest whatever their order."""
    msgs = [f"t = {t} s: dead point of the crank input (coupler line through the contact point (w . B' = 0)) at "
            f"crank angle {a} rad: the crank reverses" for t, a in ((2.177, 0.0584047), (3.279, 0.0611))]
    groups = group_warnings(msgs)
    assert len(groups) == 1
    assert groups[0]["kind"] == ("dead point of the crank input (coupler line through the contact point "
                                 "(w . B' = 0)) at crank angle 0.0584047 .. 0.0611 rad")
    reversed_order = group_warnings(msgs[::-1])
    assert reversed_order[0]["kind"] == groups[0]["kind"]
    assert group_line(groups[0]).startswith(f"warning: 2 x {groups[0]['kind']} between t = 2.177 s and 3.279 s")


def test_native_output_is_captured_not_printed(capfd):
    libc = ctypes.CDLL(None)
    with native_output() as lines:
        os.write(1, b"[IDAHandleFailure, Error: -3] raw fd 1\n")
        os.write(2, b"raw fd 2\n")
        libc.printf(b"buffered C stdio\n")
        print("\n[IDASolve, Error: -4] printed by python\n")
        warnings.warn("a library warning", RuntimeWarning)
    captured = capfd.readouterr()
    assert captured.out == "" and captured.err == ""
    assert set(lines) == {"[IDAHandleFailure, Error: -3] raw fd 1", "raw fd 2", "buffered C stdio",
                          "[IDASolve, Error: -4] printed by python", "python: RuntimeWarning: a library warning"}
    os.write(1, b"after\n")                      # the descriptors are back
    assert capfd.readouterr().out == "after\n"


def test_quiet_run_prints_nothing_and_loud_run_one_line_per_kind(tmp_path):
    args = ("run", "geneva-torque", "--set", "duration=2 s", "--set", "output.plots=false")
    r = invoke(*args, "--out", tmp_path / "quiet", "--quiet")
    assert r.exit_code == 0, r.output
    assert r.stdout == "" and r.stderr == ""
    s = json.loads((tmp_path / "quiet" / "summary.json").read_text())
    assert len(s["warnings"]) >= 5 and sum(g["count"] for g in s["warning_groups"]) == len(s["warnings"])
    r = invoke(*args, "--out", tmp_path / "loud")
    assert r.exit_code == 0, r.output
    lines = r.stderr.strip().splitlines()
    assert len(lines) == len(s["warning_groups"]) and all(line.startswith("warning: ") for line in lines)
    # the run's line, its located peaks and, as it settles, its periodic regime (docs/theory.md §K5), the time line
    out = r.stdout.strip().splitlines()
    assert "rows" in out[0] and out[1].startswith("peaks, min .. max: contact_force_N")
    assert out[-1].startswith("time: ")
    assert len(out) == 3 or (len(out) == 4 and out[2].startswith("periodic from t = "))


def test_the_time_line_splits_the_whole_command():
    from mechsim.scenarios.cli import time_line
    solver = {"wall_time_s": 2.0, "solve_time_s": 0.5, "compile_time_s": 0.25}
    line = time_line(solver, 10.0)
    # 10 s in all = 0.5 solve + 0.25 compile + 1.25 tables and summary + 8 of the rest
    assert line.startswith("time: 10.00 s in all (solve 0.50 s, compile or load compiled code 0.25 s, tables and "
                           "summary 1.25 s, start-up, files and figures 8.00 s)")
    assert "output.plots=false" in line and "output.plots=false" not in time_line(solver, 10.0, plots=False)
    no_compilation = {"wall_time_s": 1.0, "solve_time_s": 0.5}
    assert "compile" not in time_line(no_compilation, 1.5)
    # the run's tables timed on their own (summary.json `tables_time_s`): the rest of the run is loading the model
    # and the solver, 2.0 - 0.5 - 0.25 - 0.75 = 0.5 s
    timed = dict(solver, tables_time_s=0.75)
    assert time_line(timed, 10.0).startswith(
        "time: 10.00 s in all (solve 0.50 s, compile or load compiled code 0.25 s, loading the model and solver 0.50 s, "
        "tables and summary 0.75 s, start-up, files and figures 8.00 s)")
    assert "loading" not in time_line(dict(no_compilation, tables_time_s=0.5), 1.5)
    assert "tables, thermal and summary 0.75 s" in time_line(timed, 10.0, thermal=True)
    # a warm part of a few milliseconds reads in ms, not as "0.00 s"
    fast = {"wall_time_s": 0.0135, "solve_time_s": 0.0042, "tables_time_s": 0.0061}
    assert time_line(fast, 1.0135).startswith(
        "time: 1.01 s in all (solve 4.2 ms, loading the model and solver 3.2 ms, tables and summary 6.1 ms, "
        "start-up, files and figures 1.00 s)")


def test_the_run_bar_moves_from_simulated_time_to_the_share_of_tables_written():
    import io

    from rich.console import Console

    from mechsim.scenarios.console import RunProgress
    with RunProgress(Console(file=io.StringIO(), force_terminal=True), "lc1", 1.0) as bar:
        bar.simulated(1.0)
        task = bar.bar.tasks[0]
        assert (task.completed, task.total, task.fields["where"]) == (1.0, 1.0, "t = 1.000 s")
        bar.writing(0.0, "timeseries.parquet")         # a 1 s run: the bar starts again for the writing
        assert task.completed == 0.0 and task.description == "lc1: writing timeseries.parquet"
        bar.writing(0.4, "timeseries.csv")
        assert (task.completed, task.fields["where"], task.description) == (0.4, "40 %", "lc1: writing timeseries.csv")
