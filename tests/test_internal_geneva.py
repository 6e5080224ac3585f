"""The internal Geneva drive (docs/internal_geneva.md): its closed forms, the hybrid DAE against them and against the
independent reduced-coordinate reference, IDA against diffrax, energy and heat balances."""
import numpy as np
import pytest

from mechsim.dynamics.drives import Drive
from mechsim.dynamics.hybrid import simulate
from mechsim.dynamics.settings import SolverSettings
from mechsim.dynamics.tables import events_table, timeseries
import mechsim.mechanisms.geneva.reduced as reduced
from mechsim.mechanisms import MECHANISMS
from mechsim.mechanisms.geneva.kinematics import GenevaGeometry, constant_speed_motion
from mechsim.mechanisms.internal_geneva.kinematics import InternalGenevaGeometry, speed_ratio_second_derivative
from mechsim.mechanisms.internal_geneva.model import InternalGeneva

J1, J2 = 0.02, 0.02
W1 = 5.34


@pytest.fixture(scope="module")
def geometry():
    """The built-in scenarios' wheel: n = 6, r = 50 mm (c = 100 mm), R = 4 mm, 4 mm thick."""
    return InternalGenevaGeometry(crank_radius=0.05, slots=6, pin_radius=0.004, thickness=0.004)


def run(mech, drive, t_end, formulation="index2", rtol=1e-10, atol=1e-12, angle0=-np.pi, speed0=W1, dt=1e-3,
        backend="ida"):
    traj = simulate(mech, drive, SolverSettings(backend=backend, formulation=formulation, rtol=rtol, atol=atol),
                    t_end, dt, angle0, speed0)
    assert traj.failure is None, traj.failure
    return traj, timeseries(traj, mech.angle_coordinates)


# -- closed forms ------------------------------------------------------------------------------------------------
@pytest.mark.parametrize("n", [3, 4, 5, 6, 8, 12])
def test_engaged_share_index_and_peak_speed_ratio(n):
    """Engaged for pi + 2 pi/n of each crank turn (share 1/2 + 1/n), one index 2 pi/n per engagement, peak wheel/crank
    speed ratio s/(1 + s) with s = sin(pi/n) at mid-engagement, the wheel turning with the crank throughout."""
    g = InternalGenevaGeometry(crank_radius=0.05, slots=n, pin_radius=0.002, thickness=0.004)
    s = np.sin(np.pi / n)
    a0 = g.engagement_half_angle
    assert 2 * a0 / (2 * np.pi) == pytest.approx(0.5 + 1 / n, rel=1e-15)
    assert 1 - g.dwell_fraction == pytest.approx(0.5 + 1 / n, rel=1e-15)
    assert g.centre_distance == pytest.approx(g.crank_radius / s, rel=1e-15)
    beta, G, _, _ = g.wheel_motion(g.ratio, np.array([-a0, 0.0, a0]))
    np.testing.assert_allclose(beta, [-np.pi / n, 0.0, np.pi / n], atol=1e-15)     # one index 2 pi/n
    assert G[1] == pytest.approx(s / (1 + s), rel=1e-14)
    # G > 0 (same sense) inside, and its largest value on a fine grid is the mid-engagement one
    alpha = np.linspace(-a0, a0, 20001)[1:-1]
    G_in = g.wheel_motion(g.ratio, alpha)[1]
    assert G_in.min() > 0 and G_in.max() == pytest.approx(s / (1 + s), rel=1e-12)
    assert alpha[np.argmax(G_in)] == pytest.approx(0.0, abs=2 * (alpha[1] - alpha[0]))
    # over whole turns at constant crank speed: the engaged share of uniformly spaced instants, and 2 pi/n per turn
    turns = 3
    theta = -np.pi + 2 * np.pi * turns * (np.arange(300000) + 0.5) / 300000
    cf = constant_speed_motion(g, theta, W1)
    assert cf["engaged"].mean() == pytest.approx(0.5 + 1 / n, abs=2e-5)
    assert cf["wheel_angle"][-1] - cf["wheel_angle"][0] == pytest.approx(turns * 2 * np.pi / n, rel=1e-12)
    assert np.all(np.diff(cf["wheel_angle"]) >= 0) and np.all(cf["wheel_speed"] >= 0)


