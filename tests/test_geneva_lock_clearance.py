"""The Geneva's lock play (mechanism.lock_clearance, mechanisms/geneva/clearance.py): zero play is the clearance model
as it was, the DAE against the reduced-coordinate reference with the play, Newton's law and the energy balance at
the lock impacts, the lock impacts kept out of the pin contact's heat, convergence as the play shrinks, IDA against
diffrax, refused input (docs/geneva.md 'Clearance and impacts')."""
from __future__ import annotations

import numpy as np
import pytest

import mechsim.scenarios.api as api
from mechsim.dynamics.invariants import energy_closure
from mechsim.mechanisms.geneva import clearance_reduced
from mechsim.mechanisms.geneva.clearance import GenevaClearance
from mechsim.scenarios import runner
from mechsim.scenarios.schema import ScenarioError

SCENARIO = "geneva-clearance"
TIGHT = ["solver.rtol=1e-10", "solver.atol=1e-12"]
#: a fast, lightly loaded index: the wheel overruns the pin late in the index, so the pin leaves on the trailing
#: flank, the lock takes the wheel at the leading end of a 3.2 mrad play (at most 3.33 mrad here) and the load
#: swings it back onto the trailing end, where it bounces (restitution 0.5) and comes to rest
PLAY = ["mechanism.lock_clearance=3.2e-3 rad", "drive.no_load_speed=14 rad/s", "initial.crank_speed=10 rad/s",
        "load.wheel_torque=0.1 N*m"]
#: events that only split the integration (a flight's or a play's apex) or are bookkeeping at mu = 0
SPLITS = ["slip reversal", "flight apex", "play apex"]


def run(*settings):
    return api.run(api.load(SCENARIO, set=list(settings)))


def throughput(ts):
    works = [c for c in ts.columns if c.startswith("work_")]
    return sum(float(np.max(np.abs(ts[c]))) for c in works) + float(np.max(ts.kinetic_energy_J))


def test_zero_lock_clearance_is_the_clearance_model():
    """lock_clearance 0 (the default) builds the clearance model as it was: its parameters, structure, modes and
    transition table; a play adds the 'play' mode and the lock's parameters."""
    plain = runner.plan(api.load(SCENARIO)).mechanism
    zero = runner.plan(api.load(SCENARIO, set=["mechanism.lock_clearance=0 rad"])).mechanism
    assert type(zero) is GenevaClearance and zero.lock_clearance == 0.0
    assert zero.parameter_values() == plain.parameter_values() and "lock_play" not in zero.parameter_names
    assert zero.structure_key() == plain.structure_key()
    assert set(zero.modes()) == {"engaged", "dwell", "free"}
    assert set(zero.transitions()) == set(plain.transitions())
    played = runner.plan(api.load(SCENARIO, set=PLAY)).mechanism
    assert set(played.modes()) == {"engaged", "dwell", "free", "play"}
    assert played.parameter_values()["lock_play"] == 3.2e-3 and played.structure_key() != plain.structure_key()


#: the wheel free in its play at exit (the pin in flight) and still bouncing there at the next entry: a light load,
#: a lively lock (restitution 0.9), the largest play the geometry allows to 1 %
INTO_PLAY = ["mechanism.lock_clearance=3.3e-3 rad", "drive.no_load_speed=12 rad/s", "initial.crank_speed=8.4 rad/s",
             "load.wheel_torque=0.02 N*m", "contact.restitution=0.9"]


@pytest.mark.parametrize("settings, duration, dt_bound", [(PLAY, 0.6, 1e-8), (INTO_PLAY, 1.0, 1e-7)],
                         ids=["onto-the-end", "into-the-play"])
