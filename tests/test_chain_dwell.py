"""Dyad kinematics and exact dwells of El-Shakery's Mech 1 and Mech 2 (docs/theory.md §K1.1-1.3)."""
import math

import numpy as np
import pytest

from mechsim.mechanisms.chain.dwell import MECH1, MECH2, ChainDwellMechanism, ChainDwellParams
from mechsim.mechanisms.chain.path import circle_circle_intersection

CM = 0.01
DEG_TOL = 5e-7  # docs/theory.md (Part K) prints driving angles to 6 decimals



def deg_rows(df):
    return [(round(math.degrees(r.start_drive_angle_rad), 6), round(math.degrees(r.end_drive_angle_rad), 6),
             round(math.degrees(r.duration_drive_angle_rad), 6), round(math.degrees(r.crank_angle_rad), 6) % 360)
            for r in df.itertuples()]


def assert_dwells(df, expected):
    got = deg_rows(df)
    assert len(got) == len(expected)
    for g, e in zip(got, expected):
        assert g == pytest.approx(e, abs=2 * DEG_TOL)


# --- §1.3 tables ---------------------------------------------------------------------------------------------


def test_mech1_apexes(m1):
    sp = m1.singular_points()
    assert list(sp["kind"]) == ["stretched touch"] * 3
    assert np.degrees(sp["drive_angle_rad"]).tolist() == pytest.approx([180.047447, 405.094895, 776.080827],
                                                                        abs=DEG_TOL)
    B = m1.path.B(sp["chain_position_m"].to_numpy())
    assert np.hypot(*B.T) / CM == pytest.approx([8.0] * 3, abs=1e-13)
    # numerical root of d|QB|^2/ds (direct B and B', Brent) against the closed form
    from scipy.optimize import brentq

    def rate(x):
        P, T = m1.path.derivatives(np.array([x]), 1)
        return float(P[0] @ T[0])

    for s_star in sp["chain_position_m"]:
        root = brentq(rate, s_star - 0.01, s_star + 0.01, xtol=1e-16)
        assert abs(root - s_star) / m1.r1 < 1e-12


def test_mech1_leading_dwells_reproduce_paper(m1):
    # paper Table 1 / text: 45, 90, 45 deg dwells (sprockets 2, 3, 1) at phi = 90, 180, 0 on the leading branch
    df = m1.dwells("leading")
    assert_dwells(df, [(180.047447, 225.047447, 45, 90), (405.094895, 495.094895, 90, 180),
                       (776.080827, 821.080827, 45, 0)])
    assert list(df["start_event"]) == ["apex"] * 3 and list(df["end_event"]) == ["arc exit"] * 3
    assert list(df["sprocket"]) == [2, 3, 1]


def test_mech1_lagging_dwells(m1):
    df = m1.dwells("lagging")
    assert_dwells(df, [(135.047447, 180.047447, 45, 90), (360.094895, 405.094895, 45, 180),
                       (686.080827, 776.080827, 90, 0)])
    assert list(df["start_event"]) == ["arc entry"] * 3 and list(df["end_event"]) == ["apex"] * 3


def test_mech1_smooth_branch_two_cycles(m1):
    df = m1.dwells("smooth", cycles=2, start_branch="leading")   # A = O_1 at theta1 = 0
    assert_dwells(df, [(360.094895, 495.094895, 135, 180), (956.128274, 1046.128274, 90, 90),
                       (1507.161653, 1642.161653, 135, 0)])
    assert list(df["start_event"]) == ["arc entry"] * 3 and list(df["end_event"]) == ["arc exit"] * 3
    # n odd: the smooth branch has period two chain cycles
    s = np.linspace(0, m1.chain_length, 97)[1:-1]
    sig1 = m1.sigma(s, "smooth")
    assert np.all(m1.sigma(s + m1.chain_length, "smooth") == -sig1)
    assert np.all(m1.sigma(s + 2 * m1.chain_length, "smooth") == sig1)


