"""The roller-chain dwell mechanism as a hybrid DAE (issue 5): against the closed-form kinematics, energy
conservation and balance, the stop-impact closed form, folds of detuned designs (docs/theory.md §K1.2-1.5)."""
import math

import numpy as np
import pytest

from mechsim.dynamics.drives import Drive
from mechsim.dynamics.hybrid import simulate
from mechsim.dynamics.settings import SolverSettings
from mechsim.dynamics.tables import events_table, timeseries
from mechsim.mechanisms.chain.dwell import MECH2, ChainDwellMechanism
from mechsim.mechanisms.chain.model import ChainDwell

CM = 0.01
R, L, r1 = 5 * CM, 3 * CM, 3 * CM
# docs/theory.md §K1.5 point 4: chain 0.5 kg, crank 0.05 kg, coupler 0.03 kg (slender rods), v = 3 cm/s
BODIES = dict(crank_mass=0.05, coupler_mass=0.03, chain_mass=0.5)
# docs/theory.md §K1.3, Mech 2 leading branch: apexes (dwell starts) and arc exits (dwell ends), deg
APEX_DEG = [180.047447, 405.094895, 630.142342, 855.189790]
EXIT_DEG = [225.047447, 450.094895, 675.142342, 900.189790]


def mass_matrix(phi, theta, J1, m3=0.03, mc=0.05):
    """M of (theta1, phi, theta), written out independently: sprocket J1; crank m R^2/3 about Q; coupler a slender
    rod (m L^2/12 about its centre at A + L/2 e(theta), whose velocity is R phi' n(phi) + L/2 theta' n(theta))."""
    k = m3 * R * (L / 2) * math.cos(phi - theta)
    return np.array([[J1, 0, 0], [0, mc * R**2 / 3 + m3 * R**2, k], [0, k, m3 * L**2 / 12 + m3 * L**2 / 4]])


def apex_tangents():
    """Velocity directions per unit drive speed at the apex (stretched dyad, phi = theta = alpha_i): on F
    phi' = 2/(R+L) per unit chain travel (docs/theory.md §K1.2); on D phi' = 0. The stretched loop equation's normal
    part R phi' + L theta' = 1 gives theta'."""
    tF = np.array([1.0, r1 * 2 / (R + L), r1 * (1 - 2 * R / (R + L)) / L])
    tD = np.array([1.0, 0.0, r1 / L])
    return tF, tD


def run(mech, drive, t_end, angle0, speed0, rtol=1e-10, atol=1e-13, dt=0.01, formulation="index2"):
    traj = simulate(mech, drive, SolverSettings(formulation=formulation, rtol=rtol, atol=atol), t_end, dt, angle0,
                    speed0)
    return traj, timeseries(traj, mech.angle_coordinates), events_table(traj)


@pytest.fixture(scope="module")
def prescribed():
    """Mech 2, crank stops (e = 0.3), chain at a prescribed 1 rad/s for one chain cycle, as a DAE."""
    mech = ChainDwell(MECH2, crank_torque=1e-3, restitution=0.3, **BODIES)
    traj, df, ev = run(mech, Drive("speed", speed=1.0), mech.kin.cycle_angle, 0.0, 1.0, atol=1e-12, dt=0.02)
    assert traj.failure is None, traj.failure
    return mech, df, ev


def test_prescribed_speed_dae_matches_closed_form_kinematics(prescribed):
    """Crank and coupler angle of the DAE = chain_dwell's leading branch (the paper's case I) to 1e-8 rad."""
    mech, df, _ = prescribed
    ref = ChainDwellMechanism(MECH2).state(df["drive_angle_rad"].to_numpy() * r1, "leading", +1)
    assert np.max(np.abs(df["crank_angle_rad"] - np.unwrap(ref["phi"]))) < 1e-8
    assert np.max(np.abs(df["coupler_angle_rad"] - np.unwrap(ref["theta"]))) < 1e-8
    assert np.max(np.abs(df["crank_speed_rad_s"] - ref["dphi"] * r1)) < 1e-8
    assert df["constraint_residual_m"].max() < 1e-10
    # the runner's closed form (inverse dynamics at the same instants) gives the same drive torque and forces
    cf = mech.closed_form(df["t_s"].to_numpy(), 0.0, 1.0)
    scale = np.max(np.abs(cf["drive_torque_N_m"]))
    assert np.max(np.abs(cf["drive_torque_N_m"] - df["drive_torque_N_m"])) < 1e-6 * scale
    # during a dwell the coupler swings about A = O_i at v/L with no force at B (Newton-Euler of the coupler), so
    # A pulls the crank with the centripetal m3 c3 theta'^2 along the coupler; the stop holds the rest of T_L
    dw = df[df["mode"] == "dwell"]
    expected = 1e-3 - 0.03 * R * (L / 2) * (r1 / L) ** 2 * np.sin(dw.coupler_angle_rad - dw.crank_angle_rad)
    np.testing.assert_allclose(cf["holding_torque_N_m"][dw.index], expected, rtol=1e-8)
    # the DAE's multipliers are kept out of IDA's error test (SolverSettings.multiplier_atol): 1e-3 here
    np.testing.assert_allclose(dw["holding_torque_N_m"], expected, rtol=1e-3)
    assert np.max(np.abs(dw["coupler_shear_N"])) < 1e-9


