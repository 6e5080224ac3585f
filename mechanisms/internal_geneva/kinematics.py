"""Closed-form kinematics of the internal Geneva drive (the crank inside the wheel, both turning the same way).

Frame and signs of docs/internal_geneva.md: wheel centre O2 at the origin, crank centre O1 at (c, 0), the pin at
P = (c + r cos alpha, r sin alpha) (alpha = 0: pin deepest in the slot, at c + r from O2), crank angle alpha and
wheel angle beta both counter-clockwise. The slots point inward to the wheel centre, so the slot the pin is in
lies along O2P: beta = atan2(r sin alpha, c + r cos alpha). Tangential entry (O1P perpendicular to O2P) at
alpha0 = pi/2 + pi/n fixes c = r / sin(pi/n), as for the external drive; the pin runs the far arc of the same pin
circle whose near arc drives an external wheel. Every formula here is the external one (mechanisms/geneva) with
the pin's x coordinate c - r cos alpha replaced by c + r cos alpha. Sources: docs/internal_geneva.md; Sclater &
Chironis (2001), "Mechanisms and Mechanical Devices Sourcebook", internal Geneva wheel; Bickford (1972),
"Mechanisms for Intermittent Motion", ch. 5.
"""
from __future__ import annotations

from typing import ClassVar

import numpy as np

from mechsim.mechanisms.geneva.kinematics import GenevaGeometry


class InternalGenevaGeometry(GenevaGeometry):
    """Internal Geneva geometry from crank radius r, slot count n, pin radius R and wheel thickness (SI).

    Engaged while |alpha| < pi/2 + pi/n: the crank turns pi + 2 pi/n (a share 1/2 + 1/n of its turn) while the wheel
    indexes 2 pi/n in the same sense (docs/internal_geneva.md, 'Kinematics').
    """

    #: the crank turns in the wheel's indexing sense (docs/internal_geneva.md, 'Slip')
    crank_sense: ClassVar[int] = +1

    @property
    def engagement_half_angle(self) -> float:
        """alpha0 = pi/2 + pi/n: the crank turns 2 alpha0 = pi + 2 pi/n while the wheel indexes 2 pi/n."""
        return np.pi / 2 + np.pi / self.slots

    @property
    def min_pin_distance(self) -> float:
        """The engaged pin's closest approach to the wheel centre: at entry and exit, c cos(pi/n)."""
        return self.entry_pin_distance

    @property
    def deepest_pin_distance(self) -> float:
        """The pin's distance from the wheel centre at mid-engagement, c + r (pin deepest in the slot)."""
        return self.centre_distance + self.crank_radius

    @property
    def wheel_radius(self) -> float:
        """About the wheel's radius: the slot bottoms, c + r from the wheel centre."""
        return self.deepest_pin_distance

    @property
    def dwell_fraction(self) -> float:
        """(n - 2) / (2 n) of a crank turn: the rest of 1/2 + 1/n engaged."""
        return (self.slots - 2) / (2 * self.slots)

    @staticmethod
    def wheel_motion(lam, alpha, lib=np):
        """(beta, G, G', x/c) while engaged, with D = 1 + 2 lam cos alpha + lam^2 (docs/internal_geneva.md, eqs. 2-4):
        beta = atan2(lam sin alpha, 1 + lam cos alpha), G = d(beta)/d(alpha) = lam (cos alpha + lam) / D,
        G' = -lam (1 - lam^2) sin alpha / D^2, x/c = sqrt(D); lib: numpy (vectorised) or sympy."""
        cos_a, sin_a = lib.cos(alpha), lib.sin(alpha)
        d = 1 + 2 * lam * cos_a + lam * lam
        return (lib.atan2(lam * sin_a, 1 + lam * cos_a), lam * (cos_a + lam) / d,
                -lam * (1 - lam * lam) * sin_a / d ** 2, lib.sqrt(d))

    @staticmethod
    def wheel_angle(lam, alpha, lib=np):
        """`wheel_motion`'s beta alone (a transition rule needs no more; docs/internal_geneva.md eq. 2)."""
        return lib.atan2(lam * lib.sin(alpha), 1 + lam * lib.cos(alpha))

    @staticmethod
    def speed_ratio(lam, alpha, lib=np):
        """`wheel_motion`'s G alone (docs/internal_geneva.md eq. 3)."""
        cos_a = lib.cos(alpha)
        return lam * (cos_a + lam) / (1 + 2 * lam * cos_a + lam * lam)

    @staticmethod
    def pin_position(r, c, alpha, lib=np):
        """The pin centre P = (c + r cos alpha, r sin alpha) in the wheel-centre frame (docs/internal_geneva.md eq. 1)."""
        return c + r * lib.cos(alpha), r * lib.sin(alpha)

    @staticmethod
    def pin_in_slot(r, c, alpha, beta, lib=np):
        """The pin centre against the slot at angle beta, (Phi, x, s, a) (docs/internal_geneva.md eqs. 5-6): lateral
        offset Phi = r sin alpha cos beta - (c + r cos alpha) sin beta, distance along the slot x, sliding speed
        per unit crank speed s = -r sin(alpha - beta) (outward positive) and the normal force's crank arm
        a = r cos(alpha - beta) (= x G)."""
        return (r * lib.sin(alpha) * lib.cos(beta) - (c + r * lib.cos(alpha)) * lib.sin(beta),
                r * lib.sin(alpha) * lib.sin(beta) + (c + r * lib.cos(alpha)) * lib.cos(beta),
                InternalGenevaGeometry.slot_sliding(r, alpha, beta, lib),
                InternalGenevaGeometry.slot_arm(r, alpha, beta, lib))

    @staticmethod
    def slot_sliding(r, alpha, beta, lib=np):
        """`pin_in_slot`'s s = -r sin(alpha - beta) alone (docs/internal_geneva.md eq. 6)."""
        return -r * lib.sin(alpha - beta)

    @staticmethod
    def slot_arm(r, alpha, beta, lib=np):
        """`pin_in_slot`'s a = r cos(alpha - beta) alone (docs/internal_geneva.md eq. 6)."""
        return r * lib.cos(alpha - beta)


def speed_ratio_second_derivative(lam: float, alpha):
    """G'' = -lam (1 - lam^2) [(1 + lam^2) cos alpha + 2 lam (1 + sin^2 alpha)] / D^3 (the wheel's jerk per
    crank speed cubed; docs/internal_geneva.md eq. 4)."""
    d = 1 + 2 * lam * np.cos(alpha) + lam * lam
    return -lam * (1 - lam * lam) * ((1 + lam * lam) * np.cos(alpha) + 2 * lam * (1 + np.sin(alpha) ** 2)) / d ** 3
