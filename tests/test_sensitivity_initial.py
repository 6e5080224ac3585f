"""Design sensitivities in the drive's initial angle and in the rolling pair's mass properties, against central finite
differences of the IDA path, Richardson-extrapolated (the method of tests/test_sensitivity.py, docs/sensitivity.md
'How it is checked').

The initial angle moves the start (scenarios/studies/sensitivity_map.py `initial_angle_seed`): on the Geneva from a
dwell (geneva-motor at -180 deg: the wheel stays locked, only the crank moves) and from inside an engagement (-20 deg:
the wheel starts at beta(alpha) with speed G(alpha) w, both moving with the angle), on the rolling pair
(rolling-a-torque, the rolling angle phi: the crank and coupler follow by the assembly's implicit-function rule). Steps:
absolute, in
radians (a start at 0 rad has no relative step), a tenth of the change at which another output row takes over a peak
(the tables' warnings, below); at rtol 1e-12 the differences' noise is ~ rtol / h <= 1e-7 relative, and Richardson's
truncation ~ h^4 is far below. Each derivative must agree to 1e-4 relative, or to 1e-6 of the quantity per radian
(per unit of the value) where it is zero (a time shift: the index time of a start in a dwell at the speed the drive
holds there).
"""
from __future__ import annotations

import numpy as np
import pytest

import mechsim
from conftest import located_peak, run_locating
from mechsim.scenarios.studies.sensitivity import PEAKS, sensitivity

FD_SOLVER = ["solver.rtol=1e-12", "solver.atol=1e-14"]
SENS_SOLVER = ["solver.rtol=1e-10", "solver.atol=1e-12"]
FLOOR = 1e-6


def _richardson_absolute(evaluate, p: float, h: float) -> dict:
    """d(quantity)/dp by central differences with absolute steps h and h/2, Richardson-extrapolated (O(h^4))."""
    diffs = {}
    for step in (h, h / 2):
        plus, minus = evaluate(p + step), evaluate(p - step)
        diffs[step] = {q: (plus[q] - minus[q]) / (2 * step) for q in plus}
    return {q: (4 * diffs[h / 2][q] - diffs[h][q]) / 3 for q in diffs[h]}


def _read(name: str, sets: list[str], rows: dict, index: bool, r=None) -> dict:
    """The peaks at the nominal rows and, where asked, the last index time (entry to exit) of an IDA run (given, or
    run here locating only those peaks: `run_locating`)."""
    r = r if r is not None else run_locating(mechsim.load(name, set=sets), [PEAKS[q] for q in rows])
    assert r.failure is None, r.failure.message()
    out = {q: located_peak(r, PEAKS[q]) for q in rows}
    if index:
        ev = r.events
        entries = ev.loc[ev["kind"] == "entry", "t_s"].to_numpy(float)
        exits = ev.loc[ev["kind"] == "exit", "t_s"].to_numpy(float)
        out["index_time_s"] = exits[-1] - entries[entries < exits[-1]][-1]
    return out


def _check(table, name: str, sets: list[str], steps: dict, setting, index: bool = False) -> dict:
    """Every (quantity, value) of the table against the finite differences; the largest relative deviations."""
    nominal = run_locating(mechsim.load(name, set=sets + FD_SOLVER),
                           [c for q, c in PEAKS.items() if q in set(table["quantity"])])
    df = nominal.timeseries
    rows = {q: int(np.nanargmax(np.abs(df[PEAKS[q]].to_numpy(float)))) for q in set(table["quantity"]) if q in PEAKS}
    ref0 = _read(name, sets + FD_SOLVER, rows, index, nominal)
    worst = {}
    for key, h in steps.items():
        part = table[table["wrt"] == key].set_index("quantity")
        p = float(part["parameter"].iloc[0])
        fd = _richardson_absolute(lambda value: _read(name, sets + FD_SOLVER + [setting(key, value)], rows, index),
                                  p, h)
        for q in ref0:
            assert part.loc[q, "value"] == pytest.approx(ref0[q], rel=1e-7)
            d = part.loc[q, "derivative"]
            assert abs(d - fd[q]) <= 1e-4 * abs(fd[q]) + FLOOR * abs(ref0[q]), (q, key, d, fd[q])
            if abs(fd[q]) > 100 * FLOOR * abs(ref0[q]):
                worst[(q, key)] = f"{abs(d - fd[q]) / abs(fd[q]):.1e}"
    return worst


def _angle(key, value):
    return f"{key}={value!r} rad"


