"""Design sensitivities of the rolling-pair four-bar (docs/theory.md §K3) against central finite differences of the
IDA path, Richardson-extrapolated (the method of tests/test_sensitivity.py, docs/sensitivity.md).

rolling-a-torque for 1.5 s: one smooth mode under gravity from rest, its masses entering through the composite
rolling link (disc + arm, centre of mass and inertia moved to it) and the slender rods; no events, so no index or
cycle. Steps 1e-3 and 5e-4 at rtol 1e-12 (noise rtol/h ~ 1e-9, Richardson truncation ~ h^4). Each entry must agree
to 1e-4 relative, or to 1e-6 in elasticity where the derivative is zero (the constant drive torque's).
"""
from __future__ import annotations

import numpy as np

import mechsim
from conftest import assert_matches_finite_differences, richardson_central
from mechsim.scenarios.sensitivity import PEAKS, sensitivity

NAME = "rolling-a-torque"
SETS = ["duration=1.5 s"]
WRT = ["drive.torque", "mechanism.crank_mass", "mechanism.disc_mass", "mechanism.arm_mass", "load.gravity"]
FD = SETS + ["solver.rtol=1e-12", "solver.atol=1e-13"]
H = 1e-3
ELASTICITY_FLOOR = 1e-6


def _peaks(sets, rows):
    r = mechsim.run(mechsim.load(NAME, set=sets))
    assert r.failure is None, r.failure.message()
    return {q: float(r.timeseries[PEAKS[q]].iloc[i]) for q, i in rows.items()}


def test_rolling_pair_matches_finite_differences():
    table = sensitivity(mechsim.load(NAME, set=SETS), WRT)        # the scenario's own rtol 1e-10
    assert set(table["quantity"]) == {"peak_contact_force_N", "peak_drive_torque_N_m", "peak_coupler_force_N",
                                      "peak_crank_accel_rad_s2", "peak_crank_speed_rad_s"}
    df = mechsim.run(mechsim.load(NAME, set=FD)).timeseries
    rows = {q: int(np.nanargmax(np.abs(df[PEAKS[q]].to_numpy(float)))) for q in set(table["quantity"])}
    ref0 = _peaks(FD, rows)
    worst = {}
    for key in WRT:
        part = table[table["wrt"] == key].set_index("quantity")
        p, unit = float(part["parameter"].iloc[0]), part["wrt_unit"].iloc[0]
        fd = richardson_central(lambda value: _peaks(FD + [f"{key}={value!r} {unit}"], rows), p, H)
        assert_matches_finite_differences(part, ref0, fd, p, key, 1e-7, ELASTICITY_FLOOR, worst)
    print("rolling pair: largest relative deviation from the finite differences:",
          {q: f"{e:.1e}" for q, e in worst.items()})