def test_mech2_dwells(m2):
    lead = [(180.047447, 225.047447, 45, 90), (405.094895, 450.094895, 45, 180),
            (630.142342, 675.142342, 45, 270), (855.189790, 900.189790, 45, 0)]
    lag = [(135.047447, 180.047447, 45, 90), (360.094895, 405.094895, 45, 180),
           (585.142342, 630.142342, 45, 270), (810.189790, 855.189790, 45, 0)]
    assert_dwells(m2.dwells("leading"), lead)
    assert_dwells(m2.dwells("lagging"), lag)
    assert_dwells(m2.dwells("smooth"), [(360.094895, 450.094895, 90, 180), (810.189790, 900.189790, 90, 0)])
    # the other smooth branch dwells on sprockets 2 and 4
    assert list(m2.dwells("smooth", start_branch="lagging")["sprocket"]) == [2, 4]
    # n even: period one cycle
    s = np.linspace(0, m2.chain_length, 97)[1:-1]
    assert np.all(m2.sigma(s + m2.chain_length, "smooth") == m2.sigma(s, "smooth"))


MECH2_PHI = [0.0, 0.6401, 2.2990, 4.7446, 7.8399, 11.4838, 15.5921, 20.0915, 24.9203, 30.0318, 35.4010, 41.0319,
             46.9735, 53.3531, 60.3642, 67.6299, 75.0129, 82.4705, 89.9644, 90, 90, 90, 90, 90.1679, 91.3522,
             93.4216, 96.2032, 99.5815, 103.4652, 107.7757, 112.4451, 117.4186, 122.6593, 128.1553, 133.9303,
             140.0654, 146.7568]


def test_mech2_crank_angle_table(m2):
    th = np.radians(np.arange(0, 361, 10))
    phi = np.degrees(m2.state(th * m2.r1, "leading")["phi"])
    diff = (phi - np.array(MECH2_PHI) + 180) % 360 - 180
    assert np.abs(diff).max() < 5e-5 + 1e-9


@pytest.mark.parametrize("params, branch", [(MECH1, "leading"), (MECH1, "lagging"), (MECH2, "leading"),
                                            (MECH2, "smooth")])
def test_crank_tip_on_sprocket_centre_during_dwell(params, branch):
    m = ChainDwellMechanism(params)
    for d in m.dwells(branch, cycles=2 if branch == "smooth" else 1).itertuples():
        th = np.linspace(d.start_drive_angle_rad, d.end_drive_angle_rad, 401)
        r = m.rates(th, branch)
        O = np.asarray(params.centres[d.sprocket - 1])
        assert np.abs(r["A"] - O).max() / CM < 1.5e-12
        assert np.abs(np.angle(np.exp(1j * (r["phi"] - d.crank_angle_rad)))).max() < 1e-12
        # crank at rest inside (the ends carry the one-sided values of the piece after, see test_chain_singular)
        assert np.abs(r["crank_speed"][1:-1]).max() < 1e-12 and np.abs(r["crank_accel"][1:-1]).max() < 1e-10


@pytest.mark.parametrize("params", [MECH1, MECH2])
def test_brute_force_scan_finds_no_other_dwell(params):
    """7201 points per cycle: A = O_i only inside the reported intervals or within 0.05 cm of their ends."""
    m = ChainDwellMechanism(params)
    th = np.linspace(0, m.cycle_angle, 7201)
    for branch in ("leading", "lagging"):
        st = m.state(th * m.r1, branch)
        dw = m.dwells(branch)
        for i, O in enumerate(np.asarray(params.centres)):
            hit = np.hypot(*(st["A"] - O).T) < 1e-9 * CM
            mine = dw[dw["sprocket"] == i + 1]
            ok = np.zeros_like(hit)
            for d in mine.itertuples():
                pad = 0.05 * CM / m.r1
                for shift in (-m.cycle_angle, 0.0, m.cycle_angle):
                    ok |= (th >= d.start_drive_angle_rad + shift - pad) & (th <= d.end_drive_angle_rad + shift + pad)
            assert not np.any(hit & ~ok)
            assert hit.sum() > 0


@pytest.mark.parametrize("params", [MECH1, MECH2, MECH1.detuned(2e-4)])
def test_dyad_closes_and_roots_are_on_their_side(params):
    """|QA| = R, |AB| = L; leading A is clockwise of ray QB, lagging counter-clockwise (independent construction)."""
    m = ChainDwellMechanism(params)
    s = np.linspace(0, m.chain_length, 157)
    for branch, k in (("leading", 0), ("lagging", 1)):
        st = m.state(s, branch)
        A, B = st["A"], st["B"]
        assert np.abs(np.hypot(*(A - m.Q).T) - m.R).max() < 1e-15
        assert np.abs(np.hypot(*(B - A).T) - m.L).max() < 1e-15
        theta = np.arctan2(*(B - A).T[::-1])
        assert np.abs(np.angle(np.exp(1j * (theta - st["theta"])))).max() < 1e-12
        for j in range(0, len(s), 13):
            try:
                P = circle_circle_intersection(m.Q, m.R, B[j], m.L)[k]
            except ValueError:
                continue
            assert np.abs(P - A[j]).max() < 1e-9 * CM


