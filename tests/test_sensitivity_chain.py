"""Design sensitivities of the chain dwell mechanism (impacts at the crank stops, e = 0) against central finite
differences of the IDA path, Richardson-extrapolated (the method of tests/test_sensitivity.py, docs/sensitivity.md).

chain-mech1-torque for 12 s: two crank stops (a plastic impact each: the velocity projection of the reset is the
jump), two dwell ends, so an index (dwell end to stop) and a cycle (dwell end to dwell end). The peak coupler force
sits 1.8 ms before the first stop, and the stop moves by dtau/dT = -1271 s/(N m): a change of the drive torque by
6e-4 relative carries the impact past the row, so the steps are chosen per value (H) at rtol 1e-12. Each entry
must agree to 1e-4 relative, or to 1e-6 in elasticity where the derivative is zero up to noise.
"""
from __future__ import annotations

import numpy as np
import pytest

import mechsim
from conftest import (assert_matches_finite_differences, located_peak, peaks_match_finite_differences,
                      richardson_central, run_locating, value_setting)
from mechsim.scenarios.studies.sensitivity import PEAKS, sensitivity

NAME = "chain-mech1-torque"
SETS = ["duration=12 s"]
WRT = ["drive.torque", "load.crank_torque", "mechanism.chain_mass", "mechanism.coupler_mass"]
FD = SETS + ["solver.rtol=1e-12", "solver.atol=1e-14"]
#: steps: a tenth of the change that carries the first stop to the peak's row (0.06 % of the drive torque, 0.36 %
#: of the load, far beyond 1 % for the masses), and not smaller, since the peak's elasticities amplify the
#: IDA noise rtol / h
H = {"drive.torque": 5e-5, "load.crank_torque": 2e-4, "mechanism.chain_mass": 1e-3, "mechanism.coupler_mass": 1e-3}
ELASTICITY_FLOOR = 1e-6


def _run(sets, peaks):
    """The run the finite differences read, the located peaks of only the quantities `peaks` (`run_locating`)."""
    r = run_locating(mechsim.load(NAME, set=sets), [PEAKS[q] for q in peaks])
    assert r.failure is None, r.failure.message()
    return r


def _work_at(df, t_event):
    """The drive's work at t_event: cubic Hermite on the two output rows before it (work' = torque x speed)."""
    t = df["t_s"].to_numpy(float)
    w = df["work_drive_J"].to_numpy(float)
    pw = (df["drive_torque_N_m"] * df["drive_speed_rad_s"]).to_numpy(float)
    i = int(np.searchsorted(t, t_event)) - 1
    t0, h = t[i - 1], t[i] - t[i - 1]
    s = (t_event - t0) / h
    h00, h10, h01, h11 = 2 * s**3 - 3 * s**2 + 1, s**3 - 2 * s**2 + s, -2 * s**3 + 3 * s**2, s**3 - s**2
    return h00 * w[i - 1] + h10 * h * pw[i - 1] + h01 * w[i] + h11 * h * pw[i]


def quantities(result, rows):
    df, ev = result.timeseries, result.events
    out = {q: located_peak(result, PEAKS[q]) for q in rows}
    ends = ev.loc[ev["kind"] == "dwell end", "t_s"].to_numpy(float)
    stops = ev.loc[ev["kind"] == "stop impact", "t_s"].to_numpy(float)
    out["index_time_s"] = stops[-1] - ends[ends < stops[-1]][-1]
    out["cycle_time_s"] = ends[-1] - ends[-2]
    out["energy_per_cycle_J"] = _work_at(df, ends[-1]) - _work_at(df, ends[-2])
    return out


# (the coupler force's pole read at the stop itself is inf, not a divide-by-zero warning: dynamics/tables.py)
@pytest.mark.filterwarnings("error:divide by zero:RuntimeWarning")
def test_chain_matches_finite_differences():
    table = sensitivity(mechsim.load(NAME, set=SETS + ["solver.rtol=1e-10", "solver.atol=1e-12"]), WRT)
    # the coupler force grows without bound toward each crank stop (docs/theory.md §K5): no peak, no derivative
    assert "peak_coupler_force_N" not in set(table["quantity"])
    assert any("peak_coupler_force_N" in w and "without bound" in w for w in table.attrs["warnings"])
    peaks = [q for q in dict.fromkeys(table["quantity"]) if q in PEAKS]
    nominal = _run(FD, peaks)
    df = nominal.timeseries
    rows = {q: int(np.nanargmax(np.abs(df[PEAKS[q]].to_numpy(float)))) for q in peaks}
    ref0 = quantities(nominal, rows)
    assert set(ref0) == set(table["quantity"])
    worst = {}
    for key in WRT:
        part = table[table["wrt"] == key].set_index("quantity")
        p, unit = float(part["parameter"].iloc[0]), part["wrt_unit"].iloc[0]
        fd = richardson_central(lambda value: quantities(_run(FD + [f"{key}={value!r} {unit}"], peaks), rows), p,
                                H[key])
        # the coupler-force peak next to the stop amplifies the solution's error ~1e3-fold (its elasticities):
        # the value at rtol 1e-10 is ~1e-7..1e-6 from the rtol-1e-12 run's (measured 8e-7)
        assert_matches_finite_differences(part, ref0, fd, p, key, 1e-5, ELASTICITY_FLOOR, worst)
    print("chain: largest relative deviation from the finite differences:", {q: f"{e:.1e}" for q, e in worst.items()})