GENEVA = {
    # from a dwell: one entry and exit in 0.8 s; the peaks' rows give way to a neighbour at 0.0077 % of pi
    # (2.4e-4 rad, the wheel speed's). The wheel acceleration's peak (139 rad/s^2) barely moves with the start
    # (2.7e-6 per rad, below the 1.4e-4 floor), and its located value carries the run's own error, about 1e-11 of
    # it at rtol 1e-12, a different sample for each start and backend (the compiled and Python residuals differ in
    # the last bit on a few rows, so IDA's steps part after the entry): Richardson's difference turns that into
    # about 3 x 1.5e-9 / h, 2e-4 at h = 2e-5 rad, at the floor on either backend; h = 1e-4 rad puts it at 4e-5
    "dwell": (["duration=0.8 s"], 1e-4, True),
    # from inside the engagement (alpha = -20 deg, entered at -45 deg): to the exit and on into the dwell
    "engaged": (["duration=0.4 s", "initial.crank_angle=-20 deg"], 2e-5, False),
}


@pytest.mark.parametrize("start, backend", [("dwell", None), ("engaged", None), ("dwell", "ida-compiled")])
def test_geneva_initial_angle_matches_finite_differences(start, backend):
    # the suite's fresh cache runs the default on `ida`; the compiled callbacks (what the default runs once they are
    # cached) are differenced explicitly, their located peaks read on the compiled callbacks too
    sets, h, index = GENEVA[start]
    sets = sets + ([f'solver.backend="{backend}"'] if backend else [])
    key = "initial.crank_angle"
    table = sensitivity(mechsim.load("geneva-motor", set=sets + SENS_SOLVER), [key])
    if index:
        assert "index_time_s" in set(table["quantity"])
    worst = _check(table[table["quantity"].isin(list(PEAKS) + ["index_time_s"])], "geneva-motor", sets, {key: h},
                   _angle, index)
    print(f"geneva-motor from {start} ({backend or 'default'}): relative deviation from the finite differences:",
          worst)


def test_geneva_start_at_a_mode_boundary_is_refused():
    # 45.2 deg before mid-engagement: the entry (alpha = -45 deg) lies within 1 % of the angle
    with pytest.raises(mechsim.ScenarioError, match=r"^initial.crank_angle: the start .* change of the initial mode"):
        sensitivity(mechsim.load("geneva-motor", set=["duration=0.05 s", "initial.crank_angle=-45.2 deg"]),
                    ["initial.crank_angle"])


#: the rolling pair with its centres of mass given (their uniform values: the run is rolling-a-torque's own), so that
#: they are traced; c4 = m_arm l4 / 2 / m4 for the 0.1 kg arm of 1.6 m and the 0.5 kg disc
ROLLING = "rolling-a-torque"
ROLLING_SETS = ["duration=1.5 s", "mechanism.crank_com=1.5 m", "mechanism.coupler_com=1.75 m",
                f"mechanism.rolling_com={0.1 * 1.6 / 2 / 0.6!r} m"]
#: a tenth of the change that lets another output row take over a peak (the table's warnings: 1.4e-3 rad of phi0,
#: ...)
ROLLING_STEPS = {"initial.drive_angle": 1.4e-4, "mechanism.crank_com": 1e-4, "mechanism.coupler_com": 1e-4,
                 "mechanism.rolling_com": 1e-5, "mechanism.rolling_com_angle": 1e-4}


def test_rolling_pair_initial_angle_and_mass_properties_match_finite_differences():
    table = sensitivity(mechsim.load(ROLLING, set=ROLLING_SETS), list(ROLLING_STEPS))   # its own rtol 1e-10
    print(table.attrs["warnings"])

    def setting(key, value):
        unit = "rad" if "angle" in key else "m"
        return f"{key}={value!r} {unit}"
    worst = _check(table, ROLLING, ROLLING_SETS, ROLLING_STEPS, setting)
    print("rolling pair: relative deviation from the finite differences:", worst)


def test_start_angle_with_cycle_averaging_is_refused():
    # the periodic turn is measured from the start angle there, a dependence that is not differentiated
    sc = mechsim.load("geneva-seed-lc1-mu015", set=["duration=60 s", "drive.type=motor", "drive.stall_torque=40 N*m",
                                                    "drive.no_load_speed=8 rad/s", "thermal.averaging=cycle"])
    with pytest.raises(mechsim.ScenarioError, match=r"^initial.crank_angle: not traced on this design: with cycle"):
        sensitivity(sc, ["initial.crank_angle"])
