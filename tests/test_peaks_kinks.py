"""Extrema at an event where the column's value or slope jumps (docs/theory.md §K5): the one-sided limit there is
read (dynamics/extrema.py `end_limits`), not ranked by the output row next to it, so the reported number does not
move with the output step.

- The internal Geneva with its motor (5 s): the contact temperature's minimum in the periodic regime sits at a slip
  reversal, where the flash rise follows |slip speed| (a kink) and the Blok share jumps, so the limit from after it
  is lower than the one from before (by 1.5e-5 K). With the side picked by the nearer row it moved by that much with
  the step. In the start-up, the minimum is the first entry's limit from after: the contact's temperature as it
  begins is the bulk one, still the ambient 20 C (the flash rise starts from zero). Ranked by their rows'
  extrapolation, that limit was never read, and a slip reversal's 0.038 K above it was reported; every limit the
  run holds the state of is now read (`stored_limits`).
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
    runs = _runs("internal-geneva-motor", [])
    mins = {step: r.summary["peaks"]["temp_contact_C"]["min"] for step, r in runs.items()}
    ref = mins["1 ms"]
    print({step: (e["value"], e["t_s"], e["at"]) for step, e in mins.items()})
    for step, e in mins.items():
        assert "slip reversal" in e["at"] and e["limit"] == "after", (step, e["at"])
        assert e["value"] == pytest.approx(ref["value"], rel=1e-8, abs=0), step
        assert e["t_s"] == pytest.approx(ref["t_s"], rel=0, abs=1e-8), step
        assert e["value"] < e["best_row_value"], step          # below every row of its window
    for step, r in runs.items():
        first = r.events[r.events["kind"] == "entry"]["t_s"].iloc[0]
        e = r.summary["peaks"]["temp_contact_C"]["startup"]["min"]
        assert "entry" in e["at"] and e["limit"] == "after", (step, e["at"])
        assert e["t_s"] == first, step
        assert e["value"] == pytest.approx(20.0, rel=1e-12), step     # the ambient: no heat yet in the bulk
        assert e["value"] < e["best_row_value"], step


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


def test_minimum_contact_temperature_among_many_events_is_at_the_first_turn_of_the_periodic_regime():
    """geneva-torque with friction 0.15 and lumped temperatures: the contact temperature falls toward the bulk one
    wherever the heat vanishes, at each slip reversal (21.068 C there) and where the normal force crosses zero at a
    flank switch: on the driving flank, as the load vanishes, the pin's share of the heat falls to 0.33 and the
    contact temperature to 20.727 C, the share-weighted bulk. The bulk rises from turn to turn, so the periodic
    regime's minimum is the limit from before its first turn's second flank switch. The rows' extrapolation toward
    these root-like cusps misses by far more than the turns differ: ranked by it, 8 limits read of about 200 picked a
    later turn's slip reversal (21.168 C at 1 ms rows, 21.359 C at 2.3 ms, 21.068 C at 0.37 ms), and the limit from
    before a flank switch was read with the time since contact of the flank the pin crosses to (zero: the pin's
    share 1, the pin's bulk 22.1 C). The limits the run holds the state of are now all read
    (`dynamics/extrema.py` `stored_limits`), a limit from before with the contact before it.

    The margin follows from the contact width's root: b ~ sqrt(N), and the load at the event is zero only to the
    run's tolerance (rtol x 300 N ~ 3e-6 N), over which the contact temperature moves by 1.4e-3 K (20.7270 C at
    zero load, 20.7256 C at 2.3e-6 N, read 1e-11 s before the switch)."""
    sets = ["thermal.model='lumped'", "contact.friction=0.15", "output.plots=false"]
    runs = {step: mechsim.run(mechsim.load("geneva-torque", set=sets + [f"output_step={step}"]))
            for step in ("0.37 ms", "1 ms", "2.3 ms")}
    ref = runs["1 ms"].summary["peaks"]["temp_contact_C"]["min"]
    for step, r in runs.items():
        e = r.summary["peaks"]["temp_contact_C"]["min"]
        switches = r.events[r.events["kind"] == "flank switch"]["t_s"].to_numpy(float)
        after_start = switches[switches > r.summary["regime"]["from_t_s"]]
        assert "flank switch" in e["at"] and e["limit"] == "before", (step, e["at"])
        assert e["t_s"] == pytest.approx(after_start[1], rel=0, abs=1e-7), step
        assert e["value"] == pytest.approx(ref["value"], rel=0, abs=2e-3), step
        assert e["value"] < e["best_row_value"], step
