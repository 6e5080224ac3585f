"""The diffrax backend on the Geneva model: closed form at prescribed speed, energy closure of the work states,
the IDA-layout rows the tables read, failure as a value, an implicit solver (issue 4, part 1)."""
from dataclasses import replace

import numpy as np
import pytest

import mechsim.dynamics.backends.diffrax_backend as dbk
from mechsim.dynamics.backends.diffrax_solvers import PatientVeryChord
from mechsim.dynamics.hybrid import simulate
from mechsim.dynamics.drives import Drive
from mechsim.dynamics.result import FailureCode
from mechsim.dynamics.settings import SolverSettings
from mechsim.dynamics.tables import events_table, timeseries
from mechsim.mechanisms.geneva.model import Geneva
from mechsim.scenarios.loader import load
from mechsim.scenarios.runner import run
from conftest import assert_wheel_matches_closed_form

J1, J2 = 0.02, 1.5626e-3
W1 = 5.34
SETTINGS = SolverSettings(backend="diffrax", rtol=1e-10, atol=1e-12)


@pytest.fixture(scope="module")
def prescribed(seed_geometry):
    mech = Geneva(seed_geometry, J1, J2, wheel_torque=7.0, friction=0.15)
    traj = simulate(mech, Drive("speed", speed=W1), SETTINGS, 2.5, 1e-3, -np.pi, W1)
    return mech, traj, timeseries(traj, mech.angle_coordinates)


@pytest.fixture(scope="module")
def motor():
    """geneva-motor on diffrax through the runner (motor curve, friction, damping), two crank turns."""
    sc = load("geneva-motor", ["solver.backend='diffrax'", "solver.rtol=1e-10", "solver.atol=1e-12",
                               "duration='2.4 s'", "output_step='2 ms'"])
    return run(sc)


def test_prescribed_speed_matches_closed_form(seed_geometry, prescribed):
    """docs/theory.md §G7 rows 1-6 (as for IDA): wheel angle, speed and acceleration to 1e-6 relative."""
    _, traj, df = prescribed
    assert traj.failure is None, traj.failure
    assert_wheel_matches_closed_form(seed_geometry, df, W1)
    # entry and exit alternate, one each per crank turn (2.5 s at 5.34 rad/s: two turns and a bit)
    kinds = [k for k in events_table(traj)["kind"] if k in ("entry", "exit")]
    assert kinds[:4] == ["entry", "exit", "entry", "exit"]


def test_rows_are_in_the_ida_layout(seed_geometry, prescribed):
    """The segment loop's rows: y holds q, v, lam (mu = 0 for index2); y' holds v, a, 0, 0, work', ext': the IDA
    residual vanishes. (The compiled whole run's rows are states only: tests/test_diffrax_run.py.)"""
    mech, _, _ = prescribed
    options = replace(dbk.default_options(SETTINGS), compiled_run=False)
    traj = simulate(mech, Drive("speed", speed=W1), SETTINGS, 1.0, 1e-3, -np.pi, W1,
                    backend=dbk.DiffraxBackend(SETTINGS, options))
    model = traj.model
    assert traj.failure is None, traj.failure
    for piece in traj.pieces[1:4]:
        mf = model.modes[piece.mode]
        for y, yp, t in zip(piece.y[::50], piece.yp[::50], piece.t[::50]):
            res = np.zeros(mf.ny)
            mf.residual(t, y, yp, res, piece.params)
            assert np.max(np.abs(res)) < 1e-6, (piece.mode, t, res)
            assert np.all(y[mf.index["mu"]] == 0.0)


def test_energy_closes_on_the_work_states(motor):
    """Drive work = change of kinetic energy - (load + friction + damping work): the work states are
    integrated with the motion, so the balance closes to the integration tolerance."""
    assert motor.success, motor.failure
    energy = motor.summary["energy"]
    assert abs(energy["closure_error_relative"]) < 1e-7, energy
    # friction and load take energy out, the motor puts it in
    assert energy["work_J"]["friction"] < 0 < energy["work_J"]["drive"]
    df = motor.timeseries
    balance = (df["work_drive_J"] + df["work_load_J"] + df["work_friction_J"] + df["work_damping_J"]
               - (df["kinetic_energy_J"] - df["kinetic_energy_J"].iloc[0]))
    assert np.max(np.abs(balance)) < 1e-7 * df["work_drive_J"].abs().max()


def test_solver_statistics_are_reported(motor):
    s = motor.summary["solver"]
    assert s["backend"] == "diffrax" and s["solver"] == "Tsit5"
    assert s["steps"] == s["accepted_steps"] + s["rejected_steps"] > 0
    assert s["residual_evaluations"] > s["steps"]
    assert s["compile_time_s"] >= 0.0 and s["solve_time_s"] > 0.0
    assert s["events"] == len(motor.events) > 0


