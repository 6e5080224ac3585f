"""Traced programs kept on disk (dynamics/traced.py): a later process loads the program instead of tracing the
Python again, computes exactly what the traced program computes, with what tracing recorded on the host; another
code or library version, a corrupt file and a program with host callbacks are traced (and compiled) as before. Two
callers of one program at once: the second waits for the first and loads what it kept."""
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


def test_a_library_process_keeps_a_program_with_equinox_checks_and_its_user_keeps_them(cache, monkeypatch):
    """mechsim imported as a library (no EQX_ON_ERROR chosen, equinox at its default "raise", where each runtime
    check is a host callback): a diffrax solve with save times, whose input checks would keep it from being
    exported, is traced with the checks NaN-returning, as the CLI traces it, and kept under the CLI's name; it
    computes the solution; the user's own checks raise again afterwards."""
    import diffrax
    import equinox
    from equinox import _errors

    monkeypatch.delenv("EQX_ON_ERROR", raising=False)
    monkeypatch.setattr(_errors, "EQX_ON_ERROR", "raise")
    ts = np.linspace(0.1, 1.0, 4)

    def make():
        """A new function each time, as mechsim's programs are made (jit keeps a trace per function)."""
        def solve(y0, k):
            sol = diffrax.diffeqsolve(diffrax.ODETerm(lambda t, y, kk: -kk * y), diffrax.Tsit5(), 0.0, 1.0, 0.01,
                                      y0, args=k, saveat=diffrax.SaveAt(ts=jnp.asarray(ts)),
                                      stepsize_controller=diffrax.PIDController(rtol=1e-10, atol=1e-12), throw=False)
            return sol.ys
        return jax.jit(solve)
    example = (np.float64(2.0), np.float64(0.7))
    with pytest.raises(NotImplementedError, match="host_callbacks"):      # at equinox's default: not exportable
        jax.export.export(make())(*example)
    fn = traced.compile_ahead("test_library_solve", ("structure", 2), make, example)
    np.testing.assert_allclose(np.asarray(fn(*example)), 2.0 * np.exp(-0.7 * ts), rtol=1e-8)
    name = traced.disk_name("test_library_solve", ("structure", 2), example)
    assert (cache / name).exists() and not list((cache.parent / "locks").glob("*.unkept"))
    monkeypatch.setenv("EQX_ON_ERROR", "nan")                              # the CLI's process names it the same
    assert traced.disk_name("test_library_solve", ("structure", 2), example) == name
    assert _errors.EQX_ON_ERROR == "raise"
    with pytest.raises(Exception, match="x must be >= 0"):
        jax.jit(lambda x: equinox.error_if(x, x < 0, "x must be >= 0"))(jnp.float64(-1.0)).block_until_ready()


def test_where_equinox_internals_differ_nothing_is_switched_and_the_program_is_compiled(cache, monkeypatch):
    """An equinox whose checks are not where `library_checks_without_callbacks` looks for them: the mode is left
    alone and the program with host callbacks is compiled (not kept), computing the same, as before the switch."""
    import diffrax
    from equinox import _errors

    monkeypatch.delenv("EQX_ON_ERROR", raising=False)
    monkeypatch.setattr(_errors, "EQX_ON_ERROR", "raise")
    original = _errors.branched_error_if_impl_jit
    monkeypatch.setattr(_errors, "branched_error_if_impl_jit",                   # the same, with no `_cached`
                        lambda *args, **kwargs: original(*args, **kwargs))
    ts = np.linspace(0.1, 1.0, 4)

    def make():
        def solve(y0, k):
            return diffrax.diffeqsolve(diffrax.ODETerm(lambda t, y, kk: -kk * y), diffrax.Tsit5(), 0.0, 1.0, 0.01,
                                       y0, args=k, saveat=diffrax.SaveAt(ts=jnp.asarray(ts)),
                                       stepsize_controller=diffrax.PIDController(rtol=1e-10, atol=1e-12),
                                       throw=False).ys
        return jax.jit(solve)
    example = (np.float64(2.0), np.float64(0.7))
    fn = traced.compile_ahead("test_library_solve_unswitched", ("structure", 3), make, example)
    np.testing.assert_allclose(np.asarray(fn(*example)), 2.0 * np.exp(-0.7 * ts), rtol=1e-8)
    assert not cache.exists() and _errors.EQX_ON_ERROR == "raise"


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


