"""Located peaks of short stiff episodes (docs/theory.md §K5): the Geneva with clearance and the compliant
(Hunt-Crossley) contact at a prescribed crank speed, whose contact episodes last about 80 us, far shorter than the
output step. The summary's located peaks read every smooth interval between events, rows or none, forward in time
from the state the run holds before it (backward, the damped stiff contact is unstable), so that they are the
episodes' own (their force peaks are events: `impacts.csv`) and do not move with the output step."""
from __future__ import annotations

import numpy as np
import pytest

import mechsim.scenarios.api as api
from mechsim.scenarios import runner

SCENARIO = "geneva-clearance"


def run(speed: str, duration: str, step: str):
    sets = ["contact.model=compliant", "drive.type=speed", f"drive.speed={speed}", f"duration={duration}",
            f"output_step={step}", "output.plots=false"]
    return api.run(api.load(SCENARIO, set=sets))


@pytest.fixture(scope="module")
def plan():
    return runner.plan(api.load(SCENARIO, set=["contact.model=compliant", "drive.type=speed", "drive.speed=8 rad/s"]))


def _rtol(plan) -> float:
    return float(plan.settings.rtol)


def test_an_episode_shorter_than_the_output_step_has_its_peak_located(plan, capfd):
    """8 rad/s, the first entry's bounces (each about 80 us) at 1 ms rows: no row falls inside the largest episode,
    yet the located maximum force is that episode's peak (the `contact force peak` event, located as dF/dt = 0) to
    the reading's tolerance, and equal to a run at 20 us rows to the runs' tolerance (each run's error is of order
    rtol in the force; 100 rtol bounds their difference)."""
    rtol = _rtol(plan)
    coarse, fine = run("8 rad/s", "0.305 s", "1 ms"), run("8 rad/s", "0.305 s", "0.02 ms")
    assert coarse.failure is None and fine.failure is None
    episodes = coarse.extra_tables["impacts"]
    longest = float(np.nanmax(episodes["duration_s"].to_numpy(float)))
    assert longest < 1e-3                                  # every episode is shorter than the output step
    peak_event = float(np.nanmax(episodes["peak_force_N"].to_numpy(float)))
    got = coarse.summary["peaks"]["contact_force_N"]["max"]
    assert got["value"] == pytest.approx(peak_event, rel=10 * rtol)
    assert got["t_s"] == pytest.approx(float(episodes["peak_force_at_t_s"].to_numpy(float)[
        np.nanargmax(episodes["peak_force_N"].to_numpy(float))]), abs=1e-9)
    assert got["value"] == pytest.approx(fine.summary["peaks"]["contact_force_N"]["max"]["value"], rel=100 * rtol)
    # the deepest penetration, between the force peak and the separation, likewise
    assert coarse.summary["peaks"]["gap_m"]["min"]["value"] == pytest.approx(
        fine.summary["peaks"]["gap_m"]["min"]["value"], rel=100 * rtol)
    assert "IDA" not in capfd.readouterr().err


def test_readings_in_a_stiff_contact_run_forward(plan, capfd):
    """2 rad/s at 20 ms rows: the entry's bounces and the long contact after them. Read backward from a row after
    the instant, the damped contact diverged (a penetration of hundreds of um, a force peak of tens of N); read
    forward, the located peaks are the 1 ms run's to the runs' tolerance, the maximum force is the largest episode's
    peak, and the deepest penetration is within its physical bound: at the penetration's maximum delta' = 0, so
    F = K delta there (Hunt-Crossley), below the episode's peak force: delta <= F_peak / K."""
    rtol = _rtol(plan)
    coarse, rows = run("2 rad/s", "1.3 s", "20 ms"), run("2 rad/s", "1.3 s", "1 ms")
    assert coarse.failure is None and rows.failure is None
    peak_event = float(np.nanmax(coarse.extra_tables["impacts"]["peak_force_N"].to_numpy(float)))
    force, gap = coarse.summary["peaks"]["contact_force_N"]["max"], coarse.summary["peaks"]["gap_m"]["min"]
    assert force["value"] == pytest.approx(peak_event, rel=10 * rtol)
    stiffness = plan.mechanism.stiffness
    assert -peak_event / stiffness <= gap["value"] < 0
    for column, side in (("contact_force_N", "max"), ("gap_m", "min")):
        assert coarse.summary["peaks"][column][side]["value"] == pytest.approx(
            rows.summary["peaks"][column][side]["value"], rel=100 * rtol)
    assert "IDA" not in capfd.readouterr().err
