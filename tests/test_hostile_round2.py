"""Hostile input, round two: a sweep never deletes what mechsim did not write, quantities follow a safe grammar
(no arithmetic, bounded exponents), units by their definitions, deep nesting and damaged sweep stores answered
by one line, special files named as such."""
import json
import math
import os

import pytest
from cli_helpers import invoke, one_line_error

from mechsim.scenarios.units import ScenarioError, to_si


def test_sweep_force_keeps_a_folder_mechsim_did_not_write(tmp_path):
    out = tmp_path / "d"
    out.mkdir()
    (out / "sweep.json").write_text("{}")             # a sweep.json alone is no proof that mechsim wrote the folder
    (out / "precious.txt").write_text("mine")
    r = invoke("sweep", "geneva-lc1", "--vary", "contact.friction=0.1,0.2", "--out", out, "--force")
    assert r.exit_code == 2
    assert "marker" in one_line_error(r)
    assert (out / "precious.txt").read_text() == "mine"


@pytest.mark.parametrize("text,why", [
    ("1 s**9**9**9", "exponent"), ("1 s^9^9^9", "exponent"), ("1 s^5", "exponent"),
    ("75 mm - 74.9999999 mm", "unexpected"), ("2 mm * 3", "unexpected"), ("1 (((m)))", "nested"),
    ("1 m)", "parentheses"), ("1 m *", "incomplete"), ("1 * m", "operator"),
])
def test_quantities_follow_the_safe_grammar(text, why):
    with pytest.raises(ScenarioError) as e:
        to_si("duration", text, "s")
    assert e.value.field == "duration" and why in e.value.problem and "no arithmetic" in e.value.problem


def test_an_exponent_tower_is_refused_at_once_by_the_cli(tmp_path):
    r = invoke("run", "geneva-lc1", "--set", "duration=1 s**9**9**9", "--out", tmp_path / "o")
    assert r.exit_code == 2 and one_line_error(r).startswith("error: duration:")
    assert not (tmp_path / "o").exists()


@pytest.mark.parametrize("text,unit,si", [
    ("0.02 kg*m^2", "kg*m^2", 0.02), ("1 W/(m^2*K)", "W/(m^2*K)", 1.0), ("3 m/s^2", "m/s^2", 3.0),
    ("7 N·m", "N*m", 7.0), ("5 N m", "N*m", 5.0), ("1 kg*m**2", "kg*m^2", 1.0), ("-180 deg", "rad", -math.pi),
])
def test_the_grammar_keeps_every_unit_the_docs_use(text, unit, si):
    assert to_si("f", text, unit) == pytest.approx(si, rel=1e-15)


def test_hertz_is_a_rotation_rate_and_angle_powers_are_exact():
    # 5 Hz is five turns a second where a rotation speed is asked (pint alone gives 5 rad/s, 2 pi off)
    assert to_si("drive.speed", "5 Hz", "rad/s") == pytest.approx(10 * math.pi, rel=1e-15)
    assert to_si("drive.speed", "300 rpm", "rad/s") == pytest.approx(10 * math.pi, rel=1e-15)
    assert to_si("mechanism.crank_damping", "2 N*m*s", "N*m*s/rad") == 2.0       # radians implied
    with pytest.raises(ScenarioError) as e:
        to_si("mechanism.crank_damping", "1 N*m*s/rad**2", "N*m*s/rad")
    assert "angle to the power -1, not -2" in e.value.problem


def test_deep_nesting_in_set_is_one_line(tmp_path):
    r = invoke("run", "geneva-lc1", "--set", "duration=" + "[" * 5000 + "]" * 5000, "--out", tmp_path / "o")
    assert r.exit_code == 2 and "deep" in one_line_error(r)


def test_a_damaged_sweep_store_is_one_line_naming_the_file(tmp_path):
    out = tmp_path / "s"
    args = ("sweep", "geneva-lc1", "--vary", "load.wheel_torque=5 N*m,7 N*m", "--set", "duration=0.2 s",
            "--out", out)
    assert invoke(*args).exit_code == 0
    manifest = out / "sweep.json"
    manifest.write_text(manifest.read_text()[:7])       # truncated
    r = invoke(*args)
    assert r.exit_code == 2
    line = one_line_error(r)
    assert "sweep.json is damaged" in line and "--force" in line
    assert invoke(*args, "--force").exit_code == 0      # the way out the line names works
    assert json.loads(manifest.read_text())["case_ids"]


def test_a_sweep_with_a_repeated_value_resumes(tmp_path):
    args = ("sweep", "geneva-lc1", "--vary", "load.wheel_torque=5 N*m, 5000 N*mm, 7 N*m", "--set", "duration=0.2 s",
            "--out", tmp_path / "s")
    assert invoke(*args).exit_code == 0
    assert invoke(*args).exit_code == 0                 # the same sweep again: resumed, not "a different sweep"


