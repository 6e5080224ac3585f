"""Flash temperature: Blok partition of exact per-body rises, transient floor, seed S(7)/S(8)/S(13) reproduction,
the 3-D circle source check. docs/theory.md §G4.4–4.7 and §7 rows 12, 15, 20."""
import math

import numpy as np
import pytest

from mechsim.thermal import (TRANSIENT_FLOOR_COEFFICIENT, band_stationary_transient, band_theta_low, band_theta_table,
                     blok_flash_high_peclet, blok_partition, circle_theta, circle_theta_avg_exact,
                     circle_theta_max_exact, effective_modulus, flash_temperature, frictional_heat, get_material,
                     half_width, high_peclet_coefficient, seed_flash_rise, seed_normal_load, seed_sliding_speed,
                     tian_kennedy)

STEEL = get_material("aisi1045")
N_SLOTS, CRANK_R, OMEGA1, PIN_R, LENGTH, TORQUE = 4, 0.075, 5.34, 4e-3, 4e-3, 7.0
LAM = math.sin(math.pi / N_SLOTS)
ALPHA0 = math.pi / 2 - math.pi / N_SLOTS


def kinematics(phi_deg):
    """Closed-form Geneva kinematics of docs/theory.md §G1 (independent of mechanisms/): alpha, beta, omega2, v_s."""
    a = np.radians(phi_deg) - ALPHA0
    D = 1 - 2 * LAM * np.cos(a) + LAM**2
    beta = np.arctan2(LAM * np.sin(a), 1 - LAM * np.cos(a))
    omega2 = OMEGA1 * LAM * (np.cos(a) - LAM) / D
    v_s = OMEGA1 * CRANK_R * np.sin(a) / np.sqrt(D)
    return a, beta, omega2, v_s


def seed_theta_sum(phi_deg):
    """theta1 + theta2 of the seed (theta1 = |alpha|, theta2 = |beta|; docs/theory.md §G1 'Seed check')."""
    a, beta, _, _ = kinematics(phi_deg)
    return np.abs(a) + np.abs(beta)


def test_seed_load_and_speed_s7_s8():
    # docs/theory.md §G2 / §7 row 7: S(8) 66.00 N at phi = 30 deg, 93.33 N at 45 deg, 0 at entry
    np.testing.assert_allclose(seed_normal_load(TORQUE, seed_theta_sum(np.array([30.0, 45.0])), CRANK_R),
                               [66.00, 93.33], atol=0.01)
    assert seed_normal_load(TORQUE, seed_theta_sum(0.0), CRANK_R) == pytest.approx(0.0, abs=1e-12)
    # S(7) equals |v_s| of the closed form
    phi = np.linspace(1, 89, 37)
    np.testing.assert_allclose(seed_sliding_speed(OMEGA1, CRANK_R, seed_theta_sum(phi)), np.abs(kinematics(phi)[3]),
                               rtol=1e-12)


def test_row12_seed_heat_maximum():
    # docs/theory.md §G7 row 12: S(8) x S(7) x mu = 1/2 mu T omega1 sin 2(theta1+theta2); max 5.607 W (mu = 0.3) at phi = 30 deg
    phi = np.linspace(0.0, 45.0, 45001)
    s = seed_theta_sum(phi)
    Q = frictional_heat(0.3, seed_normal_load(TORQUE, s, CRANK_R), seed_sliding_speed(OMEGA1, CRANK_R, s))
    assert Q.max() == pytest.approx(5.607, rel=1e-3)
    assert Q.max() == pytest.approx(0.5 * 0.3 * TORQUE * OMEGA1, rel=1e-6)
    assert phi[Q.argmax()] == pytest.approx(30.0, abs=0.01)


def test_seed_s13_reproduces_seed_values():
    # docs/theory.md §G4.7, column "seed S(13) mu=.15/.3": U = omega1 r, Hertz b of the S(8) load, C = 2.5
    phi = np.array([5.0, 15.0, 30.0, 45.0])
    expected_015 = np.array([3.4, 5.9, 6.7, 0.0])
    s = seed_theta_sum(phi)
    W = seed_normal_load(TORQUE, s, CRANK_R)
    V = seed_sliding_speed(OMEGA1, CRANK_R, s)
    b = half_width(W, PIN_R, LENGTH, effective_modulus(STEEL))
    for mu, scale in [(0.15, 1.0), (0.3, 2.0)]:
        T = seed_flash_rise(frictional_heat(mu, W, V), b, OMEGA1 * CRANK_R, LENGTH, STEEL)
        np.testing.assert_allclose(T, scale * expected_015, atol=0.051 * scale)
        via_api = flash_temperature(W, V, V, OMEGA1 * CRANK_R, b, LENGTH, mu, STEEL, STEEL, method="seed-blok")
        np.testing.assert_allclose(via_api["temp_flash_rise_K"], T, rtol=1e-14)
        assert np.all(np.isnan(via_api["heat_share_pin"]))


