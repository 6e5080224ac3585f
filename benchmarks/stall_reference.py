"""An independent reference for Geneva stalls: the one-coordinate equation of docs/theory.md §G2 written out
here from scratch (own kinematics, own events) and integrated with scipy's solve_ivp at tight tolerance.

Kinematics (docs/theory.md §G1), crank angle alpha local to the slot, c = r / sin(pi/n):
    beta = atan2(r sin alpha, c - r cos alpha),   x = |pin - wheel centre| = sqrt(c^2 - 2 c r cos alpha + r^2),
    G = dbeta/dalpha = r (c cos alpha - r) / x^2,   G' = dG/dalpha.
Engaged, driving flank (N > 0), slip u = theta' s_u with s_u = r sin(alpha + beta) + R (1 + G), sigma = sign(u):
    wheel:  J2 (G theta'' + G' theta'^2) = -c2 G theta' - T_L + N (x - sigma mu R)
    crank:  J1 theta''                   = T_in - c1 theta' - N (r cos(alpha + beta) + sigma mu (r sin(alpha + beta) + R))
so, with h = (x G + sigma mu (r sin(alpha + beta) + R)) / (x - sigma mu R) (x G = r cos(alpha + beta)):
    (J1 + h J2 G) theta'' = T_in - c1 theta' - h (J2 G' theta'^2 + c2 G theta' + T_L).
On the trailing flank (N < 0: the wheel decelerates faster than the load alone would) the pin touches the
other side of the slot: the contact point's offset from the pin centre is s R with s = sign(N) = -1, so the
slip is u = theta' (r sin(alpha + beta) + s R (1 + G)) and the friction force sigma mu |N| = sigma mu s N acts at
that offset: the wheel's friction moment stays N sigma mu R and the crank's becomes N sigma mu (s r sin(alpha +
beta) + R). The flank switch (N crossing zero) is a located event.
Dwell: J1 theta'' = T_in - c1 theta'. T_in = T0 - slope theta' (constant torque or linear motor curve).
The crank stalls where theta' reaches 0 (a located event); a crank creeping to rest (theta' and theta'' both
vanishing) is reported where theta' + rest_time |theta''| first falls below rest_speed; the static equilibrium
(theta' = theta'' = 0: T0 = h T_L) is solved with brentq.
"""
from __future__ import annotations

from dataclasses import dataclass

import numpy as np
from scipy.integrate import solve_ivp
from scipy.optimize import brentq


@dataclass(frozen=True)
class GenevaCase:
    """A torque- or motor-driven Geneva in SI units (slope = 0 for a constant torque)."""

    slots: int
    r: float
    R: float
    J1: float
    J2: float
    T0: float
    slope: float = 0.0
    T_L: float = 0.0
    mu: float = 0.0
    c1: float = 0.0
    c2: float = 0.0

    @property
    def c(self) -> float:
        return self.r / np.sin(np.pi / self.slots)

    @property
    def alpha0(self) -> float:
        return np.pi / 2 - np.pi / self.slots

    def kinematics(self, alpha: float):
        """(beta, x, G, G') at local crank angle alpha."""
        r, c = self.r, self.c
        x2 = c * c - 2 * c * r * np.cos(alpha) + r * r
        num = r * (c * np.cos(alpha) - r)
        G = num / x2
        Gp = (-r * c * np.sin(alpha) * x2 - num * 2 * c * r * np.sin(alpha)) / x2**2
        return np.arctan2(r * np.sin(alpha), c - r * np.cos(alpha)), np.sqrt(x2), G, Gp

    def slip_factor(self, alpha: float, s: float = 1.0) -> float:
        """u / theta' on flank s (+1 driving, -1 trailing)."""
        beta, _, G, _ = self.kinematics(alpha)
        return self.r * np.sin(alpha + beta) + s * self.R * (1 + G)

    def gain(self, alpha: float, sigma: float, s: float = 1.0) -> tuple[float, float, float]:
        """(h, G, G') of the engaged equation: friction sign sigma = sign(u), flank s."""
        beta, x, G, Gp = self.kinematics(alpha)
        arm = s * self.r * np.sin(alpha + beta) + self.R
        return (x * G + sigma * self.mu * arm) / (x - sigma * self.mu * self.R), G, Gp

    def accel(self, alpha: float, w: float, engaged: bool, sigma: float, s: float = 1.0) -> float:
        T_in = self.T0 - self.slope * w - self.c1 * w
        if not engaged:
            return T_in / self.J1
        h, G, Gp = self.gain(alpha, sigma, s)
        return (T_in - h * (self.J2 * Gp * w * w + self.c2 * G * w + self.T_L)) / (self.J1 + h * self.J2 * G)

    def normal_force(self, alpha: float, w: float, sigma: float, s: float = 1.0) -> float:
        """N from the wheel's equation at the engaged acceleration."""
        _, x, G, Gp = self.kinematics(alpha)
        a = self.accel(alpha, w, True, sigma, s)
        return (self.J2 * (G * a + Gp * w * w) + self.c2 * G * w + self.T_L) / (x - sigma * self.mu * self.R)

    def contact(self, alpha: float, w: float) -> tuple[float, float]:
        """(sigma, s) that hold at (alpha, w): the driving flank unless its normal force would be negative."""
        for s in (1.0, -1.0):
            sigma = 1.0 if self.slip_factor(alpha, s) * w >= 0 else -1.0
            if s < 0 or self.normal_force(alpha, w, sigma, s) >= 0:
                return sigma, s
        raise AssertionError


