"""The thermal peaks of a closed-form run (a prescribed crank speed, no DAE) are located on the continuous solution
too (scenarios/thermal_peaks.py `ClosedFormThermalReader`, docs/thermal.md "Reported temperatures"): the closed form
between rows, the network's states integrated exactly in its modes from the row before the instant on quadrature
pieces fixed by the cycle (not by the output step), and the heat input's switches that are no event (the slip
reversal, where the contact temperature's minimum lies) read as one-sided limits. So the peaks do not move with the
output step beyond the quadrature's own error, which is estimated here by doubling its nodes; the rows' peaks do."""
import numpy as np
import pytest

import mechsim
from mechsim.scenarios import runner
from mechsim.thermal.exact import ModalNetwork, integrate_closed_form
from conftest import assert_peaks_bracket_rows

COLUMNS = ("temp_contact_C", "temp_flash_rise_K", "temp_bulk_pin_C", "temp_bulk_wheel_C", "heat_rate_W")
STEPS = (0.25, 1, 4)


def _scenario(step, *extra):
    return mechsim.load("geneva-lc1", set=["duration=1 s", f"output_step={step} ms", *extra])


@pytest.fixture(scope="module")
def runs():
    return {step: runner.run(_scenario(step)) for step in STEPS}


def quadrature_error(step, run) -> float:
    """The largest error of the network's temperatures on a run's rows (K), estimated as their change when the
    quadrature's nodes per piece are doubled (6 -> 12; the quadrature's error is of far higher order)."""
    plan = runner.plan(_scenario(step))
    th, mech = plan.thermal, plan.mechanism
    ext = th.setup.extension
    t = np.asarray(run.timeseries["t_s"], float)
    angle0 = plan.scenario.si["initial"][mech.initial_keys[0]]
    six, inputs, breaks = integrate_closed_form(ext, mech, angle0, th.speed, t, th.setup.initial,
                                                max_piece=th.quadrature_piece)
    twelve = ModalNetwork(ext.system, ext.loss).integrate(inputs, t, th.setup.initial, breaks, nodes=12,
                                                          max_piece=th.quadrature_piece)
    n = ext.system.size
    return float(np.max(np.abs(six[:, :n] - twelve[:, :n])))


def test_closed_form_thermal_peaks_do_not_move_with_the_output_step(runs):
    """0.25 / 1 / 4 ms: every thermal peak located, equal to the quadrature's error (round-off here: the pieces are
    the cycle's, at most 1.2 ms) plus the locating polynomial's own error at an interior peak (|F^(7)| d^7 for its
    grid step d = h/16: 1.6e-12 of the contact temperature measured at 4 ms; bound 1e-11), at one instant; the 4 ms
    rows miss the contact temperature's peak by far more than that."""
    error = max(quadrature_error(step, r) for step, r in runs.items())
    ref = runs[0.25].summary["peaks"]
    for col in COLUMNS:
        assert ref[col]["how"].startswith("located: the closed form"), col
        for step, r in runs.items():
            got = r.summary["peaks"][col]
            for side in ("max", "min"):
                bound = 4 * error + 1e-11 * max(1.0, abs(ref[col][side]["value"]))
                assert got[side]["value"] == pytest.approx(ref[col][side]["value"], rel=0, abs=bound), (col, side, step)
                assert got[side]["t_s"] == pytest.approx(ref[col][side]["t_s"], abs=1e-5), (col, side, step)
    assert ref["temp_contact_C"]["max"]["at"] == "interior"
    # the minimum of the contact temperature: the slip reversal, where the flash rise vanishes (a kink of the
    # heat input that no event marks) and the pin's share jumps: the lower one-sided limit there
    assert ref["temp_contact_C"]["min"]["at"].startswith("switch of the heat input")
    rows = np.nanmax(runs[4].timeseries["temp_contact_C"])
    assert ref["temp_contact_C"]["max"]["value"] - rows > 1e3 * (4 * error + 1e-11 * rows)


def test_closed_form_thermal_peaks_are_never_below_a_row(runs):
    assert_peaks_bracket_rows(runs, COLUMNS, 1e-12)


def test_flash_model_peaks_are_located_at_a_prescribed_speed():
    """The flash model (no network: the contact temperature is the ambient plus the flash rise, algebraic in the
    closed form): the same maxima at 1 and 4 ms to round-off, its minimum the slip reversal's ambient. The minimum is
    the one-sided limit at the reversal: the flash rise of a slip of round-off, which grows like its square root
    (6.5e-10 K here); the reversal's instant is bisected to 1e-13 of t in brackets the rows make (at 4 ms, 1.2
    degrees apart, searched on instants 0.5 degree apart: `thermal.exact._switch_grid`), so that value moves by
    3e-11 K between the steps: both are the ambient to 1e-9 K."""
    one, four = (runner.run(_scenario(step, "thermal.model=flash")).summary["peaks"] for step in (1, 4))
    for col in ("temp_contact_C", "temp_flash_rise_K"):
        assert four[col]["max"]["value"] == pytest.approx(one[col]["max"]["value"], rel=1e-12, abs=1e-12)
        assert four[col]["min"]["value"] == pytest.approx(one[col]["min"]["value"], rel=0, abs=1e-9)
    assert one["temp_contact_C"]["min"]["value"] == pytest.approx(20.0, abs=1e-9)
    assert one["temp_flash_rise_K"]["min"]["value"] == pytest.approx(0.0, abs=1e-9)