# -- the geometry: a design whose driving sprocket is not tuned (r1 = 2.5 cm, |QO_1| = R = 5 cm, L = 3 cm), so its
# centre and radius move freely while sprockets 2 and 3 keep their exact dwells and stops; the stops bounce (e = 0.5),
# and the dwell's constraint absorbs the rebound (transitions.py: a second, plastic projection), so the jump map is
# the plastic one and the events table has a 'rebound absorbed' row after each stop
GEOMETRY = ['mechanism.sprocket_radii=["2.5 cm", "3 cm", "3 cm"]', "mechanism.restitution=0.5"]
WRT_GEOMETRY = ["mechanism.sprocket_radii[0]", "mechanism.sprockets[0][0]", "mechanism.sprocket_inertias[1]"]
#: steps a tenth of the change that carries a stop or another output row onto a peak's row (the table's
#: warnings: 0.011 % of the radius for the crank-speed peak, 0.53 % of the centre's x, none for the inertia)
H_GEOMETRY = {"mechanism.sprocket_radii[0]": 1e-5, "mechanism.sprockets[0][0]": 5e-4,
              "mechanism.sprocket_inertias[1]": 1e-3}


def test_chain_geometry_matches_finite_differences():
    """The path pieces' geometry traced through every transition (docs/sensitivity.md "Geometry of the chain and
    the rolling pair"), and the impacts with restitution. A closed form besides: at a constant drive torque T the
    energy from the end of sprocket 2's dwell to that of sprocket 3's is E = T (l23 + r3 w3) / r1 (the chain travel
    between the ends of their arcs over the driving radius); r1 turns the line 3->1 by dg = -dr1 / l31 (its angle
    g = asin((r3 - r1) / Z31), docs/theory.md §K1.1) and with it the end of arc 3, so
    dE/dr1 = -E/r1 - T r3 / (r1 l31)."""
    base = SETS + GEOMETRY
    scenario = mechsim.load(NAME, set=base + ["solver.rtol=1e-10", "solver.atol=1e-12"])
    table = sensitivity(scenario, WRT_GEOMETRY)
    peaks = [q for q in dict.fromkeys(table["quantity"]) if q in PEAKS]
    nominal = _run(base + FD[len(SETS):], peaks)
    assert (nominal.events["kind"] == "rebound absorbed").sum() >= 2
    df = nominal.timeseries
    rows = {q: int(np.nanargmax(np.abs(df[PEAKS[q]].to_numpy(float)))) for q in peaks}
    ref0 = quantities(nominal, rows)
    si = scenario.si
    worst = {}
    for key in WRT_GEOMETRY:
        part = table[table["wrt"] == key].set_index("quantity")
        p, unit = float(part["parameter"].iloc[0]), part["wrt_unit"].iloc[0]

        def moved(value):
            return quantities(_run(base + FD[len(SETS):] + [value_setting(si, key, value, unit)], peaks), rows)
        fd = richardson_central(moved, p, H_GEOMETRY[key])
        assert_matches_finite_differences(part, ref0, fd, p, key, 1e-5, ELASTICITY_FLOOR, worst)
    print("chain geometry: largest relative deviation from the finite differences:",
          {q: f"{e:.1e}" for q, e in worst.items()})
    m = si["mechanism"]
    (x3, y3), (x1, y1), r3 = m["sprockets"][2], m["sprockets"][0], m["sprocket_radii"][2]
    torque, r1 = si["drive"]["torque"], m["sprocket_radii"][0]
    l31 = float(np.sqrt((x1 - x3) ** 2 + (y1 - y3) ** 2 - (r3 - r1) ** 2))
    got = table[(table["wrt"] == "mechanism.sprocket_radii[0]") & (table["quantity"] == "energy_per_cycle_J")]
    energy = float(got["value"].iloc[0])
    # the run's rtol 1e-10 on the event times: the closed form holds to ~1e-9
    assert float(got["derivative"].iloc[0]) == pytest.approx(-energy / r1 - torque * r3 / (r1 * l31), rel=1e-7)


# -- a detuned design (coupler 2 mm longer than tuned: no exact dwell, no stop): nothing is tuned, so the crank,
# the coupler, the detuning and every sprocket move freely; a line -> arc -> line passage in 4.5 s
DETUNED = "chain-mech2-detuned"
DETUNED_SETS = ["duration=4.5 s", 'mechanism.detuning="2 mm"']
WRT_DETUNED = ["mechanism.crank_radius", "mechanism.coupler_length", "mechanism.detuning", "mechanism.sprockets[1][1]"]
#: a tenth of the change that lets another row take over a peak (the table's warnings: 0.12 % of sprocket 2's y)
H_DETUNED = {"mechanism.crank_radius": 5e-4, "mechanism.coupler_length": 5e-4, "mechanism.detuning": 5e-4,
             "mechanism.sprockets[1][1]": 1e-4}


def test_detuned_chain_geometry_matches_finite_differences():
    """Crank, coupler, detuning and a sprocket's position against finite differences; the coupler's length and the
    detuning enter only as their sum L + delta (ChainDwellParams.detuned), so their derivatives are equal."""
    scenario = mechsim.load(DETUNED, set=DETUNED_SETS)
    table = sensitivity(scenario, WRT_DETUNED)
    fd_sets = DETUNED_SETS + ["solver.rtol=1e-12", "solver.atol=1e-14"]
    worst = peaks_match_finite_differences(DETUNED, table, WRT_DETUNED, fd_sets, H_DETUNED, scenario.si, 1e-5,
                                           ELASTICITY_FLOOR)
    peaks = [q for q in dict.fromkeys(table["quantity"]) if q in PEAKS]
    print("detuned chain geometry: largest relative deviation from the finite differences:",
          {q: f"{e:.1e}" for q, e in worst.items()})
    by = table.set_index(["quantity", "wrt"])["derivative"]
    for q in peaks:
        assert by[q, "mechanism.detuning"] == pytest.approx(by[q, "mechanism.coupler_length"], rel=1e-12, abs=1e-300)