@pytest.mark.parametrize("params", [MECH1, MECH2, MECH2.detuned(1e-4)])
def test_rates_against_finite_differences(params):
    """Closed-form phi', phi'', theta', theta'' against central differences of the position (independent)."""
    m = ChainDwellMechanism(params)
    s = np.linspace(0, m.chain_length, 4001)
    ev = m.event_angles() * m.r1
    s = s[np.min(np.abs(s[:, None] - ev[None, :]), axis=1) > 1e-4]
    h = 1e-6
    for branch in ("leading", "lagging"):
        st, sp, sm = (m.state(x, branch) for x in (s, s + h, s - h))
        for ang, d1, d2 in (("phi", "dphi", "d2phi"), ("theta", "dtheta", "d2theta")):
            U = np.unwrap(np.stack([sm[ang], st[ang], sp[ang]]), axis=0)
            fd1 = (U[2] - U[0]) / (2 * h)
            fd2 = (U[2] - 2 * U[1] + U[0]) / h ** 2
            fdd = (sp[d1] - sm[d1]) / (2 * h)
            assert np.abs(fd1 - st[d1]).max() < 1e-6 * np.abs(st[d1]).max()
            assert np.abs(fdd - st[d2]).max() < 1e-6 * np.abs(st[d2]).max()
            assert np.abs(fd2 - st[d2]).max() < 1e-3 * np.abs(st[d2]).max()


@pytest.mark.parametrize("params, w_max, f_max", [(MECH1, 1.0375, 0.910), (MECH2, 0.75, 0.848528)])
def test_peak_speed_and_acceleration(params, w_max, f_max):
    m = ChainDwellMechanism(params)
    th = np.linspace(0, m.cycle_angle, 20001)
    ev = m.event_angles()
    for branch in ("leading", "lagging"):
        r = [m.rates(th, branch), m.rates(ev, branch, -1), m.rates(ev, branch, +1)]   # grid + one-sided limits
        w = np.concatenate([x["crank_speed"] for x in r])
        f = np.concatenate([x["crank_accel"] for x in r])
        assert np.nanmax(np.abs(w)) == pytest.approx(w_max, abs=5e-5)
        assert np.nanmax(np.abs(f)) == pytest.approx(f_max, abs=5e-4 if f_max == 0.910 else 1e-6)


def test_dyad_that_can_never_close():
    bad = ChainDwellParams.from_cm("short dyad", MECH1_CM, [3, 3, 3], 1, 1)
    with pytest.raises(ValueError, match=r"dyad can never close: \|QB\| ranges over"):
        ChainDwellMechanism(bad)
    far = ChainDwellParams.from_cm("far pivot", MECH1_CM, [3, 3, 3], 5, 3, pivot_cm=(40, 0))
    with pytest.raises(ValueError, match="dyad can never close"):
        ChainDwellMechanism(far)
    with pytest.raises(ValueError, match="crank R and coupler L must be positive"):
        ChainDwellMechanism(ChainDwellParams.from_cm("zero", MECH1_CM, [3, 3, 3], 0, 3))
    with pytest.raises(ValueError, match="listed clockwise"):
        ChainDwellMechanism(ChainDwellParams.from_cm("cw", MECH1_CM[::-1], [3, 3, 3], 5, 3))


MECH1_CM = [(5, 0), (0, 5), (-5, 0)]


def test_branch_name_is_checked(m1):
    with pytest.raises(ValueError, match="branch must be one of"):
        m1.state(np.array([0.0]), "middle")


def test_coupler_along_sprocket_radius_at_dwell_end(m2):
    """At v_e the coupler lies along O_iB: theta_l = phi_i = pi/4, 3pi/4, 5pi/4, 7pi/4 for Mech 2 (paper Table 1
    with E11 corrected), not phi_i + alpha_i (eqs. 9/37, E8)."""
    d = m2.dwells("leading")
    r = m2.rates(d["end_drive_angle_rad"].to_numpy(), "leading", side=-1)
    got = np.degrees(r["theta"]) % 360
    assert got == pytest.approx([135, 225, 315, 45], abs=1e-9)     # sprockets 2, 3, 4, 1
