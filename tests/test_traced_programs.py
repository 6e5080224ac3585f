"""Traced programs kept on disk (dynamics/traced.py): a later process loads the program instead of tracing the
Python again, computes exactly what the traced program computes, with what tracing recorded on the host; another
code or library version, a corrupt file and a program with host callbacks are traced (and compiled) as before."""
from __future__ import annotations

import json

import jax
import jax.numpy as jnp
import numpy as np
import pytest

import mechsim.dynamics.jax_model  # noqa: F401  (float64, as in mechsim's programs)
from mechsim.dynamics import traced, user_cache
from mechsim.dynamics.programs import kept_key

EXAMPLE = (np.linspace(0.1, 2.0, 7), np.float64(0.3))


class Layout:
    """A stand-in for the compiled run's output layout (`diffrax_run.Outputs`): set while the program is traced."""

    def __init__(self):
        self.value = None

    def recorded(self):
        return self.value

    def restore(self, value):
        self.value = value


def _program(layout: Layout):
    def f(x, a):
        layout.value = [list(x.shape), "sin"]
        return jnp.sin(x) * jnp.exp(-a * x) + jnp.cumsum(x)
    return jax.jit(f)


def _untraceable(x, a):
    raise AssertionError("traced although the program is kept")


@pytest.fixture
def cache(tmp_path, monkeypatch):
    monkeypatch.setenv("MECHSIM_CACHE_DIR", str(tmp_path))
    return tmp_path / "traced"


def test_a_kept_program_is_loaded_not_traced(cache):
    first = Layout()
    fn = traced.compile_ahead("test_program", ("structure", 1), lambda: _program(first), EXAMPLE, first)
    expected = np.sin(EXAMPLE[0]) * np.exp(-EXAMPLE[1] * EXAMPLE[0]) + np.cumsum(EXAMPLE[0])
    got = np.asarray(fn(*EXAMPLE))
    np.testing.assert_allclose(got, expected, rtol=1e-14)
    assert first.value == [[7], "sin"] and len(list(cache.iterdir())) == 1
    again = Layout()
    loaded = traced.compile_ahead("test_program", ("structure", 1), lambda: jax.jit(_untraceable), EXAMPLE, again)
    assert np.array_equal(np.asarray(loaded(*EXAMPLE)), got)      # the same program: the same bits
    assert again.value == [[7], "sin"]                            # what tracing recorded, restored
    other = np.linspace(-1.0, 1.0, 7), np.float64(2.0)
    assert np.array_equal(np.asarray(loaded(*other)), np.asarray(fn(*other)))


@pytest.mark.parametrize("change", ["code", "library", "shapes", "key"])
def test_another_code_library_shape_or_key_is_traced(cache, monkeypatch, change):
    traced.compile_ahead("test_program", ("structure", 1), lambda: _program(Layout()), EXAMPLE, Layout())
    example, key = EXAMPLE, ("structure", 1)
    if change == "code":
        monkeypatch.setattr(user_cache, "code_fingerprint", lambda: "another revision")
    elif change == "library":
        monkeypatch.setattr(traced, "_versions", lambda: (("jax", "0.0.0"),))
    elif change == "shapes":
        example = (np.zeros(8), np.float64(0.3))
    else:
        key = ("structure", 2)
    with pytest.raises(AssertionError, match="traced although"):
        traced.compile_ahead("test_program", key, lambda: jax.jit(_untraceable), example, Layout())


def test_a_corrupt_file_is_traced_again_and_rewritten(cache):
    traced.compile_ahead("test_program", ("structure", 1), lambda: _program(Layout()), EXAMPLE, Layout())
    (kept,) = cache.iterdir()
    kept.write_bytes(kept.read_bytes()[:200])               # a file cut short
    layout = Layout()
    fn = traced.compile_ahead("test_program", ("structure", 1), lambda: _program(layout), EXAMPLE, layout)
    assert layout.value == [[7], "sin"]                       # traced again
    loaded = traced.compile_ahead("test_program", ("structure", 1), lambda: jax.jit(_untraceable), EXAMPLE, Layout())
    assert np.array_equal(np.asarray(loaded(*EXAMPLE)), np.asarray(fn(*EXAMPLE)))   # and kept again, whole
    assert [p.name for p in cache.iterdir()] == [kept.name]  # no partial file left behind


