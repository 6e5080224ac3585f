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


def test_a_thermal_readers_requests_are_read_in_one_pass_as_each_alone(monkeypatch):
    """The thermal reader's readings of many requests (scenarios/thermal_peaks.py `ThermalReader._columns_many`) take
    the mechanics' window readings of all of them in one pass of the run's reader (one read-out per mode, not one per
    reading), and every column of every request is the same to the last bit as that request read alone."""
    from mechsim.dynamics.trajectory_reader import TrajectoryReader
    from mechsim.scenarios import thermal_peaks
    readers = []
    locate = thermal_peaks.locate_thermal
    monkeypatch.setattr(thermal_peaks, "locate_thermal", lambda reader, *a, **k: (readers.append(reader),
                                                                                  locate(reader, *a, **k))[1])
    runner.run(mechsim.load("geneva-motor", set=["duration=1.2 s", 'thermal.model="lumped"', "contact.friction=0.15",
                                                 'solver.backend="diffrax"', "output.plots=false"]))
    reader = readers[0]
    assert isinstance(reader, thermal_peaks.ThermalReader)
    requests = [(iv, 0, np.linspace(iv.lo, iv.hi, 7)) for iv in reader.windows if len(iv.rows) > 1]
    assert len(requests) >= 4
    passes = []
    read_many = TrajectoryReader.read_many
    monkeypatch.setattr(TrajectoryReader, "read_many", lambda self, asks: (passes.append(len(asks)),
                                                                           read_many(self, asks))[1])
    together = reader._columns_many(requests)
    assert passes == [len(requests)]                  # one pass: a window reading per request, all at once
    for request, got in zip(requests, together):
        alone = reader._columns(*request)
        frame, states, since = got
        assert list(frame) == list(alone[0])
        for c in frame:
            assert np.array_equal(np.asarray(frame[c]), np.asarray(alone[0][c])), c
        assert np.array_equal(states, alone[1]) and np.array_equal(since, alone[2])


def test_kinks_apart_from_the_events_are_those_farther_than_near_from_every_one():
    """`apart` finds each kink's nearest event by bisection: the kinks kept are exactly those whose distance to every
    event exceeds `near` (events unordered, repeated, a kink on an event, before the first and after the last)."""
    from mechsim.dynamics.extrema import apart
    rng = np.random.default_rng(3)
    for _ in range(200):
        known = rng.uniform(0.0, 10.0, int(rng.integers(0, 30)))
        if len(known) > 2:
            known[1] = known[0]
        at = rng.uniform(-1.0, 11.0, int(rng.integers(0, 40)))
        if len(known) and len(at):
            at[0] = known[-1]
        kinks = [(float(x), f"k{n}") for n, x in enumerate(at)]
        near = float(rng.choice([0.0, 1e-9, 0.05, 0.5]))
        brute = [k for k in kinks if not len(known) or np.min(np.abs(known - k[0])) > near]
        assert apart(kinks, known, near) == brute


def test_time_since_contact_start_from_before_a_start_is_the_earlier_contacts():
    """The limit from before an instant where a contact starts (a flank switch: the pin crosses to the other flank)
    belongs to the contact before it: its time since contact runs on from the earlier start; at or after the start
    it is the new contact's, zero at the start itself (thermal/plan.py `_time_since`)."""
    from mechsim.thermal.plan import ThermalPlan
    starts = np.array([0.1, 0.3])
    t = np.array([0.05, 0.3, 0.3, 0.35, 0.3])
    before = np.array([False, True, False, False, True])
    since = ThermalPlan._time_since(t, starts, before)
    np.testing.assert_allclose(since, [np.inf, 0.2, 0.0, 0.05, 0.2], rtol=1e-15, atol=1e-15)
    np.testing.assert_array_equal(ThermalPlan._time_since(t, starts), [np.inf, 0.0, 0.0, since[3], 0.0])