@dataclass
class StallOutcome:
    kind: str                 # "stall" (theta' = 0), "rest" (crept to rest) or "running"
    time: float
    angle: float              # unwrapped crank angle at that time


def local(theta: float) -> tuple[int, float]:
    k = int(np.floor((theta + np.pi) / (2 * np.pi)))
    return k, theta - 2 * np.pi * k


def first_stop(case: GenevaCase, theta0: float, w0: float, t_end: float, rest_speed: float = 1e-5,
               rest_time: float = 1.0, rtol: float = 1e-12, atol: float = 1e-14) -> StallOutcome:
    """Integrate from (theta0, w0) to the first stall (theta' = 0), creeping rest, or t_end."""
    t, y = 0.0, np.array([theta0, w0], float)
    a0 = case.alpha0
    while t < t_end:
        k, alpha = local(y[0])
        engaged = -a0 <= alpha < a0
        sigma, s = case.contact(alpha, y[1]) if engaged else (1.0, 1.0)
        base = 2 * np.pi * k

        def rhs(_t, z):
            return [z[1], case.accel(z[0] - base, z[1], engaged, sigma, s)]

        # the engagement boundary ahead, fixed for the piece: a boundary function that switched its target
        # with the angle would be discontinuous, and a long step of the smooth dwell motion could jump over the
        # whole engagement zone without a sign change (it did: grid case g029, 3 slots, 47 rad/s)
        ahead = a0 if engaged else (2 * np.pi - a0 if alpha >= a0 else -a0)

        def boundary(_t, z):
            return z[0] - base - ahead
        boundary.terminal, boundary.direction = True, 1

        def stall(_t, z):
            return z[1]
        stall.terminal, stall.direction = True, -1

        def rest(_t, z):
            return z[1] + rest_time * abs(case.accel(z[0] - base, z[1], engaged, sigma, s)) - rest_speed
        rest.terminal, rest.direction = True, -1

        def slip(_t, z):
            return case.slip_factor(z[0] - base, s) if engaged else 1.0
        slip.terminal, slip.direction = True, 0

        def flank(_t, z):
            return case.normal_force(z[0] - base, z[1], sigma, s) * s if engaged else 1.0
        flank.terminal, flank.direction = True, -1

        sol = solve_ivp(rhs, (t, t_end), y, method="DOP853", rtol=rtol, atol=atol,
                        events=[boundary, stall, rest, slip, flank])
        if sol.status != 1:
            return StallOutcome("running", float(sol.t[-1]), float(sol.y[0, -1]))
        which = next(i for i, te in enumerate(sol.t_events) if len(te))
        t, y = float(sol.t_events[which][0]), np.asarray(sol.y_events[which][0], float)
        if which == 1:
            return StallOutcome("stall", t, float(y[0]))
        if which == 2:
            return StallOutcome("rest", t, float(y[0]))
        y[0] += 1e-13 * (1 + abs(y[0]))   # step past the boundary / slip root (own events' root tolerance)
    return StallOutcome("running", t, float(y[0]))


def static_equilibrium(case: GenevaCase, lo: float, hi: float) -> float:
    """Local crank angle in [lo, hi] (engaged) where the drive's torque at zero speed balances the load:
    T0 = h(alpha) T_L, with friction opposing the forward slip of the approach (sigma = sign of s_u)."""
    def f(alpha):
        return case.T0 - case.gain(alpha, 1.0 if case.slip_factor(alpha) >= 0 else -1.0)[0] * case.T_L
    return brentq(f, lo, hi, xtol=1e-15, rtol=4 * np.finfo(float).eps)
