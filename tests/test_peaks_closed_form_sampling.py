"""A closed-form run's columns are sampled between its rows at a fixed drive-angle step before their candidates are
ranked (`extrema.with_rowless(finest=)`, `peaks._finest`): a peak narrower than the output step is then among the
candidates at any output step (docs/theory.md §K5).

- rolling-a-speed, the coupler force's minimum: a V-shaped dip to 0.158401 N at t = 7.3477 s, a few degrees of
  crank wide. At 23 ms rows (2.3x the scenario's step) none of the rows near it was a row minimum below another
  turn's, and 0.2170 N (the dip of another turn, 37 % higher) was reported.

The closed form is exact to round-off; what differs between steps is the refinement: the polynomial through seven
readings about 0.14 ms apart (a 4.6 ms bracket between samples, 32 intervals) across a dip whose own time scale is
depth / slope = 0.158 N / 28 N/s = 5.6 ms errs by about (0.4 / 5.6)^7 of the depth, 1e-9 of the value (measured:
1.4e-10 N between 10 and 23 ms rows); 1e-8 is the margin, far below the 37 % this closes.
"""
import functools

import numpy as np
import pytest

import mechsim
from mechsim.dynamics.extrema import Interval, between, finish_all, plans, with_rowless


def _coupler_min(step):
    r = mechsim.run(mechsim.load("rolling-a-speed", set=["output.plots=false", f'output_step="{step}"']))
    return r.summary["peaks"]["coupler_force_N"]["min"], r.timeseries


@pytest.mark.parametrize("step", ["23 ms", "2 ms"])
def test_a_dip_narrower_than_the_rows_is_the_minimum_at_any_step(step):
    own, _ = _coupler_min("10 ms")
    other, table = _coupler_min(step)
    assert own["at"] == other["at"] == "interior"
    assert other["value"] == pytest.approx(own["value"], rel=1e-8)
    assert other["t_s"] == pytest.approx(own["t_s"], abs=1e-7)
    # what the rows alone show, beside it: the best row of the run, above the located minimum
    rows = table["coupler_force_N"].to_numpy(float)
    assert other["best_row_value"] == rows.min() > other["value"]
    if step == "23 ms":
        assert rows.min() > 1.5 * other["value"]               # the rows miss the dip by half its depth


def test_between_fills_every_gap_wider_than_the_step_evenly():
    knots = np.array([0.0, 0.05, 0.3, 0.31, 1.0])
    got = between(knots, 0.1)
    merged = np.sort(np.r_[knots, got])
    assert np.diff(merged).max() <= 0.1 + 1e-15
    # the fewest that do it: ceil(gap / 0.1) - 1 in each gap, evenly spaced
    assert len(got) == sum(int(np.ceil(g / 0.1)) - 1 for g in np.diff(knots))
    inside = got[(got > 0.31) & (got < 1.0)]
    np.testing.assert_allclose(np.diff(np.r_[0.31, inside, 1.0]), 0.69 / 7, rtol=1e-12)
    assert len(between(knots, 10.0)) == 0


def test_a_narrow_dip_between_rows_is_located_from_the_sampled_candidates():
    """f = t - 0.9 exp(-((t - 0.537)/0.01)^2) on rows 0.1 apart: the rows rise monotonically (the dip adds under
    1e-5 at each), so their one candidate for the minimum is the start, f(0) = 0; sampled at 0.005, the dip's bottom
    (about -0.36) is the minimum, located to the refinement's accuracy (against scipy's bounded minimisation)."""
    from scipy.optimize import minimize_scalar

    def f(x):
        x = np.asarray(x, dtype=float)
        return x - 0.9 * np.exp(-((x - 0.537) / 0.01) ** 2)

    def read(interval, position, times):
        return {"f": f(times), "t_s": np.asarray(times, dtype=float)}
    t = np.arange(0.0, 1.0 + 1e-9, 0.1)
    iv = Interval(0.0, 1.0, "start", "end", np.arange(len(t)))
    assert np.all(np.diff(f(t)) > 0.09)
    exact = minimize_scalar(lambda x: float(f(x)), bounds=(0.52, 0.55), method="bounded", options={"xatol": 1e-12})
    for finest in (None, 0.005):
        (p,) = plans([with_rowless(t, {"f": f(t)}, [iv], read, finest)])
        e = finish_all([p], [read(*r) for r in p.requests], read)[0]["f"]["min"]
        if finest is None:
            assert (e.value, e.t) == (0.0, 0.0)
        else:
            assert e.value == pytest.approx(exact.fun, rel=1e-9)
            assert e.t == pytest.approx(exact.x, abs=1e-6)


@functools.cache
def _lc3_contact_peak(step):
    """geneva-seed-lc3-mu015's located contact-temperature peaks at output_step `step`, run once for the module (the
    1 ms reference is read for both coarse steps; only read)."""
    r = mechsim.run(mechsim.load("geneva-seed-lc3-mu015", set=["output.plots=false", f'output_step="{step}"']))
    return r.summary["peaks"]["temp_contact_C"]


@pytest.mark.parametrize("step", ["20 ms", "45 ms"])
def test_the_contact_temperature_peak_does_not_move_with_the_output_step(step):
    """A closed-form run's thermal columns are sampled between the rows too (`ClosedFormThermalReader.sampler`:
    the closed form at the samples, the network's states interpolated between rows, which ranks the candidates;
    every located value is then read exactly). geneva-seed-lc3-mu015's contact temperature peaks at 51.94051 C
    just after an entry, a flash a few milliseconds wide: at 20 and 45 ms rows (12 and 28 degrees of crank)
    51.875 and 51.625 C were reported. The readings integrate the network exactly from the rows (to the
    quadrature's error, ~1e-12 here), so the steps agree to 1e-9 of the value."""
    own, coarse = _lc3_contact_peak("1 ms"), _lc3_contact_peak(step)
    for side in ("max", "min"):
        assert coarse[side]["value"] == pytest.approx(own[side]["value"], rel=1e-9), side
        assert coarse[side]["t_s"] == pytest.approx(own[side]["t_s"], abs=1e-7), side
    assert coarse["max"]["best_row_value"] < own["max"]["value"] - 0.05        # the rows alone miss the flash
