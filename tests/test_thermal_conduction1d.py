"""1-D conduction under the contact (docs/theory.md §G6, §7 row 17): MOL vs exact solutions, mesh convergence
order, energy balance, exact-solution consistency."""
import math

import numpy as np
import pytest
import scipy.sparse as sps
from scipy.integrate import solve_ivp

from mechsim.thermal import (conduction_system, duhamel_surface, flux_step_profile, flux_step_surface, get_material,
                     graded_mesh, graded_mesh_cells, mesh_settings, moving_band_high_peclet_max,
                     switched_flux_surface, validity)

STEEL = get_material("aisi1045")


def test_row17_switched_flux_bdf_with_sparse_jacobian():
    # docs/theory.md §G7 row 17: q = 4.33e7 W/m^2 on for 161.6 us: 48.91 K at t_on, 20.26 K at 2 t_on (exact)
    q, t_on = 4.33e7, 161.6e-6
    assert switched_flux_surface(t_on, q, t_on, STEEL) == pytest.approx(48.91, rel=1e-3)
    assert switched_flux_surface(2 * t_on, q, t_on, STEEL) == pytest.approx(20.26, rel=1e-3)
    model = conduction_system(graded_mesh(0.5e-6, 1.15, 2.06e-3), STEEL)      # docs/theory.md §G6 example, 46 cells
    assert model.mesh.n_cells == 46
    assert sps.issparse(model.system.jacobian())
    n = model.mesh.n_cells
    on = model.system.integrate((0, t_on), np.zeros(n), lambda t: [q], method="BDF")
    off = model.system.integrate((t_on, 2 * t_on), on.y[:, -1], lambda t: [0.0], method="BDF")
    assert on.success and off.success
    assert model.surface_temperature(on.y[:, -1], q) == pytest.approx(48.91, rel=5e-3)
    assert model.surface_temperature(off.y[:, -1], 0.0) == pytest.approx(20.26, rel=5e-3)


def test_stiffness_spectrum():
    # docs/theory.md §G6 example mesh (0.5 um, 1.15, 2.06 mm): lambda_max ≈ 1.07e8 1/s <= 4 chi/dz_min^2 (Gershgorin);
    # lambda_min = chi pi^2/(4 H^2) for a far face held fixed (0 if insulated)
    mesh = graded_mesh(0.5e-6, 1.15, 2.06e-3)
    lam = 1.0 / conduction_system(mesh, STEEL, far="fixed").system.time_constants()
    assert lam.max() <= 4 * STEEL.diffusivity / mesh.widths[0] ** 2
    assert lam.max() == pytest.approx(1.07e8, rel=5e-3)
    assert lam.min() == pytest.approx(STEEL.diffusivity * math.pi**2 / (4 * mesh.depth**2), rel=2e-3)
    insulated = conduction_system(mesh, STEEL).system.time_constants()
    assert insulated[0] == np.inf


def test_mesh_convergence_second_order():
    # constant flux, insulated far face 8 diffusion lengths deep; exact-in-time (expm) so only space error is left
    q, t = 1e7, 1e-3
    depth = 8 * math.sqrt(STEEL.diffusivity * t)
    errors = []
    for k in range(4):
        model = conduction_system(graded_mesh_cells(depth, 10 * 2**k, 1.3 ** (1 / 2**k)), STEEL)
        T = model.system.propagate(np.zeros(model.mesh.n_cells), [q], [t])[0]
        errors.append(abs(model.surface_temperature(T, q) - flux_step_surface(t, q, STEEL)))
    orders = np.log2(np.array(errors[:-1]) / np.array(errors[1:]))
    np.testing.assert_allclose(orders, 2.0, atol=0.05)
    assert errors[-1] / flux_step_surface(t, q, STEEL) < 1e-3


def test_profile_matches_ierfc_solution():
    q, t = 1e7, 2e-3
    model = conduction_system(graded_mesh(1e-6, 1.1, 8 * math.sqrt(STEEL.diffusivity * t)), STEEL)
    T = model.system.propagate(np.zeros(model.mesh.n_cells), [q], [t])[0]
    exact = flux_step_profile(model.mesh.centres, t, q, STEEL)
    assert np.max(np.abs(T - exact)) < 2e-3 * exact[0]


