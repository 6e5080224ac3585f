"""The rolling-pair 4-bar DAE (mechanisms/rolling/model.py) against docs/theory.md §K3 and independent physics:
the minimal-coordinate equation, energy, link 4's Newton-Euler balance with the rolling contact force, the
closed form at prescribed speed, and dead points (docs/theory.md §K2.2, §4 point 4)."""
import math

import numpy as np
import pytest

from mechsim.dynamics.drives import Drive
from mechsim.dynamics.hybrid import simulate
from mechsim.dynamics.settings import SolverSettings
from mechsim.dynamics.tables import events_table, timeseries
import mechsim.mechanisms.rolling.reduced as reduced
from mechsim.mechanisms.rolling.model import Bodies, RollingPairFourBar
from mechsim.mechanisms.rolling.sets import make

G = 9.81


def mechanism(set_name="A", **kw):
    """docs/theory.md §K3 bodies: rods 0.2 / 0.3 kg, link 4 = 0.5 kg disc + 0.1 kg arm."""
    kin = make(set_name)
    return RollingPairFourBar(kin, Bodies.uniform(kin, 0.2, 0.3, 0.5, 0.1), **kw)


def run(mech, drive, t_end, angle0, speed0=0.0, formulation="index2", rtol=1e-10, atol=1e-11, dt=0.01, **kw):
    traj = simulate(mech, drive, SolverSettings(formulation=formulation, rtol=rtol, atol=atol, **kw), t_end, dt,
                    angle0, speed0)
    return traj, timeseries(traj, mech.angle_coordinates)


def test_bodies_follow_kinematics_md_3():
    b = mechanism().bodies
    assert (b.I2, b.I3) == pytest.approx((0.15, 0.30625), abs=1e-12)
    assert (b.m4, b.c4, b.I4) == pytest.approx((0.6, 0.13333, 0.324667), abs=1e-5)


@pytest.mark.parametrize("branch,phi_end", [(1, 32.268), (-1, 35.237)])
def test_torque_on_rolling_link_matches_minimal_coordinates(branch, phi_end):
    """docs/theory.md §K3: set A, tau = 15 N m on link 4, gravity, from rest, 4 s. The DAE's phi(t) equals the
    minimal-coordinate equation (closed-form kinematics, DOP853) to 1e-8 rad; phi(4 s) = 32.268 / 35.237;
    drive work = kinetic + potential energy change to 1e-8 of the drive work."""
    mech = mechanism(gravity=G, branch=branch)
    traj, df = run(mech, Drive("torque", torque=15.0), 4.0, 0.0, rtol=1e-12, atol=1e-13)
    assert traj.failure is None and not traj.events
    t = df["t_s"].to_numpy()
    phi, omega = reduced.integrate(mech, 15.0, 0.0, 0.0, 0.0, t, rtol=1e-12, atol=1e-12)
    assert np.max(np.abs(df["rolling_angle_rad"].to_numpy() - phi)) <= 1e-8
    assert np.max(np.abs(df["rolling_speed_rad_s"].to_numpy() - omega)) <= 1e-6
    assert df["rolling_angle_rad"].iloc[-1] == pytest.approx(phi_end, abs=1e-3)
    W = df["work_drive_J"].iloc[-1]
    assert W == pytest.approx(15.0 * phi[-1], rel=1e-9)
    dE = (df["kinetic_energy_J"] + df["potential_energy_J"]).to_numpy()
    assert abs(W - (dE[-1] - dE[0])) <= 1e-8 * W
    # the work columns alone: drive + gravity = kinetic energy change
    closure = df["work_drive_J"] + df["work_gravity_J"] - (df["kinetic_energy_J"] - df["kinetic_energy_J"].iloc[0])
    assert np.max(np.abs(closure)) <= 1e-8 * W
    # the reduced model's own energy agrees with the DAE's (an independent kinetic/potential energy)
    assert np.max(np.abs(reduced.energy(mech, phi, omega) - dE)) <= 1e-7 * W
    assert df["constraint_residual_m"].max() <= 1e-9


