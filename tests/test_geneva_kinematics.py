"""Closed-form Geneva kinematics against docs/theory.md §G1 and §7 rows 1-6, 8-9 (independently derived numbers)."""
import numpy as np
import pytest

import mechsim.mechanisms.geneva.kinematics as gk
W1 = 5.34


def test_row1_centre_distance_and_pin_distances(seed_geometry):
    g = seed_geometry
    assert g.centre_distance == pytest.approx(0.106066, abs=1e-6)
    assert g.min_pin_distance == pytest.approx(0.031066, abs=1e-6)
    assert g.entry_pin_distance == pytest.approx(0.075000, abs=1e-6)


def test_row2_max_wheel_speed(seed_geometry):
    lam = seed_geometry.ratio
    assert W1 * gk.speed_ratio(lam, 0.0) == pytest.approx(12.8919, rel=1e-4)


def test_row3_accelerations(seed_geometry):
    lam = seed_geometry.ratio
    a0 = seed_geometry.engagement_half_angle
    assert W1**2 * gk.speed_ratio_derivative(lam, -a0 + 1e-12) == pytest.approx(28.516, rel=1e-4)
    alpha = np.linspace(-a0, a0, 200001)
    acc = np.abs(W1**2 * gk.speed_ratio_derivative(lam, alpha))
    i = np.argmax(acc)
    assert acc[i] == pytest.approx(154.183, rel=1e-4)
    assert np.degrees(abs(alpha[i])) == pytest.approx(11.464, abs=2e-3)
    # closed-form location cos(alpha_m) = -K + sqrt(K^2 + 2), K = (1 + lam^2) / (4 lam)
    K = (1 + lam**2) / (4 * lam)
    assert np.degrees(np.arccos(-K + np.sqrt(K**2 + 2))) == pytest.approx(11.464, abs=1e-3)


def test_row4_jerk(seed_geometry):
    lam = seed_geometry.ratio
    a0 = seed_geometry.engagement_half_angle
    assert W1**3 * gk.speed_ratio_second_derivative(lam, 0.0) == pytest.approx(-7315.5, rel=1e-4)
    assert W1**3 * gk.speed_ratio_second_derivative(lam, -a0) == pytest.approx(456.8, rel=1e-3)


def test_row5_sliding_speed_and_zero_slip_angle(seed_geometry):
    g = seed_geometry
    a0 = g.engagement_half_angle
    assert gk.pin_sliding_speed(g, -a0, W1) == pytest.approx(-0.40050, abs=1e-4)
    assert gk.pin_sliding_speed(g, np.radians(30) - a0, W1) == pytest.approx(-0.28320, abs=1e-4)
    from scipy.optimize import brentq
    f = lambda a: gk.slip_speed(g, a, W1, W1 * gk.speed_ratio(g.ratio, a))  # noqa: E731
    root = brentq(f, -0.5, 0.0)
    assert np.degrees(root + a0) == pytest.approx(41.97, abs=1e-2)


def test_row6_times(seed_geometry):
    g = seed_geometry
    assert 2 * g.engagement_half_angle / W1 == pytest.approx(0.29415, abs=1e-5)
    assert 2 * np.pi / W1 == pytest.approx(1.17663, abs=1e-5)
    assert g.dwell_fraction == pytest.approx(0.75)


def test_table_section1(seed_geometry):
    """The numeric table of docs/theory.md §G1 (phi = 5 ... 45 deg)."""
    rows = [(5, -44.761, 0.5341, 37.330, -0.3988, 68.464), (15, -42.368, 2.1800, 66.533, -0.3817, 55.647),
            (30, -30.000, 7.2946, 145.375, -0.2832, 38.823), (40, -11.777, 11.9733, 105.718, -0.1156, 32.026)]
    g = seed_geometry
    for phi, beta, w2, a2, vs, x in rows:
        alpha = np.radians(phi) - g.engagement_half_angle
        assert np.degrees(gk.wheel_angle(g.ratio, alpha)) == pytest.approx(beta, abs=2e-3)
        assert W1 * gk.speed_ratio(g.ratio, alpha) == pytest.approx(w2, abs=2e-4)
        assert W1**2 * gk.speed_ratio_derivative(g.ratio, alpha) == pytest.approx(a2, abs=2e-3)
        assert gk.pin_sliding_speed(g, alpha, W1) == pytest.approx(vs, abs=1e-4)
        assert gk.pin_distance(g, alpha) * 1e3 == pytest.approx(x, abs=2e-3)


def test_derivatives_match_finite_differences(seed_geometry):
    lam = seed_geometry.ratio
    a = np.linspace(-0.7, 0.7, 15)
    h = 1e-6
    fd1 = (gk.wheel_angle(lam, a + h) - gk.wheel_angle(lam, a - h)) / (2 * h)
    fd2 = (gk.speed_ratio(lam, a + h) - gk.speed_ratio(lam, a - h)) / (2 * h)
    fd3 = (gk.speed_ratio_derivative(lam, a + h) - gk.speed_ratio_derivative(lam, a - h)) / (2 * h)
    np.testing.assert_allclose(gk.speed_ratio(lam, a), fd1, atol=1e-8)
    np.testing.assert_allclose(gk.speed_ratio_derivative(lam, a), fd2, atol=1e-7)
    np.testing.assert_allclose(gk.speed_ratio_second_derivative(lam, a), fd3, atol=1e-6)


def test_rows8_9_normal_force_and_input_torque(seed_geometry):
    g = seed_geometry
    a0 = g.engagement_half_angle
    # N = T_L / x at entry and centre (row 8)
    assert 7.0 / g.entry_pin_distance == pytest.approx(93.33, abs=0.01)
    assert 7.0 / g.min_pin_distance == pytest.approx(225.33, abs=0.01)
    # row 9: with J2 at phi = 30 deg, mu = 0
    alpha = np.radians(30) - a0
    a2 = W1**2 * gk.speed_ratio_derivative(g.ratio, alpha)
    N = gk.normal_force_from_wheel(g, alpha, a2, 0.0, 1.5626e-3, 7.0, 0.0, 1.0)
    assert N == pytest.approx(186.16, rel=1e-3)
