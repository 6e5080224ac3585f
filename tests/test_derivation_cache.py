"""The derived model kept on disk (dynamics/derivation_cache.py): a model loaded from the cache is the derived one,
bit for bit, for every mechanism type; its sympy pieces come on demand; a damaged file is derived again; a second
process runs a DAE scenario without importing sympy. Behaviour only: the time it saves is in docs/benchmarks.md."""
import os
import re
import subprocess
import sys

import numpy as np
import pytest

import mechsim
from mechsim.dynamics import derivation_cache, model as model_module
from mechsim.dynamics.hybrid import prepare
from mechsim.scenarios import runner

CASES = [("geneva-motor", ['thermal.model="lumped"']), ("chain-mech1-torque", []), ("rolling-a-torque", [])]


def _prepared(name, overrides):
    plan = runner.plan(mechsim.load(name, set=overrides))
    si, mech, drive = plan.scenario.si, plan.mechanism, plan.drive
    ext = plan.thermal.extension if plan.thermal is not None else None
    ext_initial = plan.thermal.ext_initial if plan.thermal is not None else None
    angle_key, speed_key = mech.initial_keys
    speed0 = drive.speed if drive.is_prescribed else si["initial"][speed_key]
    return prepare(mech, drive, plan.settings, 0.05, si["output_step"], si["initial"][angle_key], speed0, ext,
                   ext_initial)


def _outputs(mf, p, rng):
    """Every stored function of a mode on one random state: residual, Jacobian, guards, the KKT pieces and the
    read-outs (the lambdified functions are vectorised over rows: evaluated on three)."""
    ny, nq = mf.ny, mf.index["q"].stop
    y, yp = rng.normal(size=ny), rng.normal(size=ny)
    res, jac, ev = np.zeros(ny), np.zeros((ny, ny)), np.zeros(len(mf.guard_names))
    mf.residual(0.3, y, yp, res, p)
    mf.jacobian(0.3, y, yp, res, 7.5, jac, p)
    mf.events(0.3, y, yp, ev, p)
    t, q, v = 0.3, y[:nq], y[nq:2 * nq]
    x = y[mf.index["ext"]]
    lam = y[mf.index["lam"]]
    out = [res, jac, ev, np.asarray(mf.mass(q, p), float), np.asarray(mf.force0(t, q, v, x, p), float),
           np.asarray(mf.G(t, q, p), float), np.asarray(mf.phi(t, q, p), float),
           np.asarray(mf.phi_dot(t, q, v, p), float), np.asarray(mf.gamma(t, q, v, p), float),
           np.asarray(mf.force_lam(t, q, v, x, p), float)]
    a = rng.normal(size=nq)
    out += [np.asarray(np.broadcast_arrays(*mf.readouts["_all"](t, q, v, a, lam, x, p)), float)]
    return out


@pytest.mark.parametrize("name,overrides", CASES, ids=[c[0] for c in CASES])
def test_a_loaded_model_is_the_derived_one_bit_for_bit(name, overrides, tmp_path, monkeypatch):
    monkeypatch.setenv("MECHSIM_CACHE_DIR", str(tmp_path))
    model_module._derive_cached.cache_clear()
    start = _prepared(name, overrides)            # derived, and stored
    files = list((tmp_path / "derived").glob("*.json"))
    assert len(files) == 1
    model_module._derive_cached.cache_clear()
    loaded = _prepared(name, overrides).model     # loaded from the file
    assert loaded is not start.model
    assert list(loaded.modes) == list(start.model.modes)
    for mode, mf in start.model.modes.items():
        other = loaded.modes[mode]
        assert other.symbolic_pieces == {}                      # nothing derived yet
        assert (other.index, other.algebraic, other.guard_names, other.guard_directions, other.readout_names) == (
            mf.index, mf.algebraic, mf.guard_names, mf.guard_directions, mf.readout_names)
        p = np.asarray(start.p, float) * (1.0 + 0.1 * np.random.default_rng(1).random(len(start.p)))
        for mine, theirs in zip(_outputs(other, p, np.random.default_rng(2)), _outputs(mf, p, np.random.default_rng(2))):
            np.testing.assert_array_equal(mine, theirs)
    # the sympy pieces are loaded on demand (test_the_sympy_pieces_are_the_stored_trees), the derivation's own
    mode = next(iter(loaded.modes))
    assert [str(r) for r in loaded.modes[mode].symbolic["residual_rows"]] == [
        str(r) for r in start.model.modes[mode].symbolic["residual_rows"]]
    model_module._derive_cached.cache_clear()