@pytest.mark.parametrize("n", [3, 6, 10])
def test_derivatives_and_slot_frame_against_finite_differences(n):
    """G = dbeta/dalpha, G' = dG/dalpha, G'' = dG'/dalpha (central differences, step 1e-5: error ~1e-10 relative);
    along the motion the pin stays on the slot line (Phi = 0), its sliding speed per crank speed is s = dx/dalpha
    and the normal force's crank arm a = x G (virtual work)."""
    g = InternalGenevaGeometry(crank_radius=0.05, slots=n, pin_radius=0.002, thickness=0.004)
    lam, h = g.ratio, 1e-5
    alpha = np.linspace(-g.engagement_half_angle, g.engagement_half_angle, 41)

    def motion(a):
        return g.wheel_motion(lam, a)

    beta, G, Gp, xc = motion(alpha)
    (bp, Gpl, Gpp, xp), (bm, Gmi, Gpm, xm) = motion(alpha + h), motion(alpha - h)
    np.testing.assert_allclose((bp - bm) / (2 * h), G, atol=1e-9)
    np.testing.assert_allclose((Gpl - Gmi) / (2 * h), Gp, atol=1e-9)
    np.testing.assert_allclose((Gpp - Gpm) / (2 * h), speed_ratio_second_derivative(lam, alpha), atol=1e-8)
    r, c = g.crank_radius, g.centre_distance
    phi, x, s_slide, arm = g.pin_in_slot(r, c, alpha, beta)
    ulp = 4 * np.finfo(float).eps * (c + r)          # round-off of lengths of size c + r
    assert np.max(np.abs(phi)) < ulp
    np.testing.assert_allclose(x, c * xc, rtol=1e-15)
    np.testing.assert_allclose(np.hypot(*g.pin_position(r, c, alpha)), x, rtol=1e-15)
    np.testing.assert_allclose(c * (xp - xm) / (2 * h), s_slide, atol=1e-10)
    np.testing.assert_allclose(arm, x * G, atol=ulp)
    # the external drive's formulas are the same ones with c - r cos(alpha): its pin runs the near arc
    ext = GenevaGeometry(crank_radius=0.05, slots=n, pin_radius=0.002, thickness=0.004)
    np.testing.assert_allclose(np.hypot(*ext.pin_position(r, c, np.pi - alpha)), x, rtol=1e-15)


@pytest.mark.parametrize("n", [3, 6, 10])
def test_shock_free_entry_and_exit(n):
    """Tangential entry: at alpha = -+alpha0 the pin moves along the slot (the normal arm a = 0), so the wheel's speed
    starts and ends at zero (no velocity jump); its acceleration jumps by w^2 tan(pi/n), as for the external drive."""
    g = InternalGenevaGeometry(crank_radius=0.05, slots=n, pin_radius=0.002, thickness=0.004)
    a0 = g.engagement_half_angle
    beta, G, Gp, _ = g.wheel_motion(g.ratio, np.array([-a0, a0]))
    np.testing.assert_allclose(G, 0.0, atol=1e-15)
    np.testing.assert_allclose(Gp, [np.tan(np.pi / n), -np.tan(np.pi / n)], rtol=1e-13)
    arm = g.pin_in_slot(g.crank_radius, g.centre_distance, np.array([-a0, a0]), beta)[3]
    np.testing.assert_allclose(arm, 0.0, atol=4 * np.finfo(float).eps * g.crank_radius)
    # the closed form's wheel speed just inside and just outside the engagement agree to O(step)
    eps = 1e-9
    cf = constant_speed_motion(g, np.array([-a0 - eps, -a0 + eps, a0 - eps, a0 + eps]), W1)
    assert list(cf["engaged"]) == [False, True, True, False]
    assert np.max(np.abs(cf["wheel_speed"])) < 1e-7 and np.ptp(cf["wheel_angle"][:2]) < 1e-9


def test_geometry_refuses_a_pin_that_does_not_fit():
    with pytest.raises(ValueError, match="pin_radius"):
        InternalGenevaGeometry(crank_radius=0.05, slots=6, pin_radius=0.05, thickness=0.004)
    with pytest.raises(ValueError, match="slots"):
        InternalGenevaGeometry(crank_radius=0.05, slots=2, pin_radius=0.002, thickness=0.004)


# -- the hybrid DAE ------------------------------------------------------------------------------------------------
def test_registered_as_internal_geneva():
    assert MECHANISMS["internal_geneva"] is InternalGeneva
    mech = InternalGeneva.from_config({"mechanism": dict(slots=6, crank_radius=0.05, pin_radius=0.004, thickness=0.004,
                                                         crank_inertia=J1, wheel_inertia=J2)})
    assert isinstance(mech.geometry, InternalGenevaGeometry) and mech.structure_key() != ("Geneva",)


