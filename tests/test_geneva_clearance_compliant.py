"""The Geneva with slot clearance and a compliant (Hunt-Crossley) pin-flank contact
(mechanisms/geneva/clearance_compliant.py): the model's choice and refusals, the energy balance with the hysteresis,
the located force peak, convergence to the rigid model's Newton impact as the stiffness grows, and the contact's
heat (docs/geneva.md 'Clearance and impacts')."""
from __future__ import annotations

import numpy as np
import pytest
from scipy.integrate import solve_ivp

import mechsim.scenarios.api as api
from mechsim.dynamics.invariants import energy_closure
from mechsim.mechanisms.geneva.clearance import GenevaClearance
from mechsim.mechanisms.geneva.clearance_compliant import GenevaCompliant
from mechsim.scenarios import runner
from mechsim.scenarios.schema import ScenarioError
from mechsim.thermal.hertz import effective_modulus
from mechsim.thermal.materials import get_material

SCENARIO = "geneva-clearance"
COMPLIANT = "contact.model=compliant"


def run(*settings):
    return api.run(api.load(SCENARIO, set=list(settings)))


def hunt_crossley_restitution(e: float) -> float:
    """The Hunt-Crossley law's own coefficient of restitution for the damping 3(1 - e)/(2 v0) on a linear spring:
    the dimensionless impact x'' = -x (1 + 1.5 (1 - e) x'), x(0) = 0, x'(0) = 1, to x = 0 (independent of the
    stiffness, the mass and the approach speed)."""
    def sep(_t, y):
        return y[0]
    sep.terminal, sep.direction = True, -1
    s = solve_ivp(lambda _t, y: [y[1], -y[0] * (1 + 1.5 * (1 - e) * y[1])], (0, 100), [0.0, 1.0], events=sep,
                  rtol=1e-12, atol=1e-14, first_step=1e-6)
    return float(-s.y_events[0][0][1])


def test_the_model_is_chosen_by_contact_model():
    """rigid (the default) builds the rigid clearance model, compliant the compliant one with K = E* l (the thermal
    model's material, the wheel thickness), or contact.stiffness where given."""
    assert type(runner.plan(api.load(SCENARIO)).mechanism) is GenevaClearance
    mech = runner.plan(api.load(SCENARIO, set=[COMPLIANT])).mechanism
    assert type(mech) is GenevaCompliant
    assert mech.stiffness == pytest.approx(effective_modulus(get_material("aisi1045")) * 0.004, rel=1e-12)
    softer = runner.plan(api.load(SCENARIO, set=[COMPLIANT, "thermal.E=103.5e9 Pa"])).mechanism
    assert softer.stiffness == pytest.approx(mech.stiffness / 2, rel=1e-12)
    given = runner.plan(api.load(SCENARIO, set=[COMPLIANT, "contact.stiffness=1e9 N/m"])).mechanism
    assert given.stiffness == 1e9


@pytest.mark.parametrize("settings, field", [
    (["contact.model=soft"], "contact.model"),
    ([COMPLIANT, "mechanism.slot_clearance=0 m"], "contact.model"),
    (["contact.stiffness=1e9 N/m"], "contact.stiffness"),
    ([COMPLIANT, "contact.stiffness=-1 N/m"], "contact.stiffness"),
])
def test_bad_input_names_the_field(settings, field):
    with pytest.raises((ScenarioError, ValueError)) as info:
        runner.plan(api.load(SCENARIO, set=settings))
    assert field in str(info.value) and "\n" not in str(info.value)


@pytest.fixture(scope="module")
def engagement():
    """The first engagement of the built-in scenario with the compliant contact: the entry's bounce sequence, the
    pin riding the driving flank, the overrun's bounces."""
    return run(COMPLIANT, "duration=0.6 s")


