"""Closed-form kinematics of the external Geneva drive at constant crank speed (vectorised numpy).

Frame and signs of docs/theory.md §G1: wheel centre O2 at the origin, crank centre O1 at (c, 0); crank angle
alpha from the line of centres (0 = pin deepest in the slot), growing with time; wheel angle beta = angle
of the engaged slot, positive in the driving direction. Sources: docs/theory.md §G1 (re-derived; agrees with
Sclater & Chironis 2001 and with the seed's S(3a), S(3b), S(7) up to the sign S(3b) loses).
"""
from __future__ import annotations

from dataclasses import dataclass
from typing import ClassVar

import numpy as np


@dataclass(frozen=True)
class GenevaGeometry:
    """External Geneva geometry from crank radius r, slot count n and pin radius R (SI).

    Tangential (shock-free) entry fixes the centre distance c = r / sin(pi/n) (docs/theory.md §G1 table, row λ, c).
    The pin-in-slot formulas (`wheel_motion`, `pin_position`, `pin_in_slot`) and `crank_sense` are the one place
    where the external drive differs from the internal one (mechanisms/internal_geneva/), which overrides them.
    """

    #: the crank's sense of turning against the wheel's indexing sense: an external wheel turns against its crank
    #: (-1); the pin turns against the wheel at w2 - crank_sense w1 (docs/theory.md §G1 'Pin spin')
    crank_sense: ClassVar[int] = -1

    crank_radius: float
    slots: int
    pin_radius: float
    thickness: float

    def __post_init__(self) -> None:
        if self.slots < 3:
            raise ValueError(f"slots must be >= 3 for a Geneva drive, got {self.slots}")
        for name in ("crank_radius", "pin_radius", "thickness"):
            if not getattr(self, name) > 0:
                raise ValueError(f"{name} must be positive, got {getattr(self, name)}")
        if self.pin_radius >= self.min_pin_distance:
            raise ValueError(
                f"pin_radius {self.pin_radius} m must be smaller than the closest pin-to-wheel-centre distance "
                f"{self.min_pin_distance} m")
        if self.pin_radius >= self.max_pin_radius:
            raise ValueError(
                f"pin_radius {self.pin_radius:g} m is too large for crank_radius {self.crank_radius:g} m and "
                f"{self.slots} slots: neighbouring slots of width 2R would merge at the wheel rim (R < r cos^2(pi/n) "
                f"= {self.max_pin_radius:.6g} m)")

    @property
    def ratio(self) -> float:
        """lambda = r/c = sin(pi/n)."""
        return float(np.sin(np.pi / self.slots))

    @property
    def centre_distance(self) -> float:
        return self.crank_radius / self.ratio

    @property
    def engagement_half_angle(self) -> float:
        """alpha0 = pi/2 - pi/n: the crank turns 2*alpha0 while the wheel indexes 2*pi/n."""
        return np.pi / 2 - np.pi / self.slots

    @property
    def pitch(self) -> float:
        """Wheel rotation per index, 2*pi/n."""
        return 2 * np.pi / self.slots

    @property
    def max_pin_radius(self) -> float:
        """Largest pin (= slot half-width) that fits: at entry the pin centre is at a = c cos(pi/n) from the wheel
        centre and the next slot's centre line lies a sin(2 pi/n) away, so 2R < a sin(2 pi/n) = 2 r cos^2(pi/n)."""
        return self.crank_radius * float(np.cos(np.pi / self.slots)) ** 2

    @property
    def min_pin_distance(self) -> float:
        """x_min = c - r (pin deepest in the slot)."""
        return self.centre_distance - self.crank_radius

    @property
    def deepest_pin_distance(self) -> float:
        """The pin's distance from the wheel centre at mid-engagement, c - r (pin deepest in the slot)."""
        return self.centre_distance - self.crank_radius

    @property
    def wheel_radius(self) -> float:
        """About the wheel's outer radius: the slot mouths, c cos(pi/n), lie on the rim."""
        return self.entry_pin_distance

    @property
    def entry_pin_distance(self) -> float:
        """x_entry = c cos(pi/n)."""
        return self.centre_distance * np.cos(np.pi / self.slots)

    @property
    def dwell_fraction(self) -> float:
        """(n + 2) / (2 n) of a crank turn (docs/theory.md §G1)."""
        return (self.slots + 2) / (2 * self.slots)

    @staticmethod
    def wheel_motion(lam, alpha, lib=np):
        """(beta, G, G', x/c) while engaged: `wheel_angle`, `speed_ratio`, `speed_ratio_derivative` and the pin
        distance over c, sqrt(D) (docs/theory.md §G1); lib: numpy (vectorised) or sympy."""
        cos_a, sin_a = lib.cos(alpha), lib.sin(alpha)
        d = 1 - 2 * lam * cos_a + lam * lam
        return (lib.atan2(lam * sin_a, 1 - lam * cos_a), lam * (cos_a - lam) / d,
                -lam * (1 - lam * lam) * sin_a / d ** 2, lib.sqrt(d))

    @staticmethod
    def wheel_angle(lam, alpha, lib=np):
        """`wheel_motion`'s beta alone (a transition rule needs no more; docs/theory.md §G1)."""
        return lib.atan2(lam * lib.sin(alpha), 1 - lam * lib.cos(alpha))

    @staticmethod
    def speed_ratio(lam, alpha, lib=np):
        """`wheel_motion`'s G alone (docs/theory.md §G1)."""
        cos_a = lib.cos(alpha)
        return lam * (cos_a - lam) / (1 - 2 * lam * cos_a + lam * lam)

    @staticmethod
    def pin_position(r, c, alpha, lib=np):
        """The pin centre P = (c - r cos alpha, r sin alpha) in the wheel-centre frame (docs/theory.md §G1)."""
        return c - r * lib.cos(alpha), r * lib.sin(alpha)

    @staticmethod
    def pin_in_slot(r, c, alpha, beta, lib=np):
        """The pin centre against the slot at angle beta, (Phi, x, s, a): its lateral offset, its distance along the
        slot, its sliding speed along the slot per unit crank speed (v_s = theta' s) and the arm of the normal
        force about the crank axis (a = x G, by virtual work); docs/theory.md §G1."""
        return (r * lib.sin(alpha) * lib.cos(beta) - (c - r * lib.cos(alpha)) * lib.sin(beta),
                r * lib.sin(alpha) * lib.sin(beta) + (c - r * lib.cos(alpha)) * lib.cos(beta),
                GenevaGeometry.slot_sliding(r, alpha, beta, lib), GenevaGeometry.slot_arm(r, alpha, beta, lib))

    @staticmethod
    def slot_sliding(r, alpha, beta, lib=np):
        """`pin_in_slot`'s s = r sin(alpha + beta) alone (docs/theory.md §G1)."""
        return r * lib.sin(alpha + beta)

    @staticmethod
    def slot_arm(r, alpha, beta, lib=np):
        """`pin_in_slot`'s a = r cos(alpha + beta) alone (docs/theory.md §G1)."""
        return r * lib.cos(alpha + beta)


