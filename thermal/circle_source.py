"""Moving uniform circular heat source on a half-space (3-D, point contacts): exact integral and Tian–Kennedy form.

Used as a cross-check of the Peclet conventions and of the Tian & Kennedy (1994) all-Pe form; the Geneva's
line contact uses `band_source`. Pe = U a/(2 chi), a = source radius, theta = dT k/(q_bar a).
Sources: Carslaw & Jaeger (1959) (moving point source dT = Q/(2 pi k R) exp(-U(R + xi)/(2 chi))),
Tian & Kennedy (1994) J. Tribol. 116:167; docs/theory.md §G4.5.
"""
from __future__ import annotations

import math

import numpy as np


def quad(*args, **kwargs):
    """scipy.integrate.quad, imported on first call (a fresh `mechsim run` need not load scipy.integrate)."""
    from scipy.integrate import quad as impl
    return impl(*args, **kwargs)


def minimize_scalar(*args, **kwargs):
    """scipy.optimize.minimize_scalar, imported on first call (a fresh `mechsim run` need not load scipy.optimize)."""
    from scipy.optimize import minimize_scalar as impl
    return impl(*args, **kwargs)

#: (A, B) of theta = A/sqrt(pi (B + Pe)) (docs/theory.md §G4.5 table; A from the high-Pe limit, B from Pe = 0).
TIAN_KENNEDY = {
    ("circle", "max"): (2.0, 4.0 / math.pi),
    ("circle", "avg"): (1.2204, 0.6580),
    ("square", "max"): (2.0, 1.0110),
    ("square", "avg"): (4.0 / 3.0, 0.6318),
}


def tian_kennedy(peclet, shape: str = "circle", statistic: str = "max"):
    """Tian & Kennedy (1994) all-Pe form theta = A/sqrt(pi (B + Pe)); docs/theory.md §G4.5 (circle max +2.2 %, avg -3.7 % worst)."""
    try:
        a, b = TIAN_KENNEDY[(shape, statistic)]
    except KeyError:
        raise ValueError(f"unknown source {shape!r}/{statistic!r}; known: {sorted(TIAN_KENNEDY)}") from None
    return a / np.sqrt(np.pi * (b + np.asarray(peclet, dtype=float)))


def circle_theta(x: float, y: float, peclet: float) -> float:
    """Exact theta at surface point (x, y) (units of a, |(x,y)| < 1) of the uniform disc moving along +x.

    Superposing the moving point source in polar coordinates (rho, phi) about the field point, the radial
    integral is closed: theta = (1/(2 pi)) int_0^{2 pi} (1 - exp(-s rho_m))/s dphi, s = Pe (1 + cos phi),
    rho_m = distance to the disc edge in direction phi (Carslaw & Jaeger 1959; docs/theory.md §G4.5).
    """
    r2 = x * x + y * y
    if r2 >= 1.0:
        raise ValueError("circle_theta: the field point must lie inside the source")

    def integrand(phi):
        c, s_ = math.cos(phi), math.sin(phi)
        pe = x * c + y * s_
        rho_m = pe + math.sqrt(pe * pe + 1.0 - r2)
        s = peclet * (1.0 + c)
        return rho_m if s * rho_m < 1e-12 else -math.expm1(-s * rho_m) / s

    return quad(integrand, 0.0, 2.0 * math.pi, limit=200, epsabs=1e-13, epsrel=1e-11)[0] / (2.0 * math.pi)


def circle_theta_max_exact(peclet: float) -> tuple[float, float]:
    """(theta_max, x at the maximum) of the exact solution (the maximum lies on the axis y = 0)."""
    res = minimize_scalar(lambda x: -circle_theta(x, 0.0, peclet), bounds=(-0.999, 0.999), method="bounded",
                          options={"xatol": 1e-7})
    return float(-res.fun), float(res.x)


def circle_theta_avg_exact(peclet: float) -> float:
    """Exact area mean of theta over the disc, reduced to one integral over the separation rho of two points:

    theta_avg = (1/pi) int_0^2 A(rho) e^{-Pe rho} I0(Pe rho) drho, A(rho) = 2 acos(rho/2) - (rho/2) sqrt(4 - rho^2)
    (overlap area of two unit discs; the angular integral of exp(-Pe rho (1 + cos phi)) is 2 pi e^{-Pe rho} I0).
    Pe = 0 gives 8/(3 pi) (docs/theory.md §G4.5).
    """
    from scipy.special import i0e      # here: a fresh `mechsim run` need not load scipy.special
    area = lambda r: 2.0 * math.acos(0.5 * r) - 0.5 * r * math.sqrt(max(0.0, 4.0 - r * r))
    return quad(lambda r: area(r) * i0e(peclet * r), 0.0, 2.0, limit=200, epsabs=1e-13, epsrel=1e-11)[0] / math.pi