def test_prescribed_speed_dwells_are_the_papers(prescribed):
    """Stop impacts at the apexes, dwell ends at the arc exits: 4 x 45 deg (docs/theory.md §K1.3, Mech 2)."""
    mech, _, ev = prescribed
    starts = np.degrees(ev[ev.kind == "stop impact"]["drive_q"].to_numpy())
    ends = np.degrees(ev[ev.kind == "dwell end"]["drive_q"].to_numpy())
    np.testing.assert_allclose(starts, APEX_DEG, atol=1e-6)
    np.testing.assert_allclose(ends, EXIT_DEG, atol=1e-6)
    # at the impact the chain speed is held, the crank (0.75 rad/s) and coupler jump from F onto D: the
    # kinetic energy falls by 1/2 (tF M tF - tD M tD), whatever e (the rebound is not admissible)
    tF, tD = apex_tangents()
    M = mass_matrix(0.0, 0.0, mech.drive_inertia)
    lost = ev.groupby("t_s")["energy_lost_J"].sum().loc[ev[ev.kind == "stop impact"]["t_s"]]
    np.testing.assert_allclose(lost, 0.5 * (tF @ M @ tF - tD @ M @ tD), rtol=1e-9)


@pytest.fixture(scope="module")
def torque_run():
    """Mech 2 under a constant sprocket torque, crank load and damping, crank stops with e = 0.5."""
    mech = ChainDwell(MECH2, crank_torque=1e-3, drive_damping=2e-3, crank_damping=1e-5, restitution=0.5,
                      sprocket_inertias=[2e-3] * 4, **BODIES)
    traj, df, ev = run(mech, Drive("torque", torque=2.4e-3), 16.5, 0.0, 1.0)
    assert traj.failure is None, traj.failure
    return mech, df, ev


def test_torque_driven_energy_balance(torque_run):
    """Work of drive + load + damping = change of kinetic energy + energy lost in the impacts, to 1e-6 of the
    drive work; the loop closure holds along the run."""
    _, df, ev = torque_run
    works = {c: df[c].iloc[-1] - df[c].iloc[0] for c in df if c.startswith("work_")}
    dke = df["kinetic_energy_J"].iloc[-1] - df["kinetic_energy_J"].iloc[0]
    lost = ev["energy_lost_J"].sum()
    assert set(works) == {"work_drive_J", "work_load_J", "work_damping_J"}
    assert lost > 0 and works["work_load_J"] < 0 and works["work_damping_J"] < 0
    assert abs(sum(works.values()) - dke - lost) < 1e-6 * works["work_drive_J"]
    assert df["constraint_residual_m"].max() < 1e-9
    # the crank stands still during every dwell (the stop and the chain hold it at alpha_i)
    for _, g in df[df["mode"] == "dwell"].groupby("segment"):
        assert np.ptp(g["crank_angle_rad"]) < 1e-10 and np.max(np.abs(g["crank_speed_rad_s"])) < 1e-10


def test_stop_impact_energy_loss_closed_form(torque_run):
    """Each stop impact loses 1/2 m_eff (1 - e^2) v_n^2 and the absorbed rebound 1/2 m_eff e^2 v_n^2, with
    v_n = R phi'- the crank-tip speed at the stop and m_eff the mass the stop sees, from the impulse balance in
    the two-dimensional velocity space the stretched dyad allows (span of the F and D tangents)."""
    mech, _, ev = torque_run
    e = 0.5
    tF, tD = apex_tangents()
    M = mass_matrix(0.0, 0.0, mech.drive_inertia)
    N = np.column_stack([tD, tF])
    c = R * N[1]                                   # stop-normal velocity R phi' of the reduced coordinates
    m_eff = 1.0 / (c @ np.linalg.solve(N.T @ M @ N, c))
    impacts = ev[ev.kind == "stop impact"]
    rebounds = ev[ev.kind == "rebound absorbed"]
    assert len(impacts) == 4 and len(rebounds) == 4
    for (_, imp), (_, reb) in zip(impacts.iterrows(), rebounds.iterrows()):
        w1 = math.sqrt(2 * imp.kinetic_energy_before_J / (tF @ M @ tF))   # arriving along F
        v_n = R * tF[1] * w1
        assert imp.energy_lost_J == pytest.approx(0.5 * m_eff * (1 - e**2) * v_n**2, rel=1e-8)
        assert reb.energy_lost_J == pytest.approx(0.5 * m_eff * e**2 * v_n**2, rel=1e-8)
        at = math.degrees(imp.drive_q) % math.degrees(mech.kin.cycle_angle)
        assert min(abs(at - a) for a in APEX_DEG) < 1e-6