def _blocked_program(started, go, layout: Layout):
    """make() of `_program` that says it has started and then waits for `go` (a trace that takes a while)."""
    def make():
        started.set()
        assert go.wait(60), "never let go"
        return _program(layout)
    return make


def test_a_program_another_is_tracing_is_waited_for_and_loaded(cache, monkeypatch):
    """Two callers of one program at once (a sweep's workers on a fresh machine): the second waits for the first,
    then loads what it kept, traced and compiled, instead of tracing it too; both compute the same bits. (flock
    treats two opens of the lock file in one process as two holders, as it does two processes.)"""
    import threading
    import time
    started, go, first_layout, got, waits = threading.Event(), threading.Event(), Layout(), {}, threading.Event()
    sleep = time.sleep
    monkeypatch.setattr(traced.time, "sleep", lambda s: (waits.set(), sleep(s)))     # the wait loop's pause

    def first():
        got["first"] = traced.compile_ahead("test_program", ("structure", 1),
                                            _blocked_program(started, go, first_layout), EXAMPLE, first_layout)
    worker = threading.Thread(target=first)
    worker.start()
    assert started.wait(60)                       # the first is tracing, holding the program's lock
    second_layout = Layout()
    waiting = threading.Thread(target=lambda: got.setdefault("second", traced.compile_ahead(
        "test_program", ("structure", 1), lambda: jax.jit(_untraceable), EXAMPLE, second_layout)))
    waiting.start()
    assert waits.wait(60) and "second" not in got     # waiting for the holder, not tracing on its own
    go.set()
    worker.join(60)
    waiting.join(60)
    assert second_layout.value == [[7], "sin"]                    # loaded: what the first traced, restored
    assert np.array_equal(np.asarray(got["second"](*EXAMPLE)), np.asarray(got["first"](*EXAMPLE)))


def test_a_holder_that_does_not_finish_is_passed_by(cache, monkeypatch):
    """A holder still busy after WAIT_S (stopped, or a slow machine) is not waited for: the program is traced here."""
    monkeypatch.setattr(traced, "WAIT_S", 0.2)
    name = traced.disk_name("test_program", ("structure", 1), EXAMPLE)
    with traced._one_at_a_time(name):                  # held, never released while the call below runs
        layout = Layout()
        fn = traced.compile_ahead("test_program", ("structure", 1), lambda: _program(layout), EXAMPLE, layout)
    assert layout.value == [[7], "sin"]
    np.testing.assert_allclose(np.asarray(fn(*EXAMPLE)), np.sin(EXAMPLE[0]) * np.exp(-EXAMPLE[1] * EXAMPLE[0])
                               + np.cumsum(EXAMPLE[0]), rtol=1e-14)


def test_a_program_that_cannot_be_kept_is_not_waited_for(cache, monkeypatch):
    """A program jax.export refuses (host callbacks) is marked once; later callers compile it at once, even while
    another holds its lock (waiting would only queue compilations that all happen anyway)."""
    monkeypatch.setattr(traced, "WAIT_S", 600.0)

    def with_callback(x, a):
        return jax.pure_callback(np.cos, jax.ShapeDtypeStruct(x.shape, x.dtype), x) * a
    traced.compile_ahead("test_program", ("structure", 1), lambda: jax.jit(with_callback), EXAMPLE)
    name = traced.disk_name("test_program", ("structure", 1), EXAMPLE)
    import threading
    got = {}
    with traced._one_at_a_time(name):
        caller = threading.Thread(target=lambda: got.setdefault("fn", traced.compile_ahead(
            "test_program", ("structure", 1), lambda: jax.jit(with_callback), EXAMPLE)))
        caller.start()
        caller.join(60)                               # returns while the lock is held: not waited for
        assert "fn" in got
    np.testing.assert_allclose(np.asarray(got["fn"](*EXAMPLE)), np.cos(EXAMPLE[0]) * EXAMPLE[1], rtol=1e-15)
    assert not cache.exists()                         # nothing kept
