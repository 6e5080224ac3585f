"""Cold start (docs/benchmarks.md, "Cold start"): what a fresh `mechsim` process must not import, and the on-disk
cache of unit conversions that lets a repeated run skip pint. Behaviour only: the timings live in the docs."""
import json
import os
import subprocess
import sys

import pytest

HEAVY = ("numpy", "pandas", "sympy", "scipy", "jax", "matplotlib", "pint", "rich", "sksundae")


def fresh(code, cache_dir, tmp_path):
    env = {**os.environ, "PYTHONPATH": os.pathsep.join(p for p in sys.path if p), "MECHSIM_CACHE_DIR": str(cache_dir)}
    out = subprocess.run([sys.executable, "-c", code], cwd=tmp_path, env=env, capture_output=True, text=True,
                         timeout=240)
    assert out.returncode == 0, out.stderr
    return out.stdout


def test_the_cli_module_and_its_help_import_only_typer(tmp_path):
    code = ("import sys, io, contextlib\nfrom mechsim.scenarios import cli\n"
            "buf = io.StringIO()\n"
            "with contextlib.redirect_stdout(buf):\n"
            "    try:\n        cli.app(['--help'])\n    except SystemExit:\n        pass\n"
            f"print(sorted(m for m in {HEAVY!r} if m in sys.modules)); print('run' in buf.getvalue())")
    lines = fresh(code, tmp_path / "cache", tmp_path).split("\n")
    assert lines[0] == "[]" and lines[1] == "True"


@pytest.mark.parametrize("command", [["list"], ["show", "geneva-lc1"], ["show", "geneva-seed-lc3-mu015"],
                                     ["run", "geneva-lc1", "--set", "duration=-1"]])
def test_listing_showing_and_refusing_a_scenario_import_neither_pandas_nor_scipy(command, tmp_path):
    """What a user does before any run (list the built-ins, print one, have a bad value refused) reads scenarios
    and the thermal models' fields only: no tables (pandas) and no thermal network (scipy.sparse) are imported
    (pint, on an empty unit cache, imports scipy's top level only). A refused run writes nothing."""
    code = ("import sys, io, contextlib\nfrom mechsim.scenarios import cli\n"
            "buf = io.StringIO()\ncode = 0\n"
            "with contextlib.redirect_stdout(buf), contextlib.redirect_stderr(io.StringIO()):\n"
            f"    try:\n        cli.app({command!r})\n    except SystemExit as e:\n        code = e.code\n"
            "print(sorted(m for m in ('pandas', 'scipy.sparse', 'sympy', 'jax', 'numba') if m in sys.modules))"
            "; print(code)"
            "; print(len(buf.getvalue()))")
    lines = fresh(code, tmp_path / "cache", tmp_path).split("\n")
    assert lines[0] == "[]"
    if command[0] == "run":
        assert lines[1] == "2" and not (tmp_path / "results").exists()
    else:
        assert lines[1] in ("0", "None") and int(lines[2]) > 100       # it printed the list, or the scenario


def test_a_second_process_converts_units_from_the_disk_cache(tmp_path):
    cache = tmp_path / "cache"
    code = ("import sys\nfrom mechsim.scenarios.units import to_si\n"
            "print(repr(to_si('a', '75 mm', 'm')), repr(to_si('b', '300 rpm', 'rad/s')), repr(to_si('c', '20 degC', 'K')),"
            " 'pint' in sys.modules)")
    first = fresh(code, cache, tmp_path).split()
    second = fresh(code, cache, tmp_path).split()
    assert first[:3] == second[:3]
    assert float(first[0]) == 0.075 and float(first[1]) == pytest.approx(10 * 3.141592653589793, rel=1e-15)
    assert float(first[2]) == pytest.approx(293.15, rel=1e-15)
    assert first[3] == "True" and second[3] == "False"          # the second process never imported pint
    # a damaged cache file is ignored (and replaced), never an error
    for f in cache.glob("*.json"):
        f.write_text("{not json")
    third = fresh(code, cache, tmp_path).split()
    assert third[:3] == first[:3] and third[3] == "True"
    assert all(isinstance(json.loads(f.read_text()), dict) for f in cache.glob("*.json"))


