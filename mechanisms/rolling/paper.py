"""Kar & Sen's rolling-pair relations *as printed*, kept only to show (in tests and docs) why mechsim
deviates from them (docs/theory.md §K2.1 and §2.5, errors K1 and K2). Do not use for simulation.
"""
from __future__ import annotations

import numpy as np

from mechsim.mechanisms.rolling.pair import CircleOnCircle


def paper_trochoid(pair: CircleOnCircle, l4: float, psi: float, phi):
    """Kar & Sen eqs. (1), (10), (11), (14): the centre turns by phi r/R about O and the body by phi.

    Returns complex B0, B, contact P and dB0/dphi. Inconsistent (K1): the contact slips at r^2/R per
    unit phi (docs/theory.md §K2.1).
    """
    phi = np.asarray(phi, dtype=float)
    g = pair.gamma0 + phi * pair.r / pair.R
    O = complex(*pair.O)
    B0 = O + (pair.R + pair.r) * np.exp(1j * g)
    dB0 = 1j * (pair.R + pair.r) * pair.r / pair.R * np.exp(1j * g)
    P = O + pair.R * np.exp(1j * g)
    B = B0 + l4 * np.exp(1j * (pair.gamma0 + psi + phi))
    return dict(B0=B0, dB0=dB0, P=P, B=B)


def paper_contact_slip(pair: CircleOnCircle, phi):
    """Velocity (per unit phi-rate) of the body's material point at the contact under the paper's
    relations: dB0/dphi + 1 x (P - B0), with the body turning at rate 1."""
    t = paper_trochoid(pair, 0.0, 0.0, phi)
    return t["dB0"] + 1j * (t["P"] - t["B0"])


def paper_rotation_matrix(alpha: float, P) -> np.ndarray:
    """Kar & Sen eq. (3) as printed: rotation by alpha about P with translation column
    (x cos a - y sin a - x, x sin a + y cos a - y) -- the wrong sign (K2): it rotates about -P."""
    x, y = P
    c, s = np.cos(alpha), np.sin(alpha)
    return np.array([[c, -s, x * c - y * s - x], [s, c, x * s + y * c - y], [0.0, 0.0, 1.0]])


def rotation_matrix(alpha: float, P) -> np.ndarray:
    """Correct homogeneous rotation by alpha about P: translation (x - x cos a + y sin a,
    y - x sin a - y cos a) (docs/theory.md §K2.5 K2)."""
    x, y = P
    c, s = np.cos(alpha), np.sin(alpha)
    return np.array([[c, -s, x - x * c + y * s], [s, c, y - x * s - y * c], [0.0, 0.0, 1.0]])