def test_rolling_contact_force_satisfies_link4_newton_euler():
    """Link 4 alone: m4 a_G4 = F_P + lam + m4 g and I4 phi'' = tau + (P - G4) x F_P + (B - G4) x lam, with the
    coupler force lam (the multipliers) and the contact force read out as normal/traction components. Every
    position and acceleration here comes from rolling_pair's closed forms, not from the DAE's model."""
    mech = mechanism(gravity=G, branch=-1, rolling_damping=0.05)
    # multipliers and accelerations in IDA's error test (they are read back here, not only q and v)
    traj, df = run(mech, Drive("torque", torque=15.0), 1.5, 0.4, formulation="index1", multiplier_atol=1e-9)
    kin, b = mech.kin, mech.bodies
    ts = np.concatenate([p.t for p in traj.pieces])
    ys = np.concatenate([p.y for p in traj.pieces])
    ys = ys[[int(np.flatnonzero(ts == t)[-1]) for t in df["t_s"]]]     # the rows the table kept
    lam = ys[:, traj.model.modes["rolling"].index["lam"]]
    lam = lam[:, 0] + 1j * lam[:, 1]
    phi, w, a = (df[f"rolling_{c}"].to_numpy() for c in ("angle_rad", "speed_rad_s", "accel_rad_s2"))
    tr = kin.trochoid(phi)
    e4 = np.exp(1j * (kin.theta4(phi) + b.d4))
    G4 = tr["B0"] + b.c4 * e4
    aG4 = (tr["ddB0"] - b.c4 * e4) * w**2 + (tr["dB0"] + 1j * b.c4 * e4) * a
    n_hat = (tr["B0"] - tr["P"]) / kin.pair.r
    F_P = (df["contact_force_N"].to_numpy() + 1j * df["traction_force_N"].to_numpy()) * n_hat
    force = b.m4 * aG4 - (F_P + lam - 1j * b.m4 * G)
    cross = lambda u, v: u.real * v.imag - u.imag * v.real  # noqa: E731
    moment = b.I4 * a - (15.0 - 0.05 * w + cross(tr["P"] - G4, F_P) + cross(tr["B"] - G4, lam))
    scale = np.max(np.abs(lam))
    assert np.max(np.abs(force)) <= 1e-7 * scale
    assert np.max(np.abs(moment)) <= 1e-7 * scale
    # no slip: the contact point is link 4's instantaneous centre, so the traction does no work
    assert np.max(np.abs(kin.solve(phi, -1).contact_material_velocity(w))) <= 1e-12 * np.max(np.abs(w))


def test_prescribed_rolling_speed_closed_form_matches_dae():
    """drive.type = speed on the rolling link: the closed form (RollingFourBar.solve + the model's force
    balance) equals the DAE with the speed constraint, with damping and gravity."""
    mech = mechanism(gravity=G, branch=-1, prescribed=True, crank_damping=0.1, rolling_damping=0.05)
    traj, df = run(mech, Drive("speed", speed=2.0), 2.0, 0.5, 2.0, atol=1e-12)
    assert traj.failure is None
    cf = mech.closed_form(df["t_s"].to_numpy(), 0.5, 2.0)
    for col in ("crank_angle_rad", "coupler_angle_rad", "crank_speed_rad_s", "coupler_point_x_m"):
        np.testing.assert_allclose(df[col], cf[col], rtol=0, atol=1e-9)
    for col in ("drive_torque_N_m", "contact_force_N", "coupler_force_N", "kinetic_energy_J"):
        np.testing.assert_allclose(df[col], cf[col], rtol=0, atol=1e-6 * np.max(np.abs(cf[col])))


def test_closed_form_cusps_of_set_c():
    """docs/theory.md §K2.3, set C (l4 = r): at phi_k the coupler point is at the tabulated cusp and stops."""
    mech = mechanism("C", prescribed=True)
    for phi_k, C in [(3.522124, (3.822356, 0.508538)), (11.899704, (-0.190889, 2.735328))]:
        h = 1e-4
        cf = mech.closed_form(np.array([0.0, h, 2 * h]), phi_k - h, 1.0)
        x, y = cf["coupler_point_x_m"], cf["coupler_point_y_m"]
        assert (x[1], y[1]) == pytest.approx(C, abs=2e-6)
        assert math.hypot(x[2] - x[0], y[2] - y[0]) / (2 * h) <= 1e-3   # |V_C| = O(dphi) at a cusp


