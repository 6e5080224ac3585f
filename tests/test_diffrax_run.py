"""The compiled whole-run diffrax loop (dynamics/backends/diffrax_run.py, issue 13 item 3): case A of the peer benchmark
against the independent reference, the segment loop and IDA (its transition table against the Python loop's
evaluation: tests/test_transition_table.py)."""
from dataclasses import replace

import numpy as np
import pytest

from mechsim.benchmarks.bench import BenchConfig, make_problem, reference
from mechsim.benchmarks.peer_bench import CASES
from mechsim.dynamics import hybrid
from mechsim.dynamics.backends import diffrax_run
from mechsim.dynamics.backends.diffrax_backend import DiffraxBackend, default_options, mode_z
from mechsim.dynamics.jax_model import jax_model
from mechsim.dynamics.settings import SolverSettings
from mechsim.dynamics.tables import events_table

RTOL = 1e-8


@pytest.fixture(scope="module")
def case_a():
    return make_problem(BenchConfig(scenario="geneva-motor", duration=5.0, overrides=CASES["A"]))


def _settings(backend: str) -> SolverSettings:
    return SolverSettings(backend=backend, formulation="index1", rtol=RTOL, atol=RTOL * 1e-2)


def _simulate(problem, settings, backend):
    return hybrid.simulate(problem.mech, problem.drive, settings, problem.duration, problem.dt_out,
                           problem.angle0, problem.speed0, backend=backend)


@pytest.fixture(scope="module")
def runs(case_a):
    settings = _settings("diffrax")
    o = default_options(settings)
    whole = _simulate(case_a, settings, DiffraxBackend(settings, o))
    segments = _simulate(case_a, settings, DiffraxBackend(settings, replace(o, compiled_run=False)))
    ida = hybrid.simulate(case_a.mech, case_a.drive, _settings("ida"), case_a.duration, case_a.dt_out,
                          case_a.angle0, case_a.speed0)
    return whole, segments, ida


def _crank(problem, traj):
    t = np.concatenate([p.t for p in traj.pieces])
    ix = traj.model.modes[traj.pieces[0].mode].index["q"]
    return t, np.concatenate([p.coordinates(ix)[:, problem.mech.drive_coordinate] for p in traj.pieces])


def test_one_compiled_call_tracks_the_reference(case_a, runs):
    """Case A in one compiled call: crank angle against the independent reduced-coordinate reference within
    100 rtol rad (the segment loop's error at this tolerance is 0.9e-9 rad, docs/benchmarks.md; the crank turns
    about 30 rad, so 1e-6 rad is 100 rtol at unit angle scale and 3 rtol relative)."""
    whole, _, _ = runs
    assert whole.failure is None, whole.failure
    assert "inside 1 compiled" in whole.stats["notes"]["segments"]
    ref = reference(case_a)
    t, angle = _crank(case_a, whole)
    assert np.all(np.diff(t) > 0)
    np.testing.assert_allclose(t[1:], case_a.dt_out * np.arange(1, len(t)), atol=1e-9)
    assert np.max(np.abs(angle - np.interp(t, ref["t"], ref["angle"]))) < 100 * RTOL


def test_agrees_with_the_segment_loop_and_ida(case_a, runs):
    """The same events (kinds, order, modes) as the segment loop and IDA, at the same times to the event
    location's accuracy set by the integration error (1e-6 s: an angle error of 1e-6 rad at about 6 rad/s is
    1.7e-7 s), and the same trajectory to the integration error."""
    whole, segments, ida = runs
    ev = [events_table(tr) for tr in (whole, segments, ida)]
    for other in ev[1:]:
        assert list(ev[0]["kind"]) == list(other["kind"])
        assert list(ev[0]["to_mode"]) == list(other["to_mode"])
        np.testing.assert_allclose(ev[0]["t_s"], other["t_s"], atol=1e-6)
    # no kinetic energy lost at the tangential entries/exits and the frictionless reversals (to round-off)
    assert np.allclose(ev[0]["kinetic_energy_before_J"], ev[0]["kinetic_energy_after_J"], rtol=1e-8)
    t_w, a_w = _crank(case_a, whole)
    t_s, a_s = _crank(case_a, segments)
    np.testing.assert_array_equal(t_w, t_s)
    assert np.max(np.abs(a_w - a_s)) < 100 * RTOL


def test_rows_satisfy_the_mode_residuals(runs):
    """Output rows are interpolated states (multipliers NaN, no y'); completed by their mode's KKT solve they
    satisfy every residual row of the mode, the position and velocity constraints included, at the integration
    error (the index-1 ODE drifts off Phi = 0 only by its Baumgarte-damped error, and the interpolant adds its
    own, of the order of the step's error)."""
    whole, _, _ = runs
    model = whole.model
    jmod = jax_model(model)
    for piece in whole.pieces[1:]:
        mf = model.modes[piece.mode]
        assert piece.yp is None and np.all(np.isnan(piece.y[:, mf.index["lam"]]))
        jm = jmod.modes[jmod.index(piece.mode)]
        p = np.asarray(piece.params, float)
        for y, t in zip(piece.y[::97], piece.t[::97]):
            z = mode_z(mf, y)
            y_full, yp_full = (np.asarray(x) for x in jm.ida_rows(t, z, p))
            res = np.zeros(mf.ny)
            mf.residual(t, y_full, yp_full, res, piece.params)
            assert np.max(np.abs(res)) < 1e-6, (piece.mode, t, res)