class StrictLayout(Layout):
    """A record that refuses what it cannot read back (as the compiled run's does: its keys, its shapes)."""

    def restore(self, value):
        if not (isinstance(value, list) and value[1] == "sin"):
            raise TypeError(f"not a layout: {value!r}")
        self.value = value


def test_a_record_that_does_not_read_back_is_traced_again(cache):
    """A file whose program reads but whose record does not (a foreign or damaged head): traced again and rewritten,
    never an error of the run."""
    traced.compile_ahead("test_program", ("structure", 1), lambda: _program(Layout()), EXAMPLE, Layout())
    (kept,) = cache.iterdir()
    head, _, body = kept.read_bytes().partition(b"\n")
    kept.write_bytes(json.dumps({"format": 1, "recorded": {"not": "a layout"}}).encode() + b"\n" + body)
    layout = StrictLayout()
    fn = traced.compile_ahead("test_program", ("structure", 1), lambda: _program(layout), EXAMPLE, layout)
    assert layout.value == [[7], "sin"]                       # traced again
    loaded = StrictLayout()
    again = traced.compile_ahead("test_program", ("structure", 1), lambda: jax.jit(_untraceable), EXAMPLE, loaded)
    assert loaded.value == [[7], "sin"]                       # the rewritten file reads back
    assert np.array_equal(np.asarray(again(*EXAMPLE)), np.asarray(fn(*EXAMPLE)))


def test_host_callbacks_and_keys_by_identity_are_compiled_not_kept(cache):
    def with_callback(x, a):
        return jax.pure_callback(np.cos, jax.ShapeDtypeStruct(x.shape, x.dtype), x) * a
    fn = traced.compile_ahead("test_program", ("structure", 1), lambda: jax.jit(with_callback), EXAMPLE)
    np.testing.assert_allclose(np.asarray(fn(*EXAMPLE)), np.cos(EXAMPLE[0]) * EXAMPLE[1], rtol=1e-15)
    assert not cache.exists()
    assert kept_key(object(), (1,)) is None                   # a structure by identity: not the same in another process
    fn = traced.compile_ahead("test_program", None, lambda: _program(Layout()), EXAMPLE)
    assert not cache.exists()


def test_the_runs_programs_loaded_compute_what_they_computed_traced(cache, monkeypatch):
    """A diffrax run and a sensitivity pass keep their programs; with the process's programs forgotten (as in a new
    process) and tracing made to fail (jax.export.export raises, and so does lambdifying the model's jax
    functions), they load them and report the same numbers to the last bit, the compiled run's output layout
    restored from the file."""
    import mechsim
    from mechsim.dynamics import jax_model, programs
    from mechsim.scenarios.studies.sensitivity import sensitivity

    def numbers():
        r = mechsim.run(mechsim.load("geneva-motor", set=['solver.backend="diffrax"', "duration=0.4 s",
                                                           "output.plots=false"]))
        table = sensitivity(mechsim.load("geneva-motor", set=["duration=0.4 s"]), ["contact.friction"],
                            ["peak_wheel_speed_rad_s"])
        return (r.timeseries["wheel_speed_rad_s"].to_numpy(), r.summary["peaks"]["wheel_speed_rad_s"],
                table["derivative"].to_numpy())

    monkeypatch.setattr(programs, "_PROGRAMS", {})
    traced_ = numbers()
    assert {p.name.split("-")[0] for p in cache.iterdir()} == {
        "diffrax_whole_run", "diffrax_run_rows", "diffrax_run_dense", "sensitivity_segment_solve", "sensitivity_tools"}
    monkeypatch.setattr(programs, "_PROGRAMS", {})

    def refuse(*a, **k):
        raise AssertionError("traced or lambdified although the program is kept")
    monkeypatch.setattr(jax.export, "export", refuse)
    monkeypatch.setattr(jax_model, "_lambdified", refuse)      # nor are the model's jax functions built
    loaded = numbers()
    assert np.array_equal(loaded[0], traced_[0]) and loaded[1] == traced_[1]
    assert np.array_equal(loaded[2], traced_[2]) and np.isfinite(loaded[2]).all()