def _d(lam: float, alpha):
    return 1.0 - 2.0 * lam * np.cos(alpha) + lam * lam


def wheel_angle(lam: float, alpha):
    """beta = atan2(lambda sin(alpha), 1 - lambda cos(alpha)) (docs/theory.md §G1; seed S(3b) with its sign)."""
    return GenevaGeometry.wheel_angle(lam, alpha)


def speed_ratio(lam: float, alpha):
    """G = d(beta)/d(alpha) = lambda (cos(alpha) - lambda) / D (docs/theory.md §G1)."""
    return GenevaGeometry.speed_ratio(lam, alpha)


def speed_ratio_derivative(lam: float, alpha):
    """G' = d2(beta)/d(alpha)2 = -lambda (1 - lambda^2) sin(alpha) / D^2 (docs/theory.md §G1)."""
    return -lam * (1 - lam * lam) * np.sin(alpha) / _d(lam, alpha) ** 2


def speed_ratio_second_derivative(lam: float, alpha):
    """G'' = -lambda (1-lambda^2) [(1+lambda^2) cos(alpha) - 2 lambda (1 + sin^2 alpha)] / D^3 (docs/theory.md §G1, jerk)."""
    return (-lam * (1 - lam * lam) * ((1 + lam * lam) * np.cos(alpha) - 2 * lam * (1 + np.sin(alpha) ** 2))
            / _d(lam, alpha) ** 3)