def test_special_files_and_encodings_are_named(tmp_path):
    os.mkfifo(tmp_path / "pipe.toml")
    (tmp_path / "dir.toml").mkdir()
    for name, words in (("pipe.toml", "not a regular file"), ("dir.toml", "is a folder")):
        r = invoke("run", tmp_path / name, "--out", tmp_path / "o")
        assert r.exit_code == 2 and words in one_line_error(r)
    text = invoke("show", "geneva-lc1").stdout
    (tmp_path / "u32.toml").write_bytes(text.encode("utf-32"))
    r = invoke("run", tmp_path / "u32.toml", "--out", tmp_path / "o")
    assert r.exit_code == 2 and "UTF-32" in one_line_error(r)
    (tmp_path / "bom.toml").write_bytes(b"\xef\xbb\xbf" + text.encode())
    r = invoke("run", tmp_path / "bom.toml", "--out", tmp_path / "o", "--quiet", "--set", "output.plots=false",
               "--set", "duration=0.1 s")
    assert r.exit_code == 0, r.output


def test_a_degenerate_1d_mesh_is_refused_before_anything_is_allocated(tmp_path):
    r = invoke("run", "geneva-lc1", "--set", "thermal.model=1d", "--set", "thermal.mesh_first_cell=1 nm",
               "--set", "thermal.mesh_growth=1.0", "--out", tmp_path / "o")
    assert r.exit_code == 2
    line = one_line_error(r)
    assert line.startswith("error: thermal.mesh_first_cell:") and "cells per track; at most" in line
    assert not (tmp_path / "o").exists()


def test_memory_is_estimated_and_bounded_before_any_work(tmp_path, monkeypatch):
    from mechsim.scenarios import schema
    monkeypatch.setattr(schema, "memory_budget", lambda: 2.0 * 2**30)      # a machine with 4 GiB
    r = invoke("run", "geneva-lc1", "--set", "duration=3600 s", "--out", tmp_path / "o")   # 3.6 M rows of 1 ms
    assert r.exit_code == 2
    line = one_line_error(r)
    assert line.startswith("error: output_step:") and "GiB of memory" in line
    assert not (tmp_path / "o").exists()


def test_a_refused_run_writes_no_unit_cache(tmp_path):
    import subprocess
    import sys
    env = {**os.environ, "MECHSIM_CACHE_DIR": str(tmp_path / "cache")}
    p = subprocess.run([sys.executable, "-m", "mechsim.scenarios.cli", "run", "geneva-lc1", "--set",
                        'mechanism.pin_radius="80 mm"',
                        "--out", str(tmp_path / "o")], env=env, capture_output=True, text=True, timeout=300)
    assert p.returncode == 2 and "pin_radius" in p.stderr
    assert not (tmp_path / "cache").exists() or not any((tmp_path / "cache").iterdir())


def test_a_denormal_where_zero_is_allowed_is_refused():
    from mechsim.scenarios.loader import load
    with pytest.raises(ScenarioError) as e:
        load("chain-mech2-torque", ['mechanism.chain_mass="1e-320 kg"'])
    assert e.value.field == "mechanism.chain_mass" and "0 or at least" in e.value.problem
    assert load("chain-mech2-torque", ['mechanism.chain_mass="0 kg"']).si["mechanism"]["chain_mass"] == 0.0


def _descendants(pid: int) -> set[int]:
    """Every process below `pid` (read from /proc)."""
    children: dict[int, list[int]] = {}
    for entry in os.listdir("/proc"):
        if entry.isdigit():
            try:
                stat = open(f"/proc/{entry}/stat").read()
            except OSError:
                continue
            ppid = int(stat.rsplit(")", 1)[1].split()[1])
            children.setdefault(ppid, []).append(int(entry))
    out, todo = set(), [pid]
    while todo:
        for c in children.get(todo.pop(), []):
            out.add(c)
            todo.append(c)
    return out


def _alive(pid: int) -> bool:
    try:
        return open(f"/proc/{pid}/stat").read().rsplit(")", 1)[1].split()[0] != "Z"
    except OSError:
        return False


