"""Extrema at an event where the column's value or slope jumps (docs/theory.md §K5): the one-sided limit there is
read (dynamics/extrema.py `end_limits`), not ranked by the output row next to it, so the reported number does not
move with the output step.

- The internal Geneva with its motor (1.5 s: one slip reversal in each of two engagements): the contact
  temperature's minimum sits at the first slip reversal, where the flash rise follows |slip speed| (a kink) and the
  Blok share jumps, so the limit from after it is lower than the one from before (by 5e-6 K there, 1.5e-5 K in the
  periodic regime of the 5 s run). With the side picked by the nearer row it moved by that much with the step.
- The Geneva with its motor (5 s): the crank's deceleration peaks at an entry's limit from after (the wheel's load
  enters); ranked by their rows, at 4 ms an interior minimum of an engagement 10 rad/s^2 above it was reported.

Both at rtol 1e-10: the limits are read at 1/10 of it and the events located to it, so 100x rtol (1e-8 relative)
is the margin; the instant of the temperature's minimum is its event's, located to 1e-9 s of these runs' time
scale (the crank deceleration's repeats every turn, equal to the solver's tolerance: its instant is not asserted).
"""
import numpy as np
import pytest

import mechsim
from mechsim.scenarios.loader import build_mechanism

STEPS = ("0.5 ms", "1 ms", "4 ms")
TIGHT = ["solver.rtol=1e-10", "solver.atol=1e-12", "output.plots=false"]


def _runs(name: str, sets: list[str]) -> dict:
    return {step: mechsim.run(mechsim.load(name, set=TIGHT + sets + [f"output_step={step}"])) for step in STEPS}


def test_minimum_contact_temperature_at_a_slip_reversal_does_not_move_with_the_output_step():
    runs = _runs("internal-geneva-motor", ["duration=1.5 s"])
    mins = {step: r.summary["peaks"]["temp_contact_C"]["min"] for step, r in runs.items()}
    ref = mins["1 ms"]
    print({step: (e["value"], e["t_s"], e["at"]) for step, e in mins.items()})
    for step, e in mins.items():
        assert "slip reversal" in e["at"] and e["limit"] == "after", (step, e["at"])
        assert e["value"] == pytest.approx(ref["value"], rel=1e-8, abs=0), step
        assert e["t_s"] == pytest.approx(ref["t_s"], rel=0, abs=1e-8), step
        assert e["value"] < e["best_row_value"], step          # below every row of its window


def test_crank_deceleration_at_an_entry_does_not_move_with_the_output_step():
    runs = _runs("geneva-motor", [])
    mins = {step: r.summary["peaks"]["crank_accel_rad_s2"]["min"] for step, r in runs.items()}
    print({step: (e["value"], e["t_s"], e["at"]) for step, e in mins.items()})
    for step, e in mins.items():
        assert "entry" in e["at"] and e["limit"] == "after", (step, e["at"])
        assert e["value"] == pytest.approx(mins["1 ms"]["value"], rel=1e-8, abs=0), step


def test_closed_form_contact_force_at_a_slip_reversal_is_the_limit_there_at_any_output_step():
    """geneva-seed-lc3 (friction 0.15, prescribed 10.5 rad/s): the friction force reverses with the slip in mid-
    engagement, and the normal force jumps there (232.1 -> 241.1 N), its maximum the limit from after. A closed form
    lists no slip reversal among its events, so before it was read as an interior maximum (a parabola across the
    jump): 242.13 to 242.37 N with the output step. Checked against the slip reversal found here by Brent's method on
    the closed form's own slip speed, and the closed form 1e-9 s after it (its slope there is ~1.5e3 N/s)."""
    from scipy.optimize import brentq
    name = "geneva-seed-lc3-mu015"
    runs = {step: mechsim.run(mechsim.load(name, set=["duration=0.5 s", "output.plots=false", f"output_step={step}",
                                                      "thermal.model='none'"]))
            for step in ("0.37 ms", "1 ms", "2.3 ms")}
    r = runs["1 ms"]
    mech = build_mechanism(r.scenario)
    angle0, speed = r.scenario["initial"]["crank_angle"], r.scenario["drive"]["speed"]

    def contact(t):
        return mech.closed_form_contact(np.array([0.0, t]), angle0, speed)
    t_rev = brentq(lambda t: contact(t)["slip_speed_m_s"][1], 0.28, 0.30, xtol=1e-15, rtol=1e-15)
    limit = contact(t_rev + 1e-9)["contact_force_N"][1]
    assert contact(t_rev - 1e-9)["contact_force_N"][1] < limit - 5.0          # a jump, not a smooth maximum
    for step, run in runs.items():
        e = run.summary["peaks"]["contact_force_N"]["max"]
        assert "slip reversal" in e["at"] and e["limit"] == "after", (step, e["at"])
        assert e["value"] == pytest.approx(limit, rel=1e-8), step
        assert e["t_s"] == pytest.approx(t_rev, abs=1e-9), step