def test_cycle_averaged_closed_form_peaks_do_not_move_with_the_output_step(runs):
    """Cycle averaging at a prescribed speed: after the window the thermal columns are the closed form at the
    instant with the cycle-averaged bulk there (its ripple integrated on pieces fixed by the turn, its start state
    read between rows): 1 and 4 ms give the same located peaks, to the bound above; the 4 ms rows do not."""
    got = {step: runner.run(_scenario(step, "duration=10 s", "thermal.averaging=cycle")) for step in (1, 4)}
    one, four = (got[s].summary["peaks"] for s in (1, 4))
    assert got[4].summary["thermal"]["averaging"] == "cycle"
    error = max(quadrature_error(step, r) for step, r in runs.items())       # the same pieces, the same quadrature
    for col in COLUMNS:
        assert "cycle-averaged solution" in four[col]["how"], col
        for side in ("max", "min"):
            bound = 4 * error + 1e-11 * max(1.0, abs(one[col][side]["value"]))
            assert four[col][side]["value"] == pytest.approx(one[col][side]["value"], rel=0, abs=bound), (col, side)
    peak = one["temp_contact_C"]["max"]
    assert peak["t_s"] > got[1].summary["thermal"]["cycle"]["mechanics_simulated_until_s"]      # after the window
    assert peak["value"] - np.nanmax(got[4].timeseries["temp_contact_C"]) > 1e-4


@pytest.mark.parametrize("name, extra", [("geneva-seed-lc1-mu015", ()), ("geneva-lc1", ("duration=1 s",)),
                                         ("internal-geneva-speed", ('thermal.model="lumped"',))])
def test_pointwise_readings_equal_the_readings_on_the_interval_rows(name, extra, monkeypatch):
    """A pointwise closed form (the Geneva's: `Mechanism.closed_form_pointwise`) is read between rows on the instants
    asked for alone, many readings in one evaluation; every located peak, mechanical and thermal, and every table is
    the same to the bit as reading each instant with its interval's rows around it (the general reader, which a
    closed form that follows the motion's history needs)."""
    from mechsim.mechanisms.geneva.model import Geneva
    sc = mechsim.load(name, set=[*extra, "output.plots=false"])
    fast = mechsim.run(sc)
    monkeypatch.setattr(Geneva, "closed_form_pointwise", False)
    general = mechsim.run(sc)
    assert fast.summary["peaks"] == general.summary["peaks"]
    assert fast.timeseries.equals(general.timeseries) and fast.events.equals(general.events)
    assert any("located" in entry.get("how", "") for entry in fast.summary["peaks"].values())


def test_a_bulk_temperature_peaking_as_a_contact_ends_is_found_at_coarse_rows():
    """geneva-seed-lc3-mu030: the pin's bulk temperature peaks as each contact ends (the heat input stops) and is
    largest at the last exit, 2.7209 s. The candidates between rows take the network's states interpolated between
    the rows and the heat input's switches (integrated exactly there): interpolated across the exit, 7.3 ms rows
    apart, the samples after it rose where the temperature falls, so the exit's limit was never read and 22.46925
    C, 1.3 ms after it, was reported. The maximum is the exit's limit at every step, 22.4699505223 C to 1e-10 of it."""
    got = {}
    for step in ("1 ms", "7.3 ms", "10 ms"):
        r = runner.run(mechsim.load("geneva-seed-lc3-mu030", set=[f"output_step={step}", "output.plots=false"]))
        got[step] = r.summary["peaks"]["temp_bulk_pin_C"]["max"]
        exit_t = float(r.events.loc[r.events["kind"] == "exit", "t_s"].max())
        assert got[step]["t_s"] == exit_t, step
    for step in ("7.3 ms", "10 ms"):
        assert got[step]["value"] == pytest.approx(got["1 ms"]["value"], rel=1e-10), step


def test_switches_between_rows_degrees_apart():
    """geneva-seed-lc3-mu015 (a closed form at 10.68 rad/s with the lumped network) at 1 s rows, ten degrees of
    crank a millisecond: the contact's switches were searched between the rows only, and a gap holding a whole
    engagement (entry, slip reversal, exit) shows the dwell at both ends. No switch was found: the located contact
    force was a polynomial across the slip reversal's jump (242.33 N against 241.148 N, the limit after it), and
    the network's heat input was integrated across the engagements' ends (the pin's bulk maximum 21.1595 C against
    21.2314 C). Searched on instants 0.5 degree apart, every peak equals the scenario's own 1 ms run's to 1e-9."""
    own, coarse = (mechsim.run(mechsim.load("geneva-seed-lc3-mu015", set=["output.plots=false", *sets])).summary
                   for sets in ([], ["output_step='1 s'"]))
    for col in ("contact_force_N", "temp_bulk_pin_C", "temp_contact_C", "temp_flash_rise_K"):
        for side in ("max", "min"):
            assert coarse["peaks"][col][side]["value"] == pytest.approx(own["peaks"][col][side]["value"], rel=1e-9,
                                                                         abs=1e-9), (col, side)
