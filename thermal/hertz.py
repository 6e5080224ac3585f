"""Hertz line contact (2-D, plane strain): a cylinder on a flat or two parallel cylinders.

All functions are vectorised over numpy arrays (whole time series); loads W are total loads (N) over
the contact length l (m). Sources: Johnson (1985) *Contact Mechanics* ch. 4 (2-D Hertz, subsurface
stresses, eq. 4.49 family); docs/theory.md §G3 (checked numbers and the seed's errors).
"""
from __future__ import annotations

import functools

import numpy as np

from mechsim.thermal.materials import Material


def brentq(*args, **kwargs):
    """scipy.optimize.brentq, imported on first call (a fresh `mechsim run` need not load scipy.optimize)."""
    from scipy.optimize import brentq as impl
    return impl(*args, **kwargs)


def effective_modulus(material_1: Material, material_2: Material | None = None) -> float:
    """Contact modulus E* with 1/E* = (1-nu1^2)/E1 + (1-nu2^2)/E2 (Pa).

    Johnson (1985) ch. 4 convention; docs/theory.md §G3 (steel/steel: 113.74 GPa). `material_2` defaults to
    `material_1`.
    """
    material_2 = material_1 if material_2 is None else material_2
    return 1.0 / (material_1.plane_strain_compliance + material_2.plane_strain_compliance)


def seed_reduced_modulus(material_1: Material, material_2: Material | None = None) -> float:
    """The seed's S(10b) "reduced modulus" E' with 1/E' = 1/2[...] = 2 E* (Pa).

    Seed formula (S&B / EHL convention), for comparison only; docs/theory.md §G3.
    """
    return 2.0 * effective_modulus(material_1, material_2)


def effective_radius(radius_1, radius_2=np.inf):
    """Effective radius R' of two parallel cylinders, 1/R' = 1/R1 + 1/R2 (m).

    A flat is R2 = inf (so R' = R1, seed S(10a) ✓); a concave surface has a negative radius
    (conformal contact, needs |R2| > R1). Johnson (1985) ch. 4; docs/theory.md §G3.
    """
    r1 = np.asarray(radius_1, dtype=float)
    r2 = np.asarray(radius_2, dtype=float)
    inv = 1.0 / r1 + 1.0 / r2
    if np.any(inv <= 0):
        raise ValueError("effective_radius: curvatures give a non-convex pair (1/R1 + 1/R2 <= 0)")
    return 1.0 / inv


def half_width(load, radius, length, modulus):
    """Hertz half-width b = sqrt(4 |W| R' / (pi l E*)) (m); Johnson (1985) ch. 4, docs/theory.md §G3."""
    load = np.abs(np.asarray(load, dtype=float))
    return np.sqrt(4.0 * load * radius / (np.pi * length * modulus))


def peak_pressure(load, radius, length, modulus):
    """Hertz peak pressure p0 = sqrt(|W| E* / (pi l R')) = 2|W|/(pi b l) (Pa); Johnson (1985) ch. 4, docs/theory.md §G3."""
    load = np.abs(np.asarray(load, dtype=float))
    return np.sqrt(load * modulus / (np.pi * length * radius))


def mean_pressure(load, radius, length, modulus):
    """Mean pressure W/(2 b l) = pi p0 / 4 (Pa); docs/theory.md §G3."""
    return 0.25 * np.pi * peak_pressure(load, radius, length, modulus)


def axis_shear_ratio(depth_ratio):
    """Principal shear on the load axis over p0, tau1/p0 = zeta - zeta^2/sqrt(1+zeta^2), zeta = z/b.

    From the Hertz subsurface stresses on x=0: sigma_x = -p0[(1+2zeta^2)/sqrt(1+zeta^2) - 2zeta],
    sigma_z = -p0/sqrt(1+zeta^2), tau1 = (sigma_x - sigma_z)/2 in magnitude (Johnson 1985, ch. 4, §4.2).
    """
    zeta = np.asarray(depth_ratio, dtype=float)
    return zeta - zeta**2 / np.sqrt(1.0 + zeta**2)


@functools.lru_cache(maxsize=None)
def max_shear_coefficients() -> tuple[float, float]:
    """(tau_max/p0, z_max/b) of the line contact computed from `axis_shear_ratio` (≈ 0.300, 0.786).

    Johnson (1985) ch. 4 quotes 0.30 p0 at 0.78 b; docs/theory.md §G3.
    """
    # d(tau)/d(zeta) = 1 - zeta (2 + zeta^2) / (1 + zeta^2)^1.5
    zeta = brentq(lambda s: 1.0 - s * (2.0 + s * s) / (1.0 + s * s) ** 1.5, 0.1, 2.0, xtol=1e-14)
    return float(axis_shear_ratio(zeta)), float(zeta)


def line_contact(load, radius, length, modulus) -> dict[str, np.ndarray]:
    """All Hertz line-contact results at once (arrays): half-width, peak/mean pressure, max subsurface shear and depth.

    Valid for b << R', l >> b, elastic (p0 < ~1.6 yield), frictionless normal load; docs/theory.md §G3.
    """
    b = half_width(load, radius, length, modulus)
    p0 = peak_pressure(load, radius, length, modulus)
    tau_ratio, depth_ratio = max_shear_coefficients()
    return {
        "half_width_m": b,
        "pressure_peak_Pa": p0,
        "pressure_mean_Pa": 0.25 * np.pi * p0,
        "shear_max_Pa": tau_ratio * p0,
        "shear_depth_m": depth_ratio * b,
    }


def seed_half_width(load, radius, length, reduced_modulus):
    """Seed S(9a) as quoted: b = sqrt(4 W R'/(pi l E')) (m).

    Seed formula, for comparison only: with the seed's E' = 2E* it is sqrt(2) too small (docs/theory.md §G3);
    the seed's own Peclet numbers are reproduced only with E' replaced by E* (then it equals `half_width`).
    """
    load = np.abs(np.asarray(load, dtype=float))
    return np.sqrt(4.0 * load * radius / (np.pi * length * reduced_modulus))


def seed_max_pressure(load, half_width_m, length):
    """Seed S(9b) as quoted: p_max = W/(pi b l) (Pa); zero where b = 0.

    Seed formula, for comparison only: half of Hertz p0 = 2W/(pi b l) for the same b (docs/theory.md §G3).
    """
    load = np.abs(np.asarray(load, dtype=float))
    b = np.asarray(half_width_m, dtype=float)
    denom = np.pi * b * length
    return np.divide(load, denom, out=np.zeros(np.broadcast(load, denom).shape), where=denom > 0)