def test_a_damaged_or_foreign_file_is_derived_again(tmp_path, monkeypatch):
    monkeypatch.setenv("MECHSIM_CACHE_DIR", str(tmp_path))
    model_module._derive_cached.cache_clear()
    start = _prepared("geneva-torque", [])
    (path,) = (tmp_path / "derived").glob("*.json")
    good = path.read_text()
    for bad in ("{not json", good.replace('"format": 1', '"format": 0'), good.replace('def ', 'df ', 1), ""):
        path.write_text(bad)
        model_module._derive_cached.cache_clear()
        again = _prepared("geneva-torque", []).model
        mf, ref = next(iter(again.modes.values())), next(iter(start.model.modes.values()))
        assert mf.symbolic_pieces != {}                           # derived, not loaded
        np.testing.assert_array_equal(_outputs(mf, start.p, np.random.default_rng(3))[0],
                                      _outputs(ref, start.p, np.random.default_rng(3))[0])
        # and stored again (the same file but for sympy's numbering of its dummy argument names)
        assert re.sub(r"_Dummy_\d+", "_Dummy", path.read_text()) == re.sub(r"_Dummy_\d+", "_Dummy", good)
    model_module._derive_cached.cache_clear()


def _tree(x):
    """A sympy piece as comparable text: every expression's full tree (`srepr`), containers and objects entry by
    entry."""
    import sympy as sp
    if isinstance(x, (sp.Basic, sp.MatrixBase)):
        return sp.srepr(x)
    if isinstance(x, dict):
        return {k: _tree(v) for k, v in x.items()}
    if isinstance(x, (list, tuple)):
        return [_tree(v) for v in x]
    if hasattr(x, "__dict__"):
        return {k: _tree(v) for k, v in vars(x).items()}
    return repr(x)


def test_the_sympy_pieces_are_the_stored_trees(tmp_path, monkeypatch):
    """The modes' sympy pieces (what diffrax, the compiled callbacks and the sensitivities trace) are kept beside
    the model and loaded on first use, not derived: the stored expression trees, to the last node, with the heat
    share's opaque functions (classes made at run time) made again from their origin, so that a loaded piece
    differentiates as the stored one does. A damaged file is derived again and written anew."""
    import sympy as sp
    monkeypatch.setenv("MECHSIM_CACHE_DIR", str(tmp_path))
    sets = ['thermal.model="lumped"', 'thermal.averaging="resolved"']
    model_module._derive_cached.cache_clear()
    start = _prepared("geneva-torque", sets).model            # derived, and stored
    (pickled,) = (tmp_path / "derived").glob("*.symbolic.pickle")
    fresh = model_module._derive_fresh

    def loaded_model():
        model_module._derive_cached.cache_clear()
        return _prepared("geneva-torque", sets).model

    def refused(*args):
        raise AssertionError("derived, not loaded")
    monkeypatch.setattr(model_module, "_derive_fresh", refused)
    loaded = loaded_model()
    opaque = 0
    for mode, mf in start.modes.items():
        mine, theirs = loaded.modes[mode].symbolic, mf.symbolic
        assert _tree(mine) == _tree(theirs)
        rows, states = sp.Matrix(mine["residual_rows"]), list(mine["y"])
        assert _tree(rows.jacobian(states)) == _tree(sp.Matrix(theirs["residual_rows"]).jacobian(list(theirs["y"])))
        opaque += sum(getattr(type(f), "opaque_origin", None) is not None
                      for f in rows.atoms(sp.Function))
    assert opaque                           # the heat share's opaque function is among the loaded pieces
    pickled.write_bytes(b"not a pickle")
    calls = []

    def counted(*args):
        calls.append(args)
        return fresh(*args)
    monkeypatch.setattr(model_module, "_derive_fresh", counted)
    assert next(iter(loaded_model().modes.values())).symbolic and len(calls) == 1     # derived again
    monkeypatch.setattr(model_module, "_derive_fresh", refused)
    assert next(iter(loaded_model().modes.values())).symbolic      # and written anew: loaded, not derived
    model_module._derive_cached.cache_clear()


