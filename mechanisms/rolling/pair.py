"""4-bar linkage with one rolling pair adjacent to the ground (Kar & Sen, iNaCoMM 2021):
geometry, corrected no-slip rolling kinematics and closed-form position/velocity/acceleration with the
rolling link as input, both assembly branches, closure intervals.

Model (docs/theory.md §K2.1-2.2). A disc of radius r (link 4, centre B0) rolls without slip outside a fixed
circle (centre O, radius R) or on a fixed line. The input phi is the absolute rotation of link 4 from
its initial configuration. Rolling parameter u: the polar angle gamma of the line of centres (circle) or
the arc position s of the contact along the line (line):

    circle:  gamma(phi) = gamma0 + phi r/(R + r),   B0 = O + (R + r) e^{i gamma},  P = O + R e^{i gamma}
    line:    s(phi) = -r phi,   B0 = P0 + r n + s t,  P = P0 + s t     (disc on the left of t, n = i t)
    B = B0 + l4 e^{i theta4},   theta4 = nu0 + psi + phi

nu0 is the outward normal angle at the initial contact (gamma0, or arg n for the line), so psi is measured
from the outward normal (the paper's eq. (7) convention; its text says from B0->contact, which differs by
pi, docs/theory.md (Part K) K6). Kar & Sen's eqs. (1), (10), (11), (14) move the centre by phi r/R instead: wrong,
the contact slips (docs/theory.md §K2.1, K1; see `rolling_paper`). The dyad A0-A-B closes by Kar & Sen eq. (18)
and the coupler point is C = A + lc e^{i(arg(B - A) + alpha)} (docs/theory.md (Part K) K3 corrects eq. 20).

Points are complex x + iy, lengths in m (the paper's lengths are unitless; we read one unit as 1 m, as the
dynamics reference docs/theory.md §K3 does). The rolling-pair primitives take `lib=numpy` or `lib=sympy`
so the same formulas can be used symbolically; they return (x, y) pairs.
"""
from __future__ import annotations

import math
from dataclasses import dataclass, field
from fractions import Fraction

import numpy as np
from scipy.optimize import brentq

from mechsim.mechanisms.planar_rolling import dyad_derivatives, dyad_tip

# --------------------------------------------------------------------------------------------------
# Rolling pairs (profiles)
# --------------------------------------------------------------------------------------------------


@dataclass(frozen=True)
class CircleOnCircle:
    """Disc radius r rolling outside the fixed circle (O, R); initial contact at polar angle gamma0.

    Rolling parameter u = gamma (polar angle of O->B0). Source: docs/theory.md §K2.1 (corrected Kar & Sen
    eqs. 1, 10, 11, 14).
    """

    R: float
    r: float
    O: tuple[float, float] = (0.0, 0.0)
    gamma0: float = 0.0
    kind: str = field(default="circle", init=False)

    @property
    def du_dphi(self) -> float:
        """d gamma / d phi = r/(R + r): no slip, R dgamma = r (dphi - dgamma)."""
        return self.r / (self.R + self.r)

    @property
    def normal0(self) -> float:
        """Outward normal angle at the initial contact (reference for psi)."""
        return self.gamma0

    def u_of_phi(self, phi):
        """gamma(phi) = gamma0 + phi r/(R + r)."""
        return self.gamma0 + phi * self.du_dphi

    def phi_of_u(self, u):
        """Body rotation for a given gamma: phi = (gamma - gamma0)(R + r)/r."""
        return (u - self.gamma0) / self.du_dphi

    def centre(self, u, lib=np):
        """B0(gamma) = O + (R + r) e^{i gamma}, as (x, y)."""
        k = self.R + self.r
        return self.O[0] + k * lib.cos(u), self.O[1] + k * lib.sin(u)

    def centre_du(self, u, lib=np):
        """dB0/dgamma."""
        k = self.R + self.r
        return -k * lib.sin(u), k * lib.cos(u)

    def centre_du2(self, u, lib=np):
        """d^2 B0/dgamma^2."""
        k = self.R + self.r
        return -k * lib.cos(u), -k * lib.sin(u)

    def contact(self, u, lib=np):
        """Contact point P(gamma) = O + R e^{i gamma}: instantaneous centre of link 4."""
        return self.O[0] + self.R * lib.cos(u), self.O[1] + self.R * lib.sin(u)

    def period(self, max_denominator: int = 100, rtol: float = 1e-12):
        """phi-period of the trochoid, 2 pi (p + q) for R/r = p/q (docs/theory.md §K2.2), or None when R/r
        is not a ratio of small integers (denominator > max_denominator or mismatch > rtol)."""
        ratio = self.R / self.r
        f = Fraction(ratio).limit_denominator(max_denominator)
        if abs(f.numerator / f.denominator - ratio) > rtol * ratio:
            return None
        return 2.0 * math.pi * (f.numerator + f.denominator)

    def phi_per_revolution(self) -> float:
        """Body rotation while B0 goes once round O: 2 pi (R + r)/r."""
        return 2.0 * math.pi / self.du_dphi

    def touch_phi(self, psi: float, kmin: int, kmax: int):
        """phi_k where a point at l4 = r of the arm psi touches the profile: nu0 + psi + phi = gamma + pi,
        phi_k = (pi - psi + 2 pi k)(R + r)/R (docs/theory.md §K2.3)."""
        k = np.arange(kmin, kmax + 1)
        return (math.pi - psi + 2.0 * math.pi * k) * (self.R + self.r) / self.R


