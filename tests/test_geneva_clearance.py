"""The Geneva with slot clearance (mechanisms/geneva/clearance.py): the exact fit at zero clearance, the DAE against
the independent reduced-coordinate reference, Newton's law and the energy balance at every impact, convergence as
the clearance shrinks, IDA against diffrax, refused input (docs/geneva.md 'Clearance and impacts')."""
from __future__ import annotations

import numpy as np
import pytest

import mechsim.scenarios.api as api
from mechsim.dynamics.invariants import energy_closure
from mechsim.mechanisms.geneva import clearance_reduced
from mechsim.mechanisms.geneva.clearance import GenevaClearance
from mechsim.mechanisms.geneva.model import Geneva
from mechsim.scenarios import runner
from mechsim.scenarios.schema import ScenarioError

SCENARIO = "geneva-clearance"
TIGHT = ["solver.rtol=1e-10", "solver.atol=1e-12"]


def run(*settings):
    return api.run(api.load(SCENARIO, set=list(settings)))


def test_zero_clearance_is_the_exact_fit_model():
    """slot_clearance 0 (the default) builds today's two-mode model, with today's parameters: same code path."""
    scenario = api.load(SCENARIO, set=["mechanism.slot_clearance=0 m"])
    mech = runner.plan(scenario).mechanism
    assert type(mech) is Geneva
    plain = api.load("geneva-motor")
    assert set(runner.plan(plain).mechanism.parameter_values()) == set(mech.parameter_values())
    assert type(runner.plan(api.load(SCENARIO)).mechanism) is GenevaClearance


def test_dae_matches_the_reduced_reference():
    """Frictionless, restitution 0.5: the DAE's crank and wheel angles and its impact times against the
    reduced-coordinate integration (scipy DOP853, its own impact law), both at tight tolerances; the bounce
    sequence at entry, the separation and the overrun impacts all in the same order."""
    r = run("contact.friction=0", "duration=0.6 s", *TIGHT)
    assert r.failure is None
    ts, mech = r.timeseries, r.mechanism
    dv = runner.plan(api.load(SCENARIO)).drive.parameter_values(0.0)
    t = ts.t_s.to_numpy()
    theta, psi, events = clearance_reduced.integrate(mech, dv["drive_T0"], dv["drive_slope"],
                                                     float(ts.crank_angle_rad[0]), float(ts.crank_speed_rad_s[0]), t)
    assert np.max(np.abs(theta - ts.crank_angle_rad.to_numpy())) < 1e-7
    assert np.max(np.abs(psi - ts.wheel_angle_rad.to_numpy())) < 1e-7
    # at mu = 0 the slip's sign is bookkeeping only; a flight's apex splits it for the root-finding only
    dae = r.events[~r.events.kind.isin(["slip reversal", "flight apex"])]
    assert list(dae.kind) == [e[1] for e in events]
    assert list(dae.to_mode) == [e[2] for e in events]
    assert sum(k == "impact" for k in dae.kind) >= 8
    assert np.max(np.abs(dae.t_s.to_numpy() - [e[0] for e in events])) < 1e-8


def test_flank_kinematics_against_finite_differences():
    """The reference's wheel angle on a flank, beta_f = beta0 - asin(f h / rho), and its derivatives G, G'."""
    mech = runner.plan(api.load(SCENARIO)).mechanism
    h = 1e-5
    for alpha in (-0.6, -0.1, 0.3, 0.7):
        for f in (1.0, -1.0):
            b = [clearance_reduced.flank_motion(mech, alpha + k * h, f) for k in (-1, 0, 1)]
            assert b[1][1] == pytest.approx((b[2][0] - b[0][0]) / (2 * h), rel=1e-8, abs=1e-9)
            assert b[1][2] == pytest.approx((b[2][1] - b[0][1]) / (2 * h), rel=1e-6, abs=1e-7)
            g = mech.geometry
            offset = g.pin_in_slot(g.crank_radius, g.centre_distance, alpha, b[1][0])[0]
            assert offset == pytest.approx(f * mech.slot_clearance / 2, rel=1e-12)


@pytest.fixture(scope="module")
def with_friction():
    return run("duration=0.6 s", *TIGHT)