def test_errors_are_never_cached(tmp_path):
    code = ("from mechsim.scenarios.units import to_si, ScenarioError\n"
            "try:\n    to_si('mechanism.crank_radius', '75 kg', 'm')\nexcept ScenarioError as e:\n    print(e.field)")
    cache = tmp_path / "cache"
    assert fresh(code, cache, tmp_path).strip() == "mechanism.crank_radius"
    assert fresh(code, cache, tmp_path).strip() == "mechanism.crank_radius"


@pytest.mark.parametrize("name, rows", [("geneva-lc1", 3001), ("geneva-seed-lc2-mu015", None)])
def test_a_closed_form_run_derives_nothing_and_loads_no_solver_stack(name, rows, tmp_path):
    """A prescribed-speed Geneva run with lumped thermal (geneva-lc1; the seed paper's lc2, whose band source reads
    the high-Peclet constant) is the closed form plus the thermal network in numpy: it must not import sympy (no
    model is derived), scipy's interpolate/special/optimize/integrate (the band-source table ships its spline and
    constants), the solvers or matplotlib."""
    code = (f"import sys\nimport mechsim\nr = mechsim.run({name!r})\n"
            "print(sorted(m for m in ('sympy', 'scipy.interpolate', 'scipy.special', 'scipy.optimize', "
            "'scipy.integrate', 'jax', 'sksundae', 'matplotlib') if m in sys.modules))\n"
            "print(r.summary['model']['method'], len(r.timeseries))")
    lines = fresh(code, tmp_path / "cache", tmp_path).split("\n")
    assert lines[0] == "[]"
    method, count = lines[1].split()
    assert method == "closed-form" and (rows is None or int(count) == rows)


def test_the_console_entry_leaves_without_teardown_but_runs_exit_handlers(tmp_path):
    """`main()` ends with os._exit (no module-by-module teardown): the unit cache written by its atexit handler is
    there, what the command printed reached the file, and the exit status is the command's."""
    env = {**os.environ, "PYTHONPATH": os.pathsep.join(p for p in sys.path if p),
           "MECHSIM_CACHE_DIR": str(tmp_path / "cache")}
    log = tmp_path / "out.txt"
    with log.open("w") as fh:
        ok = subprocess.run([sys.executable, "-m", "mechsim.scenarios.cli", "run", "geneva-lc1", "--set",
                             "output.plots=false", "--out", str(tmp_path / "out")], env=env, stdout=fh,
                            stderr=subprocess.PIPE, text=True, timeout=240)
    assert ok.returncode == 0, ok.stderr
    assert log.read_text().startswith("geneva-lc1: closed-form") and log.read_text().endswith("\n")
    assert [json.loads(f.read_text()) for f in (tmp_path / "cache").glob("units-*.json")]
    bad = subprocess.run([sys.executable, "-m", "mechsim.scenarios.cli", "run", "no-such-scenario"], env=env,
                         capture_output=True, text=True, timeout=240)
    assert bad.returncode == 2 and bad.stderr.startswith("error: ") and bad.stdout == ""


def test_a_dae_run_from_the_caches_without_figures_loads_no_figure_or_fallback_stack(tmp_path):
    """`mechsim run geneva-motor --set output.plots=false` in a process that finds the derived model and the
    compiled callbacks on disk (the default backend runs them compiled): no matplotlib (no figures), no
    scikit-sundae binding with its scipy.optimize (the compiled path reaches SUNDIALS through ctypes), no sympy,
    no JAX."""
    from mechsim.dynamics.user_cache import cache_dir
    # the caches written by a process of their own: a run in this process may find the derived model in memory,
    # derived while another test had another cache folder, and write nothing to this one
    fresh("import mechsim\nmechsim.run('geneva-motor', set={'solver.backend': 'ida-compiled', 'duration': '0.3 s', "
          "'output.plots': False})", cache_dir(), tmp_path)
    code = ("import sys\nfrom mechsim.scenarios import cli\n"
            "try:\n    cli.app(['run', 'geneva-motor', '--quiet', '--set', 'duration=0.3 s', '--set', "
            f"'output.plots=false', '--out', {str(tmp_path / 'out')!r}])\nexcept SystemExit as e:\n"
            "    assert not e.code, e.code\n"
            "print(sorted(m for m in ('matplotlib', 'sksundae', 'scipy.optimize', 'sympy', 'jax') if m in sys.modules))")
    assert fresh(code, cache_dir(), tmp_path).strip() == "[]"
    assert (tmp_path / "out" / "timeseries.parquet").is_file()