def test_energy_closes_with_the_hysteresis(engagement):
    """Works of drive, load, friction, damping, the contact's elastic force (minus its stored energy) and its
    hysteresis = change of kinetic energy on every row (no impact term: the rows lose no energy at an event), to
    1e-6 of the energy throughput; the hysteresis loss is that of the episodes, each > 0."""
    r = engagement
    assert r.failure is None
    ts, ev = r.timeseries, r.events
    works = [c for c in ts.columns if c.startswith("work_")]
    throughput = sum(float(np.max(np.abs(ts[c]))) for c in works) + float(np.max(ts.kinetic_energy_J))
    assert np.nansum(np.abs(ev.energy_lost_J[ev.kind != "exit"])) == 0.0
    closure = energy_closure(ts, ev)
    assert np.max(np.abs(closure)) < 1e-6 * throughput
    episodes = r.extra_tables["impacts"]
    assert len(episodes) >= 8 and np.all(episodes.energy_lost_J > 0)
    lost = -ts.work_hysteresis_J.iloc[-1]
    assert lost > 1e-4 * throughput                   # a hundred times the bound below
    assert episodes.energy_lost_J.sum() == pytest.approx(lost, rel=1e-9)
    assert r.summary["impacts"]["energy_lost_J"] == pytest.approx(lost, rel=1e-9)


def test_the_force_and_gap_columns(engagement):
    """The contact force is finite and compressive, zero out of contact; the gap is negative (a penetration) exactly
    where the pin is engaged."""
    ts, mech = engagement.timeseries, engagement.mechanism
    engaged = (ts["mode"] == "engaged").to_numpy()
    force, gap = ts.contact_force_N.to_numpy(), ts.gap_m.to_numpy()
    assert np.all(np.isfinite(force)) and np.all(force[~engaged] == 0) and np.all(force * ts.flank >= 0)
    assert np.all(gap[engaged] <= 1e-12) and np.all(gap[~engaged] >= -1e-12)
    assert np.all(np.abs(force[engaged]) > 0) and np.min(gap) > -2 * np.max(np.abs(force)) / mech.stiffness


def test_the_force_peak_is_located(engagement):
    """The largest contact force is the located peak of its column (the peak machinery) and the episode's located
    maximum (its event), independent of the output step: at another output step the same to 1e-6; each episode's
    peak lies between its onset and its end."""
    peak = engagement.summary["peaks"]["contact_force_N"]["abs_max"]["value"]
    s = engagement.summary["impacts"]
    assert peak == pytest.approx(s["peak_force_N"], rel=1e-6)
    assert peak > 2 * np.max(np.abs(engagement.timeseries.contact_force_N))     # the rows miss it
    other = run(COMPLIANT, "duration=0.32 s", "output_step=0.37 ms")
    assert other.summary["impacts"]["peak_force_N"] == pytest.approx(s["peak_force_N"], rel=1e-6)
    assert other.summary["impacts"]["peak_force_at_t_s"] == pytest.approx(s["peak_force_at_t_s"], abs=1e-9)
    ep = engagement.extra_tables["impacts"]
    closed = np.isfinite(ep.duration_s)
    assert np.all(ep.peak_force_at_t_s[closed] > ep.t_s[closed])
    assert np.all(ep.peak_force_at_t_s[closed] < (ep.t_s + ep.duration_s)[closed])


def test_hunt_crossley_restitution():
    """The law's own restitution is only approximately e: 0.663 at e = 0.5, 0.909 at 0.9, 0.488 at 0 (measured
    relation, docs/geneva.md)."""
    assert hunt_crossley_restitution(0.5) == pytest.approx(0.6630, abs=1e-4)
    assert hunt_crossley_restitution(0.9) == pytest.approx(0.9090, abs=1e-4)
    assert hunt_crossley_restitution(0.0) == pytest.approx(0.4877, abs=1e-4)


