"""The thermal columns' peaks are located on the continuous solution (scenarios/thermal_peaks.py, docs/thermal.md
"Reported temperatures"): independent of the output step to the integration's tolerance, never below an output row,
and their design derivatives are the located extremum's (dT*/dp = dT/dp at t*), checked against central differences
of the located peak."""
import numpy as np
import pytest

import mechsim
from mechsim.scenarios import runner
from conftest import assert_peaks_bracket_rows

#: the seed's load case 1 with a motor (its speed follows from the dynamics: a DAE run with the bulk states in it)
MOTOR = ["duration=1.5 s", "drive.type=motor", "drive.stall_torque=40 N*m", "drive.no_load_speed=8 rad/s",
         "solver.rtol=1e-10", "solver.atol=1e-12"]
COLUMNS = ("temp_contact_C", "temp_flash_rise_K", "temp_bulk_pin_C", "heat_rate_W")


@pytest.fixture(scope="module")
def runs():
    return {step: runner.run(mechsim.load("geneva-seed-lc1-mu015", set=MOTOR + [f"output_step={step} ms"]))
            for step in (0.25, 1, 4)}


def test_thermal_peaks_do_not_move_with_the_output_step(runs):
    """The rows' peak contact temperature moves by 1e-3 K from 0.25 to 4 ms; the located one is one number to the
    run's tolerance (rtol 1e-10 on the bulk states and the mechanics: 1e-8 relative leaves a hundredfold margin),
    at one instant (an interior maximum pins its instant down to sqrt(tolerance) of the time scale only)."""
    ref = runs[0.25].summary["peaks"]
    for col in COLUMNS:
        assert ref[col]["how"].startswith("located"), col
        for step, r in runs.items():
            got = r.summary["peaks"][col]
            for side in ("max", "min"):
                assert got[side]["value"] == pytest.approx(ref[col][side]["value"], rel=1e-8), (col, side, step)
                assert got[side]["t_s"] == pytest.approx(ref[col][side]["t_s"], abs=1e-5), (col, side, step)
    assert ref["temp_contact_C"]["max"]["at"] == "interior"
    coarse = np.nanmax(runs[4].timeseries["temp_contact_C"])
    assert ref["temp_contact_C"]["max"]["value"] - coarse > 1e-4       # what the 4 ms rows miss


def test_thermal_peaks_are_never_below_a_row(runs):
    assert_peaks_bracket_rows(runs, COLUMNS, 1e-9)
