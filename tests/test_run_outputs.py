"""An output folder is all or nothing, and the same run writes the same bytes (docs/limits.md, "Where results go"):
Ctrl-C while solving or while writing leaves no folder and no temporary folder (exit 130); two runs racing into
one --out leave one complete folder, never a mix; two identical runs differ only in their timing fields."""
import json
import os
import re
import signal
import subprocess
import sys
import time
from pathlib import Path

import pytest
from cli_helpers import invoke, one_line_error

#: fields that measure this machine rather than the simulation (docs/limits.md, "Identical runs")
TIMING = re.compile(r'"(derive|solve|tables|wall)_time_s": [0-9.e+-]+')
TIMING_HTML = re.compile(r"<td>(derive|solve|tables|wall) time</td><td class=\"num\">[0-9.e+-]+</td>")


#: the CLI with Python's own Ctrl-C handler, whatever SIGINT disposition the test process passes on (a worker may
#: ignore SIGINT; a preexec_fn would fork a multithreaded JAX process)
CLI = ("import runpy, signal, sys; signal.signal(signal.SIGINT, signal.default_int_handler); "
       "sys.argv = ['mechsim', *sys.argv[1:]]; runpy.run_module('mechsim.scenarios.cli', run_name='__main__')")


def mechsim(*args):
    """`mechsim ARGS` in a fresh interpreter seeing the same mechsim as this test."""
    env = {**os.environ, "PYTHONPATH": os.pathsep.join(p for p in sys.path if p)}
    return subprocess.Popen([sys.executable, "-c", CLI, *map(str, args)], env=env, stdout=subprocess.PIPE,
                            stderr=subprocess.PIPE, text=True)


def temporaries(parent: Path) -> list[str]:
    return [p.name for p in parent.iterdir() if p.name.startswith(".")]


def files(folder: Path) -> dict[str, bytes]:
    return {p.name: p.read_bytes() for p in sorted(folder.iterdir())}


def complete(folder: Path) -> dict:
    """The folder is one whole run: marker, summary, every table readable and as long as the summary says."""
    import pandas as pd
    names = set(os.listdir(folder))
    assert {".mechsim-output", "summary.json", "scenario.toml", "timeseries.parquet", "timeseries.csv",
            "events.csv"} <= names, names
    assert not any(n.startswith(".") and n != ".mechsim-output" for n in names)
    summary = json.loads((folder / "summary.json").read_text())
    rows = len(pd.read_parquet(folder / "timeseries.parquet"))
    assert rows == len(pd.read_csv(folder / "timeseries.csv")) == summary["solver"]["output_rows"]
    return summary


@pytest.mark.parametrize("moment", ["computing", "writing"])
def test_ctrl_c_leaves_no_folder_and_no_temporary(tmp_path, moment):
    out = tmp_path / "o"
    # computing: a DAE run of 200 s (tens of seconds of work: still computing when interrupted at 3 s, however fast
    # the machine); writing: a closed-form run whose figures take seconds to draw
    args = (["geneva-torque", "--set", "duration=200 s", "--set", "output.plots=false"] if moment == "computing"
            else ["geneva-lc1"])
    proc = mechsim("run", *args, "--out", out, "--quiet")
    t0 = time.monotonic()
    while proc.poll() is None and time.monotonic() - t0 < 120:
        writing = bool(temporaries(tmp_path))
        if (moment == "writing" and writing) or (moment == "computing" and time.monotonic() - t0 > 3.0):
            break
        time.sleep(0.01)
    assert proc.poll() is None, proc.communicate()
    caught_writing = bool(temporaries(tmp_path))
    assert caught_writing == (moment == "writing")
    proc.send_signal(signal.SIGINT)
    _, stderr = proc.communicate(timeout=60)
    assert proc.returncode == 130, stderr
    assert "Traceback" not in stderr
    assert not out.exists() and temporaries(tmp_path) == []