def test_the_file_name_follows_the_key_and_the_code():
    a = derivation_cache.file_for(("Geneva",))
    assert a == derivation_cache.file_for(("Geneva",))
    assert a != derivation_cache.file_for(("Geneva", "index1"))
    # and the targets the functions were emitted for: another target's functions are another file
    assert a == derivation_cache.file_for(("Geneva",), derivation_cache.TARGETS)
    assert a != derivation_cache.file_for(("Geneva",), {**derivation_cache.TARGETS, "lambdified": "jax"})


def test_a_second_process_runs_a_dae_scenario_without_sympy(tmp_path, monkeypatch):
    """This process derives geneva-torque (IDA) and stores it; a second process loads it and never imports sympy,
    and both write the same time series. (Deriving here rather than in a first subprocess: what is asserted is
    the second process's load, and the first process only had to derive and store, which it did through the
    same code, the cache directory being the same.)"""
    monkeypatch.setenv("MECHSIM_CACHE_DIR", str(tmp_path))
    model_module._derive_cached.cache_clear()
    first = mechsim.run("geneva-torque", set=["duration=0.3 s"])
    model_module._derive_cached.cache_clear()
    assert len(list((tmp_path / "derived").glob("*.json"))) == 1          # derived and stored
    env = {**os.environ, "PYTHONPATH": os.pathsep.join(p for p in sys.path if p), "MECHSIM_CACHE_DIR": str(tmp_path)}
    code = ("import sys, mechsim\nr = mechsim.run('geneva-torque', set=['duration=0.3 s'])\n"
            "print('sympy' in sys.modules)\nprint(r.timeseries.to_csv(float_format='%.17g'))")
    out = subprocess.run([sys.executable, "-c", code], cwd=tmp_path, env=env, capture_output=True, text=True,
                         timeout=240)
    assert out.returncode == 0, out.stderr
    second = out.stdout.split("\n", 1)
    assert second[0] == "False"
    assert second[1] == first.timeseries.to_csv(float_format="%.17g") + "\n"      # print's newline


@pytest.mark.parametrize("name", ["chain-mech2-kinematic", "rolling-c-cusp"])
def test_a_closed_forms_stored_functions_are_the_derived_ones_bit_for_bit(name, tmp_path, monkeypatch):
    """The chain's and rolling pair's closed-form inverse dynamics (`_numeric`, `derivation_cache.store_functions`):
    the functions loaded from the file give every table column and event as the derived ones do, to the bit."""
    from mechsim.mechanisms.chain import model as chain_model
    from mechsim.mechanisms.rolling import model as rolling_model
    monkeypatch.setenv("MECHSIM_CACHE_DIR", str(tmp_path))
    sc = mechsim.load(name, set=["output.plots=false"])

    def fresh_run():
        chain_model._SYM_CACHE.clear()
        rolling_model._MODEL_CACHE.clear()
        return mechsim.run(sc)
    derived = fresh_run()                                    # derived, and stored
    assert len(list((tmp_path / "derived").glob("*.json"))) == 1

    def derive_again(self):
        raise AssertionError("derived again instead of loaded")
    monkeypatch.setattr(chain_model.ChainDwell, "_numeric_functions", derive_again)
    monkeypatch.setattr(rolling_model.RollingPairFourBar, "_numeric_functions", derive_again)
    loaded = fresh_run()                                     # loaded from the file
    assert loaded.timeseries.equals(derived.timeseries) and loaded.events.equals(derived.events)
    assert loaded.summary["peaks"] == derived.summary["peaks"]
