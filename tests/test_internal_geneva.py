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