def test_ctrl_c_in_another_command_is_said_in_one_line(tmp_path):
    """typer turns a Ctrl-C outside `mechsim run` into exit 130 without a word: the CLI says it (`main`)."""
    out = tmp_path / "s"
    proc = mechsim("sensitivity", "geneva-torque", "--wrt", "load.wheel_torque", "--set", "duration=200 s",
                   "--out", out)
    time.sleep(3.0)
    assert proc.poll() is None, proc.communicate()
    proc.send_signal(signal.SIGINT)
    _, stderr = proc.communicate(timeout=60)
    assert proc.returncode == 130, stderr
    assert "Traceback" not in stderr
    assert [line for line in stderr.splitlines() if line.startswith("error:")] == ["error: interrupted (Ctrl-C)"]
    assert not out.exists() and temporaries(tmp_path) == []


@pytest.mark.parametrize("force", [False, True])
def test_two_runs_racing_into_one_folder_leave_one_whole_run(tmp_path, force):
    out = tmp_path / "o"
    args = ["run", "geneva-lc1", "--out", out, "--quiet", "--set", "output.plots=false"] + (["--force"] if force else [])
    procs = [mechsim(*args) for _ in range(2)]
    results = [(p.wait(timeout=120), p.communicate()[1]) for p in procs]
    codes = sorted(code for code, _ in results)
    if force:
        assert codes == [0, 0], results                      # each replaced the folder whole
    else:
        assert codes == [0, 2], results                      # one wins, the other refuses in one line
        refusal = next(err for code, err in results if code == 2).strip().splitlines()
        assert len(refusal) == 1 and refusal[0].startswith("error: --out:") and "exists" in refusal[0]
    complete(out)
    assert temporaries(tmp_path) == []


@pytest.mark.parametrize("plots", [False, True])
def test_a_folder_written_while_the_run_ran_is_refused_as_at_the_start(tmp_path, monkeypatch, plots):
    """The race above, made certain: another run writes --out after this one's check at the start. The refusal is
    the start's (exit 2, one line naming --out), with or without figures, and the other run's folder stays."""
    from mechsim.scenarios import api
    out, run = tmp_path / "o", api.run

    def run_then_folder_appears(*args, **kwargs):
        result = run(*args, **kwargs)
        out.mkdir()
        (out / "theirs.txt").write_text("another run's")
        return result

    monkeypatch.setattr(api, "run", run_then_folder_appears)
    r = invoke("run", "geneva-lc1", "--set", "duration=0.2 s", "--set", f"output.plots={str(plots).lower()}",
               "--out", out, "--quiet")
    assert r.exit_code == 2, r.output
    line = one_line_error(r)
    assert line.startswith("error: --out:") and "exists" in line, line
    assert os.listdir(out) == ["theirs.txt"] and temporaries(tmp_path) == []


def test_identical_runs_write_identical_bytes_but_the_timing_fields(tmp_path):
    outs = [tmp_path / "a", tmp_path / "b"]
    for out in outs:
        # on `ida` by name: where the default runs a model's compiled callbacks (marked ready by another test of the
        # session), the first run in a process loads them and counts it (compilations, compile times), the second not
        r = invoke("run", "geneva-torque", "--set", "duration=0.3 s", "--set", 'solver.backend="ida"', "--out", out,
                   "--quiet")
        assert r.exit_code == 0, r.output
    a, b = (files(o) for o in outs)
    assert a.keys() == b.keys() and {"timeseries.parquet", "mechanism.png", "report.html"} <= a.keys()
    for name in a:
        if name == "summary.json":
            assert TIMING.sub("", a[name].decode()) == TIMING.sub("", b[name].decode())
            assert len(TIMING.findall(a[name].decode())) == 4
        elif name == "report.html":
            assert TIMING_HTML.sub("", a[name].decode()) == TIMING_HTML.sub("", b[name].decode())
            assert len(TIMING_HTML.findall(a[name].decode())) == 4
        else:
            assert a[name] == b[name], name
    complete(outs[0])
