"""A closed-form run's works: its exact powers integrated between the rows to the powers' own accuracy, whatever
the output step (dynamics/quadrature.py; docs/stability.md, 'The closed form's works')."""
import numpy as np
import pytest
from scipy import integrate

import mechsim
from mechsim.dynamics.invariants import energy_closure
from mechsim.dynamics.quadrature import cumulative_integrals
from mechsim.scenarios.runner import plan


def _kinked(c_kink: float, t_jump: float):
    """A rate with a kink at c_kink (|t - c|, no break names it) and a jump of 1 at t_jump (a break), and its
    integral from 0."""
    def rate(t):
        return {"f": np.abs(t - c_kink) + np.sin(3.0 * t) + (t >= t_jump)}

    def exact(t):
        kink = np.where(t < c_kink, c_kink * t - 0.5 * t**2, 0.5 * c_kink**2 + 0.5 * (t - c_kink) ** 2)
        return kink + (1.0 - np.cos(3.0 * t)) / 3.0 + np.maximum(t - t_jump, 0.0)
    return rate, exact


@pytest.mark.parametrize("c_kink", [0.10 + 0.0275e-2, 0.25, 0.7071])
def test_a_kink_and_a_jump_are_integrated_exactly_on_any_rows(c_kink):
    """The kink 2.75 % of a panel from its start (before every Gauss-Legendre node of the panel and of its half:
    both extrapolate over it alike) and at other places; the jump at a break. Each row's integral to 1e-10 of the
    rate's scale, on rows 1e-2 apart and on 4 rows, and the error estimate is not below the error."""
    rate, exact = _kinked(c_kink, 0.4321)
    for rows in (np.linspace(0.0, 1.0, 101), np.linspace(0.0, 1.0, 4)):
        got, estimate = cumulative_integrals(rate, rows, np.array([0.4321]), 0.01, 100_000)
        error = np.abs(got["f"] - exact(rows))
        assert error.max() < 1e-10
        assert np.all(error <= 10.0 * estimate + 1e-14)


def test_an_integrable_singularity_ends_within_the_bound_on_panels():
    """A rate growing like 1/sqrt(distance) toward an instant no break names: the panels next to it are halved
    until the halvings run out (LEVELS), and the integral is then off by at most the last panels' share, 2 sqrt(h)
    of an h about 0.05 / 2^40 wide: 1e-5 bounds it with the margin of the panels' rounding."""
    def rate(t):
        return {"f": 1.0 / np.sqrt(np.abs(t - 0.3) + 1e-300)}
    rows = np.linspace(0.0, 1.0, 11)
    got, _ = cumulative_integrals(rate, rows, np.array([]), 0.05, 1000)
    exact = 2.0 * np.sqrt(0.3) + 2.0 * np.sqrt(np.maximum(rows - 0.3, 0.0)) - 2.0 * np.sqrt(np.maximum(0.3 - rows, 0.0))
    exact[rows < 0.3] = 2.0 * np.sqrt(0.3) - 2.0 * np.sqrt(0.3 - rows[rows < 0.3])
    assert np.abs(got["f"] - exact).max() < 1e-5


def _works(name, sets=()):
    r = mechsim.run(mechsim.load(name, set=["output.plots=false", *sets]))
    assert r.success, r.summary.get("failure")
    df = r.timeseries
    return r, df, {c: df[c].to_numpy(float) for c in df if c.startswith("work_")}


@pytest.mark.parametrize("name, coarse", [("geneva-lc1", "1 s"), ("chain-mech1-kinematic", "4.78 s"),
                                          ("internal-geneva-speed", "1 s"), ("rolling-a-speed", "3.333 s")])
def test_the_works_do_not_depend_on_the_output_step(name, coarse):
    """The works at the rows a coarse run shares with the scenario's own (three rows a run, which the trapezoidal
    rule on the rows refused as an energy balance broken: internal-geneva-speed 0.0771 J against 0.0766 J) agree to
    1e-9 of the largest work, and the energy balance closes to 1e-12 of it on both."""
    r_fine, fine, w_fine = _works(name)
    r_coarse, coarse_df, w_coarse = _works(name, [f"output_step='{coarse}'"])
    t_fine, t_coarse = fine["t_s"].to_numpy(float), coarse_df["t_s"].to_numpy(float)
    shared = np.isin(t_coarse, t_fine)
    assert shared.sum() >= 2
    at = np.searchsorted(t_fine, t_coarse[shared])
    scale = max(np.abs(w).max() for w in w_fine.values())
    for c in w_fine:
        assert np.abs(w_coarse[c][shared] - w_fine[c][at]).max() <= 1e-9 * scale, c
    for r, df in ((r_fine, fine), (r_coarse, coarse_df)):
        assert np.abs(energy_closure(df, r.events)).max() <= 1e-12 * max(scale, 1e-300)


def test_the_geneva_friction_work_is_scipys_adaptive_quadrature():
    """geneva-lc1's friction work over its 3 s: scipy's QUADPACK between the engagements' ends (the slip
    reversal's kink inside, found by its adaptive bisection) to 1e-10 of it."""
    sc = mechsim.load("geneva-lc1", set=["output.plots=false"])
    p = plan(sc)
    mech, speed = p.mechanism, p.drive.speed
    angle0 = sc.si["initial"][mech.initial_keys[0]]
    ends = [e["t_s"] for e in mech.closed_form_events(np.array([0.0, 3.0]), angle0, speed)]

    def friction(t):
        return float(mech.closed_form(np.array([0.0, t]), angle0, speed)["powers"]["friction"][-1])
    edges = [0.0, *ends, 3.0]
    reference = sum(integrate.quad(friction, a, b, limit=400, epsabs=1e-13, epsrel=1e-12)[0]
                    for a, b in zip(edges[:-1], edges[1:]))
    _, _, works = _works("geneva-lc1")
    assert works["work_friction_J"][-1] == pytest.approx(reference, rel=1e-10)