def test_newton_law_at_every_impact(with_friction):
    """Each impact's energy lost and impulse obey Newton's law in the mass metric: with k = G M^-1 G^T at the
    impact's position and e the rule's coefficient (0 where the pin stays on the flank),
    energy lost = (1 - e) / (2 (1 + e)) k impulse^2."""
    r = with_friction
    assert r.failure is None
    mech = r.mechanism
    g = mech.geometry
    impacts = r.events[r.events.kind.str.startswith("impact")]
    assert len(impacts) >= 8
    e_rule = mech.restitution
    for row in impacts.itertuples():
        k = np.floor((row.crank_q + np.pi) / (2 * np.pi))
        alpha, beta = row.crank_q - 2 * np.pi * k, row.wheel_q - k * g.pitch
        _, x, _, arm = g.pin_in_slot(g.crank_radius, g.centre_distance, alpha, beta)
        kk = arm**2 / mech.crank_inertia + x**2 / mech.wheel_inertia
        e = e_rule if row.to_mode == "free" and row.kind == "impact" else 0.0
        assert row.energy_lost_J == pytest.approx((1 - e) / (2 * (1 + e)) * kk * row.impulse_N_s**2, rel=1e-6)
        assert row.energy_lost_J > 0


def test_energy_closes_with_the_impact_losses(with_friction):
    """Works of drive, load, friction and damping = change of kinetic energy + impact losses, on every row, to
    1e-6 of the energy throughput."""
    r = with_friction
    ts = r.timeseries
    closure = energy_closure(ts, r.events)
    works = [c for c in ts.columns if c.startswith("work_")]
    throughput = sum(float(np.max(np.abs(ts[c]))) for c in works) + float(np.max(ts.kinetic_energy_J))
    assert r.events.energy_lost_J.sum() > 1e-4 * throughput
    assert np.max(np.abs(closure)) < 1e-6 * throughput


def test_impacts_in_every_engagement():
    """Light load, heavy wheel, 0.25 mm clearance (the built-in scenario): every engagement has impacts (the
    entry's bounce sequence at least), and the gap column is zero in contact, c/2 - |offset| in flight."""
    r = api.run(api.load(SCENARIO, set=["duration=2 s"]))
    assert r.failure is None
    ev = r.events
    entries, exits = ev.t_s[ev.kind == "entry"].to_numpy(), ev.t_s[ev.kind == "exit"].to_numpy()
    assert len(entries) >= 2
    for t0, t1 in zip(entries, exits):
        assert np.sum((ev.kind == "impact") & (ev.t_s > t0) & (ev.t_s < t1)) >= 1
    impacts = r.extra_tables["impacts"]
    assert len(impacts) == ev.kind.str.startswith("impact").sum() and set(impacts.flank) <= {"driving", "trailing"}
    assert (impacts.groupby("turn").size() == impacts.groupby("turn").impacts_in_turn.first()).all()
    assert np.all(impacts.energy_lost_J > 0) and np.all(impacts.impulse_N_s > 0)   # driving flank: N > 0
    ts = r.timeseries
    half = r.mechanism.slot_clearance / 2
    gap, residual = ts.gap_m.to_numpy(), np.abs(ts.constraint_residual_m.to_numpy())
    engaged = (ts["mode"] == "engaged").to_numpy()
    # in contact the gap is the flank constraint's residual (the integrator's drift, within its tolerances)
    assert np.allclose(np.abs(gap[engaged]), residual[engaged], rtol=1e-6, atol=1e-15)
    assert np.max(residual) < 1e-3 * half
    assert np.all(gap[~engaged] >= -1e-3 * half) and np.all(gap <= half * (1 + 1e-12))
    assert np.min(gap[~engaged]) < 0.5 * half


