"""Faults: the issue's malformed files and values (one line naming the field, exit 2, nothing written), and sweeps
that keep nothing broken (a stored case that does not verify is computed again, with a line saying so)."""
import json
import os
import subprocess
import sys

import pandas as pd
import pytest
import tomli_w
from cli_helpers import invoke, one_line_error

from mechsim.scenarios.loader import MAX_FILE_BYTES


def run_file(tmp_path, data: bytes):
    path = tmp_path / "case.toml"
    path.write_bytes(data)
    return invoke("run", path, "--out", tmp_path / "out", "--quiet")


FILES = [
    ("binary", bytes(range(256)) * 8, "binary"),
    ("latin-1", 'name = "café"\n'.encode("latin-1"), "UTF-8"),
    ("utf-16", 'name = "x"\n'.encode("utf-16"), "UTF-16"),
    ("nested 100,000 deep", b"x = " + b"[" * 100_000 + b"]" * 100_000 + b"\n", "deep"),
    ("nested 20 deep (parses)", b"x = " + b"[" * 20 + b"]" * 20 + b"\n", "deep"),
    ("over the size limit", b"# " + b"x" * MAX_FILE_BYTES + b"\n", "bytes"),
    ("5000-digit integer", b"slots = " + b"9" * 5000 + b"\n", "scenario"),
]


@pytest.mark.parametrize("label,data,words", FILES, ids=[f[0] for f in FILES])
def test_unreadable_files_are_one_line(tmp_path, label, data, words):
    r = run_file(tmp_path, data)
    assert r.exit_code == 2
    line = one_line_error(r)
    assert line.startswith("error: scenario:") and words in line
    assert not (tmp_path / "out").exists()


def _torque(value):
    return lambda r: r.update(drive={"type": "torque", "torque": value})


def _set(section, key, value):
    return lambda r: (r.setdefault(section, {}) if section else r).update({key: value})


NAN, INF = float("nan"), float("inf")
VALUES = [  # every class the issue lists: (mutation, field the line names)
    (lambda r: r["mechanism"].update(type=["geneva"]), "mechanism.type"),
    (_set("initial", "crank_angle", "nan deg"), "initial.crank_angle"),
    (_set("initial", "crank_angle", "inf deg"), "initial.crank_angle"),
    (_set("initial", "crank_angle", -180), "initial.crank_angle"),
    (_torque("1e308 N*m"), "drive.torque"),
    (_torque("nan N*m"), "drive.torque"),
    (_torque("inf N*m"), "drive.torque"),
    (_set("contact", "friction", NAN), "contact.friction"),
    (_set("contact", "friction", INF), "contact.friction"),
    (_set("contact", "friction", 11), "contact.friction"),
    (_set("contact", "friction", 1e6), "contact.friction"),
    (_set("load", "wheel_torque", "nan N*m"), "load.wheel_torque"),
    (_set("mechanism", "crank_damping", "nan N*m*s/rad"), "mechanism.crank_damping"),
    (_set("mechanism", "wheel_inertia", "1e-320 kg*m^2"), "mechanism.wheel_inertia"),
    (_set(None, "duration", "inf s"), "duration"),
    (_set(None, "duration", "1e308 s"), "duration"),
    (_set(None, "duration", "1e400 s"), "duration"),
    (lambda r: r.update(duration="1000 s", output_step="1 ns"), "output_step"),
    (_set("solver", "baumgarte_beta", NAN), "solver.baumgarte_beta"),
    (_set("thermal", "mesh_growth", NAN), "thermal.mesh_growth"),
    (_set("mechanism", "slots", 1_000_000), "mechanism.slots"),
    (_set("mechanism", "slots", 9223372036854775808), "mechanism.slots"),
    (_set("output", "drawing_instants", 1_000_000), "output.drawing_instants"),
    (lambda r: r["mechanism"].update(pin_radius="60 mm", crank_radius="50 mm", slots=12), "pin_radius"),
    (_set(None, "duration", "9**9**9 s"), "duration"),
]


