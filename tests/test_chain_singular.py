"""The singular apex: one-sided rates (docs/theory.md §K1.4), smooth branch, detuned designs (§1.5)."""
import math

import numpy as np
import pytest
from scipy.optimize import minimize_scalar

from mechsim.mechanisms.chain.dwell import MECH1, ChainDwellMechanism

CM = 0.01



def ends(df, sprocket, event):
    row = df[(df.sprocket == sprocket) & (df.event == event)].iloc[0]
    return (row.crank_speed_before_rad_s, row.crank_speed_after_rad_s,
            row.crank_accel_before_rad_s2, row.crank_accel_after_rad_s2)


F_EXIT = 0.848528  # v^2/(R L sin 45 deg), docs/theory.md §K1.4


def test_one_sided_rates_mech2(m2):
    lead = m2.dwell_end_rates("leading")
    lag = m2.dwell_end_rates("lagging")
    for sp in (1, 2, 3, 4):
        # leading: apex 0.75 -> 0 (jump 2v/(R+L)), f 0 -> 0; arc exit: 0 -> 0, f 0 -> 0.848528
        assert ends(lead, sp, "start") == pytest.approx((0.75, 0, 0, 0), abs=1e-12)
        assert ends(lead, sp, "end") == pytest.approx((0, 0, 0, F_EXIT), abs=1e-6)
        # lagging: arc entry 0 -> 0, f -0.848528 -> 0; apex 0 -> 0.75, f 0 -> 0
        assert ends(lag, sp, "start") == pytest.approx((0, 0, -F_EXIT, 0), abs=1e-6)
        assert ends(lag, sp, "end") == pytest.approx((0, 0.75, 0, 0), abs=1e-12)
    assert set(lead.event_kind) == {"apex", "arc exit"} and set(lag.event_kind) == {"arc entry", "apex"}


def test_one_sided_rates_mech1_135_degree_wraps(m1):
    # the 135-degree wraps give 0.6 = v^2/(R L sin 90 deg): Mech 1 sp3 exit (leading), sp1 entry (lagging)
    assert ends(m1.dwell_end_rates("leading"), 3, "end")[3] == pytest.approx(0.6, abs=1e-12)
    assert ends(m1.dwell_end_rates("lagging"), 1, "start")[2] == pytest.approx(-0.6, abs=1e-12)
    assert ends(m1.dwell_end_rates("leading"), 2, "start")[:2] == pytest.approx((0.75, 0.0), abs=1e-12)


def test_closed_form_limits_agree_with_approach(m2):
    """The exact one-sided limits at the apex equal the generic closed-form rates evaluated ever closer."""
    s_star = m2.touches[0]
    v = m2.r1
    for branch in ("leading", "lagging"):
        for side in (-1, +1):
            lim = m2.state(np.array([s_star]), branch, side)
            for ds in (1e-7, 1e-9):
                st = m2.state(np.array([s_star + side * ds]), branch)
                assert st["dphi"][0] * v == pytest.approx(lim["dphi"][0] * v, abs=2 * ds / CM)
                assert st["d2phi"][0] * v * v == pytest.approx(lim["d2phi"][0] * v * v, abs=1e-4)
                assert st["dtheta"][0] * v == pytest.approx(lim["dtheta"][0] * v, abs=2 * ds / CM)


def test_smooth_branch_is_continuous_through_the_apex(m2):
    """Tangent predictor across the apex lands on the smooth branch and misses the fixed-sign root."""
    s_star = m2.touches[0]
    h = 1e-4
    for start in ("leading", "lagging"):
        before = m2.state(np.array([s_star - h]), "smooth", start_branch=start)
        after = m2.state(np.array([s_star + h]), "smooth", start_branch=start)
        pred = before["phi"] + 2 * h * before["dphi"] + 2 * h * h * before["d2phi"]
        assert abs(after["phi"][0] - pred[0]) < 1e-6
        pred_w = before["dphi"] + 2 * h * before["d2phi"]
        assert abs(after["dphi"][0] - pred_w[0]) < 1e-3 * abs(1 / m2.c_out)
        # one-sided rates match at the apex on the smooth branch
        lo = m2.rates(np.array([s_star / m2.r1]), "smooth", -1, start_branch=start)
        hi = m2.rates(np.array([s_star / m2.r1]), "smooth", +1, start_branch=start)
        assert lo["crank_speed"][0] == pytest.approx(hi["crank_speed"][0], abs=1e-14)
        assert lo["crank_accel"][0] == pytest.approx(hi["crank_accel"][0], abs=1e-14)
        assert lo["phi"][0] == pytest.approx(hi["phi"][0], abs=1e-15)
    # the fixed-sign root kinks: its phi after the apex is O(h) away from the prediction
    before = m2.state(np.array([s_star - h]), "leading")
    after = m2.state(np.array([s_star + h]), "leading")
    pred = before["phi"] + 2 * h * before["dphi"] + 2 * h * h * before["d2phi"]
    assert abs(after["phi"][0] - pred[0]) == pytest.approx(2 * h / m2.c_out, rel=1e-3)