def test_converges_to_the_rigid_impact_as_the_stiffness_grows():
    """Frictionless, e = 0.5: the first impact's impulse m (v_in + v_out) tends to the rigid model's with Newton's
    e_HC = 0.663 (the law's own restitution) at order 1/2 in K (the episode's duration ~ K^-1/2, over which the
    load and the geometry change), its rebound ratio to e_HC, and the velocities after it to Newton's law with
    e_HC applied at its onset."""
    base = ["contact.friction=0", "duration=0.3 s", "solver.rtol=1e-9", "solver.atol=1e-12"]
    e_hc = hunt_crossley_restitution(0.5)
    rigid = run(*base, f"contact.restitution={e_hc}")
    first = rigid.events[rigid.events.kind.str.startswith("impact")].iloc[0]
    err, ratio, vel = [], [], []
    for K in (4.5e8, 4.5e9, 4.5e10):
        r = run(*base, COMPLIANT, f"contact.stiffness={K} N/m")
        assert r.failure is None
        ep = r.extra_tables["impacts"].iloc[0]
        assert ep.t_s == pytest.approx(first.t_s, abs=1e-9)
        err.append(abs(ep.impulse_N_s / first.impulse_N_s - 1))
        ratio.append(abs(ep.separation_speed_m_s / ep.approach_speed_m_s - e_hc))
        ev, mech = r.events, r.mechanism
        on, off = ev[ev.kind == "impact"].iloc[0], ev[ev.kind == "separation"].iloc[0]
        p = mech.parameter_values()
        q, v = np.array([on.crank_q, on.wheel_q]), np.array([on.crank_speed_rad_s, on.wheel_speed_rad_s])
        newton = np.array(mech._after_impact(q, v, p, np, 1.0, e_hc))
        vel.append(np.max(np.abs(np.array([off.crank_speed_rad_s, off.wheel_speed_rad_s]) - newton) / np.abs(newton)))
    for e in (err, ratio, vel):
        orders = np.log10(np.array(e[:-1]) / np.array(e[1:]))
        assert np.all((orders > 0.4) & (orders < 0.6)), e
    assert err[-1] < 1e-3 and ratio[-1] < 1e-3


def test_contact_heat_closes_the_heat_balance():
    """With a thermal model each episode's hysteresis work enters the network as the impact's heat at its onset
    (thermal/impact.py): heat generated = friction work + hysteresis to 1e-6, the balance closed; the run ends with
    the pin riding the flank, an episode its end closes."""
    r = run(COMPLIANT, "thermal.model=lumped", "duration=0.32 s")
    assert not r.extra_tables["impacts"].rebound.iloc[-1]
    assert r.failure is None
    hb = r.summary["thermal"]["heat_balance"]
    lost = -r.summary["energy"]["work_J"]["hysteresis"]
    assert hb["impacts_J"] == pytest.approx(lost, rel=1e-9)
    friction = -r.summary["energy"]["work_J"]["friction"]
    assert hb["generated_J"] == pytest.approx(friction + lost, rel=1e-6)
    assert abs(hb["closure_error_relative"]) < 1e-7, hb
    ev = r.events
    assert np.all(np.isfinite(ev.impact_flash_rise_K[ev.kind == "impact"]))


def test_ida_and_diffrax_agree():
    """The same contact episodes on both backends (diffrax's explicit Tsit5 at the scenario's tolerances: the
    contact's period, about 0.2 ms at the default stiffness, is far above its stability limit; every onset, force
    peak and separation is handed back to the Python loop, which records its readings)."""
    over = [COMPLIANT, "duration=0.32 s"]
    a, b = run(*over), run(*over, "solver.backend=diffrax")
    assert a.failure is None and b.failure is None
    for col in ("crank_angle_rad", "wheel_angle_rad"):
        assert np.max(np.abs(a.timeseries[col].to_numpy() - b.timeseries[col].to_numpy())) < 1e-7
    assert list(a.events.kind) == list(b.events.kind)
    assert np.max(np.abs(a.events.t_s.to_numpy() - b.events.t_s.to_numpy())) < 1e-7
    ea, eb = a.extra_tables["impacts"], b.extra_tables["impacts"]
    # the episodes of a bounce sequence shrink by e_HC each: tolerances on the largest
    np.testing.assert_allclose(eb.peak_force_N, ea.peak_force_N, rtol=0, atol=1e-5 * ea.peak_force_N.max())
    np.testing.assert_allclose(eb.energy_lost_J, ea.energy_lost_J, rtol=0, atol=1e-5 * ea.energy_lost_J.max())