@dataclass(frozen=True)
class CircleOnLine:
    """Disc radius r rolling on the line through P0 with direction angle `tangent`; the disc is on the
    left of the tangent t (outward normal n = i t). Rolling parameter u = s, arc position of the contact
    from P0. A counter-clockwise phi moves the centre by -r phi t (docs/theory.md §K2.1; Kar & Sen eq. 12
    gives no direction)."""

    r: float
    P0: tuple[float, float] = (0.0, 0.0)
    tangent: float = 0.0
    kind: str = field(default="line", init=False)

    @property
    def du_dphi(self) -> float:
        """ds/dphi = -r."""
        return -self.r

    @property
    def normal0(self) -> float:
        return self.tangent + 0.5 * math.pi

    def u_of_phi(self, phi):
        return -self.r * phi

    def phi_of_u(self, u):
        return -u / self.r

    def centre(self, u, lib=np):
        """B0(s) = P0 + r n + s t, as (x, y)."""
        c, s_ = lib.cos(self.tangent), lib.sin(self.tangent)
        return self.P0[0] - self.r * s_ + u * c, self.P0[1] + self.r * c + u * s_

    def centre_du(self, u, lib=np):
        c, s_ = lib.cos(self.tangent), lib.sin(self.tangent)
        z = 0 * u
        return c + z, s_ + z

    def centre_du2(self, u, lib=np):
        z = 0 * u
        return z + 0.0, z + 0.0

    def contact(self, u, lib=np):
        c, s_ = lib.cos(self.tangent), lib.sin(self.tangent)
        return self.P0[0] + u * c, self.P0[1] + u * s_

    def period(self, *args, **kwargs):
        """A line is not closed: no period."""
        return None

    def touch_phi(self, psi: float, kmin: int, kmax: int):
        """phi_k = -pi - psi + 2 pi k (docs/theory.md §K2.3)."""
        k = np.arange(kmin, kmax + 1)
        return -math.pi - psi + 2.0 * math.pi * k


# --------------------------------------------------------------------------------------------------
# The mechanism
# --------------------------------------------------------------------------------------------------