def test_constraint_jacobian_loses_rank_at_the_apex(m2):
    """G = [-B', R n(phi), L n(theta)] has rank 1 at the apex (docs/theory.md §K1.5 point 1)."""
    def sv(s):
        st = m2.state(np.array([s]), "leading")
        B1 = m2.path.derivatives(np.array([s]), 1)[1][0]
        n = lambda a: np.array([-math.sin(a), math.cos(a)])
        G = np.column_stack([-B1, m2.R * n(st["phi"][0]), m2.L * n(st["theta"][0])])
        return np.linalg.svd(G, compute_uv=False)

    s_star = m2.touches[0]
    at = sv(s_star)
    assert at[1] / at[0] < 1e-15
    away = sv(s_star + 0.01)
    assert away[1] / away[0] > 1e-2


@pytest.mark.parametrize("delta_cm, f_peak", [(1e-2, 3.63), (1e-3, 11.48), (1e-4, 36.3), (1e-5, 114.8)])
def test_detuned_positive_near_dwell(delta_cm, f_peak):
    """delta > 0: roots never meet; omega = 0.375 at the apex, peak |f| ~ delta^-1/2 (docs/theory.md §K1.5)."""
    m = ChainDwellMechanism(MECH1.detuned(delta_cm * CM))
    assert len(m.singular) == 0
    s_apex = m.path.arc_of(1).apex_travel(m.Q)
    th_apex = s_apex / m.r1
    assert math.degrees(th_apex) == pytest.approx(180.047447, abs=5e-7)
    for branch in ("leading", "lagging", "smooth"):
        assert m.rates(np.array([th_apex]), branch)["crank_speed"][0] == pytest.approx(0.375, abs=1e-12)
    res = minimize_scalar(lambda t: -abs(m.rates(np.array([t]), "leading")["crank_accel"][0]),
                          bounds=(th_apex - 0.3, th_apex + 0.3), method="bounded", options=dict(xatol=1e-12))
    assert -res.fun == pytest.approx(f_peak, rel=5e-3)
    # a near-dwell remains on the dwell curve side: the crank creeps by less than a milliradian-ish
    nd = m.near_dwells("leading", speed_ratio_tol=0.01)
    assert len(nd) == 3
    assert (nd["crank_excursion_rad"] < 3e-3).all()


def test_detuned_negative_fold(m1):
    """delta < 0: |QB| reaches R + L before the apex, a fold at 178.176150 deg for delta = -1e-3 cm."""
    m = ChainDwellMechanism(MECH1.detuned(-1e-3 * CM))
    folds = m.folds()
    assert len(folds) == 6 and set(folds["kind"]) == {"stretched fold"}
    deg = np.degrees(folds["drive_angle_rad"].to_numpy())
    assert deg[0] == pytest.approx(178.176150, abs=5e-7)
    # symmetric about the apex 180.047447
    assert deg[1] == pytest.approx(2 * 180.047447 - 178.176150, abs=1e-6)
    # between the folds the dyad cannot close
    th = np.radians(np.linspace(deg[0], deg[1], 7)[1:-1])
    st = m.rates(th, "leading")
    assert not st["closes"].any() and np.isnan(st["phi"]).all()
    # at a fold the dyad is stretched and the crank speed diverges (dead centre)
    w = [abs(m.rates(np.radians([deg[0] - d]), "leading")["crank_speed"][0]) for d in (1e-2, 1e-4, 1e-6)]
    assert w[0] < w[1] < w[2] and w[2] > 10 * w[0]
    assert m.rates(folds["drive_angle_rad"].to_numpy()[:1], "leading")["stretch"][0] == pytest.approx(0, abs=1e-17)


def test_exact_design_has_no_folds(m1, m2):
    assert len(m1.folds()) == 0 and len(m2.folds()) == 0
    assert len(m2.singular) == 4


@pytest.mark.parametrize("delta", [-1e-11, -1e-9, 1e-11])
def test_tiny_detuning_is_classified(delta, m1):
    """Folds appear in symmetric pairs about each apex for any delta < 0 above round-off; none for delta > 0."""
    m = ChainDwellMechanism(MECH1.detuned(delta))
    folds = m.folds()
    if delta > 0:
        assert len(m.singular) == 0
        return
    assert len(folds) == 6 and len(m.touches) == 0
    s = folds["chain_position_m"].to_numpy().reshape(3, 2).mean(axis=1)
    assert s == pytest.approx(m1.touches, abs=1e-12)
    # closed-form half-width: sin^2(dpsi/2) = ((L_i + r_i)^2 - (R + L)^2) / (4 L_i r_i)
    half = 2 * math.asin(math.sqrt(((0.08) ** 2 - (0.08 + delta) ** 2) / (4 * 0.05 * 0.03))) * 0.03
    assert np.diff(folds["chain_position_m"].to_numpy()[:2])[0] == pytest.approx(2 * half, rel=1e-6)


def test_dwell_curve_rates_stay_exact_next_to_the_apex(m2):
    """On the dwell curve just after the apex omega = f = 0 exactly. The textbook 2x2 solve of the paper's
    eqs. (28)-(29) is 0/0 there (docs/theory.md §K1.4, E10); the cancellation-free form keeps round-off level."""
    s_star = m2.touches[0]
    th = (s_star + np.array([1e-3, 1e-4, 1e-5, 1e-6]) * CM) / m2.r1
    r = m2.rates(th, "leading")
    assert np.abs(r["crank_speed"]).max() < 1e-14
    assert np.abs(r["crank_accel"]).max() < 1e-9
