"""The Python API (docs/api.md): `import mechsim` stays cheap, `mechsim.load/run` give the runner's numbers,
`Result.save` writes exactly what `mechsim run` writes, `Result.plot` returns those figures as matplotlib
Figures, and the notebook-style tour in docs/examples runs from an unrelated folder."""
import json
import os
import subprocess
import sys
from pathlib import Path

import numpy as np
import pandas as pd
import pytest
from matplotlib.figure import Figure

import mechsim
from mechsim.scenarios.loader import load as loader_load
from mechsim.scenarios.runner import run as runner_run
from tests.cli_helpers import invoke

ROOT = Path(__file__).resolve().parents[1]
SHORT = {"duration": "0.8 s", "output_step": "2 ms"}


def python(code_or_file, *args, cwd):
    """Run Python in a fresh interpreter, in `cwd`, seeing the same mechsim as this test."""
    env = {**os.environ, "PYTHONPATH": os.pathsep.join(p for p in sys.path if p)}
    cmd = [sys.executable, *(["-c", code_or_file] if not str(code_or_file).endswith(".py") else [code_or_file]),
           *map(str, args)]
    return subprocess.run(cmd, cwd=cwd, env=env, capture_output=True, text=True, timeout=240)


def test_import_mechsim_loads_no_heavy_packages(tmp_path):
    """`import mechsim` is the version and a lazy table of names: no numpy, pandas, sympy, jax or matplotlib."""
    out = python("import sys, mechsim; print(sorted({'numpy', 'pandas', 'sympy', 'jax', 'matplotlib'} & "
                 "set(sys.modules)), callable(mechsim.run))", cwd=tmp_path)
    assert out.returncode == 0, out.stderr
    assert out.stdout.split() == ["[]", "True"]


@pytest.fixture(scope="module")
def lc1():
    return mechsim.run(mechsim.load("geneva-lc1", set=SHORT))


def test_load_accepts_the_cli_strings_or_a_dict():
    a = mechsim.load("geneva-lc1", set=["duration=0.8 s", "output_step=2 ms", "thermal.model='flash'"])
    b = mechsim.load("geneva-lc1", set={**SHORT, "thermal.model": "flash"})
    assert a.si == b.si and a.si["duration"] == pytest.approx(0.8)


def test_a_user_error_names_the_field():
    with pytest.raises(mechsim.ScenarioError) as err:
        mechsim.load("geneva-lc1", set={"mechanism.crank_radius": "75 kg"})
    assert err.value.field == "mechanism.crank_radius"


def test_run_is_the_runner_with_the_mechanism_kept(lc1):
    direct = runner_run(loader_load("geneva-lc1", [f"{k}={v}" for k, v in SHORT.items()]))
    pd.testing.assert_frame_equal(lc1.timeseries, direct.timeseries)
    pd.testing.assert_frame_equal(lc1.events, direct.events)
    assert lc1.summary["peaks"] == direct.summary["peaks"]
    assert isinstance(lc1, mechsim.Result) and lc1.success and lc1.mechanism.name == "geneva"
    # one output row per step over the whole duration, events at the closed form's entry and exit
    assert len(lc1.timeseries) == 401
    assert list(lc1.events["kind"]) == ["entry", "exit"]


@pytest.fixture(scope="module")
def saved(lc1, tmp_path_factory):
    return lc1.save(tmp_path_factory.mktemp("saved") / "api")


def test_save_writes_what_the_cli_writes(lc1, saved, tmp_path):
    cli = invoke("run", "geneva-lc1", "--out", tmp_path / "cli", "--quiet",
                 *[a for k, v in SHORT.items() for a in ("--set", f"{k}={v}")])
    assert cli.exit_code == 0, cli.output
    api_files = sorted(p.name for p in saved.iterdir())
    assert api_files == sorted(p.name for p in (tmp_path / "cli").iterdir())
    a = pd.read_parquet(saved / "timeseries.parquet")
    b = pd.read_parquet(tmp_path / "cli" / "timeseries.parquet")
    pd.testing.assert_frame_equal(a, b)
    sa, sb = (json.loads((d / "summary.json").read_text()) for d in (saved, tmp_path / "cli"))
    assert sa["peaks"] == sb["peaks"]
    with pytest.raises(FileExistsError):                # never over an existing folder without force
        lc1.save(saved)