@pytest.mark.parametrize("mutate,field", VALUES, ids=[v[1] + f"-{i}" for i, v in enumerate(VALUES)])
def test_the_issues_values_are_refused_before_any_work(tmp_path, lc1_raw, mutate, field):
    mutate(lc1_raw)
    r = run_file(tmp_path, tomli_w.dumps(lc1_raw).encode())
    assert r.exit_code == 2, r.output
    line = one_line_error(r)
    assert field in line
    assert not (tmp_path / "out").exists() and sorted(p.name for p in tmp_path.iterdir()) == ["case.toml"]


CHAIN_GEOMETRY = [
    ("mechanism.coupler_length=2 cm", "initial.drive_angle"),        # the dyad cannot reach the chain at the start
    ("mechanism.coupler_length=12 cm", "mechanism.coupler_length"),  # a prescribed run would jam at a fold
    ("mechanism.coupler_length=20 cm", "mechanism"),                 # it can never close
]


@pytest.mark.parametrize("override,field", CHAIN_GEOMETRY)
def test_chain_that_cannot_run_is_refused_at_load(tmp_path, override, field):
    r = invoke("run", "chain-mech2-kinematic", "--set", override, "--out", tmp_path / "out", "--quiet")
    assert r.exit_code == 2 and field in one_line_error(r)
    assert not (tmp_path / "out").exists()


def test_geneva_pin_must_fit_between_slots():
    """R < r cos^2(pi/n): the slot walls of width 2R must not merge at the rim (a 60 mm pin on a 50 mm crank
    with 12 slots passes the older c - r test, 143 mm, but not this one, 46.7 mm)."""
    from mechsim.mechanisms.geneva.kinematics import GenevaGeometry
    g = GenevaGeometry(0.05, 12, 0.04, 0.004)
    assert g.max_pin_radius == pytest.approx(0.05 * 0.9330127, rel=1e-6) and g.min_pin_distance > 0.06
    with pytest.raises(ValueError, match="merge"):
        GenevaGeometry(0.05, 12, 0.06, 0.004)


# -- sweeps keep nothing broken --------------------------------------------------------------------------------

SWEEP = ["geneva-lc1", "--vary", "contact.friction=0.1,0.2,0.3", "--set", "duration=0.2 s",
         "--set", "output_step=10 ms", "--set", "thermal.model='none'", "--workers", 0, "--no-plots", "--quiet"]


def _dead_pid():
    proc = subprocess.Popen([sys.executable, "-c", "pass"])
    proc.wait()
    return proc.pid


def test_resume_recomputes_corrupt_cases_and_says_so(tmp_path):
    out = tmp_path / "sw"
    r = invoke("sweep", *SWEEP, "--timeseries", "--out", out)
    assert r.exit_code == 0, r.output
    cases = sorted((out / "cases").glob("*.json"))
    assert len(cases) == 3
    first = {p.name: json.loads(p.read_text()) for p in cases}
    truncated, edited, series_broken = cases
    truncated.write_bytes(truncated.read_bytes()[:40])                      # a kill -9 / disk fault mid-file
    rec = json.loads(edited.read_text())
    rec["row"]["work_drive_J"] = 123.0                                      # changed content, stale checksum
    edited.write_text(json.dumps(rec))
    ts = out / "timeseries" / (series_broken.stem + ".parquet")
    ts.write_bytes(ts.read_bytes()[:-100])
    from mechsim.scenarios.studies.sweep.store import _host_tag
    junk = out / "cases" / f".x.json.tmp-{_dead_pid()}-{_host_tag()}-abc"       # a temporary file of a killed sweep
    junk.write_text("{")
    r = invoke("sweep", *SWEEP, "--timeseries", "--out", out)
    assert r.exit_code == 0, r.output
    lines = [line for line in r.stderr.splitlines() if "did not verify" in line]
    assert len(lines) == 3 and "Traceback" not in r.output
    assert any(truncated.stem in line and "unreadable" in line for line in lines)
    assert any(edited.stem in line and "checksum mismatch" in line for line in lines)
    assert any(series_broken.stem in line and "time series" in line for line in lines)
    assert "(3 computed, 0 reused, 0 failed)" in r.stdout and not junk.exists()
    again = {p.name: json.loads(p.read_text()) for p in (out / "cases").glob("*.json")}
    for name, rec in again.items():     # recomputed cases equal the originals, except when and by which run
        assert rec["row"]["work_drive_J"] == first[name]["row"]["work_drive_J"]
        assert rec["run_id"] != first[name]["run_id"]
    df = pd.read_parquet(out / "sweep.parquet")
    assert len(df) == 3 and df["success"].all()
    r = invoke("sweep", *SWEEP, "--timeseries", "--out", out)       # now everything verifies: all reused
    assert r.exit_code == 0 and "(0 computed, 3 reused, 0 failed)" in r.stdout and "did not verify" not in r.stderr