def test_dae_matches_the_reduced_reference_with_lock_play(settings, duration, dt_bound):
    """Frictionless: crank and wheel angles and every event (entry with the wheel off its nominal angle, on an end
    of the play or moving in it; the pin's impacts; exit onto the nearer end or into the play; the wheel's bounces)
    against the reduced-coordinate integration with its own lock law (scipy DOP853), both at tight tolerances: the
    clearance test's bounds (1e-7 rad, 1e-8 s). An impact's time is its position's error over the closing speed,
    which falls to about the bounce speed over e before a bounce train ends; at e = 0.9 a train of 30 bounces
    carries each impact's error into the next: 1e-7 s there (measured 3.7e-8 s)."""
    scenario = api.load(SCENARIO, set=["contact.friction=0", f"duration={duration} s", *TIGHT, *settings])
    r = api.run(scenario)
    assert r.failure is None
    ts, mech = r.timeseries, r.mechanism
    dv = runner.plan(scenario).drive.parameter_values(0.0)
    t = ts.t_s.to_numpy()
    theta, psi, events = clearance_reduced.integrate(mech, dv["drive_T0"], dv["drive_slope"],
                                                     float(ts.crank_angle_rad[0]), float(ts.crank_speed_rad_s[0]), t)
    assert np.max(np.abs(theta - ts.crank_angle_rad.to_numpy())) < 1e-7
    assert np.max(np.abs(psi - ts.wheel_angle_rad.to_numpy())) < 1e-7
    dae = r.events[~r.events.kind.isin(SPLITS)]
    assert list(dae.kind) == [e[1] for e in events]
    assert list(dae.to_mode) == [e[2] for e in events]
    assert np.max(np.abs(dae.t_s.to_numpy() - [e[0] for e in events])) < dt_bound
    hits = dae[dae.kind == "lock impact"]
    assert (hits.to_mode == "play").sum() >= 3
    exits = dae[dae.kind == "exit"]
    if settings is PLAY:           # the pin leaves on the trailing flank, the wheel ahead of the play: onto its end
        assert list(exits.to_mode) == ["play"] and exits.impulse_N_s.notna().all()
        assert list(hits.to_mode)[-1] == "dwell"
    else:                          # the pin in flight, the wheel within its play: it goes on free, no impact
        assert set(exits.to_mode) == {"play"} and exits.impulse_N_s.isna().all()
        assert "play" in set(dae.from_mode[dae.kind == "entry"])
    # the wheel stays within its play in the dwell
    dwell = ts["mode"].isin(["dwell", "play"]).to_numpy()
    pitch = mech.geometry.pitch
    w = ts.wheel_angle_rad.to_numpy()
    offset = w - (np.round(w / pitch - 0.5) + 0.5) * pitch
    assert np.max(np.abs(offset[dwell])) < mech.lock_clearance / 2 * (1 + 1e-6)


def test_without_load_the_wheel_stays_where_the_lock_put_it():
    """No wheel torque: a wheel at rest on an end has a lock force of exactly zero; it stays there (no release, no
    motion) through the dwell, as the reduced reference holds it (-s T_L >= 0)."""
    r = run("duration=1.2 s", "mechanism.lock_clearance=3.2e-3 rad", "load.wheel_torque=0 N*m")
    assert r.failure is None
    ev, ts = r.events, r.timeseries
    assert "lock release" not in set(ev.kind) and (ev.kind == "entry").sum() == 2
    t_exit, t_entry = ev.t_s[ev.kind == "exit"].iloc[0], ev.t_s[ev.kind == "entry"].iloc[1]
    held = ((ts.t_s > t_exit) & (ts.t_s < t_entry)).to_numpy()
    assert set(ts["mode"][held]) == {"dwell"}
    w = ts.wheel_angle_rad.to_numpy()[held]
    pitch = r.mechanism.geometry.pitch
    offset = w - (np.round(w / pitch - 0.5) + 0.5) * pitch     # the pin left on the trailing flank: leading end
    assert np.allclose(offset, r.mechanism.lock_clearance / 2, rtol=0, atol=1e-9)


@pytest.fixture(scope="module")
def heated():
    """Friction 0.15, the lumped thermal network: pin impacts, the exit's lock impact and the wheel's bounces (the
    scenario's tolerances, rtol 1e-8)."""
    return run("duration=0.6 s", "thermal.model=lumped", *PLAY)


def test_newton_law_at_every_lock_impact(heated):
    """The lock constraint r (psi - psi_end) moves the wheel only: k = G M^-1 G^T = r^2 / J2, and each lock impact's
    energy lost is (1 - e) / (2 (1 + e)) k P^2 with e the rule's (0 where the wheel stays or leaves at once); a
    rebound leaves the wheel at -e times its speed."""
    r = heated
    assert r.failure is None
    mech, ev = r.mechanism, r.events
    hits = ev[ev.kind.str.startswith("lock impact") | ((ev.kind == "exit") & ev.impulse_N_s.notna())]
    assert len(hits) >= 4
    k = mech.geometry.crank_radius**2 / mech.wheel_inertia
    e = np.where((hits.kind == "lock impact") & (hits.to_mode == "play"), mech.restitution, 0.0)
    np.testing.assert_allclose(hits.energy_lost_J, (1 - e) / (2 * (1 + e)) * k * hits.impulse_N_s**2, rtol=1e-6)
    assert np.all(hits.energy_lost_J > 0)
    table = r.extra_tables["lock_impacts"]
    assert len(table) == len(hits) and r.summary["lock_impacts"]["count"] == len(hits)
    assert r.summary["lock_impacts"]["energy_lost_J"] == pytest.approx(hits.energy_lost_J.sum(), rel=1e-12)
    assert set(table.end) == {"leading", "trailing"}


