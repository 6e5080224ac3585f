"""Materials, Hertz line contact, heat and Peclet numbers: docs/theory.md §G0, §3, §4.1–4.2, §7 rows 10–11."""
import math
import subprocess
import sys

import numpy as np
import pytest

from mechsim.thermal import (MATERIALS, Material, axis_shear_ratio, effective_modulus, effective_radius, frictional_heat,
                     get_material, half_width, line_contact, max_shear_coefficients, mean_flux, mean_pressure,
                     peak_pressure, peclet, seed_half_width, seed_max_pressure, seed_reduced_modulus)

STEEL = get_material("aisi1045")
R_PIN, LENGTH = 4e-3, 4e-3
LOADS = np.array([35.0, 93.33, 225.33])


def test_thermal_imports_nothing_else_from_mechsim():
    code = ("import sys, thermal; bad = [m for m in sys.modules if m.split('.')[0] in "
            "('mechanisms', 'dynamics', 'scenarios')]; print(bad); sys.exit(1 if bad else 0)")
    done = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True)
    assert done.returncode == 0, done.stdout + done.stderr


def test_aisi1045_derived_properties():
    # docs/theory.md §G0: chi = 1.1096e-5 m^2/s, e = 12698 W s^0.5/(m^2 K)
    assert STEEL.diffusivity == pytest.approx(1.1096e-5, rel=1e-4)
    assert STEEL.effusivity == pytest.approx(12698, rel=1e-4)
    assert STEEL.effusivity == pytest.approx(STEEL.conductivity / math.sqrt(STEEL.diffusivity), rel=1e-12)


def test_material_lookup_errors_name_the_material():
    assert get_material("AISI1045") is MATERIALS["aisi1045"]
    with pytest.raises(ValueError, match="unobtainium"):
        get_material("unobtainium")
    with pytest.raises(ValueError, match="conductivity"):
        Material("bad", 1e9, 0.3, 1000.0, 500.0, -1.0)


def test_effective_modulus_conventions():
    # docs/theory.md §G3: E* = 113.74 GPa (Johnson), seed E' = 2 E* = 227.47 GPa
    assert effective_modulus(STEEL) == pytest.approx(113.74e9, rel=1e-4)
    assert seed_reduced_modulus(STEEL) == pytest.approx(227.47e9, rel=1e-4)


def test_effective_radius():
    assert effective_radius(R_PIN) == R_PIN                       # cylinder on flat (seed S(10a))
    assert effective_radius(2.0, 2.0) == pytest.approx(1.0)
    assert effective_radius(1.0, -2.0) == pytest.approx(2.0)      # conformal (pin in a hole)
    with pytest.raises(ValueError):
        effective_radius(2.0, -1.0)


def test_hertz_row10_half_width_and_peak_pressure():
    # docs/theory.md §G7 row 10
    res = line_contact(LOADS, R_PIN, LENGTH, effective_modulus(STEEL))
    np.testing.assert_allclose(res["half_width_m"], [19.79e-6, 32.32e-6, 50.22e-6], rtol=1e-3)
    np.testing.assert_allclose(res["pressure_peak_Pa"], [281.4e6, 459.5e6, 714.0e6], rtol=1e-3)
    # the consistent pair check of docs/theory.md §G3: p0 b = 2W/(pi l), mean = W/(2bl) = pi p0/4
    np.testing.assert_allclose(res["pressure_peak_Pa"] * res["half_width_m"], 2 * LOADS / (np.pi * LENGTH), rtol=1e-12)
    np.testing.assert_allclose(res["pressure_mean_Pa"], LOADS / (2 * res["half_width_m"] * LENGTH), rtol=1e-12)
    np.testing.assert_allclose(mean_pressure(LOADS, R_PIN, LENGTH, effective_modulus(STEEL)),
                               res["pressure_mean_Pa"], rtol=1e-12)


def test_hertz_signed_loads_and_zero():
    Es = effective_modulus(STEEL)
    assert half_width(-35.0, R_PIN, LENGTH, Es) == half_width(35.0, R_PIN, LENGTH, Es)
    assert half_width(0.0, R_PIN, LENGTH, Es) == 0.0 and peak_pressure(0.0, R_PIN, LENGTH, Es) == 0.0


def test_max_subsurface_shear_from_stress_field():
    # Johnson (1985) ch. 4: 0.30 p0 at 0.78 b (rounded); brute-force maximum of the on-axis principal shear
    tau, depth = max_shear_coefficients()
    zeta = np.linspace(0.0, 3.0, 300001)
    brute = axis_shear_ratio(zeta)
    assert tau == pytest.approx(brute.max(), rel=1e-9)
    assert depth == pytest.approx(zeta[brute.argmax()], abs=2e-5)
    assert round(tau, 2) == 0.30 and round(depth, 2) == 0.79 and 0.78 <= depth < 0.79 + 1e-9
    # the on-axis shear from the stress components sigma_x, sigma_z (independent form)
    z = 0.37
    sx = -((1 + 2 * z**2) / math.sqrt(1 + z**2) - 2 * z)
    sz = -1 / math.sqrt(1 + z**2)
    assert axis_shear_ratio(z) == pytest.approx(0.5 * abs(sx - sz), rel=1e-12)


def test_seed_s9_as_quoted():
    # docs/theory.md §G3 table: S&B-as-quoted b and p, and the seed's effective W/(pi b l) with Hertz b
    b_q = seed_half_width(LOADS, R_PIN, LENGTH, seed_reduced_modulus(STEEL))
    np.testing.assert_allclose(b_q, [14.00e-6, 22.86e-6, 35.51e-6], rtol=1e-3)
    np.testing.assert_allclose(seed_max_pressure(LOADS, b_q, LENGTH), [199.0e6, 324.9e6, 504.9e6], rtol=1e-3)
    b_h = half_width(LOADS, R_PIN, LENGTH, effective_modulus(STEEL))
    np.testing.assert_allclose(seed_max_pressure(LOADS, b_h, LENGTH), [140.7e6, 229.8e6, 357.0e6], rtol=1e-3)
    np.testing.assert_allclose(b_h / b_q, math.sqrt(2), rtol=1e-12)         # sqrt(2) too small
    assert seed_max_pressure(0.0, 0.0, LENGTH) == 0.0


def test_row11_seed_peclet_numbers():
    # docs/theory.md §G7 row 11: U = omega1 r = 0.4005 m/s, Hertz b of the S(8) loads 35 / 93.33 N
    b = half_width(np.array([35.0, 93.33]), R_PIN, LENGTH, effective_modulus(STEEL))
    np.testing.assert_allclose(peclet(0.4005, b, STEEL.diffusivity), [0.357, 0.583], rtol=5e-3)
    # with S(9) as printed (E' = 2E*) the seed's numbers are NOT reproduced (0.253...0.412)
    b_q = seed_half_width(np.array([35.0, 93.33]), R_PIN, LENGTH, seed_reduced_modulus(STEEL))
    np.testing.assert_allclose(peclet(0.4005, b_q, STEEL.diffusivity), [0.253, 0.412], rtol=5e-3)


def test_heat_and_flux_vectorised():
    N = np.array([-100.0, 0.0, 50.0])
    u = np.array([0.2, 1.0, -0.4])
    np.testing.assert_allclose(frictional_heat(0.15, N, u), [3.0, 0.0, 3.0])
    q = mean_flux(frictional_heat(0.15, N, u), np.array([1e-5, 0.0, 2e-5]), LENGTH)
    np.testing.assert_allclose(q, [3.0 / (2e-5 * LENGTH), 0.0, 3.0 / (4e-5 * LENGTH)])
