"""Each mechanism's transitions are written once (`Mechanism.transitions`) and evaluated twice: with numpy by the
Python hybrid loop (`Mechanism.on_guard`) and traced in JAX by the compiled diffrax run
(dynamics/backends/jax_transitions.py). On random states, for every (mode, guard) of the external and internal Geneva
and the rolling-pair 4-bar (both drive links, torque and prescribed speed), the two give the same next mode and the
same parameter vector to the bit, and the compiled run hands the state back exactly where the numeric evaluation
stops. The Geneva drives' friction directions chosen at entry and flank switch, and the stall test at a slip
reversal, agree with the slip of each drive's own engaged mode (its geometry's pin-in-slot formulas)."""
import jax
import numpy as np
import pytest

from mechsim.dynamics.drives import Drive
from mechsim.dynamics.jax_model import jax_model
from mechsim.dynamics.backends.jax_transitions import jax_transitions
from mechsim.dynamics.model import derive
from mechsim.mechanisms.geneva.kinematics import GenevaGeometry
from mechsim.mechanisms.geneva.model import Geneva
from mechsim.mechanisms.internal_geneva.kinematics import InternalGenevaGeometry
from mechsim.mechanisms.internal_geneva.model import InternalGeneva
from mechsim.mechanisms.rolling.model import Bodies, RollingPairFourBar
from mechsim.mechanisms.rolling.sets import make


def _geneva():
    """The seed geometry with friction (flank switches and slip reversals re-choose the friction direction)."""
    return Geneva(GenevaGeometry(0.075, 4, 0.004, 0.004), 0.02, 1.5626e-3, wheel_torque=7.0, friction=0.15)


def _internal_geneva():
    """The built-in internal wheel (n = 6, r = 50 mm, R = 4 mm) with friction."""
    return InternalGeneva(InternalGenevaGeometry(0.05, 6, 0.004, 0.004), 0.02, 0.02, wheel_torque=3.0, friction=0.15)


def _rolling(**kw):
    kin = make("A")
    return RollingPairFourBar(kin, Bodies.uniform(kin, 0.2, 0.3, 0.5, 0.1), **kw)


def _geneva_state(rng, values):
    values = dict(values, slot=float(rng.integers(-3, 4)), flank=float(rng.choice([-1.0, 1.0])),
                  slide=float(rng.choice([-1.0, 1.0])), lock_angle=float(rng.normal()))
    # speeds from working level down to rest level, so that slip reversals at a stopped crank come up
    return values, rng.normal(size=2) * 3.0, rng.normal(size=2) * 10.0 ** rng.uniform(-5, 1)


def _rolling_state(rng, values):
    return dict(values, dead_sign=float(rng.choice([-1.0, 1.0]))), rng.normal(size=3) * 2.0, rng.normal(size=3)


CASES = {
    "geneva-torque": (_geneva, Drive("torque", torque=6.0), _geneva_state),
    "internal-geneva-torque": (_internal_geneva, Drive("torque", torque=6.0), _geneva_state),
    "rolling-crank-torque": (lambda: _rolling(driven_link="crank"), Drive("torque", torque=5.0), _rolling_state),
    "rolling-crank-speed": (lambda: _rolling(driven_link="crank", prescribed=True), Drive("speed", speed=1.0),
                            _rolling_state),
    "rolling-rolling-torque": (lambda: _rolling(), Drive("torque", torque=2.0), _rolling_state),
    "rolling-rolling-speed": (lambda: _rolling(prescribed=True), Drive("speed", speed=1.0), _rolling_state),
}


@pytest.mark.parametrize("case", sorted(CASES))
def test_numeric_and_compiled_evaluation_agree(case):
    make_mech, drive, draw = CASES[case]
    mech = make_mech()
    model = derive(mech, "index1", drive.is_prescribed, None)
    jmod = jax_model(model)
    table = jax_transitions(mech, model, jmod)
    apply = jax.jit(table.apply)
    names = list(model.parameter_names)
    # every guard of every mode has its transition in the table
    assert {(jm.name, g) for jm in jmod.modes for g in jm.guard_names} == set(mech.transition_rules())
    base = dict(mech.parameter_values())
    base.update(drive.parameter_values(0.0, 0.0), baumgarte_alpha=1.0, baumgarte_beta=1.0)
    rng = np.random.default_rng(13)
    seen = set()
    for _ in range(300):
        kk = int(rng.integers(len(jmod.modes)))
        jm = jmod.modes[kk]
        j = int(rng.integers(jm.ng))
        values, q, v = draw(rng, base)
        p = np.array([values[n] for n in names])
        tr = mech.on_guard(jm.name, jm.guard_names[j], values, 0.0, q, v)
        k_new, p_new, back = (np.asarray(x) for x in apply(kk, j, q, v, p))
        key = (jm.name, jm.guard_names[j])
        if tr.stop or tr.restitution is not None:
            assert back, (key, q, v)
            assert tr.mode == jm.name
        else:
            assert not back and jmod.names[int(k_new)] == tr.mode, key
            np.testing.assert_array_equal(p_new, [dict(values, **tr.updates)[n] for n in names])
        seen.add(key + (bool(tr.stop),))
    assert {s[:2] for s in seen} == set(mech.transition_rules())
    if "geneva" in case:      # the slip reversal is a stop at a crank coming to rest, else a reversal
        assert {("engaged", "slip_reversal", True), ("engaged", "slip_reversal", False)} <= seen
    else:
        assert {s[2] for s in seen} == {mech.prescribed}