def test_exact_solutions_are_consistent():
    q, t = 3e6, 1e-3
    # surface value of the profile; the profile satisfies -k dT/dz = q at z = 0 and the heat equation
    assert flux_step_profile(0.0, t, q, STEEL) == pytest.approx(flux_step_surface(t, q, STEEL), rel=1e-14)
    dz = 1e-8
    grad = (flux_step_profile(dz, t, q, STEEL) - flux_step_profile(0.0, t, q, STEEL)) / dz
    assert -STEEL.conductivity * grad == pytest.approx(q, rel=1e-3)
    z, h, dt = 40e-6, 1e-6, 1e-8
    d2 = (flux_step_profile(z + h, t, q, STEEL) - 2 * flux_step_profile(z, t, q, STEEL)
          + flux_step_profile(z - h, t, q, STEEL)) / h**2
    dTdt = (flux_step_profile(z, t + dt, q, STEEL) - flux_step_profile(z, t - dt, q, STEEL)) / (2 * dt)
    assert dTdt == pytest.approx(STEEL.diffusivity * d2, rel=1e-4)
    # stored heat = q t
    zz = np.linspace(0, 30 * math.sqrt(STEEL.diffusivity * t), 20001)
    stored = STEEL.volumetric_heat_capacity * np.trapezoid(flux_step_profile(zz, t, q, STEEL), zz)
    assert stored == pytest.approx(q * t, rel=1e-6)
    # Duhamel with a switched flux equals the closed form; with a ramp q = a tau, (4/3) a t^1.5/(sqrt(pi) e)
    t_on = 0.4e-3
    assert duhamel_surface(t, lambda s: q if s < t_on else 0.0, STEEL, [t_on]) == pytest.approx(
        switched_flux_surface(t, q, t_on, STEEL), rel=1e-9)
    a = 1e9
    assert duhamel_surface(t, lambda s: a * s, STEEL) == pytest.approx(
        4 / 3 * a * t**1.5 / (math.sqrt(math.pi) * STEEL.effusivity), rel=1e-9)
    # high-L band maximum = flux step with t_on = 2b/U
    b, U = 50e-6, 2.0
    assert moving_band_high_peclet_max(q, b, U, STEEL) == pytest.approx(flux_step_surface(2 * b / U, q, STEEL),
                                                                        rel=1e-12)


def test_fixed_far_face_steady_state_is_linear_profile():
    # q in at the surface, h = 0, far face at T_far: exact steady T(z) = T_far + q (H - z)/k; FV is exact for it
    mesh = graded_mesh(5e-6, 1.2, 1e-3)
    model = conduction_system(mesh, STEEL, far="fixed")
    q, T_far = 2e5, 310.0
    T = model.system.steady_state([q, T_far])
    np.testing.assert_allclose(T, T_far + q * (mesh.depth - mesh.centres) / STEEL.conductivity, rtol=1e-12)
    assert model.surface_temperature(T, q) == pytest.approx(T_far + q * mesh.depth / STEEL.conductivity, rel=1e-12)


def test_conduction_energy_balance_with_convection():
    # sum C_i dT_i = int q dt - int h (T_s - T_inf) dt, to 1e-6 relative (BDF, sparse Jacobian)
    h, T_inf, q0, period = 5e4, 300.0, 2e6, 2e-3
    model = conduction_system(graded_mesh(1e-6, 1.15, 1e-3), STEEL, h=h, temp_ambient=T_inf)
    n = model.mesh.n_cells
    A = model.system.jacobian()
    q = lambda t: q0 * math.sin(math.pi * t / period) ** 2

    def rhs(t, y):
        return np.concatenate([model.system.rhs(y[:n], [q(t)]), [model.convected_flux(y[:n], q(t))]])

    conv_row = sps.csr_matrix(([h * model.surface_weight], ([0], [0])), shape=(1, n))   # d(convected)/dT
    jac = sps.bmat([[A, sps.csr_matrix((n, 1))], [conv_row, sps.csr_matrix((1, 1))]], format="csc")
    t_end = 20 * period
    sol = solve_ivp(rhs, (0, t_end), np.r_[np.full(n, T_inf), 0.0], method="BDF",
                    jac=jac, rtol=1e-10, atol=1e-10)
    assert sol.success
    stored = model.system.energy(sol.y[:n, -1], T_inf)
    q_in = 0.5 * q0 * t_end
    convected = sol.y[n, -1]
    assert convected > 0.01 * q_in
    assert stored == pytest.approx(q_in - convected, rel=1e-6)


def test_mesh_settings_and_validity():
    s = mesh_settings(45e-6, 0.3, STEEL.diffusivity, 1.2)
    delta = math.sqrt(STEEL.diffusivity * 2 * 45e-6 / 0.3)
    assert s["first_cell"] == pytest.approx(delta / 10)
    assert s["depth"] >= 3 * math.sqrt(STEEL.diffusivity * 1.2)
    mesh = graded_mesh(**s)
    assert mesh.widths[0] <= s["first_cell"] * (1 + 1e-12)
    assert mesh.depth == pytest.approx(s["depth"])
    assert np.allclose(mesh.widths[1:] / mesh.widths[:-1], s["growth"])
    ok, msg = validity(0.6)
    assert not ok and "0.6" in msg and "band" in msg
    assert validity(np.array([8.0, 12.0]))[0]
