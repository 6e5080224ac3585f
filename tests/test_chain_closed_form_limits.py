"""The chain's closed form read a hair from an event: each instant on its own side (docs/theory.md §K5).

The chain's kinematics put a travel value within SNAP of a junction or a crank stop onto that point (1e-12 of the
chain length: about 1.4e-11 s at 1 rad/s on Mech 1), while the located peaks read an interval's one-sided limit
1e-12 s (relative) inside it (`Interval.inside`). Read on the side the point itself picks, the limit before a stop
was the dwell after it: the crank-speed jump of 0.75 rad/s sat in the last Simpson panel of every swing, and the
cycle mean moved with the output step (1.5e-4 of it at the 10 ms rows).
"""
import numpy as np
import pytest

from mechsim.scenarios.loader import load
from mechsim.scenarios.runner import plan, run

SCENARIOS = ["chain-mech1-kinematic", "chain-mech2-kinematic"]


@pytest.mark.parametrize("name, sets", [(name, []) for name in SCENARIOS] + [
    ("chain-mech1-kinematic", ["mechanism.branch='lagging'"]), ("chain-mech1-kinematic", ["mechanism.apex='smooth'"])])
def test_an_instant_a_hair_from_an_event_reads_its_own_side(name, sets):
    """Just before every event the closed form is the mode before it and continues the motion there; just after,
    the mode after: the crank speed at 1e-12 s (relative) from the event differs from its value 1e-7 s out by at
    most the largest crank acceleration times 1e-7 s (Lipschitz), on both sides, even where the speed jumps (a stop
    impact: 0.75 rad/s to rest). The lagging branch (its apex law switches root at the first apex) and the smooth
    branch (apexes passed without a stop) alike."""
    sc = load(name, ["output.plots=false", *sets])
    the_plan = plan(sc)
    mech, speed = the_plan.mechanism, the_plan.drive.speed
    angle0 = sc.si["initial"][mech.initial_keys[0]]
    events = run(sc).events
    assert "arc entry" in set(events["kind"]) and len(events) >= 8
    for _, event in events.iterrows():
        te = float(event["t_s"])
        hair, out = 1e-12 * max(1.0, te), 1e-7
        at = np.array([0.0, te - out, te - hair, te + hair, te + out])
        cols = mech.closed_form(at, angle0, speed)
        assert list(cols["mode"][2:4]) == [event["from_mode"], event["to_mode"]], (event["kind"], te)
        w, a = cols["crank_speed_rad_s"], np.abs(cols["crank_accel_rad_s2"])
        bound = 1.01 * out * max(a[1], a[2], a[3], a[4]) + 1e-12
        assert abs(w[2] - w[1]) <= bound, (event["kind"], te, w[1], w[2])
        assert abs(w[3] - w[4]) <= bound, (event["kind"], te, w[3], w[4])


@pytest.mark.parametrize("name", SCENARIOS)
@pytest.mark.parametrize("step", [0.01, 0.00613])
def test_the_cycle_mean_crank_speed_is_the_net_turn_over_the_cycle(name, step):
    """The summary's mean crank speed over the last drive cycle is the crank's net turn over it divided by its
    duration (the closed form's angle, unwrapped on a fine grid), whatever the output step: Simpson's rule on
    knots half a degree apart with the one-sided limits at every event errs by O(h^4) there (1e-13 of it
    measured), where a jump inside a panel erred by O(h)."""
    sc = load(name, ["output.plots=false", f"output_step={step} s"])
    result = run(sc)
    cycle = result.summary["peaks"]["crank_speed_rad_s"]["cycle"]
    a, b = cycle["mean_over"]
    the_plan = plan(sc)
    mech = the_plan.mechanism
    grid = np.linspace(0.0, b, 20001)
    crank = mech.closed_form(grid, sc.si["initial"][mech.initial_keys[0]], the_plan.drive.speed)["crank_angle_rad"]
    turn = np.interp(b, grid, crank) - np.interp(a, grid, crank)
    assert cycle["mean"] == pytest.approx(turn / (b - a), rel=1e-9)