def test_messages_are_the_templates_filled_from_the_state():
    """The events-table texts: the flank switch names the new flank and the local crank angle; a slip reversal at
    a crank at rest is the stall with its crank angle; the rolling dead point names the dyad's posture."""
    mech = _geneva()
    values = dict(mech.parameter_values(), slot=1.0, flank=1.0)
    q = np.array([2 * np.pi + np.radians(10.0), np.pi / 2])
    tr = mech.on_guard("engaged", "flank_switch", values, 0.0, q, np.array([5.0, 2.0]))
    assert tr.message.startswith("normal force changed sign at crank angle 10.00 deg (local): the pin crossed to "
                                 "the trailing flank")
    stall = mech.on_guard("engaged", "slip_reversal", values, 0.0, q, np.array([1e-6, 0.0]))
    assert stall.kind == "stall" and stall.stop.startswith("crank stalled: its speed fell to zero at crank angle "
                                                            "370.00 deg (engaged)")
    rolling = _rolling()
    tr = rolling.on_guard("rolling", "dead_point", rolling.parameter_values(), 0.0, np.array([0.5, 0.5, 1.0]),
                          np.array([0.0, 0.0, -0.25]))
    assert tr.message == ("dead point of the rolling link input (stretched dyad (sin(theta3 - theta2) = 0)) at crank "
                          "angle 0.5 rad, rolling angle 1 rad: the rolling link reverses (its speed -0.25 rad/s) and "
                          "the motion goes on")
    assert tr.updates == {"dead_sign": -rolling.parameter_values()["dead_sign"]}


@pytest.mark.parametrize("make_mech", [_geneva, _internal_geneva], ids=["geneva", "internal_geneva"])
def test_geneva_friction_direction_follows_the_modes_slip(make_mech):
    """The table's slip formulas are the engaged mode's: at entry (wheel at rest at the angle the pin meets, flank
    1) the new slide is the sign of the mode's slip readout; at a flank switch it is the sign of the slip on the new
    flank; a slip reversal is a stall exactly where the slip per unit crank speed, s = u / theta' with the wheel
    following at G theta', is away from zero (> 1e-3 (r + R)) and the crank at rest level. For the internal drive
    the pin's spin is R (w2 - w1) and s = -r sin(alpha - beta) + flank R (G - 1) (docs/internal_geneva.md): the
    external formulas would choose the wrong direction there."""
    import sympy as sp
    mech = make_mech()
    g, s = mech.geometry, mech.symbols
    slip = sp.lambdify((s.q, s.v, [s.p(n) for n in mech.parameter_names]),
                       mech.modes()["engaged"].readouts["slip_speed_m_s"], "numpy")
    base = dict(mech.parameter_values())
    rng = np.random.default_rng(7)
    a0, R, r = g.engagement_half_angle, g.pin_radius, g.crank_radius
    stops = set()
    for _ in range(200):
        k = float(rng.integers(-2, 3))
        alpha = rng.uniform(-a0, a0)
        values = dict(base, slot=k, flank=float(rng.choice([-1.0, 1.0])), slide=float(rng.choice([-1.0, 1.0])))
        beta, G = (float(x) for x in g.wheel_motion(g.ratio, alpha)[:2])
        q = np.array([2 * np.pi * k + alpha, k * g.pitch + beta])
        w1 = float(rng.choice([-1.0, 1.0])) * 10.0 ** rng.uniform(-5, 1)

        def u(v, **change):
            return slip(q, v, [dict(values, **change)[n] for n in mech.parameter_names])
        entry = mech.on_guard("dwell", "entry", values, 0.0, q, np.array([w1, 0.0]))
        assert entry.updates["slide"] == (1.0 if u(np.array([w1, 0.0]), flank=1.0) >= 0 else -1.0)
        v = np.array([w1, rng.normal() * 3.0])
        switch = mech.on_guard("engaged", "flank_switch", values, 0.0, q, v)
        assert switch.updates["slide"] == np.sign(u(v, flank=-values["flank"]))
        s_kin = u(np.array([1.0, G]))
        stalled = mech.on_guard("engaged", "slip_reversal", values, 0.0, q, np.array([w1, G * w1])).stop is not None
        assert stalled == (abs(s_kin) > 1e-3 * (r + R) and abs(w1) < mech.STOPPED_SPEED)
        stops.add(stalled)
    assert stops == {True, False}