@pytest.mark.parametrize("n", [3, 6, 8])
def test_prescribed_speed_dae_matches_closed_form(n):
    """The DAE with the crank speed as a rheonomic constraint against the closed form over two turns: wheel angle,
    speed and acceleration, normal force (wheel's moment balance with friction), slip and drive torque to 1e-8 of
    their peaks; entry and exit at the closed form's crank angles 2 pi k -+ (pi/2 + pi/n), so the engagement lasts
    (pi + 2 pi/n)/w; one index 2 pi/n per turn, in the crank's sense."""
    geometry = InternalGenevaGeometry(crank_radius=0.05, slots=n, pin_radius=0.004, thickness=0.004)
    mech = InternalGeneva(geometry, J1, J2, wheel_torque=7.0, friction=0.15)
    traj, df = run(mech, Drive("speed", speed=W1), 2 * 2 * np.pi / W1)
    t = df["t_s"].to_numpy()
    cf = mech.closed_form(t, -np.pi, W1)
    for col in ("wheel_angle_rad", "wheel_speed_rad_s", "wheel_accel_rad_s2", "contact_force_N", "slip_speed_m_s",
                "drive_torque_N_m"):          # rtol 1e-10: measured 3e-11 to 1.5e-10 of the peaks
        assert np.max(np.abs(df[col].to_numpy() - cf[col])) <= 1e-8 * np.max(np.abs(cf[col])), col
    assert list(df["mode"]) == list(cf["mode"])
    ev = events_table(traj)
    ev = ev[ev["kind"].isin(["entry", "exit"])]          # the DAE lists its slip reversals too
    expected = mech.closed_form_events(t, -np.pi, W1)
    assert list(ev["kind"]) == [e["kind"] for e in expected] == ["entry", "exit", "entry", "exit"]
    np.testing.assert_allclose(ev["t_s"], [e["t_s"] for e in expected], atol=1e-9)
    assert ev["t_s"].iloc[1] - ev["t_s"].iloc[0] == pytest.approx((np.pi + 2 * np.pi / n) / W1, abs=1e-9)
    assert df["wheel_angle_rad"].iloc[-1] - df["wheel_angle_rad"].iloc[0] == pytest.approx(2 * 2 * np.pi / n,
                                                                                             rel=1e-9)


@pytest.mark.parametrize("backend", ["ida", "ida-compiled"])
def test_torque_drive_matches_the_reduced_reference(geometry, backend):
    """Constant crank torque with pin-slot friction and damping: theta(t) of the DAE (index 1, rtol 1e-11) equals the
    independent one-coordinate equation on DOP853 (mechanisms/geneva/reduced.py with the internal geometry) to 1e-8 rad
    over 4 turns and more (about 30 rad at rtol 1e-11: measured 4e-10), through entries, exits and slip reversals."""
    mech = InternalGeneva(geometry, J1, J2, wheel_torque=7.0, friction=0.1, crank_damping=0.5)
    traj, df = run(mech, Drive("torque", torque=6.0), 3.0, "index1", rtol=1e-11, atol=1e-13, backend=backend)
    kinds = set(events_table(traj)["kind"])
    assert {"entry", "exit", "slip reversal"} <= kinds and "flank switch" not in kinds   # the reference's flank
    t = df["t_s"].to_numpy()
    theta, omega = reduced.integrate(mech, 6.0, 0.0, -np.pi, W1, t)
    assert (theta[-1] - theta[0]) / (2 * np.pi) >= 4
    assert np.max(np.abs(df["crank_angle_rad"].to_numpy() - theta)) <= 1e-8
    assert np.max(np.abs(df["crank_speed_rad_s"].to_numpy() - omega)) <= 1e-8 * np.max(np.abs(omega))
    np.testing.assert_allclose(mech.reference_solution(Drive("torque", torque=6.0), t[:50], -np.pi, W1), theta[:50],
                               atol=1e-9)