def test_dense_readings_at_the_rows_are_the_rows(runs):
    """The run's dense output read at its own output instants, all in one pass (more instants than one call of
    the dense reading holds), gives the rows themselves: the same step's interpolant, evaluated the same way
    (`make_rows`, `make_dense`), so a located peak is never below a row."""
    whole, _, _ = runs
    dense = whole.dense
    requests, expected = [], []
    for a, b, *_ in dense.segments:
        held = [(p.t[(p.t > a) & (p.t <= b)], p.y[(p.t > a) & (p.t <= b)]) for p in whole.pieces[1:]]
        t, y = np.concatenate([h[0] for h in held]), np.concatenate([h[1] for h in held])
        if len(t):
            requests.append((t, a, b))
            expected.append(y)
    assert sum(len(r[0]) for r in requests) > diffrax_run.DENSE_BATCH
    for (t, _, _), y, got in zip(requests, expected, dense.read_many(requests)):
        assert got is not None and len(got[3]) == len(t)
        np.testing.assert_array_equal(got[3], y)


def test_calls_resume_where_the_buffers_end(case_a, runs, monkeypatch):
    """With buffers of 128 steps and 3 events the run takes many calls: full step buffers end a call between
    steps, a full event buffer hands the transition to `apply_transition` in Python (which also re-bases the
    coordinates). The result is the single call's to the integration error, with the same events."""
    whole, _, _ = runs
    monkeypatch.setattr(diffrax_run, "STEPS_PER_CALL", 128)
    monkeypatch.setattr(diffrax_run, "EVENTS_PER_CALL", 3)
    settings = _settings("diffrax")
    split = _simulate(case_a, settings, DiffraxBackend(settings))
    assert split.failure is None, split.failure
    calls = int(split.stats["notes"]["segments"].split("inside ")[1].split()[0])
    assert calls >= split.stats["accepted_steps"] // 128
    e1, e2 = events_table(whole), events_table(split)
    assert list(e1["kind"]) == list(e2["kind"])
    np.testing.assert_allclose(e1["t_s"], e2["t_s"], atol=1e-6)
    t1, a1 = _crank(case_a, whole)
    t2, a2 = _crank(case_a, split)
    np.testing.assert_array_equal(t1, t2)
    assert np.max(np.abs(a1 - a2)) < 100 * RTOL


def test_the_step_records_of_several_calls_read_as_one_joined_table():
    """The dense reading's step records (`diffrax_run._Records`) stay in each compiled call's buffer: a record
    taken, a column read, in the calls' order or another, are those of the records joined into one table (what
    the reading gathered from before, at the cost of copying every record of the run)."""
    from mechsim.dynamics.backends.diffrax_run import _Records
    rng = np.random.default_rng(3)
    parts = [rng.standard_normal((n, 5)) for n in (7, 1, 4)]
    joined = np.concatenate(parts)
    order = rng.permutation(len(joined))
    for rec, table in ((_Records(parts, 5), joined), (_Records(parts, 5).reordered(order), joined[order]),
                       (_Records(parts, 5).reordered(order).reordered(order[::-1]), joined[order][order[::-1]]),
                       (_Records(parts[:1], 5), parts[0])):
        steps = rng.integers(0, len(table), 9)
        out = np.empty((9, 5))
        rec.take(steps, out)
        assert np.array_equal(out, table[steps])
        assert all(np.array_equal(rec.column(k), table[:, k]) for k in range(5))


def test_a_mode_traced_outside_the_unrolled_kkt_solves_is_traced_again_inside():
    """The compiled whole run traces each mode's vector field with the KKT solve unrolled (`kkt.unrolled_solves`),
    the segment solve with LAPACK's. jit's trace cache does not see that switch: a batched sweep's segment solve
    traced first in a process had the whole run reuse its trace, LAPACK's LU inside the whole run (3-5x slower a
    0.8 s geneva-motor run), kept so on disk for every later process. Each switch now gets its own trace of the
    mode, whichever comes first."""
    import re

    import jax

    from mechsim.dynamics import kkt
    from mechsim.dynamics.model import derive
    from mechsim.scenarios.loader import build_mechanism, load
    model = derive(build_mechanism(load("geneva-motor").si), "index2", False)
    jm = jax_model(model).modes[0]
    args = (0.0, np.zeros(jm.nz), np.zeros(len(model.parameter_names)))

    def primitives():
        return set(re.findall(r"= (\w+)", str(jax.make_jaxpr(jm.traced_once)(*args))))
    outside = primitives()
    with kkt.unrolled_solves():
        inside = primitives()
    assert "lu" in outside and "lu" not in inside
    assert "lu" in primitives()                 # and outside again: the first trace is kept for its own switch
