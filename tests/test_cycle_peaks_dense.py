"""A cycle-averaged DAE run reads its periodic turn on the window's continuous solution, not on its output rows
(thermal/plan.py `WindowReadings`, scenarios/thermal_peaks.py `ThermalReader.readings`; docs/thermal.md "Reported
temperatures"): the turn's ends where the crank passes its start angle, the network's states and heat energies
there, and the heat input on pieces fixed by the turn and its events. The cycle-averaged solution, and the peaks
located on it, then do not depend on the output step beyond the run's tolerance (with the input linear between the
rows they moved by about 1e-4 K per ms of output step: the input jumps at the entries and exits between rows)."""
import numpy as np
import pytest

import mechsim
from mechsim.scenarios import runner

COLUMNS = ("temp_contact_C", "temp_flash_rise_K", "temp_bulk_pin_C", "temp_bulk_wheel_C")
#: geneva-motor (its speed follows from the dynamics) with the lumped network, cycle-averaged after its window
SETS = ["duration=12 s", "thermal.model=lumped", "thermal.averaging=cycle", "solver.rtol=1e-10",
        "solver.atol=1e-12"]


def _plan(step):
    return runner.plan(mechsim.load("geneva-motor", set=SETS + [f"output_step={step} ms"]))


@pytest.fixture(scope="module")
def runs():
    return {step: runner.execute(_plan(step)) for step in (1, 4)}


def test_cycle_averaged_peaks_do_not_move_with_the_output_step(runs):
    """1 and 4 ms: the periodic turn, its mean heat and every located thermal peak equal to 100 times the run's
    rtol (relative; measured: 1e-10 on the pin's bulk peak, 2e-11 on the contact temperature's), the peaks after the
    window."""
    one, four = runs[1].summary, runs[4].summary
    for r in (one, four):
        assert r["thermal"]["averaging"] == "cycle"
    a, b = one["thermal"]["cycle"], four["thermal"]["cycle"]
    assert b["periodic_turn_s"] == pytest.approx(a["periodic_turn_s"], rel=1e-8)
    assert b["mean_heat_rate_W"] == pytest.approx(a["mean_heat_rate_W"], rel=1e-8)
    for col in COLUMNS:
        for side in ("max", "min"):
            assert four["peaks"][col][side]["value"] == pytest.approx(one["peaks"][col][side]["value"], rel=1e-8), \
                (col, side)
    peak = one["peaks"]["temp_contact_C"]["max"]
    assert peak["t_s"] > a["mechanics_simulated_until_s"]


def test_traced_turn_bulk_is_the_runs():
    """The cycle-averaged bulk the design sensitivities trace (thermal/cycle_exact.py `dense_turn_bulk`: the ripple
    exact for the turn's piecewise-cubic input through its Gauss-Legendre nodes) equals the run's (thermal/cycle.py
    `bulk_response`, which integrates the same input by quadrature) across the turn, at the turn itself and 1 and 30
    periods later, to 1e-9 K (measured 5e-11 K; the ripple's swing over the turn is 0.25 K); the turn's start states
    are the run's own."""
    from mechsim.scenarios.studies.sensitivity_cycle import _network, dense_turn
    from mechsim.thermal.cycle_exact import dense_turn_bulk, lagrange_monomials
    turn = dense_turn(runner.settled(_plan(4)))
    setup = turn["thermal"].setup
    a, P, nodes = turn["t_start"], turn["period"], turn["nodes"]
    u_of_phase, _ = turn["solution"]["input"]
    u = u_of_phase(nodes.ravel() - a)
    ends = turn["ends_frame"]
    x = {"ends": np.array([a, a + P]), "gen": ends["heat_generated_J"].to_numpy(float),
         "pin": ends["heat_pin_J"].to_numpy(float), "start": ends[list(setup.system.state_names)].to_numpy(float)[0],
         "edges": turn["edges"]}
    np.testing.assert_array_equal(x["start"], turn["solution"]["means"].start)
    times = np.linspace(a, a + P, 37)[:-1] + 1e-4
    data = {"weights": np.polynomial.legendre.leggauss(nodes.shape[1])[1] / 2,
            "lagrange": lagrange_monomials(turn["node_offsets"]),
            "piece": np.searchsorted(turn["edges"], times, side="right") - 1, "times": times}
    for m in (0, 1, 30):
        data["periods"] = np.full(len(times), float(m))
        mine = dense_turn_bulk(x, data, _network(setup.system), u.T.reshape(nodes.shape + (-1,)))[0]
        run = turn["thermal"].cycle_states(turn["solution"], times + m * P)
        np.testing.assert_allclose(mine, run, rtol=0, atol=1e-9)
        assert np.ptp(run[:, 0]) > 0.1