@dataclass(frozen=True)
class RollingFourBar:
    """A0 (fixed pivot) - crank l2 - A - coupler l3 - B - arm l4 on the rolling disc - B0 (disc centre).

    psi: angle of the arm B0->B from the outward normal at the initial contact. Coupler point C at
    distance lc from A, at angle alpha from AB. span: the phi range to tabulate; None = one period
    for a rational R/r, else `n_revolutions` turns of B0 round O (see `rolling_span`).
    """

    pair: CircleOnCircle | CircleOnLine
    l2: float
    l3: float
    l4: float
    psi: float
    lc: float = 0.0
    alpha: float = 0.0
    A0: tuple[float, float] = (0.0, 0.0)
    span: tuple[float, float] | None = None
    n_revolutions: int = 10
    name: str = ""

    @property
    def a0(self) -> complex:
        return complex(*self.A0)

    # ---- closed-form rolling-link kinematics (input phi) ----------------------------------------

    def theta4(self, phi, lib=np):
        """Absolute angle of B0->B: nu0 + psi + phi (d/dphi = 1)."""
        return self.pair.normal0 + self.psi + phi

    def theta4_of_param(self, u):
        """Arm angle theta4 as a function of the rolling parameter u (gamma or s):
        nu0 + psi + phi(u); d theta4/du = 1/du_dphi (constant)."""
        return self.theta4(self.pair.phi_of_u(u))

    def param_of_theta4(self, theta4):
        """Rolling parameter u (gamma or s) for an arm angle theta4: the rolling constraint
        B0 = centre(u(theta4)) of a Cartesian (DAE) model, docs/theory.md §K3."""
        return self.pair.u_of_phi(theta4 - self.pair.normal0 - self.psi)

    def point_B(self, phi, lib=np):
        """B(phi) = B0(u(phi)) + l4 e^{i theta4} as (x, y): an epi-/trochoid (docs/theory.md §K2.1)."""
        u = self.pair.u_of_phi(phi)
        x0, y0 = self.pair.centre(u, lib)
        th = self.theta4(phi)
        return x0 + self.l4 * lib.cos(th), y0 + self.l4 * lib.sin(th)

    def trochoid(self, phi):
        """B0, B, P (contact) and dB/dphi, d2B/dphi2 as complex arrays (numpy)."""
        phi = np.asarray(phi, dtype=float)
        p = self.pair
        u = p.u_of_phi(phi)
        k = p.du_dphi
        c = lambda f: (lambda xy_: xy_[0] + 1j * xy_[1])(f(u))  # noqa: E731
        B0, dB0, ddB0, P = c(p.centre), c(p.centre_du) * k, c(p.centre_du2) * k * k, c(p.contact)
        arm = self.l4 * np.exp(1j * self.theta4(phi))
        return dict(B0=B0, dB0=dB0, ddB0=ddB0, P=P, B=B0 + arm, dB=dB0 + 1j * arm, ddB=ddB0 - arm)

    def solve(self, phi, branch: int = 1) -> "RollingState":
        """Closed-form position, velocity and acceleration (per unit phi-rate) on one branch (+1/-1)."""
        phi = np.asarray(phi, dtype=float)
        t = self.trochoid(phi)
        A, closes = dyad_tip(self.a0, t["B"], self.l2, self.l3, branch)
        d = dyad_derivatives(self.a0, A, t["B"], t["dB"], t["ddB"])
        th3 = np.angle(t["B"] - A)
        e = np.exp(1j * (th3 + self.alpha))
        C = A + self.lc * e
        dC = d["dA"] + self.lc * d["dth3"] * 1j * e
        ddC = d["ddA"] + self.lc * (1j * d["ddth3"] - d["dth3"] ** 2) * e
        one = np.ones_like(phi)
        return RollingState(
            phi=phi, branch=branch, closes=closes, P=t["P"],
            B0=t["B0"], dB0=t["dB0"], ddB0=t["ddB0"], B=t["B"], dB=t["dB"], ddB=t["ddB"],
            A=A, dA=d["dA"], ddA=d["ddA"], C=C, dC=dC, ddC=ddC,
            theta2=np.angle(A - self.a0), dtheta2=d["dth2"], ddtheta2=d["ddth2"],
            theta3=th3, dtheta3=d["dth3"], ddtheta3=d["ddth3"],
            theta4=self.theta4(phi), dtheta4=one, ddtheta4=0.0 * one,
        )

    def coupler(self, phi, branch: int = 1):
        """C(phi) (complex) on one branch."""
        return self.solve(phi, branch).C

    def dyad_distance(self, phi):
        """|A0 B|(phi) and its phi-derivative."""
        t = self.trochoid(phi)
        D = t["B"] - self.a0
        d = np.abs(D)
        return d, (D.real * t["dB"].real + D.imag * t["dB"].imag) / d

    @property
    def d_stretched(self) -> float:
        return self.l2 + self.l3

    @property
    def d_folded(self) -> float:
        return abs(self.l2 - self.l3)


@dataclass(frozen=True)
class RollingState:
    """Configuration of the mechanism at input phi on one branch, with phi-derivatives (d = d/dphi).

    Points complex (x + iy): P contact, B0 disc centre, B, A, C; angles theta2 (crank A0A), theta3
    (coupler AB), theta4 (arm B0B, absolute). `closes` is False where the dyad cannot assemble
    (A, C, theta2, theta3 are nan there). Time derivatives: `velocity`/`acceleration`.
    """

    phi: np.ndarray
    branch: int
    closes: np.ndarray
    P: np.ndarray
    B0: np.ndarray
    dB0: np.ndarray
    ddB0: np.ndarray
    B: np.ndarray
    dB: np.ndarray
    ddB: np.ndarray
    A: np.ndarray
    dA: np.ndarray
    ddA: np.ndarray
    C: np.ndarray
    dC: np.ndarray
    ddC: np.ndarray
    theta2: np.ndarray
    dtheta2: np.ndarray
    ddtheta2: np.ndarray
    theta3: np.ndarray
    dtheta3: np.ndarray
    ddtheta3: np.ndarray
    theta4: np.ndarray
    dtheta4: np.ndarray
    ddtheta4: np.ndarray

    def velocity(self, name: str, phidot):
        """d(name)/dt = name' * phidot."""
        return getattr(self, "d" + name) * phidot

    def acceleration(self, name: str, phidot, phiddot):
        """d2(name)/dt2 = name'' phidot^2 + name' phiddot."""
        return getattr(self, "dd" + name) * phidot ** 2 + getattr(self, "d" + name) * phiddot

    def contact_material_velocity(self, phidot=1.0):
        """Velocity of link 4's material point at the contact: dB0/dt + omega4 x (P - B0); zero for
        rolling without slip."""
        return (self.dB0 + 1j * self.dtheta4 * (self.P - self.B0)) * phidot