def test_seed_s13_is_c_over_2L_times_line_source():
    # docs/theory.md §G4.4: S(13) = 0.159 C Q/(k l) / (2 L); the exact solution has C(L) = pi theta(L) and no 1/(2L)
    b, U, Q = 40e-6, 0.4, 5.0
    L = U * b / (2 * STEEL.diffusivity)
    T = seed_flash_rise(Q, b, U, LENGTH, STEEL)
    assert T == pytest.approx(0.159 * 2.5 * Q / (STEEL.conductivity * LENGTH) / (2 * L), rel=1e-12)
    # C for the exact maximum at the seed's Peclet numbers (0.35 / 0.5 / 0.58): 4.67/4.10/3.87 uniform
    np.testing.assert_allclose(math.pi * band_theta_table(np.array([0.35, 0.5, 0.58]), "uniform", "max"),
                               [4.67, 4.10, 3.87], atol=0.006)


# corrected model, docs/theory.md §G4.7 table (phi, N, dT_flash at mu = 0.15)
TABLE47 = [(5, 103.1, 14.8), (15, 127.7, 17.1), (30, 186.2, 16.0), (45, 225.3, 7.6), (60, 174.5, 21.7),
           (75, 123.9, 19.5), (85, 101.4, 17.0)]


def corrected_case(phi, N, mu):
    """§4.7 recipe: driving-flank slip incl. pin spin, Hertz b, semi-elliptic exact theta, Blok partition;
    floors: pin t_on = time since entry, wall t_on = min(2b/U_wall, 2 sqrt(2b/a_s))."""
    _, _, omega2, v_s = kinematics(phi)
    slip = v_s + PIN_R * (OMEGA1 + omega2)
    b = half_width(N, PIN_R, LENGTH, effective_modulus(STEEL))
    a_s = OMEGA1**2 * CRANK_R / (1 - LAM)
    U_wall = abs(v_s)
    t_wall = min(2 * b / U_wall if U_wall > 0 else np.inf, 2 * math.sqrt(2 * b / a_s))
    return flash_temperature(N, slip, U_wall, PIN_R * (OMEGA1 + omega2), b, LENGTH, mu, STEEL, "aisi1045",
                             t_on_pin=math.radians(phi) / OMEGA1, t_on_wall=t_wall)


def test_row20_corrected_flash_phi60():
    # docs/theory.md §G7 row 20: 21.7 K (15 %); the recipe is followed exactly, so it agrees much closer
    res = corrected_case(60, 174.5, 0.15)
    assert res["temp_flash_rise_K"] == pytest.approx(21.7, rel=0.15)
    assert res["temp_flash_rise_K"] == pytest.approx(21.7, rel=0.01)
    assert res["peclet_wheel"] == pytest.approx(0.56, abs=0.006)
    assert res["peclet_pin"] == pytest.approx(0.10, abs=0.006)
    assert res["heat_rate_W"] == pytest.approx(8.73, rel=2e-3)


@pytest.mark.parametrize("phi,N,dT", TABLE47)
def test_table47_corrected_model(phi, N, dT):
    for mu, scale in [(0.15, 1.0), (0.3, 2.0)]:
        res = corrected_case(phi, N, mu)
        assert res["temp_flash_rise_K"] == pytest.approx(scale * dT, rel=0.01)
        assert 0.28 <= res["heat_share_pin"] <= (0.52 if phi == 45 else 0.37)   # §4.7: pin share 0.30–0.36
        # energy split: the shares add up to Q
        assert res["heat_rate_pin_W"] + res["heat_rate_wheel_W"] == pytest.approx(res["heat_rate_W"], rel=1e-12)


def test_blok_partition_properties():
    # equal bodies, equal Peclet: half the heat each, half the single-body rise
    share, r = blok_partition(np.array([2.0, 1.0, np.inf]), np.array([2.0, 3.0, 1.0]))
    np.testing.assert_allclose(share, [0.5, 0.75, 0.0])
    np.testing.assert_allclose(r, [1.0, 0.75, 1.0])
    share, r = blok_partition(np.inf, np.inf)
    assert share == 0.5 and r == np.inf
    share, r = blok_partition(np.array([0.0, 0.0]), np.array([2.0, 0.0]))   # just switched on: no rise
    np.testing.assert_allclose(share, [1.0, 0.5])
    np.testing.assert_allclose(r, [0.0, 0.0])


def test_source_just_switched_on_has_no_rise():
    b = 40e-6
    res = flash_temperature(100.0, 0.3, 0.3, 0.05, b, LENGTH, 0.15, STEEL, STEEL, t_on_pin=0.0, t_on_wall=1.0)
    assert res["temp_flash_rise_K"] == 0.0 and res["heat_share_pin"] == 1.0
    # and it grows with t_on toward the steady value
    t = np.array([1e-6, 1e-4, 1e-2, 1.0, np.inf])
    rises = flash_temperature(100.0, 0.3, 1e-3, 1e-3, b, LENGTH, 0.15, STEEL, STEEL, t_on_pin=t, t_on_wall=t)
    assert np.all(np.diff(rises["temp_flash_rise_K"]) > 0)