def pin_distance(geom: GenevaGeometry, alpha):
    """x = c sqrt(D) (docs/theory.md §G1; seed S(3a))."""
    return geom.centre_distance * np.sqrt(_d(geom.ratio, alpha))


def pin_sliding_speed(geom: GenevaGeometry, alpha, crank_speed):
    """v_s = dx/dt = omega1 r sin(alpha) c / x, signed (< 0 inward) (docs/theory.md §G1)."""
    return crank_speed * geom.crank_radius * np.sin(alpha) * geom.centre_distance / pin_distance(geom, alpha)


def slip_speed(geom: GenevaGeometry, alpha, crank_speed, wheel_speed, flank: float = 1.0):
    """Surface slip on the contact flank, u = v_s + flank * R (omega1 + omega2) (docs/theory.md §G1 'Pin spin')."""
    return pin_sliding_speed(geom, alpha, crank_speed) + flank * geom.pin_radius * (crank_speed + wheel_speed)


def engaged_slot(geom: GenevaGeometry, crank_angle):
    """Index k of the slot nearest the pin and the local crank angle alpha = theta - 2 pi k in (-pi, pi]."""
    k = np.floor((np.asarray(crank_angle) + np.pi) / (2 * np.pi))
    return k, np.asarray(crank_angle) - 2 * np.pi * k


def constant_speed_motion(geom: GenevaGeometry, crank_angle, crank_speed: float) -> dict[str, np.ndarray]:
    """Wheel angle (unwrapped), speed and acceleration at constant crank speed (the jerk: speed_ratio_second_derivative),
    and the pin distance x (`pin_distance`).

    crank_angle is the unwrapped crank angle theta (0 at the first mid-engagement). During a dwell the wheel
    rests at the nearest half-pitch: it has indexed once per engagement passed (docs/theory.md §G1-2).
    """
    theta = np.asarray(crank_angle, dtype=float)
    a0 = geom.engagement_half_angle
    k, alpha = engaged_slot(geom, theta)
    engaged = np.abs(alpha) < a0
    beta, G, Gp, xc = geom.wheel_motion(geom.ratio, alpha)
    w = crank_speed
    return {
        "engaged": engaged,
        "alpha": alpha,
        "wheel_angle": k * geom.pitch + np.where(engaged, beta, np.sign(alpha) * np.pi / geom.slots),
        "wheel_speed": np.where(engaged, w * G, 0.0),
        "wheel_accel": np.where(engaged, w * w * Gp, 0.0),
        "pin_distance": geom.centre_distance * xc,
    }


def normal_force_from_wheel(geom: GenevaGeometry, alpha, wheel_accel, wheel_speed, wheel_inertia: float,
                            load_torque: float, friction: float, slide_sign, wheel_damping: float = 0.0):
    """N = (J2 beta'' + T_L + c2 beta') / (x - sigma mu R): the wheel's moment balance (docs/theory.md §G2).

    The normal force acts perpendicular to the slot through the pin centre (arm x about O2); friction mu|N|
    acts along the slot at lateral offset R (arm R); sigma = sign(u_slip) on the driving flank.
    """
    x = pin_distance(geom, alpha)
    return (wheel_inertia * wheel_accel + load_torque + wheel_damping * wheel_speed) / (
        x - slide_sign * friction * geom.pin_radius)