def test_resume_recomputes_cases_another_build_computed_and_says_so_once(tmp_path):
    """A case stored by another build of mechsim (other code, another version of a library that computes it), or
    by one that did not record its build, is computed again: a table never mixes two builds' rows."""
    from mechsim.dynamics.user_cache import results_fingerprint
    from mechsim.scenarios.studies.sweep.store import _checksum
    out = tmp_path / "sw"
    r = invoke("sweep", *SWEEP, "--out", out)
    assert r.exit_code == 0, r.output
    cases = sorted((out / "cases").glob("*.json"))
    first = {p.name: json.loads(p.read_text()) for p in cases}
    assert {rec["computed_by"] for rec in first.values()} == {results_fingerprint()}
    for p, build in zip(cases, ("another build", "another build", None)):     # checksums sound: only the build differs
        rec = json.loads(p.read_text())
        rec.pop("checksum")
        rec.pop("computed_by")
        if build is not None:
            rec["computed_by"] = build
        rec["checksum"] = _checksum(rec)
        p.write_text(json.dumps(rec))
    r = invoke("sweep", *SWEEP, "--out", out)
    assert r.exit_code == 0, r.output
    lines = [line for line in r.stderr.splitlines() if "did not verify" in line]
    assert len(lines) == 1 and "3 stored cases" in lines[0] and "another mechsim build" in lines[0], lines
    assert "(3 computed, 0 reused, 0 failed)" in r.stdout
    again = {p.name: json.loads(p.read_text()) for p in (out / "cases").glob("*.json")}
    assert {rec["computed_by"] for rec in again.values()} == {results_fingerprint()}
    for name, rec in again.items():
        assert rec["row"]["work_drive_J"] == first[name]["row"]["work_drive_J"]
        assert rec["run_id"] != first[name]["run_id"]
    r = invoke("sweep", *SWEEP, "--out", out)
    assert "(0 computed, 3 reused, 0 failed)" in r.stdout and "did not verify" not in r.stderr


def test_sweep_force_refuses_a_folder_mechsim_did_not_write(tmp_path):
    victim = tmp_path / "victim"
    victim.mkdir()
    (victim / "keep.txt").write_text("mine")
    r = invoke("sweep", *SWEEP, "--out", victim, "--force")
    assert r.exit_code == 2 and "not written by mechsim" in one_line_error(r)
    assert sorted(p.name for p in victim.iterdir()) == ["keep.txt"]


def test_sweep_into_a_read_only_folder_is_one_line(tmp_path, monkeypatch):
    """The OS refuses the folder (patched at the OS boundary, os.mkdir): exit 4, one line."""
    real_mkdir = os.mkdir

    def refuse(path, *args, **kwargs):
        if str(path).startswith(str(tmp_path / "ro")):
            raise PermissionError(13, "Permission denied", str(path))
        return real_mkdir(path, *args, **kwargs)

    monkeypatch.setattr(os, "mkdir", refuse)
    r = invoke("sweep", *SWEEP, "--out", tmp_path / "ro" / "sw")
    assert r.exit_code == 4 and "Permission denied" in one_line_error(r)
    assert not (tmp_path / "ro").exists()
