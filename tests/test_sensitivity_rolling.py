"""Design sensitivities of the rolling-pair four-bar (docs/theory.md §K3) against central finite differences of the
IDA path, Richardson-extrapolated (the method of tests/test_sensitivity.py, docs/sensitivity.md).

rolling-a-torque for 1.5 s: one smooth mode under gravity from rest, its masses entering through the composite
rolling link (disc + arm, centre of mass and inertia moved to it) and the slender rods, its geometry as itself; no
events, so no index or cycle. Steps 1e-3 and 5e-4 at rtol 1e-12 (noise rtol/h ~ 1e-9, Richardson truncation ~ h^4),
smaller for the geometry (`H`). Each entry must agree
to 1e-4 relative, or to 1e-6 in elasticity where the derivative is zero (the constant drive torque's).
"""
from __future__ import annotations

import numpy as np

import mechsim
from conftest import peaks_match_finite_differences
from mechsim.scenarios.studies.sensitivity import PEAKS, sensitivity

NAME = "rolling-a-torque"
SETS = ["duration=1.5 s"]
#: with the geometry (docs/sensitivity.md "Geometry of the chain and the rolling pair"): the disc's radius (the rolling
#: constraint and the disc's inertia m r^2/2), the crank's length (the loop, its rod's centre and inertia) and the
#: fixed circle's centre (a list entry), eight values in one compiled pass
WRT = ["drive.torque", "mechanism.crank_mass", "mechanism.disc_mass", "mechanism.arm_mass", "load.gravity",
       "mechanism.disc_radius", "mechanism.crank_length", "mechanism.profile_centre[1]"]
FD = SETS + ["solver.rtol=1e-12", "solver.atol=1e-13"]
#: relative steps: 1e-3, but a tenth of the change that lets another output row take over a peak for the geometry
#: (the table's warnings: 0.036 % of the disc's radius, 0.057 % of the crank's length, for the acceleration peak)
H = {"mechanism.disc_radius": 3e-5, "mechanism.crank_length": 5e-5}
ELASTICITY_FLOOR = 1e-6


def test_rolling_pair_matches_finite_differences():
    table = sensitivity(mechsim.load(NAME, set=SETS), WRT)        # the scenario's own rtol 1e-10
    assert set(table["quantity"]) == {"peak_contact_force_N", "peak_drive_torque_N_m", "peak_coupler_force_N",
                                      "peak_crank_accel_rad_s2", "peak_crank_speed_rad_s"}
    worst = peaks_match_finite_differences(NAME, table, WRT, FD, {k: H.get(k, 1e-3) for k in WRT},
                                           mechsim.load(NAME, set=SETS).si, 1e-7, ELASTICITY_FLOOR)
    print("rolling pair: largest relative deviation from the finite differences:",
          {q: f"{e:.1e}" for q, e in worst.items()})


# -- through dead points: rolling-b-components (2 N*m on the rolling link from rest) reaches the stretched dyad twice
# in 6 s, each a 'dead point' transition that flips the side (dead_sign); the largest coupler force, crank
# acceleration and crank speed come after the first, next to the second
EVENTS = "rolling-b-components"
WRT_EVENTS = ["mechanism.crank_length", "mechanism.disc_radius", "mechanism.arm_length", "mechanism.profile_centre[0]"]
#: a tenth of the change that lets another output row take over a peak (the table's warnings: 0.047 %, 0.016 %,
#: 0.084 %, 0.074 %)
H_EVENTS = {"mechanism.crank_length": 4e-5, "mechanism.disc_radius": 1.5e-5, "mechanism.arm_length": 8e-5,
            "mechanism.profile_centre[0]": 7e-5}


def test_rolling_pair_geometry_through_dead_points():
    table = sensitivity(mechsim.load(EVENTS), WRT_EVENTS)          # the scenario's own rtol 1e-10
    fd_sets = ["solver.rtol=1e-12", "solver.atol=1e-13"]
    nominal = mechsim.run(mechsim.load(EVENTS, set=fd_sets))
    assert list(nominal.events["kind"]) == ["dead point", "dead point"]
    df = nominal.timeseries
    rows = [int(np.nanargmax(np.abs(df[PEAKS[q]].to_numpy(float)))) for q in set(table["quantity"])]
    assert max(df["t_s"].iloc[i] for i in rows) > nominal.events["t_s"].iloc[0]
    worst = peaks_match_finite_differences(EVENTS, table, WRT_EVENTS, fd_sets, H_EVENTS, mechsim.load(EVENTS).si,
                                           1e-7, ELASTICITY_FLOOR)
    print("rolling pair through dead points: largest relative deviation from the finite differences:",
          {q: f"{e:.1e}" for q, e in worst.items()})
