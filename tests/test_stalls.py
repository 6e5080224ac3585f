"""Stalls are their own exact events (issue 17, part 2), checked against an independent one-coordinate
integration (benchmarks/stall_reference.py: docs/theory.md §G2 written out from scratch, scipy solve_ivp at
rtol 1e-12) on IDA index-1, index-2 and diffrax."""
import numpy as np
import pytest

import mechsim
from mechsim.benchmarks.stall_reference import GenevaCase, first_stop, static_equilibrium

BACKENDS = {"index1": {"solver.formulation": "index1"}, "index2": {"solver.formulation": "index2"},
            "diffrax": {"solver.backend": "diffrax"}, "compiled": {"solver.backend": "ida-compiled"}}

# the first reproducer: the crank comes to rest mid-engagement, where the slip vanishes with it
HARD = {"mechanism.slots": 4, "load.wheel_torque": "20 N*m", "contact.friction": 0.15, "solver.rtol": 1e-10,
        "solver.atol": 1e-12, "duration": "0.25 s", "drive.torque": "12 N*m"}
HARD_CASE = GenevaCase(4, 0.075, 0.004, 0.02, 1.5626e-3, T0=12.0, T_L=20.0, mu=0.15, c1=0.1)
# the second: a motor curve creeping to its static equilibrium (exponential approach, theta' never 0)
CREEP = {"mechanism.slots": 4, "load.wheel_torque": "20 N*m", "contact.friction": 0.3, "solver.rtol": 1e-8,
         "solver.atol": 1e-10, "duration": "2.5 s", "drive.stall_torque": "30 N*m", "drive.no_load_speed": "4 rad/s"}
CREEP_CASE = GenevaCase(4, 0.075, 0.004, 0.02, 1.5626e-3, T0=30.0, slope=30.0 / 4.0, T_L=20.0, mu=0.3, c1=0.002,
                        c2=0.001)


def stop_row(result):
    assert result.failure is not None and result.failure.kind == "physics", result.failure
    last = result.events.iloc[-1]
    assert last["t_s"] == pytest.approx(result.failure.time, abs=0)
    return last


@pytest.fixture(scope="module")
def hard_reference():
    out = first_stop(HARD_CASE, -np.pi, 5.34, 1.0)
    assert out.kind == "stall"
    return out


@pytest.fixture(scope="module")
def creep_reference():
    out = first_stop(CREEP_CASE, -np.pi, 5.34, 5.0)
    assert out.kind == "rest"
    return out


@pytest.mark.parametrize("backend", BACKENDS)
def test_stall_is_its_own_event_at_the_reduced_models_time(backend, hard_reference):
    """The stall wins over the slip reversal that vanishes with it: one 'stall' row at the reduced model's
    stall time to 1e-6 s (the roots are located to ~1e-10 s at rtol 1e-10), nothing integrated after it, the
    crank never turned backwards and friction never created energy."""
    r = mechsim.run("geneva-torque", set={**HARD, **BACKENDS[backend]})
    row = stop_row(r)
    assert row["kind"] == "stall" and row["guard"] == "stall"
    assert abs(row["t_s"] - hard_reference.time) < 1e-6
    assert abs(row["crank_q"] - hard_reference.angle) < 1e-6
    assert "stalled" in r.failure.reason
    ts = r.timeseries
    assert ts["t_s"].iloc[-1] <= row["t_s"]
    assert ts["crank_speed_rad_s"].min() > -1e-6
    assert ts["friction_power_W"].min() >= 0.0
    # no slip reversal logged at the stall instant
    reversals = r.events[r.events["kind"] == "slip reversal"]["t_s"]
    assert not np.any(np.abs(reversals - row["t_s"]) < 1e-3)


@pytest.fixture(scope="module")
def creep_runs():
    return {b: mechsim.run("geneva-motor", set={**CREEP, **o}) for b, o in BACKENDS.items()}


def test_creeping_rest_at_the_static_equilibrium(creep_runs, creep_reference):
    """A crank creeping to rest stops where theta' + (1 s)|theta''| < 1e-5 rad/s: the rest angle is the static
    equilibrium (motor torque at zero speed = load through the mechanism, brentq) to 1e-6 rad (the remaining
    creep is theta' tau ~ 1e-7 rad), the time agrees between the three backends and the reference to 1e-3 s."""
    a0 = CREEP_CASE.alpha0
    rest = static_equilibrium(CREEP_CASE, -a0 + 1e-9, -0.1)
    times = []
    for backend, r in creep_runs.items():
        row = stop_row(r)
        assert row["kind"] == "rest", backend
        assert abs(row["crank_q"] - rest) < 1e-6, backend
        times.append(row["t_s"])
        # it was caught while creeping: not seconds late, and never by a late sign change of theta'
        assert r.timeseries["crank_speed_rad_s"].iloc[-1] < 1e-4
    assert max(times) - min(times) < 1e-3
    assert abs(np.mean(times) - creep_reference.time) < 1e-3


# a 3-slot Geneva whose crank enters the engagement at 47 rad/s: the smooth dwell motion let the reference's
# step jump the whole engagement zone until its boundary event was made continuous (grid case g029)
FAST_ENTRY = {"mechanism.slots": 3, "load.wheel_torque": "15 N*m", "contact.friction": 0.15, "drive.torque": "12 N*m",
              "solver.rtol": 1e-10, "solver.atol": 1e-12, "duration": "0.3 s"}
FAST_ENTRY_CASE = GenevaCase(3, 0.075, 0.004, 0.02, 1.5626e-3, T0=12.0, T_L=15.0, mu=0.15, c1=0.1)


def test_reference_sees_an_engagement_entered_at_speed():
    ref = first_stop(FAST_ENTRY_CASE, -np.pi, 5.34, 1.0)
    r = mechsim.run("geneva-torque", set=FAST_ENTRY)
    assert ref.kind == "stall" and stop_row(r)["kind"] == "stall"
    # both at rtol <= 1e-10: the stall instants agree far inside the 1e-6 s of the stall tests above
    assert r.failure.time == pytest.approx(ref.time, abs=1e-6)


@pytest.mark.parametrize("backend", ["index1", "index2"])
def test_slip_reversal_at_speed_is_not_a_stall_at_loose_tolerance(backend):
    """At rtol 1e-4 the slip-reversal root of a violent 3-slot engagement (crank at 37 rad/s) lies 1.4e-3 (r + R)
    from the kinematic zero: a reversal, not the crank stopping (grid cases g027, g185). The run goes on, and
    its crank angle stays within the loose tolerance's reach of the reference (independent model, rtol 1e-12)."""
    sets = {"mechanism.slots": 3, "load.wheel_torque": "20 N*m", "contact.friction": 0.0, "drive.torque": "16 N*m",
            "solver.rtol": 1e-4, "solver.atol": 1e-6, "duration": "0.5 s", **BACKENDS[backend]}
    r = mechsim.run("geneva-torque", set=sets)
    assert r.failure is None
    ref = first_stop(GenevaCase(3, 0.075, 0.004, 0.02, 1.5626e-3, T0=16.0, T_L=20.0, mu=0.0, c1=0.1),
                     -np.pi, 5.34, 0.5)
    assert ref.kind == "running"
    # the global error of a run is a modest multiple of rtol times the angle turned (docs/stability.md: the
    # grid measured at most 18 rtol S); 1000 rtol |angle| is the invariant checks' bound
    assert abs(r.timeseries["crank_angle_rad"].iloc[-1] - ref.angle) < 1000 * 1e-4 * abs(ref.angle)
