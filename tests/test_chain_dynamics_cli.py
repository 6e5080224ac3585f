"""The chain-dwell built-in scenarios through the CLI (in process): files, columns, dwells.csv against
docs/theory.md §K1.3, energy closure in the summary, and the one-line errors and physics failures."""
import json

import numpy as np
import pandas as pd
import pytest
from typer.testing import CliRunner

from mechsim.scenarios.cli import app
from mechsim.scenarios.loader import builtin_names

CHAIN = [n for n in builtin_names() if n.startswith("chain-")]
COLUMNS = ["t_s", "mode", "chain_travel_m", "chain_speed_m_s", "drive_angle_rad", "drive_speed_rad_s",
           "crank_angle_rad", "crank_speed_rad_s", "crank_accel_rad_s2", "coupler_angle_rad", "coupler_force_N",
           "segment", "branch", "drive_torque_N_m", "kinetic_energy_J", "constraint_residual_m"]


@pytest.fixture(scope="module")
def outputs(tmp_path_factory):
    """Every chain built-in run once; plots only for one of them (they cost more than the runs)."""
    base = tmp_path_factory.mktemp("chain")
    runner = CliRunner()
    out = {}
    for name in CHAIN:
        args = ["run", name, "--out", str(base / name), "--quiet"]
        if name != "chain-mech2-torque":
            args += ["--set", "output.plots=false"]
        res = runner.invoke(app, args)
        out[name] = (res, base / name)
    return out


def test_all_chain_builtins_run(outputs):
    assert set(CHAIN) >= {"chain-mech1-kinematic", "chain-mech2-kinematic", "chain-mech1-torque",
                          "chain-mech2-torque", "chain-mech2-detuned", "chain-mech2-smooth"}
    for name, (res, folder) in outputs.items():
        assert res.exit_code == 0, (name, res.output)
        for f in ("timeseries.parquet", "timeseries.csv", "events.csv", "summary.json", "scenario.toml",
                  "dwells.csv"):
            assert (folder / f).is_file(), (name, f)
        df = pd.read_parquet(folder / "timeseries.parquet")
        assert set(COLUMNS) <= set(df.columns), (name, set(COLUMNS) - set(df.columns))
        s = json.loads((folder / "summary.json").read_text())
        assert s["model"]["thermal"] == "none" and s["success"]
        assert s["max_constraint_residual_m"] < 1e-8
        # impact losses (events.csv, closed-form runs too) close the balance; closed form: trapezoid quadrature
        tol = 1e-6 if s["model"]["method"] == "dae" else 1e-4
        assert abs(s["energy"]["closure_error_relative"]) < tol, name
    folder = outputs["chain-mech2-torque"][1]
    for f in ("chain_displacement.png", "chain_velocity.png", "chain_acceleration.png", "chain_crank.png",
              "mechanism.png"):
        assert (folder / f).is_file(), f


def dwells(outputs, name):
    return pd.read_csv(outputs[name][1] / "dwells.csv")


def test_mech1_kinematic_dwells_are_table_1(outputs):
    """Leading branch of Mech 1: 45, 90, 45 deg on sprockets 2, 3, 1 at phi = 90, 180, 0 deg (docs/theory.md §K1.3)."""
    d = dwells(outputs, "chain-mech1-kinematic")
    assert list(d.sprocket) == [2, 3, 1] and set(d.kind) == {"exact"}
    np.testing.assert_allclose(np.degrees(d.start_drive_angle_rad), [180.047447, 405.094895, 776.080827], atol=1e-6)
    np.testing.assert_allclose(np.degrees(d.end_drive_angle_rad), [225.047447, 495.094895, 821.080827], atol=1e-6)
    np.testing.assert_allclose(np.exp(1j * d.crank_angle_rad), np.exp(1j * np.radians([90, 180, 0])), atol=1e-12)
    assert d.crank_excursion_rad.max() < 1e-12


def test_torque_driven_dwells_start_with_an_impact(outputs):
    """Torque-driven Mech 2: every dwell starts with a stop impact at an apex and lasts 45 deg of drive angle;
    impacts lose energy (events.csv); Mech 1 the same with 45, 90, 45 deg."""
    d = dwells(outputs, "chain-mech2-torque")
    assert len(d) >= 4 and set(d.start_event) == {"stop impact"} and set(d.end_event) == {"dwell end"}
    np.testing.assert_allclose(np.degrees(d.duration_drive_angle_rad), 45.0, atol=1e-6)
    ev = pd.read_csv(outputs["chain-mech2-torque"][1] / "events.csv")
    assert (ev[ev.kind == "stop impact"].energy_lost_J > 0).all()
    d1 = dwells(outputs, "chain-mech1-torque")
    np.testing.assert_allclose(np.degrees(d1.duration_drive_angle_rad[:3]), [45, 90, 45], atol=1e-6)


def test_smooth_and_detuned_scenarios(outputs):
    """Smooth branch: 90 deg full-arc dwells on sprockets 3 and 1 only (docs/theory.md §K1.3); detuned delta > 0:
    near-dwells with a small crank excursion, no impacts, no exact dwell."""
    d = dwells(outputs, "chain-mech2-smooth")
    assert set(d.sprocket) == {1, 3}
    np.testing.assert_allclose(np.degrees(d.duration_drive_angle_rad), 90.0, atol=1e-6)
    d = dwells(outputs, "chain-mech2-detuned")
    assert set(d.kind) == {"near"} and len(d) == 4
    assert d.crank_excursion_rad.max() < 2e-3
    ev = pd.read_csv(outputs["chain-mech2-detuned"][1] / "events.csv")
    assert set(ev.kind) <= {"arc entry", "arc exit"}


def test_fold_is_a_physics_failure_and_thermal_a_user_error(tmp_path):
    runner = CliRunner()
    res = runner.invoke(app, ["run", "chain-mech2-detuned", "--out", str(tmp_path / "fold"), "--quiet",
                              "--set", "mechanism.detuning=-0.01mm", "--set", "output.plots=false"])
    assert res.exit_code == 3, res.output
    assert "reverse" in res.output and "178.176" in res.output
    assert (tmp_path / "fold" / "timeseries.csv").is_file()          # what ran is saved
    res = runner.invoke(app, ["run", "chain-mech2-kinematic", "--out", str(tmp_path / "th"), "--quiet",
                              "--set", "thermal.model=flash"])
    assert res.exit_code == 2 and "thermal.model" in res.output
    assert "Traceback" not in res.output
    res = runner.invoke(app, ["run", "chain-mech2-kinematic", "--out", str(tmp_path / "e"), "--quiet",
                              "--set", "mechanism.restitution=1.5"])
    assert res.exit_code == 2 and "restitution" in res.output
    res = runner.invoke(app, ["run", "chain-mech2-kinematic", "--out", str(tmp_path / "d"), "--quiet",
                              "--set", "mechanism.detuning=0.01mm"])
    assert res.exit_code == 2 and "detuning" in res.output