def test_motor_with_friction_energy_closes(geometry):
    """Drive work = dKE - load, friction and damping work to 1e-7 of the drive work (rtol 1e-9; measured 1e-9) over
    4 turns and more; the drive work equals the quadrature of torque x speed; constraint residual <= 1e-9 m."""
    from scipy.integrate import trapezoid
    mech = InternalGeneva(geometry, J1, J2, wheel_torque=7.0, friction=0.15, crank_damping=0.002, wheel_damping=0.001)
    _, df = run(mech, Drive("motor", stall_torque=40.0, no_load_speed=8.0), 4.0, rtol=1e-9, atol=1e-11)
    assert (df["crank_angle_rad"].iloc[-1] - df["crank_angle_rad"].iloc[0]) / (2 * np.pi) >= 4
    works = {c: df[c].iloc[-1] for c in df.columns if c.startswith("work_")}
    dke = df["kinetic_energy_J"].iloc[-1] - df["kinetic_energy_J"].iloc[0]
    closure = sum(works.values()) - dke
    assert abs(closure) <= 1e-7 * works["work_drive_J"]
    assert works["work_friction_J"] < 0 and works["work_load_J"] < 0
    quad = trapezoid(df["drive_torque_N_m"] * df["crank_speed_rad_s"], df["t_s"])
    assert quad == pytest.approx(works["work_drive_J"], rel=1e-4)
    assert df["constraint_residual_m"].abs().max() <= 1e-9


# -- the scenario pipeline: both integrators, every thermal model ------------------------------------------------
def test_ida_and_diffrax_agree():
    """`mechsim compare --backends` on the motor scenario with friction (entries, slip reversals, exits over 2.5 s):
    the same event sequence, event times within 1e-8 s, every compared column within its tolerance (angles 1e-7 relative,
    speeds and forces 1e-6 / 1e-5) at rtol 1e-10, the same mode on every row (tests/test_compare_builtins.py leaves
    this built-in to this test)."""
    from mechsim.scenarios import api
    table = api.compare_backends("internal-geneva-motor", ["duration=2.5 s", "output_step=2 ms"],
                                  rtol=1e-10)
    assert table.attrs["failures"] == {} and table.attrs["passed"]
    assert table.attrs["same_event_sequence"] and table.attrs["events"]["ida"] >= 9
    assert table.attrs["event_time_max_diff_s"] < 1e-8
    rows = table.set_index("column")
    assert rows.loc["mode (rows differing)", "max_abs_diff"] == 0       # same mode on every output row
    for col in ("crank_angle_rad", "wheel_angle_rad", "crank_speed_rad_s", "wheel_speed_rad_s", "contact_force_N",
                "slip_speed_m_s"):
        assert rows.loc[col, "passed"], (col, rows.loc[col].to_dict())


@pytest.mark.parametrize("thermal", ["none", "flash", "lumped", "1d"])
@pytest.mark.parametrize("scenario", ["internal-geneva-speed", "internal-geneva-motor"])
def test_every_thermal_model_and_its_heat_balance(scenario, thermal):
    """The built-in scenarios (closed form at a prescribed speed; the DAE under a motor) with each thermal model:
    they succeed; the heat generated is the friction work of the mechanics, and generated = stored + convected to
    1e-6 of it where bulk temperatures are integrated (lumped, 1d); the flash rise is positive while sliding."""
    from mechsim.scenarios import api
    r = api.run(scenario, ["duration=1.5 s", f"thermal.model={thermal}"])
    assert r.success, r.failure
    df = r.timeseries
    if thermal == "none":
        assert "temp_contact_C" not in df and "thermal" not in r.summary
        return
    assert r.summary["thermal"]["model"] == thermal
    sliding = (df["mode"] == "engaged") & (df["slip_speed_m_s"].abs() > 1e-3)
    assert (df.loc[sliding, "temp_flash_rise_K"] > 0).all()
    if thermal in ("lumped", "1d"):
        hb = r.summary["thermal"]["heat_balance"]
        assert abs(hb["closure_error_relative"]) <= 1e-6, hb
        assert hb["generated_J"] > 0 and hb["stored_J"] > 0.9 * hb["generated_J"]
        if scenario == "internal-geneva-motor":       # the friction work: a state integrated with the mechanics
            assert hb["generated_J"] == pytest.approx(-df["work_friction_J"].iloc[-1], rel=1e-6)
        else:             # the closed form's friction power integrated adaptively (the table's trapezoid is 4e-4 off)
            from scipy.integrate import quad

            def power(t):
                return float(r.mechanism.closed_form_heat(np.array([0.0, t]), -np.pi, W1)["friction_power_W"][1])
            exact = quad(power, 0.0, 1.5, points=list(r.events["t_s"]), limit=500, epsabs=0.0, epsrel=1e-10)[0]
            assert hb["generated_J"] == pytest.approx(exact, rel=1e-6)