def test_exact_design_without_stops_follows_the_smooth_branch():
    """docs/theory.md §K1.5 point 4, tau = 0: from F the crank passes the apex (where DOP853 jammed numerically in
    the reference runs, the regular F rows do not), from D it dwells through it to the arc exit; energy is
    conserved."""
    mech = ChainDwell(MECH2, apex="smooth", **BODIES)
    _, df, ev = run(mech, Drive("torque", torque=0.0), 1.5, math.radians(150), 1.0, dt=0.005)
    assert list(ev.kind[:2]) == ["apex", "arc exit"]
    after = df[(df.drive_angle_rad > math.radians(181)) & (df["mode"] == "swing")]
    assert (after.crank_speed_rad_s > 0.5).all()           # no kink: the crank keeps turning past alpha_2
    E = df["kinetic_energy_J"].to_numpy()
    assert np.ptp(E) < 1e-8 * E[0]
    lag = ChainDwell(MECH2, apex="smooth", branch="lagging", **BODIES)
    _, df, ev = run(lag, Drive("torque", torque=0.0), 1.5, math.radians(150), 1.0, dt=0.005)
    assert list(ev.kind[:2]) == ["apex", "dwell end"]
    dw = df[df["mode"] == "dwell"]
    assert np.max(np.abs(dw.crank_angle_rad - math.pi / 2)) < 1e-12
    assert math.degrees(ev[ev.kind == "dwell end"].drive_q.iloc[0]) == pytest.approx(EXIT_DEG[0], abs=1e-6)


def test_detuned_fold_stalls_and_is_reported():
    """delta = -1e-3 cm: the chain reaches the fold at 178.176150 deg (docs/theory.md §K1.5) and must reverse; the
    run stops there with a physics failure instead of integrating through."""
    mech = ChainDwell(MECH2, apex="detuned", detuning=-1e-5, **BODIES)
    fold = math.degrees(mech.kin.folds().drive_angle_rad.iloc[0])
    assert fold == pytest.approx(178.176150, abs=1e-6)
    traj, df, ev = run(mech, Drive("torque", torque=0.0), 2.0, math.radians(150), 1.0, rtol=1e-9, atol=1e-12)
    f = traj.failure
    assert f is not None and f["kind"] == "physics"
    assert "reverse" in f["reason"] and "fold" in f["reason"]
    assert math.degrees(f["where"]["drive"]) == pytest.approx(178.176150, abs=1e-4)
    assert ev.kind.iloc[-1] in ("reversal", "dead centre")
    E = df["kinetic_energy_J"].to_numpy()
    assert np.ptp(E) < 1e-7 * E[0]


def test_detuned_near_dwell_moves_the_cranks_energy_into_the_chain():
    """delta = +1e-3 cm: the crank stops smoothly and the chain speeds up from 3 cm/s to 3.148 cm/s (docs/theory.md
    §K1.5 point 4); energy conservation with the crank at rest and the coupler swinging about A ~ O_2 at v/L gives
    the same speed (closed form)."""
    mech = ChainDwell(MECH2, apex="detuned", detuning=1e-5, **BODIES)
    _, df, ev = run(mech, Drive("torque", torque=0.0), 1.3, math.radians(150), 1.0, rtol=1e-9, atol=1e-12)
    E0 = df["kinetic_energy_J"].iloc[0]
    Ld = L + 1e-5
    J_rest = mech.drive_inertia + (0.03 * Ld**2 / 12 + 0.03 * Ld**2 / 4) * (r1 / Ld) ** 2
    v_after = r1 * math.sqrt(2 * E0 / J_rest)
    row = df.iloc[np.argmin(np.abs(df.drive_angle_rad - math.radians(220)))]
    assert abs(row.crank_speed_rad_s) < 1e-3
    assert row.chain_speed_m_s == pytest.approx(v_after, rel=1e-4)
    assert row.chain_speed_m_s / CM == pytest.approx(3.148, abs=1e-3)