def test_convergence_to_the_exact_fit():
    """Plastic impacts, a load that keeps the pin on the driving flank: as the clearance c shrinks the energy lost
    (the entry impact and the lock taking the wheel) is proportional to c, and the crank angle approaches the
    exact-fit model's at order between 1/2 (the gap crossed at entry in a crank angle ~ sqrt(c / r)) and 1."""
    base = ["contact.restitution=0", "duration=0.8 s", "load.wheel_torque=2 N*m", *TIGHT]
    exact = run(*base, "mechanism.slot_clearance=0 m").timeseries.crank_angle_rad.to_numpy()
    err, lost = [], []
    for c in (2e-4, 1e-4, 5e-5):
        r = run(*base, f"mechanism.slot_clearance={c} m")
        assert r.failure is None
        assert set(r.events.kind) <= {"entry", "impact", "exit", "slip reversal", "flight apex"}
        err.append(np.max(np.abs(r.timeseries.crank_angle_rad.to_numpy() - exact)))
        lost.append(r.events.energy_lost_J.sum())
    assert lost[0] / lost[1] == pytest.approx(2.0, rel=1e-2) and lost[1] / lost[2] == pytest.approx(2.0, rel=1e-2)
    orders = np.log2(np.array(err[:-1]) / np.array(err[1:]))
    assert np.all((orders > 0.5) & (orders < 1.0))


def test_ida_and_diffrax_agree():
    """The same impacts on both backends (diffrax hands every impact back to the Python loop)."""
    over = ["duration=0.32 s", "solver.rtol=1e-9", "solver.atol=1e-11"]
    a, b = run(*over), run(*over, "solver.backend=diffrax")
    assert a.failure is None and b.failure is None
    for col in ("crank_angle_rad", "wheel_angle_rad"):
        assert np.max(np.abs(a.timeseries[col].to_numpy() - b.timeseries[col].to_numpy())) < 1e-7
    assert list(a.events.kind) == list(b.events.kind)
    assert np.max(np.abs(a.events.t_s.to_numpy() - b.events.t_s.to_numpy())) < 1e-7
    ia, ib = (x.events.impulse_N_s.dropna().to_numpy() for x in (a, b))
    assert np.max(np.abs(ia - ib)) < 1e-5 * np.max(np.abs(ia))


def test_prescribed_speed_impacts_dissipate_and_the_drive_works():
    """At a prescribed crank speed the drive constraint takes an impulse too: the kinetic energy's change is its
    impulsive work minus the dissipation, so each impact's energy lost is the dissipation (>= 0) and the balance
    closes with the drive's work (dynamics/transitions.impact_split)."""
    w = 8.0
    T = np.radians(245) / w
    r = run("drive.type=speed", f"drive.speed={w} rad/s", f"duration={T} s", f"output_step={T / 500} s", *TIGHT)
    assert r.failure is None
    impacts = r.events[r.events.kind.str.startswith("impact")]
    assert len(impacts) >= 5 and np.all(impacts.energy_lost_J > 0)
    ke_drop = impacts.kinetic_energy_before_J - impacts.kinetic_energy_after_J
    assert np.max(np.abs(ke_drop - impacts.energy_lost_J)) > 1e-3 * impacts.energy_lost_J.max()  # drive's share
    ts = r.timeseries
    works = [c for c in ts.columns if c.startswith("work_")]
    throughput = sum(float(np.max(np.abs(ts[c]))) for c in works) + float(np.max(ts.kinetic_energy_J))
    assert np.max(np.abs(energy_closure(ts, r.events))) < 1e-6 * throughput


@pytest.mark.parametrize("setting, field", [
    ("mechanism.slot_clearance=-1 mm", "mechanism.slot_clearance"),
    ("mechanism.slot_clearance=nan mm", "mechanism.slot_clearance"),
    ("mechanism.slot_clearance=5 mm", "mechanism.slot_clearance"),
    ("contact.restitution=1.5", "contact.restitution"),
    ("contact.restitution=-0.1", "contact.restitution"),
])
def test_bad_input_names_the_field(setting, field):
    with pytest.raises((ScenarioError, ValueError)) as info:
        runner.plan(api.load(SCENARIO, set=[setting]))
    assert field in str(info.value) and "\n" not in str(info.value)