def test_rolling_input_dead_point_is_the_closure_end():
    """Set B, torque on the rolling link from phi = 3: the dyad stretches at the end of the closure interval
    [2.081243, 5.781935] (docs/theory.md §K2.2); the guard fires there with phi' = 0, the link reverses, the motion
    continues on the other branch (a dichromatic component), and energy still closes."""
    mech = mechanism("B")
    traj, df = run(mech, Drive("torque", torque=2.0), 3.0, 3.0)
    assert traj.failure is None
    ev = events_table(traj)
    assert list(ev["kind"]) == ["dead point"]
    assert ev["rolling_q"].iloc[0] == pytest.approx(5.781935, abs=1e-6)
    t_dead = ev["t_s"].iloc[0]
    before, after = df[df["t_s"] < t_dead], df[df["t_s"] > t_dead]
    assert set(before["branch"]) == {1.0} and set(after["branch"]) == {-1.0}
    assert before["rolling_speed_rad_s"].iloc[-1] > 0 > after["rolling_speed_rad_s"].iloc[0]
    closure = df["work_drive_J"] - (df["kinetic_energy_J"] - df["kinetic_energy_J"].iloc[0])
    assert np.max(np.abs(closure)) <= 1e-7 * df["work_drive_J"].abs().max()


def _crank_dead_point(mech, q):
    """w . B'(phi) = 0: the coupler's line passes through the contact point (independent of the model)."""
    kin = mech.kin
    tr = kin.trochoid(np.array([q[2]]))
    w = tr["B"][0] - (kin.a0 + kin.l2 * np.exp(1j * q[0]))
    return (w.real * tr["dB"][0].real + w.imag * tr["dB"][0].imag) / (kin.l3 * abs(tr["dB"][0]))


def test_crank_torque_passes_dead_points_and_reports_them():
    """Set A driven at the crank (5 N m, no gravity): where the coupler line passes through the contact point
    the crank cannot turn the rolling link; the crank speed is zero there, the events table reports the dead
    point, the crank reverses and the run goes on."""
    mech = mechanism(driven_link="crank")
    theta0 = float(mech.kin.solve(np.array([0.0]), 1).theta2[0])
    traj, df = run(mech, Drive("torque", torque=5.0), 4.0, theta0)
    assert traj.failure is None
    ev = events_table(traj)
    assert len(ev) == 2 and set(ev["kind"]) == {"dead point"}
    assert all("dead point of the crank input" in w for w in traj.warnings)
    for _, row in ev.iterrows():
        q = np.array([row["crank_q"], row["coupler_q"], row["rolling_q"]])
        assert abs(_crank_dead_point(mech, q)) <= 1e-8
        i = int(np.searchsorted(df["t_s"], row["t_s"]))
        assert df["crank_speed_rad_s"].iloc[i - 1] * df["crank_speed_rad_s"].iloc[i] < 0   # the crank reverses
    assert df["t_s"].iloc[-1] == pytest.approx(4.0)
    closure = df["work_drive_J"] - (df["kinetic_energy_J"] - df["kinetic_energy_J"].iloc[0])
    assert np.max(np.abs(closure)) <= 1e-7 * df["work_drive_J"].abs().max()


def test_prescribed_crank_speed_stops_before_the_dead_point():
    """A prescribed crank speed cannot pass that dead point (singular KKT matrix, infinite torque): the run stops
    at |transmission| = dead_point_margin with a physics failure naming it, before IDA meets the singularity."""
    mech = mechanism(driven_link="crank", prescribed=True, dead_point_margin=0.01)
    theta0 = float(mech.kin.solve(np.array([0.0]), 1).theta2[0])
    traj, df = run(mech, Drive("speed", speed=1.0), 4.0, theta0, 1.0)
    f = traj.failure
    assert f is not None and f["kind"] == "physics" and "dead point" in f["reason"]
    q = np.array([f["where"][c] for c in mech.coordinates])
    assert abs(mech.transmissions(q)[1]) == pytest.approx(0.01, abs=1e-8)
    # the dead point itself is just ahead: the torque-driven run's crank angle there is 0.0584 rad
    assert 0.05 < q[0] < 0.0585
    assert df["drive_torque_N_m"].abs().iloc[-1] > 100 * df["drive_torque_N_m"].abs().iloc[0]


def test_crank_start_assembles_on_the_requested_branch():
    """Starting from a crank angle, phi is found from |B(phi) - A| = l3 on the requested branch."""
    for branch in (1, -1):
        mech = mechanism(driven_link="crank", branch=branch)
        st = mech.kin.solve(np.array([0.7]), branch)
        mech.start_rolling_angle = 0.7
        q, v = mech.start(float(st.theta2[0]), 1.0)
        assert q[2] == pytest.approx(0.7, abs=1e-10)
        assert q[1] == pytest.approx(float(st.theta3[0]), abs=1e-10)
        assert v[2] == pytest.approx(1.0 / float(st.dtheta2[0]), rel=1e-9)   # dphi/dtheta2 = 1/theta2'
