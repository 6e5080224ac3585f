"""A cycle-averaged run with output rows a turn or more apart (docs/thermal.md, "Cycle averaging").

Cycle averaging compares the window's crank turns on its rows; rows more than a sixteenth of a nominal turn apart
are computed at the least integer fraction of the output step that brings them within it, and the table keeps the
output step's rows (scenarios/runner.py `rows_every`). Before, an hour of geneva-seed-lc1-mu015 at 7 s or 100 s
rows, and 300 s of internal-geneva-motor at 1 s or 7 s rows, stopped on an internal error (an empty turn of rows);
at 1 s and 0.41 s rows the turns were said not to repeat and the whole run was resolved (73 s for the hour).

The DAE's later turns repeat the window's periodic turn on a rising bulk, so its largest contact temperature is
the last exit's; its samples between rows over that turn (scenarios/thermal_peaks.py `ThermalReader.cycle_finest`)
find it at any step: at 0.05 s rows it was another turn's, 35.1367 C at t = 286.3 s, 0.07 K low.
"""
from __future__ import annotations

import numpy as np
import pytest

import mechsim
from mechsim.thermal.cycle import output_times

#: the located contact temperature at any step against the finest: the same instant of the continuous solution,
#: read to the located peaks' accuracy (measured: 1.6e-10 relative, the DAE; 1e-12, the closed form)
SAME = 1e-8
#: a derivative against central differences (step 1e-3 relative: those at 1e-3 and 3e-3 agree to 1e-9)
DERIVATIVE_REL = 2e-5


def _run(name: str, duration: str, step: str):
    return mechsim.run(mechsim.load(name, set=["output.plots=false", f"duration={duration}", f"output_step={step}"]))


def _contact_max(result) -> dict:
    return result.summary["peaks"]["temp_contact_C"]["max"]


def _check_rows(result, duration: float, step: float) -> None:
    """Cycle averaging kept (no fall-back), and the table's rows exactly the output grid."""
    assert result.summary["thermal"]["averaging"] == "cycle"
    assert not [w for w in result.summary["warnings"] if "fell back" in w]
    t = result.timeseries["t_s"].to_numpy(float)
    assert np.array_equal(t, output_times(duration, step))
    assert result.summary["solver"]["output_rows"] == len(t)


@pytest.fixture(scope="module")
def fine_hour():
    """The hour's located contact temperature at 0.1 s rows, the reference of every coarser step."""
    return _contact_max(_run("geneva-seed-lc1-mu015", "1 h", "0.1 s"))


@pytest.mark.parametrize("step, seconds", [("7 s", 7.0), ("100 s", 100.0)])
def test_an_hour_of_the_seed_at_rows_minutes_apart(fine_hour, step, seconds):
    fine = fine_hour
    coarse = _run("geneva-seed-lc1-mu015", "1 h", step)
    _check_rows(coarse, 3600.0, seconds)
    got = _contact_max(coarse)
    assert got["value"] == pytest.approx(fine["value"], rel=SAME)
    assert got["t_s"] == pytest.approx(fine["t_s"], abs=1e-6)


def test_a_motor_driven_geneva_at_any_step():
    """The DAE: 300 s of internal-geneva-motor, its bulk still rising; the last exit's contact temperature at
    0.05 s, 1 s and 7 s rows as at 5 ms."""
    fine = _contact_max(_run("internal-geneva-motor", "300 s", "5 ms"))
    assert fine["t_s"] > 299.0
    for step, seconds in (("0.05 s", 0.05), ("1 s", 1.0), ("7 s", 7.0)):
        coarse = _run("internal-geneva-motor", "300 s", step)
        _check_rows(coarse, 300.0, seconds)
        got = _contact_max(coarse)
        assert got["value"] == pytest.approx(fine["value"], rel=SAME), step
        assert got["t_s"] == pytest.approx(fine["t_s"], abs=1e-6), step


def test_the_last_exit_among_hundreds_whose_limits_are_guessed_from_rows():
    """The one-sided limits beside the rows' guesses (dynamics/extrema.py `end_limits`): with friction 0.15015 at
    0.05 s rows the eight best guesses were limits after earlier entries (read about 28 C, guessed above 35.2 C from
    rows 0.05 s apart) and the last exit's, the largest, was not read: 35.18399 C at t = 292.0 s was reported
    against 35.22494 C at 299.32 s. A pass whose limits are no repeat of the best now reads the next guesses, twice
    as many each pass, while they may beat it. The two runs' cycle averagings differ by 2.5e-8 of the value."""
    sets = ["contact.friction=0.15015"]
    fine = _contact_max(mechsim.run(mechsim.load("internal-geneva-motor", set=[
        "output.plots=false", "duration=300 s", "output_step=5 ms", *sets])))
    got = _contact_max(mechsim.run(mechsim.load("internal-geneva-motor", set=[
        "output.plots=false", "duration=300 s", "output_step=0.05 s", *sets])))
    assert fine["t_s"] > 299.0
    assert got["value"] == pytest.approx(fine["value"], rel=1e-7)
    assert got["t_s"] == pytest.approx(fine["t_s"], abs=1e-5)


def test_the_hours_contact_temperature_derivative_at_rows_minutes_apart():
    """`mechsim sensitivity` of the hour at 7 s rows against central differences of the run's located peak: a
    closed form's cycle bulk is traced on its input linear between the window's rows, so the window is traced on
    rows 1/720 of a turn apart whatever the output step (scenarios/studies/sensitivity.py CLOSED_CYCLE_ROWS).
    Before: 193.857 against 193.936 (4e-4; 2e-4 at 0.1 s rows). Measured now 3.5e-6 (1.1e-6 at the scenario's own
    1 ms): DERIVATIVE_REL leaves a factor of 6."""
    from conftest import located_peak, run_locating
    from mechsim.scenarios.studies.sensitivity import sensitivity
    sets = ["duration=1 h", "output_step=7 s"]
    table = sensitivity(mechsim.load("geneva-seed-lc1-mu015", set=sets), ["contact.friction"],
                        ["peak_temp_contact_C"]).set_index("quantity").loc["peak_temp_contact_C"]
    ends = [located_peak(run_locating(mechsim.load("geneva-seed-lc1-mu015", set=[*sets, f"contact.friction={f!r}"]),
                                      ["temp_contact_C"]), "temp_contact_C")
            for f in (0.15 * (1 - 1e-3), 0.15 * (1 + 1e-3))]
    fd = (ends[1] - ends[0]) / (2 * 0.15e-3)
    assert table["derivative"] == pytest.approx(fd, rel=DERIVATIVE_REL)
