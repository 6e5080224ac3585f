"""A compiled diffrax run's peaks are located on its own dense output (docs/theory.md §K5, step 2): the step
interpolants its output rows come from. Its steps do not depend on the output grid, so the located extremum is
one number whatever the output step, to the polynomial's error (1e-13 of the value at 4 ms) and round-off; it is
never below a row (a reading at a row's instant is the row), and it agrees with IDA's located peak to the two
integrations' tolerances."""
import numpy as np
import pytest

import mechsim
from mechsim.scenarios import runner
from mechsim.scenarios.peaks import HOW_DENSE

BASE = ["duration=1 s", 'load.wheel_torque="7.5 N*m"', "output.plots=false"]
DIFFRAX = ['solver.backend="diffrax"', "solver.rtol=1e-8", "solver.atol=1e-10"]


@pytest.fixture(scope="module")
def runs():
    out = {step: runner.run(mechsim.load("geneva-motor", set=BASE + DIFFRAX + [f"output_step={step} ms"]))
           for step in (1, 4)}
    out["ida"] = runner.run(mechsim.load("geneva-motor", set=BASE + ["solver.rtol=1e-10", "solver.atol=1e-12",
                                                                      "output_step=1 ms"]))
    return out


@pytest.mark.parametrize("column", ["contact_force_N", "wheel_accel_rad_s2", "drive_torque_N_m"])
def test_dense_peak_does_not_move_with_the_output_step(runs, column):
    fine, coarse = (runs[s].summary["peaks"][column] for s in (1, 4))
    assert fine["how"] == HOW_DENSE
    for side in ("max", "min"):
        a, b = fine[side], coarse[side]
        scale = max(abs(a["value"]), 1.0)
        # the same interpolants at both steps: equal to the polynomial's error and round-off amplified by it
        assert b["value"] == pytest.approx(a["value"], rel=1e-10, abs=1e-10 * scale), side
        # an interior extremum pins its instant to sqrt(2 e / |F''|): 1e-8 s for e ~ 1e-12 F and 10 ms
        assert b["t_s"] == pytest.approx(a["t_s"], abs=1e-7), side
    for step in (1, 4):                       # never beyond a row
        rows = runs[step].timeseries[column].to_numpy(float)
        peaks = runs[step].summary["peaks"][column]
        assert peaks["max"]["value"] >= np.nanmax(rows) - 1e-12 * abs(np.nanmax(rows))
        assert peaks["min"]["value"] <= np.nanmin(rows) + 1e-12 * abs(np.nanmin(rows))


def test_dense_peak_agrees_with_ida_to_the_tolerance(runs):
    """diffrax at rtol 1e-8 against IDA at 1e-10 (re-integrated readings): the contact force's peak to the diffrax
    run's global error, its rtol times a growth of ten over the engagement (1e-7; the 4 ms rows miss it by 2.6e-5),
    the instant to sqrt(2 x 1e-7) of the 10 ms time scale (5e-6 s)."""
    d = runs[1].summary["peaks"]["contact_force_N"]["max"]
    i = runs["ida"].summary["peaks"]["contact_force_N"]["max"]
    assert runs["ida"].summary["peaks"]["contact_force_N"]["how"] != HOW_DENSE
    assert d["value"] == pytest.approx(i["value"], rel=1e-7)
    assert d["t_s"] == pytest.approx(i["t_s"], abs=5e-6)
