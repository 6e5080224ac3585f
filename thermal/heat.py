"""Frictional heat and Peclet numbers (vectorised over time series).

Sources: seed S(12) and docs/theory.md §G4.1 (heat, incl. pin spin in the slip), §4.2 (Peclet
number convention of Jaeger 1942 / Archard 1959 / Tian & Kennedy 1994).
"""
from __future__ import annotations

import numpy as np


def frictional_heat(mu, normal_force, slip_speed):
    """Heat rate Q = mu |N| |u_slip| (W); docs/theory.md §G4.1 (seed S(12) with the full slip speed)."""
    return np.asarray(mu, dtype=float) * np.abs(normal_force) * np.abs(slip_speed)


def heat_per_length(heat_rate, length):
    """Line-contact heat per unit length Q' = Q/l (W/m); docs/theory.md §G4.1."""
    return np.asarray(heat_rate, dtype=float) / length


def mean_flux(heat_rate, half_width_m, length):
    """Mean flux over the band q_bar = Q/(2 b l) (W/m^2); zero where b = 0. docs/theory.md §G4.1."""
    q = np.asarray(heat_rate, dtype=float)
    area = 2.0 * np.asarray(half_width_m, dtype=float) * length
    return np.divide(q, area, out=np.zeros(np.broadcast(q, area).shape), where=area > 0)


def peclet(source_speed, half_width_m, diffusivity):
    """Peclet number L = |U| b / (2 chi) of one body (b = half-width; U = source speed over that body).

    Jaeger (1942), Archard (1959), seed S(11); docs/theory.md §G4.2. Papers using Ub/chi or U(2b)/chi
    differ by factors 2 or 4.
    """
    return np.abs(source_speed) * np.asarray(half_width_m, dtype=float) / (2.0 * diffusivity)