def test_energy_closes_with_the_lock_losses(heated):
    """Works = change of kinetic energy + pin and lock impact losses, on every row, to 1e-6 of the throughput; the
    lock's losses exceed that tolerance tenfold."""
    r = heated
    ts, ev = r.timeseries, r.events
    lock = ev.energy_lost_J[ev.kind.str.startswith("lock impact") | (ev.kind == "exit")].sum()
    bound = 1e-6 * throughput(ts)
    assert lock > 10 * bound                                   # left out, they would open the balance
    assert np.max(np.abs(energy_closure(ts, ev))) < bound


def test_lock_impacts_do_not_heat_the_pin_contact(heated):
    """The locking arc is another contact than the pin and slot: the pin contact's heat is its friction work plus the
    pin-flank impacts' losses only (docs/theory.md §G2.2), and its balance still closes."""
    hb, ev = heated.summary["thermal"]["heat_balance"], heated.events
    pin = ev.energy_lost_J[ev.kind.str.startswith("impact")].sum()
    assert hb["impacts_J"] == pytest.approx(pin, rel=1e-12)
    friction = -heated.summary["energy"]["work_J"]["friction"]
    assert hb["generated_J"] == pytest.approx(friction + pin, rel=1e-6)
    assert abs(hb["closure_error_relative"]) < 1e-7, hb


def test_lock_impacts_in_console_report_and_figure(heated):
    """The console's impacts line, report.html and a sweep table's row name the lock impacts; the lock figure draws
    the wheel's offset inside the play's ends."""
    from mechsim.scenarios.console import impacts_line
    from mechsim.scenarios.output.report_html import report_html
    lock = heated.summary["lock_impacts"]
    assert f"lock impacts {lock['count']} (largest {lock['peak_impulse_N_s'] * 1e3:.4g} mN*s" in impacts_line(
        heated.summary)
    assert "lock impacts: count" in report_html(heated, {})
    from mechsim.scenarios.studies.sweep.rows import summary_row
    row = summary_row(heated.summary)
    assert row["lock_impacts"] == lock["count"] and row["lock_peak_impulse_N_s"] == lock["peak_impulse_N_s"]
    fig = heated.mechanism.extra_figures(heated.timeseries, heated.extra_tables)["lock_play_vs_angle"]
    ax = fig.axes[0]
    half = heated.mechanism.lock_clearance / 2 * 1e3
    drawn = np.concatenate([line.get_ydata() for line in ax.get_lines()[:-2]] if len(ax.get_lines()) > 2 else [[]])
    assert len(drawn) and np.max(np.abs(drawn)) <= half * (1 + 1e-6)


def test_a_separation_starts_a_flight_without_an_apex():
    """The wheel overruns the pin: its normal force falls through zero and the pin leaves the driving flank with the
    gap, its rate and its acceleration all zero, the rate's zero a double one, so its sign there is round-off. The
    flight's apex guard is armed only once the gap has opened past the arm (`GenevaClearance._apex_guard`): at tight
    tolerances it fired at the separation itself, then again at once (a chattering failure at t = 0.2305 s). The
    pin crosses the gap: its offset falls monotonically to the trailing flank's impact, no apex between, and the
    energy closes through the flight to 1e-6 of the throughput."""
    r = run("duration=0.24 s", "thermal.model=lumped", *TIGHT, *PLAY)
    assert r.failure is None
    ev, ts = r.events.reset_index(drop=True), r.timeseries
    k = int(np.flatnonzero(ev.kind == "separation")[0])
    sep, hit = ev.iloc[k], ev.iloc[k + 1]
    assert sep.from_mode == "engaged" and (hit.kind, hit.guard, hit.from_mode) == ("impact", "close_trailing", "free")
    flight = ((ts.t_s > sep.t_s) & (ts.t_s < hit.t_s)).to_numpy()
    offset = ts.pin_offset_m.to_numpy()[flight]
    half = r.mechanism.slot_clearance / 2
    assert len(offset) >= 5 and np.all(np.diff(offset) < 0) and half > offset[0] > offset[-1] > -half
    assert np.max(np.abs(energy_closure(ts, r.events))) < 1e-6 * throughput(ts)