def test_clearance_refuses_varying_loads():
    """Per-station and time-varying wheel torques are not modelled with clearance: refused, naming the key."""
    m = dict(slots=4, crank_radius=0.075, pin_radius=0.004, thickness=0.004, crank_inertia=0.02,
             wheel_inertia=1.5e-3, slot_clearance=2.5e-4)
    with pytest.raises(ValueError, match=r"^load\.wheel_torque_per_station: with mechanism\.slot_clearance"):
        Geneva.from_config({"mechanism": m, "load": {"wheel_torque_per_station": [1.0, 1.0, 1.0, 1.0]}})
    assert type(Geneva.from_config({"mechanism": m, "load": {"wheel_torque": 1.0}})) is GenevaClearance


@pytest.fixture(scope="module")
def heated():
    """The built-in scenario with the lumped bulk network: impacts in every engagement beside the sliding heat."""
    return run("thermal.model=lumped")


def test_impact_heat_closes_the_heat_balance(heated):
    """The heat generated is the mechanics' friction work plus the pin-flank impacts' energy lost (the lock taking
    the wheel at exit dissipates at the locking arc, not at this contact), to 1e-6; stored +
    convected close it at the tolerance the sliding-only balance closes (the impacts' jumps and their decay,
    thermal/impact.py, are in the stored and the convected heat independently)."""
    hb, ev = heated.summary["thermal"]["heat_balance"], heated.events
    lost = ev.energy_lost_J[ev.kind.str.startswith("impact")].sum()
    assert lost > 5e-3 * hb["generated_J"]                                   # the impacts matter at this tolerance
    assert hb["impacts_J"] == pytest.approx(lost, rel=1e-12)
    assert heated.summary["thermal"]["impacts"]["heat_J"] == pytest.approx(lost, rel=1e-12)
    friction = -heated.summary["energy"]["work_J"]["friction"]        # the mechanics' own friction work
    assert hb["generated_J"] == pytest.approx(friction + lost, rel=1e-6)
    assert hb["sliding_J"] == pytest.approx(hb["generated_J"] - lost, rel=1e-12)
    assert abs(hb["closure_error_relative"]) < 1e-7, hb


def test_impact_flash_estimate_closed_form(heated):
    """Each impact's approach speed v and effective mass m obey Newton's law (impulse m (1 + e) v, energy lost
    m (1 - e^2) v^2 / 2); the largest impact's flash rise against the closed form of docs/theory.md §G2.2: a
    half-sine pulse of the spring E* l, tau = pi sqrt(m / (E* l)), F = v sqrt(m E* l), Hertz half-width b(F),
    dT = E / (b l 2 e sqrt(pi tau)) with the effusivity e = k / sqrt(chi) of the one material."""
    ev = heated.events
    hits = ev[ev.kind.str.startswith("impact")]
    e = np.where((hits.kind == "impact") & (hits.to_mode == "free"), 0.5, 0.0)
    m, v = hits.impact_mass_kg.to_numpy(), hits.approach_speed_m_s.to_numpy()
    # rtol: a plastic restart's projection leaves the rebound rate r+ at the solver's tolerance, not at zero
    np.testing.assert_allclose(np.abs(hits.impulse_N_s), m * (1 + e) * v, rtol=1e-8)
    np.testing.assert_allclose(hits.energy_lost_J, 0.5 * m * (1 - e**2) * v**2, rtol=1e-6)
    th = heated.summary["thermal"]
    mat = th["material"]
    E_star = mat["E_Pa"] / (2 * (1 - mat["nu"] ** 2))
    R, l = 4e-3, 4e-3
    k = hits.impact_flash_rise_K.to_numpy().argmax()
    tau = np.pi * np.sqrt(m[k] / (E_star * l))
    F = v[k] * np.sqrt(m[k] * E_star * l)
    b = np.sqrt(4 * F * R / (np.pi * l * E_star))
    effusivity = mat["conductivity_W_mK"] / np.sqrt(mat["diffusivity_m2_s"])
    rise = hits.energy_lost_J.iloc[k] / (b * l * 2 * effusivity * np.sqrt(np.pi * tau))
    assert hits.impact_flash_rise_K.iloc[k] == pytest.approx(rise, rel=1e-12)
    assert th["impacts"]["flash_rise_max_K"] == pytest.approx(rise, rel=1e-12)
    assert th["impacts"]["duration_at_max_s"] == pytest.approx(tau, rel=1e-12)
    np.testing.assert_allclose(heated.extra_tables["impacts"].impact_flash_rise_K,
                               hits.impact_flash_rise_K, rtol=0)


