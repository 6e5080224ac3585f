"""Friction through flank switches, against an independent derivation.

A 3-slot Geneva at mu = 0.3 driven hard (16 N*m against 10 N*m) decelerates its wheel faster than the load
alone would: the normal force changes sign twice per engagement and the pin bears on the trailing flank in
between, with the slip reversing around it. The reduced one-coordinate equation of
benchmarks/stall_reference.py (its own kinematics, flank and slip events, DOP853 at rtol 1e-12; the trailing
flank's friction arm derived there from the contact offset s R) must give the same crank angle as the DAE.
Tolerance: the DAE's own global error at rtol 1e-10 on an angle that reaches ~64 rad after 1 s (measured
2e-8 rad on IDA index1): 1e-6 rad. Before the reference knew the trailing flank the two differed by 8e-4 rad
within 5 ms of the first switch.
"""
import numpy as np
import pytest

import mechsim
from mechsim.benchmarks.stall_reference import GenevaCase, first_stop
from mechsim.scenarios.runner import execute, plan

SETS = {"mechanism.slots": 3, "load.wheel_torque": "10 N*m", "contact.friction": 0.3, "solver.rtol": 1e-10,
        "solver.atol": 1e-12, "duration": "1 s", "drive.torque": "16 N*m", "output.plots": False}
BACKENDS = {"index1": {"solver.formulation": "index1"}, "index2": {"solver.formulation": "index2"}}


@pytest.mark.parametrize("backend", BACKENDS)
def test_crank_angle_through_flank_switches_matches_the_reduced_equation(backend):
    the_plan = plan(mechsim.load("geneva-torque", set={**SETS, **BACKENDS[backend]}))
    r = execute(the_plan)
    assert r.failure is None, r.failure
    kinds = set(r.events["kind"])
    assert {"flank switch", "slip reversal"} <= kinds
    mech, si = the_plan.mechanism, the_plan.scenario.si
    dv, g = the_plan.drive.parameter_values(si["initial"]["crank_angle"]), mech.geometry
    case = GenevaCase(g.slots, g.crank_radius, g.pin_radius, mech.crank_inertia, mech.wheel_inertia, dv["drive_T0"],
                      dv["drive_slope"], mech.wheel_torque, mech.friction, mech.crank_damping, mech.wheel_damping)
    ts = r.timeseries
    for t in (0.1, 0.3, 1.0):
        ref = first_stop(case, si["initial"]["crank_angle"], si["initial"]["crank_speed"], t)
        assert ref.kind == "running"
        row = int(np.argmin(np.abs(ts["t_s"].to_numpy() - t)))
        assert ts["t_s"].iloc[row] == pytest.approx(t, abs=1e-12)
        assert abs(ts["crank_angle_rad"].iloc[row] - ref.angle) < 1e-6, t