# --------------------------------------------------------------------------------------------------
# Span and closure intervals
# --------------------------------------------------------------------------------------------------


def rolling_span(mech: RollingFourBar, max_denominator: int = 100) -> tuple[tuple[float, float], bool]:
    """The phi range to tabulate and whether it is one exact period.

    Explicit `mech.span` wins (required for a line). Otherwise one period 2 pi (p + q) for R/r = p/q;
    an irrational (or large-denominator) ratio never closes, so a finite span of `mech.n_revolutions`
    turns of B0 about O is used (docs/rolling_pair.md).
    """
    if mech.span is not None:
        a, b = mech.span
        periodic = mech.pair.kind == "circle" and mech.pair.period(max_denominator) is not None and \
            abs((b - a) - mech.pair.period(max_denominator)) <= 1e-12 * abs(b - a)
        return (float(a), float(b)), periodic
    if mech.pair.kind != "circle":
        raise ValueError("a circle-on-line mechanism needs an explicit span (phi_min, phi_max)")
    T = mech.pair.period(max_denominator)
    if T is not None:
        return (0.0, T), True
    return (0.0, mech.n_revolutions * mech.pair.phi_per_revolution()), False


@dataclass(frozen=True)
class ClosureInterval:
    """A maximal phi interval where the dyad closes. Ends: 'stretched' (|A0B| = l2 + l3), 'folded'
    (|A0B| = |l2 - l3|), 'span' (the tabulated range ends inside closure) or 'period' (the interval
    continues across the period boundary; only for whole-period closure)."""

    start: float
    end: float
    start_kind: str
    end_kind: str


def _monotone_breaks(mech: RollingFourBar, a: float, b: float, n: int):
    """phi where d|A0B|/dphi changes sign in [a, b] (Brent on a grid of n points)."""
    g = lambda x: float(mech.dyad_distance(np.array(x))[1])  # noqa: E731
    x = np.linspace(a, b, n)
    y = mech.dyad_distance(x)[1]
    out = []
    for i in np.nonzero(np.sign(y[:-1]) * np.sign(y[1:]) < 0)[0]:
        out.append(brentq(g, x[i], x[i + 1], xtol=1e-15, rtol=8.9e-16))
    return out


def closure_intervals(mech: RollingFourBar, span: tuple[float, float] | None = None,
                      periodic: bool | None = None, samples_per_turn: int = 720) -> list[ClosureInterval]:
    """Closure intervals of the dyad over the span (docs/theory.md §K2.2; Kar & Sen §3.1 with the
    inequalities of K5 corrected: |l2 - l3| <= |A0B| <= l2 + l3).

    |A0B|(phi) is split into monotone pieces at the roots of its derivative; in each piece each of the
    levels l2 + l3 and |l2 - l3| is crossed at most once, located by Brent's method (xtol 1e-15), so the
    ends are exact to round-off. For a periodic span an interval running through the period boundary is
    reported once, starting before the boundary and ending after it (end > span end).
    """
    if span is None:
        span, per = rolling_span(mech)
        periodic = per if periodic is None else periodic
    periodic = bool(periodic)
    a, b = span
    n = max(64, int(samples_per_turn * (b - a) / (2 * math.pi)) + 1)
    knots = [a] + _monotone_breaks(mech, a, b, n) + [b]
    lo, hi = mech.d_folded, mech.d_stretched
    dist = lambda x: float(mech.dyad_distance(np.array(x))[0])  # noqa: E731
    events = []  # (phi, kind, entering?)
    for x0, x1 in zip(knots[:-1], knots[1:]):
        d0, d1 = dist(x0), dist(x1)
        for level, kind in ((hi, "stretched"), (lo, "folded")):
            if (d0 - level) * (d1 - level) < 0:
                root = brentq(lambda x: dist(x) - level, x0, x1, xtol=1e-15, rtol=8.9e-16)
                # entering closure: moving into [lo, hi]
                entering = (d1 < d0) if kind == "stretched" else (d1 > d0)
                events.append((root, kind, entering))
    events.sort()
    inside0 = lo <= dist(a) <= hi
    intervals = []
    cur = (a, "period" if periodic else "span") if inside0 else None
    for x, kind, entering in events:
        if entering:
            cur = (x, kind)
        elif cur is not None:
            intervals.append(ClosureInterval(cur[0], x, cur[1], kind))
            cur = None
    if cur is not None:
        intervals.append(ClosureInterval(cur[0], b, cur[1], "period" if periodic else "span"))
    if periodic and len(intervals) > 1 and intervals[0].start_kind == "period" \
            and intervals[-1].end_kind == "period":
        first, last = intervals[0], intervals[-1]
        T = b - a
        intervals = intervals[1:-1] + [ClosureInterval(last.start, first.end + T, last.start_kind,
                                                       first.end_kind)]
    return intervals
