"""Lumped bulk model (docs/theory.md §G5, §7 row 19): geometry, time constants, steady state, exact integrator,
energy balance."""
import math

import numpy as np
import pytest
from scipy.integrate import solve_ivp

from mechsim.thermal import (biot_number, bulk_system, cycle_means, disc_volume_area, geneva_bulk_system, get_material,
                     integrate_mean_heat, pin_volume_area, steady_bulk_temperatures, time_constant)

STEEL = get_material("aisi1045")


def test_geometry_helpers():
    v, a = disc_volume_area(0.075, 0.004)
    assert a == pytest.approx(0.0372, rel=2e-3)                 # docs/theory.md §G5: A = 0.0372 m^2
    assert v / a == pytest.approx(1.90e-3, rel=2e-3)            # V/A = 1.90 mm
    v, a = pin_volume_area(0.004, 0.010)
    assert v / a == pytest.approx(1.67e-3, rel=2e-3)            # V/A = 1.67 mm
    assert biot_number(25.0, v, a, STEEL.conductivity) < 1e-3   # lumping valid (Bi ~ 4e-4 << 0.1)


def test_row19_time_constants():
    # docs/theory.md §G7 row 19 and §5: wheel 1034 s (h=7), 603 s (h=12); pin 635 s (h=10), 254 s (h=25)
    vw, aw = disc_volume_area(0.075, 0.004)
    vp, ap = pin_volume_area(0.004, 0.010)
    assert time_constant(STEEL, vw, aw, 7.0) == pytest.approx(1034, rel=1e-2)
    assert time_constant(STEEL, vw, aw, 12.0) == pytest.approx(603, rel=1e-2)
    assert time_constant(STEEL, vp, ap, 10.0) == pytest.approx(635, rel=1e-2)
    assert time_constant(STEEL, vp, ap, 25.0) == pytest.approx(254, rel=1e-2)
    # the network's modal time constants equal the body ones when uncoupled
    sysm = geneva_bulk_system(h_pin=10.0, h_wheel=7.0)
    np.testing.assert_allclose(sysm.time_constants(), [time_constant(STEEL, vw, aw, 7.0),
                                                       time_constant(STEEL, vp, ap, 10.0)], rtol=1e-12)


def test_row19_steady_wheel_rise():
    # docs/theory.md §G7 row 19: gamma_wheel = 0.65, Q_bar = 1.588 W (mu = 0.15), h = 7, A = 0.0372 -> 3.96 K
    sysm = geneva_bulk_system(h_wheel=7.0, temp_ambient=300.0)
    T = steady_bulk_temperatures(sysm, 1.588, share_pin=0.35)
    assert T[1] - 300.0 == pytest.approx(3.96, rel=1e-2)
    assert sysm.state_names == ("temp_bulk_pin", "temp_bulk_wheel")


def test_coupling_conductance_and_structure():
    sysm = bulk_system(10.0, 20.0, 0.1, 0.2, conductance_pin_wheel=0.5, temp_ambient=0.0)
    K = sysm.conductance
    np.testing.assert_allclose(K, K.T)
    np.testing.assert_allclose(K.sum(axis=1), [0.1, 0.2])       # G cancels in the row sums: only losses remain
    # steady state: total heat out by convection equals heat in
    T = steady_bulk_temperatures(sysm, 3.0, 0.4)
    assert 0.1 * T[0] + 0.2 * T[1] == pytest.approx(3.0, rel=1e-12)


def test_exact_integrator_matches_bdf_and_approaches_steady_state():
    sysm = geneva_bulk_system(h_pin=15.0, h_wheel=7.0, conductance_pin_wheel=0.02, temp_ambient=293.15)
    times = np.array([0.0, 60.0, 600.0, 3600.0])
    T = integrate_mean_heat(sysm, 1.588, 0.35, times)
    np.testing.assert_allclose(T[0], 293.15)
    ref = solve_ivp(lambda t, y: sysm.rhs(y, [0.35 * 1.588, 0.65 * 1.588]), (0, 3600.0), [293.15, 293.15],
                    method="Radau", t_eval=times, rtol=1e-11, atol=1e-11)
    np.testing.assert_allclose(T, ref.y.T, rtol=0, atol=1e-7)
    steady = steady_bulk_temperatures(sysm, 1.588, 0.35)
    late = integrate_mean_heat(sysm, 1.588, 0.35, [50 * sysm.time_constants()[0]])[0]
    np.testing.assert_allclose(late, steady, atol=1e-9)


def test_lumped_energy_balance():
    # sum C_i dT_i = int Q dt - convected, to 1e-6 relative, with a periodic heat input
    sysm = geneva_bulk_system(h_pin=15.0, h_wheel=7.0, conductance_pin_wheel=0.05, temp_ambient=293.15)
    hA = np.asarray(sysm.conductance).sum(axis=1)
    T_inf = 293.15
    period = 1.177

    def heat(t):
        return 3.0 * math.sin(math.pi * t / period) ** 2          # mean 1.5 W

    def rhs(t, y):
        T = y[:2]
        Q = heat(t)
        dT = sysm.rhs(T, [0.35 * Q, 0.65 * Q])
        return np.concatenate([dT, [hA @ (T - T_inf)]])

    t_end = 200 * period
    sol = solve_ivp(rhs, (0, t_end), [T_inf, T_inf, 0.0], method="DOP853", rtol=1e-11, atol=1e-12)
    stored = sysm.energy(sol.y[:2, -1], T_inf)
    q_in = 1.5 * t_end                                            # int 3 sin^2 over whole half-periods
    convected = sol.y[2, -1]
    assert stored == pytest.approx(q_in - convected, rel=1e-6)
    assert convected > 0.05 * q_in                               # the check is not trivial


def test_cycle_means():
    t = np.linspace(0.0, 1.177, 2001)
    Q = 3.0 * np.sin(np.pi * t / 1.177) ** 2
    share = np.where(t < 0.5 * 1.177, 0.3, 0.4)
    Q_bar, g_bar = cycle_means(t, Q, share)
    assert Q_bar == pytest.approx(1.5, rel=1e-6)
    assert g_bar == pytest.approx(0.35, rel=1e-3)                   # heat-weighted, symmetric halves
    assert cycle_means(t, 0.0, 0.3) == (0.0, 0.5)