def test_impact_heat_in_the_track_mesh_and_no_cycle_averaging():
    """The 1-D track model takes the wheel's share as a pulse into the surface cell of the track in contact: its
    balance closes with the impacts too. Cycle averaging, which reads the sliding heat only, is refused."""
    r = run("thermal.model=1d", "duration=0.8 s")
    hb = r.summary["thermal"]["heat_balance"]
    lost = r.events.energy_lost_J[r.events.kind.str.startswith("impact")].sum()
    assert lost > 0 and hb["impacts_J"] == pytest.approx(lost, rel=1e-12)
    assert abs(hb["closure_error_relative"]) < 1e-7, hb
    with pytest.raises((ScenarioError, ValueError), match="thermal.averaging") as info:
        runner.plan(api.load(SCENARIO, set=["thermal.model=lumped", "thermal.averaging=cycle"]))
    assert "\n" not in str(info.value)


def test_impacts_summary_sweep_row_and_report(heated):
    """summary['impacts']: the largest impulse is the events' largest |P| (impacts are located events), the impacts
    per turn are the impacts table's; a sweep table's row carries them, and report.html has their section."""
    from mechsim.scenarios.output.report_html import report_html
    from mechsim.scenarios.studies.sweep.rows import summary_row
    ev, table = heated.events, heated.extra_tables["impacts"]
    hits = ev[ev.kind.str.startswith("impact")]
    s = heated.summary["impacts"]
    assert s["count"] == len(hits) and s["peak_impulse_N_s"] == np.abs(hits.impulse_N_s).max()
    at = hits.t_s.iloc[int(np.argmax(np.abs(hits.impulse_N_s.to_numpy())))]
    assert s["peak_impulse_at_t_s"] == at
    per_turn = table.groupby("turn").size()
    assert s["impacts_per_turn_max"] == per_turn.max() >= 8 and s["impacts_per_turn_mean"] == per_turn.mean()
    assert s["energy_lost_J"] == pytest.approx(hits.energy_lost_J.sum(), rel=1e-12)
    row = summary_row(heated.summary)
    assert row["peak_impulse_N_s"] == s["peak_impulse_N_s"] and row["impacts_per_turn_max"] == s["impacts_per_turn_max"]
    page = report_html(heated, {})
    assert "<h2>Impacts</h2>" in page and "peak impulse" in page and "N·s" in page


def test_the_console_names_the_impacts(heated):
    """The console's impacts line says the summary's numbers: the count, the largest impulse and where, the energy
    lost and the largest impact flash."""
    from mechsim.scenarios.console import impacts_line
    s = heated.summary
    line = impacts_line(s)
    assert line.startswith(f"impacts: {s['impacts']['count']} ({s['impacts']['impacts_per_turn_max']} per turn")
    assert f"{s['impacts']['peak_impulse_N_s'] * 1e3:.4g} mN*s" in line
    assert f"+{s['thermal']['impacts']['flash_rise_max_K']:.3g} K" in line
    assert impacts_line({"impacts": {"count": 0}}) is None and impacts_line({}) is None


def test_index3_is_refused_with_the_rigid_contact(tmp_path):
    """IDA's index-3 form fails at the first restart onto a flank (a plastic impact; docs/geneva.md 'Clearance and
    impacts'): refused at load, one line naming solver.formulation, exit 2, nothing written. diffrax (the index-1 ODE
    whatever the key) and the compliant contact (no flank constraint) keep it."""
    from cli_helpers import invoke, one_line_error
    r = invoke("run", SCENARIO, "--set", "solver.formulation=index3", "--out", tmp_path / "o", "--quiet")
    line = one_line_error(r)
    assert r.exit_code == 2 and "solver.formulation" in line and "'index2'" in line
    assert not (tmp_path / "o").exists()
    for kept in (["solver.backend=diffrax"], ["contact.model=compliant"]):
        assert runner.plan(api.load(SCENARIO, set=["solver.formulation=index3", *kept])).settings.formulation == "index3"