def test_apex_guard_is_the_gap_rate_outside_the_arm():
    """The apex guard: the gap's rate where |gap| >= arm (an apex located where it was), lifted by the bounce speed
    at the flank (gap 0: a flight leaving without a rebound) and linearly in between."""
    arm, speed = 2.5e-13, 1e-3
    guard = runner.plan(api.load(SCENARIO)).mechanism._apex_guard
    for gap in (arm, 3 * arm, 1e-4, -arm, -1e-6):
        assert guard(gap, -0.2, arm, speed) == -0.2
    assert guard(0.0, 0.0, arm, speed) == speed
    assert guard(arm / 4, 1e-4, arm, speed) == pytest.approx(1e-4 + 0.75 * speed, rel=1e-12)


def test_convergence_as_the_play_shrinks():
    """Plastic impacts, the load holding the wheel on the trailing end of its play: as the play delta halves, the
    crank angle approaches the model without play at first order (the pin meets the slot's driving flank nearer by
    x_e sin(delta/2), which shifts its entry impact linearly) and the energy lost by delta's linear term."""
    base = ["contact.restitution=0", "duration=0.8 s", "load.wheel_torque=2 N*m", *TIGHT]
    ref = run(*base)
    exact = ref.timeseries.crank_angle_rad.to_numpy()
    err, lost = [], []
    for d in (8e-4, 4e-4, 2e-4, 1e-4):
        r = run(*base, f"mechanism.lock_clearance={d} rad")
        assert r.failure is None
        err.append(np.max(np.abs(r.timeseries.crank_angle_rad.to_numpy() - exact)))
        lost.append(r.events.energy_lost_J.sum() - ref.events.energy_lost_J.sum())
    orders = np.log2(np.array(err[:-1]) / np.array(err[1:]))
    assert np.all((orders > 0.95) & (orders < 1.15)), orders
    np.testing.assert_allclose(np.array(lost[:-1]) / np.array(lost[1:]), 2.0, rtol=2e-3)


def test_ida_and_diffrax_agree_with_lock_play():
    """The same events and angles on both backends through the exit and the wheel's bounces in its play."""
    over = ["duration=0.36 s", "solver.rtol=1e-9", "solver.atol=1e-11", *PLAY]
    a, b = run(*over), run(*over, "solver.backend=diffrax")
    assert a.failure is None and b.failure is None
    for col in ("crank_angle_rad", "wheel_angle_rad"):
        assert np.max(np.abs(a.timeseries[col].to_numpy() - b.timeseries[col].to_numpy())) < 1e-7
    assert list(a.events.kind) == list(b.events.kind) and (a.events.kind == "lock impact").sum() >= 3
    assert np.max(np.abs(a.events.t_s.to_numpy() - b.events.t_s.to_numpy())) < 1e-7
    ia, ib = (x.events.impulse_N_s.dropna().to_numpy() for x in (a, b))
    assert np.max(np.abs(ia - ib)) < 1e-5 * np.max(np.abs(ia))


@pytest.mark.parametrize("setting, reason", [
    ("mechanism.lock_clearance=-1e-3 rad", "must not be negative"),
    ("mechanism.lock_clearance=nan rad", "finite"),
    ("mechanism.lock_clearance=0.2 deg", "strike the slot's corner"),
])
def test_bad_lock_play_names_the_field(setting, reason):
    with pytest.raises((ScenarioError, ValueError)) as info:
        runner.plan(api.load(SCENARIO, set=[setting]))
    message = str(info.value)
    assert "mechanism.lock_clearance" in message and reason in message and "\n" not in message


def test_lock_play_needs_slot_clearance():
    """An exact-fit slot turned off its nominal angle cannot take the pin: refused in one line."""
    with pytest.raises((ScenarioError, ValueError), match=r"mechanism\.lock_clearance: lock play needs slot") as info:
        runner.plan(api.load(SCENARIO, set=["mechanism.slot_clearance=0 m", "mechanism.lock_clearance=1e-3 rad"]))
    assert "\n" not in str(info.value)


def test_lock_play_needs_the_rigid_contact():
    """The compliant contact's model has no play modes: lock play with it is refused in one line."""
    with pytest.raises((ScenarioError, ValueError), match=r"mechanism\.lock_clearance: .*rigid") as info:
        runner.plan(api.load(SCENARIO, set=["contact.model=compliant", "mechanism.lock_clearance=1e-3 rad"]))
    assert "\n" not in str(info.value)


def test_cli_refuses_a_play_too_large(tmp_path):
    from cli_helpers import invoke, one_line_error
    r = invoke("run", SCENARIO, "--set", "mechanism.lock_clearance=1 deg", "--out", tmp_path / "o", "--quiet")
    assert r.exit_code == 2 and "mechanism.lock_clearance" in one_line_error(r)
    assert not (tmp_path / "o").exists()