@pytest.mark.skipif(not os.path.isdir("/proc"), reason="reads the process tree from /proc")
def test_pool_workers_die_with_a_killed_sweep(tmp_path):
    import signal
    import subprocess
    import sys
    import time
    p = subprocess.Popen([sys.executable, "-m", "mechsim.scenarios.cli", "sweep", "geneva-motor", "--vary",
                          "load.wheel_torque=0:6:200 N*m", "--set", "duration=60 s", "--workers", "2", "--quiet",
                          "--out", str(tmp_path / "s")], stdout=subprocess.DEVNULL, stderr=subprocess.DEVNULL)
    try:
        deadline, below = time.monotonic() + 180, set()
        while time.monotonic() < deadline and len(below) < 3 and p.poll() is None:
            time.sleep(0.2)
            below = _descendants(p.pid)
        assert len(below) >= 3                          # the fork server and its two workers, busy
        os.kill(p.pid, signal.SIGKILL)
        p.wait()
        deadline = time.monotonic() + 30
        while time.monotonic() < deadline and any(_alive(c) for c in below):
            time.sleep(0.2)
        assert not [c for c in below if _alive(c)]
    finally:
        if p.poll() is None:
            p.kill()


def test_ctrl_c_during_a_run_is_one_line_and_exit_130(tmp_path, monkeypatch):
    from mechsim.scenarios import api

    def interrupted(sc, progress=None):
        progress(0.25)                                  # a quarter of a second simulated, then Ctrl-C
        raise KeyboardInterrupt
    monkeypatch.setattr(api, "run", interrupted)
    r = invoke("run", "geneva-lc1", "--out", tmp_path / "o", "--set", "output.plots=false")
    assert r.exit_code == 130
    line = one_line_error(r)
    assert "interrupted (Ctrl-C) at t = 0.25 s of 3 s; nothing was written" in line
    assert not (tmp_path / "o").exists()


def _ctrl_c_surfacing_as(error: Exception):
    """A call that takes a Ctrl-C through the CLI's own handler and then raises `error` instead of the
    KeyboardInterrupt, as CPython does when the signal lands inside C code that raises next (an import building its
    ImportError: a TypeError 'expected a message argument', seen while pyarrow.parquet loaded)."""
    import signal

    from mechsim.scenarios import cli

    def call(*args, **kwargs):
        try:
            cli._on_ctrl_c(signal.SIGINT, None)
        except KeyboardInterrupt:
            raise error from None
    return call


@pytest.mark.parametrize("moment", ["computing", "writing"])
def test_a_ctrl_c_that_surfaces_as_another_error_is_still_an_interrupt(tmp_path, monkeypatch, moment):
    from mechsim.scenarios import api, cli
    from mechsim.scenarios.output import writer
    monkeypatch.setattr(cli, "_ctrl_c_seen", False)          # (restored after the test: the handler sets it)
    surfacing = _ctrl_c_surfacing_as(TypeError("expected a message argument"))
    monkeypatch.setattr(api if moment == "computing" else writer, "run" if moment == "computing" else "write_parquet",
                        surfacing)
    r = invoke("run", "geneva-lc1", "--out", tmp_path / "o", "--set", "output.plots=false")
    assert r.exit_code == 130
    line = one_line_error(r)
    assert "interrupted (Ctrl-C)" in line and ("nothing was written" if moment == "computing"
                                               else "nothing half-written is left") in line
    assert list(tmp_path.iterdir()) == []                     # no folder, no temporary beside it


def test_any_command_reports_a_ctrl_c_that_surfaces_as_another_error_as_the_interrupt(tmp_path, monkeypatch):
    from mechsim.scenarios import api, cli
    monkeypatch.setattr(cli, "_ctrl_c_seen", False)
    monkeypatch.setattr(api, "sensitivity", _ctrl_c_surfacing_as(TypeError("expected a message argument")))
    r = invoke("sensitivity", "geneva-lc1", "--wrt", "load.wheel_torque", "--out", tmp_path / "s")
    assert r.exit_code == 130
    assert one_line_error(r) == "error: interrupted (Ctrl-C)"
    assert list(tmp_path.iterdir()) == []


def test_without_a_ctrl_c_the_same_error_is_an_internal_error(tmp_path, monkeypatch):
    from mechsim.scenarios import api, cli
    monkeypatch.setattr(cli, "_ctrl_c_seen", False)

    def broken(sc, progress=None):
        raise TypeError("expected a message argument")
    monkeypatch.setattr(api, "run", broken)
    r = invoke("run", "geneva-lc1", "--out", tmp_path / "o", "--set", "output.plots=false")
    assert r.exit_code == 3
    assert "internal error (TypeError: expected a message argument)" in one_line_error(r)
    assert list(tmp_path.iterdir()) == []


def test_a_rolling_pair_on_a_line_refuses_the_circle_keys():
    from mechsim.scenarios.loader import load
    with pytest.raises(ScenarioError) as e:
        load("rolling-d-line", ['mechanism.fixed_radius="50 mm"'])
    assert e.value.field == "mechanism.fixed_radius" and "profile = 'line'" in e.value.problem