def test_high_peclet_limit_is_blok_formula():
    # docs/theory.md §G4.6: both L >> 1 -> Blok's 1.11 Q'/(sqrt(2b)(e1 sqrt U1 + e2 sqrt U2)), share e1 sqrt U1/(...)
    b, U1, U2, N, mu = 40e-6, 30.0, 120.0, 100.0, 0.2
    slip = U2 - U1
    res = flash_temperature(N, slip, U2, U1, b, LENGTH, mu, STEEL, STEEL)
    assert min(res["peclet_pin"], res["peclet_wheel"]) > 50
    blok = blok_flash_high_peclet(res["heat_per_length_W_m"], b, U1, U2, STEEL.effusivity, STEEL.effusivity,
                                  coefficient=high_peclet_coefficient("semi-elliptic", "max"))
    assert res["temp_flash_rise_K"] == pytest.approx(blok, rel=0.01)
    assert res["heat_share_pin"] == pytest.approx(math.sqrt(U1) / (math.sqrt(U1) + math.sqrt(U2)), rel=0.01)


def test_flash_vectorised_and_zero_load():
    N = np.array([0.0, 50.0, 150.0])
    b = half_width(N, PIN_R, LENGTH, effective_modulus(STEEL))
    res = flash_temperature(N, 0.3, 0.3, 0.05, b, LENGTH, 0.15, STEEL, STEEL, t_on_pin=0.1, t_on_wall=0.1)
    assert res["temp_flash_rise_K"].shape == (3,)
    assert res["temp_flash_rise_K"][0] == 0.0 and np.all(np.isfinite(res["temp_flash_rise_K"]))
    assert np.all(np.diff(res["temp_flash_rise_K"]) > 0)
    # the fit evaluator is within its stated few % of the table one
    fit = flash_temperature(N, 0.3, 0.3, 0.05, b, LENGTH, 0.15, STEEL, STEEL, t_on_pin=0.1, t_on_wall=0.1,
                            evaluator="fit")
    np.testing.assert_allclose(fit["temp_flash_rise_K"][1:], res["temp_flash_rise_K"][1:], rtol=0.05)
    with pytest.raises(ValueError):
        flash_temperature(N, 0.3, 0.3, 0.05, b, LENGTH, 0.15, STEEL, STEEL, method="magic")


def test_transient_floor_coefficient_matches_switched_on_band():
    # docs/theory.md §G4.6: L_eff = 0.749 b/sqrt(chi t_on) makes the steady low-L centre rise (uniform) equal the
    # stationary band switched on for t_on
    assert TRANSIENT_FLOOR_COEFFICIENT == pytest.approx(0.749, abs=5e-4)
    fourier = 400.0                                      # chi t_on / b^2
    L_floor = TRANSIENT_FLOOR_COEFFICIENT / math.sqrt(fourier)
    steady = float(band_theta_low(L_floor, "uniform", "max"))
    assert float(band_stationary_transient(0.0, fourier)) == pytest.approx(steady, rel=2e-3)


def test_row15_circle_source_and_tian_kennedy():
    # docs/theory.md §G7 row 15: Pe = 1 exact max/avg 0.7324/0.5554; T&K form 0.7484/0.5347
    tmax, _ = circle_theta_max_exact(1.0)
    assert tmax == pytest.approx(0.7324, rel=5e-4)
    assert circle_theta_avg_exact(1.0) == pytest.approx(0.5554, rel=5e-4)
    assert tian_kennedy(1.0, "circle", "max") == pytest.approx(0.7484, rel=5e-4)
    assert tian_kennedy(1.0, "circle", "avg") == pytest.approx(0.5347, rel=5e-4)
    # stationary limits: max 1 (centre), avg 8/(3 pi); T&K reproduces them by construction
    assert circle_theta(0.0, 0.0, 0.0) == pytest.approx(1.0, rel=1e-12)
    assert circle_theta_avg_exact(0.0) == pytest.approx(8 / (3 * math.pi), rel=1e-10)
    assert tian_kennedy(0.0, "circle", "avg") == pytest.approx(8 / (3 * math.pi), rel=2e-4)


def test_circle_avg_reduction_equals_area_mean():
    # the one-integral area mean equals the disc average of the pointwise solution (Gauss-Legendre x trapezoid)
    xr, wr = np.polynomial.legendre.leggauss(10)
    r, wr = 0.5 * (xr + 1), 0.5 * wr
    psi = np.linspace(0, 2 * np.pi, 12, endpoint=False)
    total = sum(w * ri * circle_theta(ri * math.cos(p), ri * math.sin(p), 1.0) * (2 * np.pi / len(psi))
                for ri, w in zip(r, wr) for p in psi)
    assert total / math.pi == pytest.approx(circle_theta_avg_exact(1.0), rel=2e-3)