def test_a_sensitivity_runs_its_run_before_loading_jax(tmp_path):
    """`mechsim sensitivity` runs the scenario before it imports JAX: the default backend compiles a model's callbacks
    in a forked background process while JAX's threads are not loaded, in a fresh interpreter (~70 ms more of the
    run's wall time) once they are (dynamics/backends/compiled_model.py `compile_in_background`)."""
    code = ("import sys, mechsim\nfrom mechsim.scenarios import runner\n"
            "from mechsim.scenarios.studies.sensitivity import sensitivity\n"
            "def stop(plan):\n    print('jax' in sys.modules)\n    raise SystemExit(0)\n"
            "runner.execute = stop\n"
            "sensitivity(mechsim.load('geneva-motor', set=['duration=0.4 s']), ['contact.friction'])\n")
    assert fresh(code, tmp_path / "cache", tmp_path).split() == ["False"]


def test_a_later_diffrax_run_loads_its_programs_and_imports_no_diffrax(tmp_path):
    """The compiled diffrax run, its row and dense-reading programs are kept traced in the cache folder
    (dynamics/traced.py): a later process loads them, and runs them without importing diffrax, equinox, optimistix,
    lineax or sympy (dynamics/backends/diffrax_solvers.py is imported only to trace), with the same results."""
    cache = tmp_path / "cache"
    code = ("import json, sys\nimport mechsim\n"
            "r = mechsim.run(mechsim.load('geneva-motor', set=['solver.backend=\"diffrax\"', 'duration=0.4 s', "
            "'output.plots=false']))\n"
            "print(sorted(m for m in ('diffrax', 'equinox', 'optimistix', 'lineax', 'sympy') if m in sys.modules))\n"
            "print(r.success, r.summary['model']['backend'], r.timeseries['wheel_angle_rad'].to_numpy().tobytes().hex()[:64])\n"
            "print(json.dumps(r.summary['peaks'], sort_keys=True))")
    first = fresh(code, cache, tmp_path).split("\n")
    second = fresh(code, cache, tmp_path).split("\n")
    assert first[0] == "['diffrax', 'equinox', 'lineax', 'optimistix', 'sympy']"      # traced
    assert second[0] == "[]"                                                            # loaded
    assert first[1].startswith("True diffrax") and second[1:] == first[1:]
    assert {p.name.split("-")[0] for p in (cache / "traced").iterdir()} >= {"diffrax_whole_run", "diffrax_run_rows",
                                                                            "diffrax_run_dense"}


def test_a_clearance_run_without_figures_imports_no_matplotlib(tmp_path):
    """The clearance model's impacts table and summary (mechanisms/geneva/impacts.py) are made without its figure
    module: a run without figures does not import matplotlib (a third of such a run's cold start), and has its
    impacts."""
    from mechsim.dynamics.user_cache import cache_dir
    code = ("import sys\nimport mechsim\nr = mechsim.run('geneva-clearance', set={'duration': '0.5 s', "
            "'output.plots': False, 'solver.backend': 'ida'})\n"
            "print('matplotlib' in sys.modules, r.summary['impacts']['count'], len(r.extra_tables['impacts']))")
    imported, count, rows = fresh(code, cache_dir(), tmp_path).split()
    assert imported == "False" and int(count) == int(rows) > 0


@pytest.mark.parametrize("name", ["chain-mech2-torque", "rolling-a-torque", "chain-mech2-kinematic", "rolling-a-speed"])
def test_a_chain_or_rolling_run_from_the_cache_derives_nothing(name, tmp_path):
    """A chain or rolling-pair run in a process that finds on disk what was derived for it imports no sympy: a DAE
    run its derived model, a closed-form run its inverse dynamics' functions (dynamics/derivation_cache.py
    `store_functions`); the mechanisms' symbolic models are made where they are derived, not at import."""
    from mechsim.dynamics.user_cache import cache_dir
    run = (f"import sys\nimport mechsim\nr = mechsim.run({name!r}, set={{'duration': '0.5 s', 'output.plots': False, "
           "'solver.backend': 'ida'})\n")
    fresh(run, cache_dir(), tmp_path)                 # the derivation written to the cache, if it was not there
    sympy, optimize, ok = fresh(run + "print('sympy' in sys.modules, 'scipy.optimize' in sys.modules, "
                                "r.summary['success'])", cache_dir(), tmp_path).split()
    assert sympy == "False" and ok == "True"
    if name == "chain-mech2-kinematic":      # (Brent's method: the chain's near-dwells only, not a run's)
        assert optimize == "False"