def test_sensitivities_match_finite_differences(geometry):
    """Forward trajectory sensitivities (dynamics/sensitivity.py) of crank angle, wheel speed and normal force at three
    instants of a motor run with friction (entry, slip reversal, exit, entry on the way) with respect to the wheel
    inertia, load torque, friction and crank radius (r with c = r / sin(pi/n)): elasticities (p/y) dy/dp equal
    Richardson-extrapolated central differences (steps 1e-3 and 5e-4 relative, so the differences' integrator noise
    rtol |y| / (p h) stays near 1e-7 in elasticity; measured below 1e-6) to 1e-4."""
    from mechsim.dynamics.hybrid import prepare
    from mechsim.dynamics.sensitivity import Seed, path_sensitivities
    drive = Drive("motor", stall_torque=40.0, no_load_speed=8.0)
    settings = SolverSettings(formulation="index2", rtol=1e-10, atol=1e-12)
    t_end, dt, times = 1.2, 1e-3, (0.3, 0.6, 1.0)
    columns = ("crank_angle_rad", "wheel_speed_rad_s", "contact_force_N")
    nominal = {"r": 0.05, "J2": J2, "T_L": 7.0, "mu": 0.15}

    def make(r, J2, T_L, mu):
        g = InternalGenevaGeometry(crank_radius=r, slots=6, pin_radius=0.004, thickness=0.004)
        return InternalGeneva(g, J1, J2, wheel_torque=T_L, friction=mu, crank_damping=0.002, wheel_damping=0.001)

    def values(**changed):
        mech = make(**{**nominal, **changed})
        traj = simulate(mech, drive, settings, t_end, dt, -np.pi, W1)
        assert traj.failure is None
        df = timeseries(traj, mech.angle_coordinates)
        rows = [int(round(t / dt)) for t in times]
        return {(c, t): float(df[c].iloc[i]) for c in columns for t, i in zip(times, rows)}, traj, mech

    base, traj, mech = values()
    ev = events_table(traj)
    assert list(ev["kind"]) == ["entry", "slip reversal", "exit", "entry"]
    names = list(prepare(mech, drive, settings, t_end, dt, -np.pi, W1).model.parameter_names)
    wrt = {"J2": {"J2": 1.0}, "T_L": {"T_L": 1.0}, "mu": {"mu": 1.0}, "r": {"r": 1.0, "c": 1 / np.sin(np.pi / 6)}}
    dp = np.zeros((len(names), len(wrt)))
    for j, parts in enumerate(wrt.values()):
        for name, d in parts.items():
            dp[names.index(name), j] = d
    zero = np.zeros((2, len(wrt)))         # the start (mid-dwell) depends on none of them
    seed = Seed(dp, zero, zero, frozenset({"slot", "lock_angle", "flank", "slide", "slot_base"}))
    path = path_sensitivities(mech, drive, settings, ev.to_dict("records"), seed, list(times), columns, t_end, dt,
                              -np.pi, W1)
    samples = {round(s.t, 9): s for s in path.samples}
    for j, key in enumerate(wrt):
        p, h = nominal[key], 1e-3
        diffs = []
        for step in (h, h / 2):
            plus, minus = values(**{key: p * (1 + step)})[0], values(**{key: p * (1 - step)})[0]
            diffs.append({q: (plus[q] - minus[q]) / (2 * p * step) for q in plus})
        for (col, t), y in base.items():
            fd = (4 * diffs[1][(col, t)] - diffs[0][(col, t)]) / 3
            sample = samples[round(t, 9)]
            assert sample.values[col] == pytest.approx(y, rel=1e-8, abs=1e-9)
            assert abs(sample.grads[col][j] - fd) * p / abs(y) <= 1e-4, (key, col, t, sample.grads[col][j], fd)
    # a pass asking for other columns runs on the model's tools already compiled (the event rule, the resets): only
    # its read-outs are new; the same integration, so the columns both passes read are the same numbers
    from mechsim.dynamics.programs import programs
    tools = {id(t) for t in programs("sensitivity_tools")}
    other = path_sensitivities(mech, drive, settings, ev.to_dict("records"), seed, list(times),
                               ("wheel_angle_rad",) + columns[::-1], t_end, dt, -np.pi, W1)
    assert {id(t) for t in programs("sensitivity_tools")} == tools
    for first, again in zip(path.samples, other.samples, strict=True):
        assert {c: again.values[c] for c in columns} == first.values
        for c in columns:
            assert np.array_equal(again.grads[c], first.grads[c])