def test_plot_returns_the_saved_figures_as_figures(lc1, saved):
    figs = lc1.plot()
    pngs = sorted(p.stem for p in saved.glob("*.png"))
    assert sorted(figs) == pngs and all(isinstance(f, Figure) for f in figs.values())


def test_sweep_returns_the_table():
    table = mechsim.sweep("geneva-lc1", vary={"load.wheel_torque": "0,7 N*m"}, set=SHORT)
    assert list(table["load.wheel_torque_N_m"]) == [0.0, 7.0] and table["success"].all()
    # a heavier load needs more contact force at the same prescribed speed
    assert table["peak_max_contact_force_N"].iloc[1] > table["peak_max_contact_force_N"].iloc[0]


def test_acceptance_command_from_an_unrelated_folder(tmp_path):
    out = python("import mechsim; r = mechsim.run(mechsim.load('geneva-lc1', set=['duration=0.5 s'])); "
                 "print(r.timeseries.shape, sorted(r.summary['peaks'])[:2])", cwd=tmp_path)
    assert out.returncode == 0, out.stderr
    assert out.stdout.startswith("(501, ")


def test_the_notebook_tour_runs(tmp_path):
    out = python(ROOT / "docs" / "examples" / "notebook_tour.py", tmp_path / "tour", cwd=tmp_path)
    assert out.returncode == 0, out.stderr[-3000:]
    assert "1.000 wheel indexes" in out.stdout
    written = {p.name for p in (tmp_path / "tour" / "geneva-lc1").iterdir()}
    assert {"timeseries.parquet", "events.csv", "summary.json", "scenario.toml", "mechanism.png"} <= written
    assert np.isfinite(float(out.stdout.split("heat balance closes to")[1].split()[0]))
    assert "to_toml round-trips: True" in out.stdout and "same timeseries: True" in out.stdout
    assert (tmp_path / "tour" / "contact_force.png").stat().st_size > 0
    # the comparison: a prescribed crank speed moves the wheel alike under either load
    assert "wheel speed peak differs by 0.0" in out.stdout
    assert (tmp_path / "tour" / "compare" / "compare.csv").is_file()
    # per-station loads: each index's peak contact force follows its station's torque (7, 2, 5, 0.5 N*m)
    forces = [float(f.split()[0]) for f in out.stdout.split("peak contact force per index:")[1].splitlines()[0]
              .split(",")]
    assert len(forces) == 4 and np.argsort(forces).tolist() == [3, 1, 2, 0]
    assert "1200001 rows" in out.stdout and "large: True" in out.stdout


def test_a_thermal_model_is_one_module_and_its_registry_line(monkeypatch):
    """docs/CONTRIBUTING.md's recipe: a two-body model (no crank arm) registered under a new name runs from a
    scenario, and its heat balance closes (generated = stored + convected, exact modal integration)."""
    from mechsim.thermal.models import MODELS
    from mechsim.thermal.models.base import ThermalModel
    from mechsim.thermal.network import assemble, bulk_bodies

    def build(setup):
        assemble(setup, [b for b in bulk_bodies(setup) if b.name != "crank"])

    monkeypatch.setitem(MODELS, "two-body", ThermalModel("two-body", "pin and wheel", "bulk pin and wheel", build))
    r = mechsim.run("geneva-lc1", set={**SHORT, "thermal.model": "two-body"})
    assert r.success and "temp_bulk_crank_C" not in r.timeseries
    assert r.timeseries["temp_bulk_pin_C"].iloc[-1] > r.timeseries["temp_bulk_pin_C"].iloc[0]
    balance = r.summary["thermal"]["heat_balance"]
    assert abs(balance["closure_error_relative"]) < 1e-8 and balance["generated_J"] > 0
