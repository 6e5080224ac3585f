"""A refined extremum's value is the polynomial through the STENCIL readings around the best one of its bracket's
grid (`dynamics/extrema.py` `_refine`). That polynomial is trusted only where the one through the LOWER readings
nearest its instant agrees with it (AGREE of the column's largest magnitude); elsewhere the grid is coarse against
the peak and the bracket is narrowed to the grid's two steps around the best reading and read again
(`_narrowed`). Without that check a polynomial across a kink, or over grid steps wider than the peak, gave a
value the solution never takes (docs/theory.md §K5).
"""
import math

import pytest

import mechsim


def _run(name, sets):
    r = mechsim.run(mechsim.load(name, set=["output.plots=false", *sets]))
    assert r.success
    return r


def test_a_constant_stretch_ending_at_a_stop_is_not_overshot():
    """chain-mech2-kinematic: the crank turns with the chain round a sprocket at a constant speed up to each stop,
    where it halts (0.75 rad/s on every row of the stretch, at any step). At its own 10 ms rows the
    polynomial through readings on both sides of the stretch's start reported 0.767605 rad/s, 2.3 % above
    anything the crank reaches; the check narrows it to the stretch's value."""
    own = _run("chain-mech2-kinematic", [])
    fine = _run("chain-mech2-kinematic", ["output_step=1 ms"]).timeseries["crank_speed_rad_s"].to_numpy()
    got = own.summary["peaks"]["crank_speed_rad_s"]["max"]["value"]
    assert got <= fine.max() + 1e-9 * abs(fine.max())
    assert got == pytest.approx(fine.max(), rel=1e-9)


def test_a_contact_temperature_between_rows_a_sixth_of_a_turn_apart():
    """geneva-seed-lc1-mu015 over an hour, cycle-averaged, at 0.1 s rows (31 degrees of crank apart): an
    engagement's bracket spans its whole interval between events, 33 readings 4.9 ms apart, and the polynomial
    around the best of them gave 48.79879 C, above the hour's largest contact temperature (48.790527 C, in the
    last turn: the bulk rises to the end). The check narrows the bracket to a temperature the contact reaches; and
    the cycle-averaged run is now sampled 0.5 degree apart next to its ends (`ClosedFormThermalReader.cycle_finest`),
    where its largest and least values lie, so the last turn's peak is found, not another turn's 2.2 mK lower."""
    fine = _run("geneva-seed-lc1-mu015", ["duration=3600 s", "output_step=5 ms"]).summary["peaks"]
    coarse = _run("geneva-seed-lc1-mu015", ["duration=3600 s", "output_step=0.1 s"]).summary["peaks"]
    top = fine["temp_contact_C"]["max"]
    assert top["value"] == pytest.approx(48.790527, abs=1e-6)
    assert top["t_s"] > 3600.0 - 2 * math.pi / 5.34
    got = coarse["temp_contact_C"]["max"]
    assert got["value"] == pytest.approx(top["value"], rel=1e-9)
    assert got["t_s"] == pytest.approx(top["t_s"], abs=1e-6)