# -- the drawing ---------------------------------------------------------------------------------------------------
@pytest.mark.parametrize("n", [3, 6, 12])
def test_the_drawn_wheel_leaves_the_pin_its_path(n):
    """Over a whole crank turn at constant speed (closed-form wheel angle) the pin, drawn at 0.98 R (the round slot
    bottom is a polygon inside its circle), stays in the ring's free space: the slot mouths lie on the entry circle
    c cos(pi/n) and the slot bottoms at the pin's deepest point c + r."""
    from matplotlib.path import Path
    from mechsim.mechanisms.internal_geneva.drawing import wheel_inner_outline
    g = InternalGenevaGeometry(crank_radius=0.05, slots=n, pin_radius=0.004, thickness=0.004)
    free = Path(wheel_inner_outline(g, samples=65))
    theta = np.linspace(-np.pi, np.pi, 721)
    psi = constant_speed_motion(g, theta, 1.0)["wheel_angle"]
    ring = 0.98 * g.pin_radius * np.exp(1j * np.linspace(0, 2 * np.pi, 48, endpoint=False))
    for th, ps in zip(theta, psi):
        pin = (g.centre_distance + g.crank_radius * np.exp(1j * th) + ring) * np.exp(-1j * ps)   # in the wheel frame
        assert free.contains_points(np.column_stack([pin.real, pin.imag])).all(), np.degrees(th)


def test_its_own_drawing_and_sensitivity_map():
    """The internal wheel is drawn with its own drawing, and its design sensitivities use its own map (the external
    Geneva's keys and parameters, its own start, contact geometry and contact state), not the external one's."""
    from mechsim.mechanisms.geneva.model import Geneva
    from mechsim.mechanisms.internal_geneva.drawing import InternalGenevaDrawing
    from mechsim.mechanisms.internal_geneva.sensitivity import MAP
    assert InternalGeneva.drawing_class() is InternalGenevaDrawing
    assert InternalGeneva.parameter_map() is MAP and MAP is not Geneva.parameter_map()
    assert MAP.keys == Geneva.parameter_map().keys


#: the peaks `mechsim sensitivity` differentiates here: two interior extrema and one at an event's one-sided limit
DESIGN_PEAKS = ["peak_contact_force_N", "peak_wheel_speed_rad_s", "peak_wheel_accel_rad_s2"]


@pytest.fixture(scope="module")
def design_sensitivities() -> dict:
    """`mechsim sensitivity` of DESIGN_PEAKS on the motor scenario against Richardson central differences of whole
    runs (`peaks_match_finite_differences` asserts each elasticity to 1e-4); one table and one set of difference runs
    for the two tests below, which check different peaks of it."""
    import mechsim
    from conftest import peaks_match_finite_differences
    from mechsim.scenarios.studies.sensitivity import sensitivity
    base = ["duration=1.45 s", "thermal.model=none", "solver.rtol=1e-10", "solver.atol=1e-12"]
    fd = ["duration=1.45 s", "thermal.model=none", "solver.rtol=1e-12", "solver.atol=1e-14"]
    wrt = ["load.wheel_torque", "contact.friction", "mechanism.crank_radius"]
    scenario = mechsim.load("internal-geneva-motor", set=base)
    table = sensitivity(scenario, wrt, DESIGN_PEAKS)
    assert set(table["quantity"]) == set(DESIGN_PEAKS)
    return peaks_match_finite_differences("internal-geneva-motor", table, wrt, fd, dict.fromkeys(wrt, 5e-4),
                                          scenario.si, value_rel=1e-7, floor=1e-6)


def test_design_sensitivities_match_finite_differences(design_sensitivities):
    """`mechsim sensitivity` on the motor scenario: the peaks' elasticities with respect to the load torque, the
    friction and the crank radius equal Richardson central differences of whole runs (step 5e-4, rtol 1e-12) to
    1e-4, through the internal Geneva's own parameter map."""
    assert {"peak_contact_force_N", "peak_wheel_speed_rad_s"} & set(design_sensitivities), design_sensitivities


def test_sensitivity_of_a_peak_at_an_event_limit(design_sensitivities):
    """The wheel's acceleration peaks at entry's one-sided limit (G' w1^2, kinematic: its elasticity by the load
    torque is 0 exactly); the derivative of that limit, with dF/dp extrapolated to the event from the two samples
    inside, equals the differences (to the floor where it is zero): checked in the fixture with the other peaks."""
    assert design_sensitivities is not None