def test_failure_is_a_value(seed_geometry):
    """Baumgarte gains of 1e6 make the index-1 ODE stiff: Tsit5 reaches max_steps. The run returns what it
    had, with a failure dict (time, mode, reason, where, hint), and does not raise."""
    mech = Geneva(seed_geometry, J1, J2, wheel_torque=7.0, friction=0.15, crank_damping=0.002, wheel_damping=0.001)
    settings = replace(SETTINGS, baumgarte_alpha=1e6, baumgarte_beta=1e6)
    traj = simulate(mech, Drive("motor", stall_torque=40.0, no_load_speed=8.0), settings, 1.0, 2e-3, -np.pi, W1)
    f = traj.failure
    assert f is not None
    assert set(f) >= {"time", "mode", "reason", "where", "hint"}
    assert "maximum number of solver steps" in f["reason"] and f["code"] is FailureCode.MAX_STEPS
    assert 0.0 < f["time"] < 1.0 and set(f["where"]) == {"crank", "wheel"}
    assert len(traj.pieces) >= 1   # what ran so far is kept


def test_unknown_solver_is_a_user_error(seed_geometry):
    with pytest.raises(ValueError, match="diffrax_solver"):
        dbk.default_options(replace(SETTINGS, diffrax_solver="RK99"))


def test_implicit_solver_agrees_with_explicit(seed_geometry, prescribed):
    """Kvaerno5 (implicit) on the same prescribed-speed run: same events, wheel angle within 1e-7 rad."""
    mech, traj, df = prescribed
    settings = replace(SETTINGS, diffrax_solver="Kvaerno5", rtol=1e-9, atol=1e-11)
    traj5 = simulate(mech, Drive("speed", speed=W1), settings, 0.8, 1e-3, -np.pi, W1)
    assert traj5.failure is None, traj5.failure
    df5 = timeseries(traj5, mech.angle_coordinates)
    n = len(df5)
    assert np.max(np.abs(df5["wheel_angle_rad"].to_numpy() - df["wheel_angle_rad"].to_numpy()[:n])) < 1e-7
    assert list(events_table(traj5)["kind"]) == list(events_table(traj)["kind"])[:len(traj5.events)]
    assert traj5.stats["rejected_steps"] < 0.25 * traj5.stats["steps"]


@pytest.mark.parametrize("step, size, prev, done, ok", [
    (2, 5e6, 4e7, False, True),     # contracting (rate 0.125) but not yet converged: go on (diffrax 0.7.2 fails here)
    (3, 1e-4, 5e-2, True, True),    # converged by the rate test
    (2, 8e7, 1e7, True, False),     # corrections growing: divergence
    (1, 1e-6, np.inf, True, True),  # first correction already far below the tolerance
    (2, 3e-5, 1e-5, True, True),    # rate 3 of round-off-sized corrections: converged, not diverged
])
def test_patient_verychord_terminates_only_on_convergence_or_divergence(step, size, prev, done, ok):
    import optimistix as optx
    from types import SimpleNamespace
    finder = PatientVeryChord(rtol=1e-8, atol=1e-10, kappa=0.1)
    state = SimpleNamespace(step=np.array(step), diffsize=np.array(size), diffsize_prev=np.array(prev),
                            result=optx.RESULTS.successful)
    terminate, result = finder.terminate(None, None, None, {}, state, frozenset())
    assert bool(terminate) is done
    assert bool(result == optx.RESULTS.successful) is ok


def test_one_compilation_serves_every_tolerance(motor):
    """An explicit solver's (rtol, atol) are traced arguments: after the rtol-1e-10 run of the `motor` fixture,
    the same model at rtol 1e-5 compiles nothing, and the tolerance still governs the solve: fewer steps, and an
    error the size of a loose run's (against the tight run), not of the tight one's."""
    sc = load("geneva-motor", ["solver.backend='diffrax'", "solver.rtol=1e-5", "solver.atol=1e-7",
                               "duration='2.4 s'", "output_step='2 ms'"])
    loose = run(sc)
    assert loose.summary["solver"]["compilations"] == 0 and loose.summary["solver"]["compile_time_s"] == 0.0
    assert loose.summary["solver"]["steps"] < motor.summary["solver"]["steps"] / 3
    q_tight = motor.timeseries["crank_angle_rad"].to_numpy()
    error = np.abs(loose.timeseries["crank_angle_rad"].to_numpy() - q_tight).max()
    scale = np.abs(q_tight).max()
    assert 1e-10 * scale < error <= 1000 * (1e-5 * scale + 1e-7)


def test_evaluations_per_step_are_the_tableaux_stages():
    """The table of vector-field evaluations per attempted step (diffrax_common, kept apart from diffrax so that a
    loading process never imports it) against each explicit method's Butcher tableau: its stages, less the one
    it shares with the next step where it is FSAL (Euler has no tableau: one evaluation)."""
    import diffrax
    from mechsim.dynamics.backends.diffrax_common import EVALUATIONS_PER_STEP, EXPLICIT
    assert set(EVALUATIONS_PER_STEP) == set(EXPLICIT)
    for name in EXPLICIT:
        tab = getattr(getattr(diffrax, name)(), "tableau", None)
        expected = 1 if tab is None else len(tab.c) + 1 - bool(tab.fsal)
        assert EVALUATIONS_PER_STEP[name] == expected, name
