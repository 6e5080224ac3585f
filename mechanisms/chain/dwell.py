"""Roller-chain dwell mechanism (El-Shakery 1991, Part II): position, velocity and acceleration kinematics.

Joint B rides on the chain loop (`chain_path.ChainPath`); the crank R turns about Q and the coupler L joins
the crank tip A to B. At prescribed driving speed omega1 the chain travel is s = r1*theta1 and everything is
closed form in s:

* assembly roots, sigma = -1 'leading' (A clockwise of ray QB, paper case I, eq. 24) and sigma = +1
  'lagging' (paper case II, eq. 30): phi = arg(QB) + sigma*beta, theta = arg(QB) - sigma*gamma, with beta and
  gamma the triangle angles at Q and B (docs/theory.md §K1.1);
* rates from the differentiated loop equation R e(phi) + L e(theta) = B - Q (the paper's eqs. 28-29 with
  the sign of D_2 corrected, docs/theory.md §K1.6 E9), written so that they keep full accuracy next to a
  stretched dyad;
* one-sided limits at the singular apex (stretched dyad, docs/theory.md §K1.2), exact, from the second- and
  third-order loop equations;
* the smooth branch: the analytic continuation of a root through every tangential stretched/folded point
  (docs/theory.md §K1.1 "Smooth branch"; here the root sign simply flips there);
* exact dwells (§1.2-1.3), near-dwells and fold points of detuned designs (§1.5).

Everything is SI (m, rad, s). Angles of the driving sprocket are theta1 = s/r1 (rad).
"""
from __future__ import annotations

import math
from dataclasses import dataclass, replace

import numpy as np
import pandas as pd

from mechsim.mechanisms.chain.path import ChainPath, cross, unit

BRANCHES = ("leading", "lagging", "smooth")
_SIGMA = {"leading": -1, "lagging": +1}
_NAME = {-1: "leading", +1: "lagging"}


# ----------------------------------------------------------------------------------------------------------
# parameters
# ----------------------------------------------------------------------------------------------------------


@dataclass(frozen=True)
class ChainDwellParams:
    """Geometry of a roller-chain dwell mechanism, SI units.

    centres/radii: sprockets listed counter-clockwise, sprocket 1 drives (m); pivot: crank pivot Q (m);
    crank: R = |QA| (m); coupler: L = |AB| (m); drive_speed: omega1 of sprocket 1 (rad/s, counter-clockwise).
    """

    name: str
    centres: tuple[tuple[float, float], ...]
    radii: tuple[float, ...]
    crank: float
    coupler: float
    pivot: tuple[float, float] = (0.0, 0.0)
    drive_speed: float = 1.0

    @classmethod
    def from_cm(cls, name, centres_cm, radii_cm, crank_cm, coupler_cm, pivot_cm=(0.0, 0.0), drive_speed=1.0):
        """Build from the paper's centimetres (converted here, at the edge)."""
        c = 0.01
        return cls(name, tuple((float(x) * c, float(y) * c) for x, y in centres_cm),
                   tuple(float(r) * c for r in radii_cm), float(crank_cm) * c, float(coupler_cm) * c,
                   (float(pivot_cm[0]) * c, float(pivot_cm[1]) * c), float(drive_speed))

    def detuned(self, delta: float) -> "ChainDwellParams":
        """The same design with coupler L + delta (m): delta = (R + L) - (L_i + r_i), docs/theory.md §K1.5."""
        return replace(self, name=f"{self.name} (delta = {delta:+.3g} m)", coupler=self.coupler + delta)


#: El-Shakery (1991) Mech 1: 3 sprockets r = 3 cm at (5,0), (0,5), (-5,0) cm; R = 5, L = 3 cm; omega1 = 1 rad/s.
MECH1 = ChainDwellParams.from_cm("El-Shakery Mech 1", [(5, 0), (0, 5), (-5, 0)], [3, 3, 3], 5, 3)
#: El-Shakery (1991) Mech 2: 4 sprockets r = 3 cm at (+-5,0), (0,+-5) cm; R = 5, L = 3 cm; omega1 = 1 rad/s.
MECH2 = ChainDwellParams.from_cm("El-Shakery Mech 2", [(5, 0), (0, 5), (-5, 0), (0, -5)], [3, 3, 3, 3], 5, 3)
PAPER_MECHANISMS = {"mech1": MECH1, "mech2": MECH2}


# ----------------------------------------------------------------------------------------------------------
# the mechanism
# ----------------------------------------------------------------------------------------------------------


@dataclass(frozen=True)
class SingularPoint:
    """A travel s (in [0, length)) where the dyad is stretched (|QB| = R+L) or folded (|QB| = |R-L|).

    kind: 'stretched touch' (|QB| has a maximum R+L: the dwell apex, the roots cross), 'folded touch'
    (minimum |R-L|), 'stretched fold' / 'folded fold' (transversal: a dead centre bounding a stretch of chain
    where the dyad cannot close), 'isolated' (closes at this point only).
    """

    s: float
    kind: str
    piece: int


class ChainDwellMechanism:
    """Kinematics of the roller-chain dwell mechanism at prescribed driving speed (docs/theory.md §K1)."""

    #: relative tolerance on lengths deciding 'exactly tuned' (R = L_i, L = r_i) and 'exactly stretched'
    GEOM_TOL = 1e-12

    def __init__(self, params: ChainDwellParams):
        self.params = params
        self.path = ChainPath(params.centres, params.radii)
        self.Q = np.asarray(params.pivot, float)
        self.R = float(params.crank)
        self.L = float(params.coupler)
        if not (self.R > 0 and self.L > 0):
            raise ValueError(f"crank R and coupler L must be positive, got R = {self.R:g} m, L = {self.L:g} m")
        self.c_out = self.R + self.L
        self.c_in = abs(self.R - self.L)
        self.r1 = self.path.r1
        self.omega1 = float(params.drive_speed)
        self._check_closure()
        self.singular = self._singular_points()
        self.touches = np.array([p.s for p in self.singular if p.kind.endswith("touch")])
        self.touch_kind = np.array([+1 if p.kind == "stretched touch" else -1
                                    for p in self.singular if p.kind.endswith("touch")], int)

    # --- geometry --------------------------------------------------------------------------------------------

    @property
    def chain_length(self) -> float:
        return self.path.length

    @property
    def cycle_angle(self) -> float:
        """Driving-sprocket angle of one chain cycle (rad), eq. (31) with S_t = chain length (E6)."""
        return self.path.length / self.r1

    def _rho_range(self):
        """(min, max) of |QB| over the loop: piece ends and closed-form interior extrema."""
        vals = []
        for p in self.path.pieces:
            pts = [p.s0, p.s1] + [s for s, _ in p.sq_dist_extrema(self.Q)]
            vals += [float(np.sqrt(p.sq_dist_minus(x, self.Q, 0.0))) for x in pts]
        return min(vals), max(vals)

    def _check_closure(self):
        lo, hi = self._rho_range()
        tol = self.GEOM_TOL * self.c_out
        if hi < self.c_in - tol or lo > self.c_out + tol:
            raise ValueError(
                f"dyad can never close: |QB| ranges over [{lo:.6g}, {hi:.6g}] m along the chain, but crank "
                f"R = {self.R:.6g} m and coupler L = {self.L:.6g} m reach only [|R-L|, R+L] = "
                f"[{self.c_in:.6g}, {self.c_out:.6g}] m")

    def _singular_points(self) -> list[SingularPoint]:
        """Stretched/folded points in closed form (piece roots of |QB| = c, and extrema touching c)."""
        Lc = self.path.length
        snap = self.path.SNAP * Lc
        out: list[SingularPoint] = []
        for c, label in ((self.c_out, "stretched"), (self.c_in, "folded")):
            if c == 0.0:
                continue
            tol2 = self.GEOM_TOL * self.c_out * self.c_out
            crit = []
            for p in self.path.pieces:
                for s, kind in p.sq_dist_extrema(self.Q):
                    if abs(float(p.sq_dist_minus(s, self.Q, c))) <= tol2:
                        inner = (kind == "max") == (label == "stretched")
                        crit.append((s, f"{label} touch" if inner else "isolated", p.index))
            roots = []
            for p in self.path.pieces:
                for s in p.sq_dist_roots(self.Q, c):
                    if any(abs(s - x[0]) <= max(snap, 1e-6 * Lc) for x in crit):
                        continue  # the double root of a touch, already listed
                    if any(abs(s - x[0]) <= snap for x in roots):
                        continue  # on a junction: found from both pieces
                    # transversal crossing (rho rho' != 0): a fold, where the position-driven dyad jams
                    if abs(float(p.radial_rate(s, self.Q))) > self.GEOM_TOL * self.c_out:
                        roots.append((s, f"{label} fold", p.index))
            out += [SingularPoint(float(s) % Lc, k, i) for s, k, i in crit + roots]
        return sorted(out, key=lambda p: p.s)

    def singular_points(self) -> pd.DataFrame:
        """Stretched/folded points of one chain cycle, with the driving angle and piece."""
        rows = [dict(drive_angle_rad=p.s / self.r1, chain_position_m=p.s, kind=p.kind, segment=p.piece,
                     segment_name=self.path.pieces[p.piece].name) for p in self.singular]
        return pd.DataFrame(rows, columns=["drive_angle_rad", "chain_position_m", "kind", "segment",
                                           "segment_name"])

    def folds(self) -> pd.DataFrame:
        """Dead-centre points where the position-driven dyad stops closing (detuned delta < 0, §1.5)."""
        df = self.singular_points()
        return df[df["kind"].str.endswith("fold")].reset_index(drop=True)

    # --- branches --------------------------------------------------------------------------------------------

    def sigma(self, s, branch: str = "leading", side=+1, start_branch: str = "leading",
              start: float = 0.0) -> np.ndarray:
        """Root sign (-1 leading, +1 lagging) at chain travel s (cumulative, m).

        'smooth': equals `start_branch` just after travel `start` and flips at every tangential
        stretched/folded point passed since (docs/theory.md §K1.1-1.2: there D continues into D).
        """
        s = np.asarray(s, float)
        if branch in _SIGMA:
            return np.full(s.shape, _SIGMA[branch], int)
        if branch != "smooth":
            raise ValueError(f"branch must be one of {BRANCHES}, got {branch!r}")
        if start_branch not in _SIGMA:
            raise ValueError(f"start_branch must be 'leading' or 'lagging', got {start_branch!r}")
        s0 = _SIGMA[start_branch]
        if len(self.touches) == 0:
            return np.full(s.shape, s0, int)
        Lc = self.path.length
        snap = self.path.SNAP * Lc
        t = self.touches

        def count(x, inclusive):
            x = np.asarray(x, float)
            cyc = np.floor(x / Lc)
            xm = x - cyc * Lc
            # touches at <= xm (inclusive) or < xm, with a snap tolerance
            n_le = np.searchsorted(t, xm + snap, side="right")
            n_lt = np.searchsorted(t, xm - snap, side="left")
            return cyc * len(t) + (n_le if inclusive else n_lt)

        n = np.where(np.asarray(side) >= 0, count(s, True), count(s, False)) - count(start, True)
        return np.where(np.mod(n, 2) == 0, s0, -s0).astype(int)

    # --- kinematics in the chain travel ----------------------------------------------------------------------

    def _snap_touch(self, s):
        """Snap travel values lying within SNAP*length of a touch onto it; return (s, touch kind or 0)."""
        s = np.array(s, float, copy=True)
        kind = np.zeros(s.shape, int)
        if len(self.touches) == 0:
            return s, kind
        Lc = self.path.length
        cyc = np.floor(s / Lc)
        sm = s - cyc * Lc
        for t, k in zip(self.touches, self.touch_kind):
            for shift in (-Lc, 0.0, Lc):
                m = np.abs(sm - (t + shift)) <= self.path.SNAP * Lc
                s[m] = cyc[m] * Lc + t + shift
                kind[m] = k
        return s, kind

    def sides_of(self, s, side: int = +1) -> np.ndarray:
        """Per travel value, the side (`state`'s) whose one-sided limit is its own state: -1 for a value within the
        snap just before a touch or a junction (`_snap_touch`, `ChainPath.locate` put it onto that point, where
        `side` would pick the state after it), +1 just after one, `side` on one or near none. A closed form read
        a hair before a stop then reads the swing there, not the dwell that follows (docs/theory.md §K5)."""
        s = np.atleast_1d(np.asarray(s, float))
        shift = self._snap_touch(s)[0] - s
        shift = np.where(shift != 0.0, shift, self.path.snap_shift(s))
        return np.where(shift > 0.0, -1, np.where(shift < 0.0, +1, side))

    def state(self, s, branch: str = "leading", side=+1, start_branch: str = "leading",
              start: float = 0.0) -> dict:
        """Dyad configuration and its s-derivatives at chain travel s (m, cumulative).

        Returns arrays: s, piece, sigma, closes, B, A (m), phi, theta (rad), dphi, dtheta (rad/m),
        d2phi, d2theta (rad/m^2), stretch (R + L - |QB|, m). At a junction or a stretched/folded touch,
        side = -1 / +1 gives the limit from before / after. Where the dyad does not close: NaN; at a fold the
        rates are infinite. Sources: docs/theory.md §K1.1 (roots), paper eqs. (28)-(29) corrected per §1.6 E9
        (rates), one-sided apex limits derived in docs/chain_dwell.md ("Apex limits", checked against §1.4).
        """
        s_in = np.atleast_1d(np.asarray(s, float))
        s, tk = self._snap_touch(s_in)
        R, L, Q = self.R, self.L, self.Q
        sig = self.sigma(s, branch, side, start_branch, start).astype(float)
        B, B1, B2, B3 = self.path.derivatives(s, 3, side)
        gp, gm, rr = self.path.radial(s, Q, self.c_out, self.c_in, side)
        gp = np.where(tk == +1, 0.0, gp)
        gm = np.where(tk == -1, 0.0, gm)
        rr = np.where(tk != 0, 0.0, rr)
        tol2 = self.GEOM_TOL * self.c_out ** 2
        closes = (gp >= -tol2) & (gm >= -tol2)
        d = B - Q
        rho2 = np.einsum("...i,...i", d, d)
        rho = np.sqrt(rho2)
        with np.errstate(divide="ignore", invalid="ignore"):
            h = np.sqrt(np.maximum(gp, 0.0) * np.maximum(gm, 0.0)) / (2.0 * rho)   # height of A over line QB
            a = (R * R + rho2 - L * L) / (2.0 * rho)     # = R cos(beta), projection of QA on QB
            b = (L * L + rho2 - R * R) / (2.0 * rho)     # = L cos(gamma), projection of AB on QB
            beta = np.arctan2(h, a)
            gamma = np.arctan2(h, b)
            ad = np.arctan2(d[..., 1], d[..., 0])
            phi = ad + sig * beta
            theta = ad - sig * gamma
            argp = cross(d, B1) / rho2                   # d arg(QB)/ds
            q = rr / (rho2 * h)                          # -(d beta/ds)/(L cos gamma), cancellation-free
            # one-sided limit at a tangential touch (h -> 0 with rho rho' -> 0): docs/chain_dwell.md "Apex limits"
            m = np.einsum("...i,...i", B1, B1) + np.einsum("...i,...i", d, B2)   # (rho rho')'
            q_touch = side * np.sign(m) * np.sqrt(np.abs(m) / (R * L)) / rho
            q = np.where(tk != 0, q_touch, q)
            dphi = argp - sig * b * q
            dtheta = argp + sig * a * q
            eph, eth = unit(phi), unit(theta)
            W = B2 + (R * dphi ** 2)[..., None] * eph + (L * dtheta ** 2)[..., None] * eth
            d2phi = -sig * L * np.einsum("...i,...i", W, eth) / (rho * h)
            d2theta = sig * R * np.einsum("...i,...i", W, eph) / (rho * h)
            if np.any(tk != 0):
                # second-order one-sided limits: n-part of the 2nd and e-part of the 3rd loop equation
                kap = np.sign(np.einsum("...i,...i", eph, eth))
                n_ph = np.stack([-eph[..., 1], eph[..., 0]], axis=-1)
                r1_ = np.einsum("...i,...i", B2, n_ph)
                r2_ = -np.einsum("...i,...i", B3, eph) / 3.0
                det = R * kap * L * (dtheta - dphi)
                t_phi = (r1_ * kap * L * dtheta - kap * L * r2_) / det
                t_th = (R * r2_ - R * dphi * r1_) / det
                d2phi = np.where(tk != 0, t_phi, d2phi)
                d2theta = np.where(tk != 0, t_th, d2theta)
        nan = np.where(closes, 1.0, np.nan)
        A = Q + R * unit(phi)
        k = self.path.piece_index(s, side)
        return dict(s=s_in, piece=k, sigma=sig.astype(int), closes=closes, B=B, A=A * nan[..., None],
                    phi=phi * nan, theta=theta * nan, dphi=dphi * nan, dtheta=dtheta * nan,
                    d2phi=d2phi * nan, d2theta=d2theta * nan, stretch=gp / (self.c_out + rho))

    def rates(self, drive_angle, branch: str = "leading", side: int = +1, omega1: float | None = None,
              start_branch: str = "leading") -> dict:
        """Crank/coupler angle, speed and acceleration at driving angles theta1 (rad), constant omega1.

        phi_dot = phi' * r1*omega1, phi_ddot = phi'' * (r1*omega1)^2 (s = r1*theta1, docs/theory.md §K1.1).
        """
        w = self.omega1 if omega1 is None else float(omega1)
        st = self.state(np.asarray(drive_angle, float) * self.r1, branch, side, start_branch)
        v = self.r1 * w
        return dict(st, omega1=w, crank_speed=st["dphi"] * v, crank_accel=st["d2phi"] * v * v,
                    coupler_speed=st["dtheta"] * v, coupler_accel=st["d2theta"] * v * v)

    # --- dwells ----------------------------------------------------------------------------------------------

    def dwell_sprockets(self) -> list[int]:
        """0-based sprockets tuned for an exact dwell: |QO_i| = R and r_i = L (paper eq. 35)."""
        tol = self.GEOM_TOL * self.c_out
        out = []
        for i, (O, r) in enumerate(zip(self.path.centres, self.path.radii)):
            if abs(float(np.hypot(*(O - self.Q))) - self.R) <= tol and abs(r - self.L) <= tol:
                out.append(i)
        return out

    def _dwell_pieces(self, arc):
        """Sub-intervals of an arc split where dpsi = k*pi, each with the root sign that sits on A = O_i."""
        cuts = [arc.s0] + [s for s, _ in arc.sq_dist_extrema(self.Q)] + [arc.s1]
        out = []
        for a, b in zip(cuts[:-1], cuts[1:]):
            mid = 0.5 * (a + b)
            # A = O_i is clockwise of ray QB (leading, sigma = -1) iff (B-Q) x (O_i-Q) < 0 (docs/theory.md §K1.2)
            Bm = arc.derivative(np.array(mid), 0)
            sD = -1 if float(cross(Bm - self.Q, np.asarray(arc.centre) - self.Q)) < 0 else +1
            out.append((a, b, sD))
        return out

    def _event_label(self, arc, s):
        if abs(s - arc.s0) <= self.path.SNAP * self.path.length:
            return "arc entry"
        if abs(s - arc.s1) <= self.path.SNAP * self.path.length:
            return "arc exit"
        p = [x for x in self.singular if abs(x.s - s) <= 1e-9 * self.path.length]
        return "apex" if p and p[0].kind == "stretched touch" else (p[0].kind if p else "cut")

    def dwells(self, branch: str = "leading", cycles: float = 1.0, start_angle: float = 0.0,
               start_branch: str = "leading") -> pd.DataFrame:
        """Exact dwells (crank at rest, A = O_i) on [start_angle, start_angle + cycles*cycle] of theta1.

        For branch='smooth' the branch is `start_branch` just after theta1 = 0 (as in `state`), whatever the window.

        Structural detection (docs/theory.md §K1.2): on the wrap of a tuned sprocket (R = L_i, L = r_i) the
        root that sits on A = O_i is the one with O_i on its side of ray QB; the branch dwells where its
        sign matches. Durations are in driving-sprocket angle, Delta s / r1 (paper eq. 10 corrected, §1.6 E7).
        """
        Lc, r1 = self.path.length, self.r1
        s_lo = start_angle * r1
        s_hi = s_lo + cycles * Lc
        rows = []
        for c in range(int(math.floor(s_lo / Lc)) - 1, int(math.ceil(s_hi / Lc)) + 1):
            for i in self.dwell_sprockets():
                arc = self.path.arc_of(i)
                run = None
                for a, b, sD in self._dwell_pieces(arc):
                    mid = c * Lc + 0.5 * (a + b)
                    sb = int(self.sigma(np.array(mid), branch, +1, start_branch, 0.0))
                    if sb == sD:
                        run = [a if run is None else run[0], b, sD]
                    elif run is not None:
                        rows.append((c, arc, run))
                        run = None
                if run is not None:
                    rows.append((c, arc, run))
        out = []
        for c, arc, (a, b, sD) in rows:
            A, B = c * Lc + a, c * Lc + b
            if B <= s_lo + 1e-12 * Lc or A >= s_hi - 1e-12 * Lc:
                continue
            A0, B0 = max(A, s_lo), min(B, s_hi)
            alpha = math.atan2(arc.centre[1] - self.Q[1], arc.centre[0] - self.Q[0]) % (2 * math.pi)
            out.append(dict(
                sprocket=arc.sprocket + 1, branch=branch, root=_NAME[sD], kind="exact",
                start_drive_angle_rad=A0 / r1, end_drive_angle_rad=B0 / r1, duration_drive_angle_rad=(B0 - A0) / r1,
                crank_angle_rad=alpha,
                start_event=self._event_label(arc, a) if A0 == A else "window start",
                end_event=self._event_label(arc, b) if B0 == B else "window end",
                start_t_s=A0 / r1 / self.omega1, end_t_s=B0 / r1 / self.omega1,
                start_chain_travel_m=A0, end_chain_travel_m=B0))
        cols = ["sprocket", "branch", "root", "kind", "start_drive_angle_rad", "end_drive_angle_rad",
                "duration_drive_angle_rad", "crank_angle_rad", "start_event", "end_event", "start_t_s",
                "end_t_s", "start_chain_travel_m", "end_chain_travel_m"]
        df = pd.DataFrame(out, columns=cols)
        return df.sort_values("start_drive_angle_rad").reset_index(drop=True)

    def dwell_end_rates(self, branch: str = "leading", cycles: float = 1.0, omega1: float | None = None,
                        start_branch: str = "leading") -> pd.DataFrame:
        """One-sided crank speed/acceleration at every dwell start and end (docs/theory.md §K1.4)."""
        rows = []
        for _, d in self.dwells(branch, cycles, start_branch=start_branch).iterrows():
            for ev, ang, lab in (("start", d.start_drive_angle_rad, d.start_event),
                                 ("end", d.end_drive_angle_rad, d.end_event)):
                s = np.array([d.start_chain_travel_m if ev == "start" else d.end_chain_travel_m]) / self.r1
                bef = self.rates(s, branch, -1, omega1, start_branch)
                aft = self.rates(s, branch, +1, omega1, start_branch)
                rows.append(dict(sprocket=d.sprocket, branch=branch, event=ev, event_kind=lab,
                                 drive_angle_rad=ang,
                                 crank_speed_before_rad_s=bef["crank_speed"][0],
                                 crank_speed_after_rad_s=aft["crank_speed"][0],
                                 crank_accel_before_rad_s2=bef["crank_accel"][0],
                                 crank_accel_after_rad_s2=aft["crank_accel"][0]))
        return pd.DataFrame(rows)

    def near_dwells(self, branch: str = "leading", speed_ratio_tol: float = 0.01, cycles: float = 1.0,
                    n: int = 40001, start_branch: str = "leading") -> pd.DataFrame:
        """Intervals where |crank speed| <= speed_ratio_tol * omega1 (any geometry, e.g. detuned §1.5).

        Scans the closed-form speed on n points per cycle and refines every edge with Brent's method.
        Reports the crank excursion (max - min phi) and the peak |acceleration| (rad/s^2 at omega1) inside.
        """
        from scipy.optimize import brentq
        Lc, r1, w = self.path.length, self.r1, self.omega1
        s = np.linspace(0.0, cycles * Lc, int(n * cycles) + 1)

        def g(x):
            st = self.state(np.atleast_1d(x), branch, +1, start_branch)
            return np.abs(st["dphi"]) * r1 - speed_ratio_tol

        gv = g(s)
        inside = np.nan_to_num(gv, nan=1.0) <= 0
        rows = []
        edges = np.flatnonzero(np.diff(inside.astype(int)))
        starts = [0] if inside[0] else []
        starts += [e + 1 for e in edges if not inside[e]]
        spans = []
        for i0 in starts:
            j = i0
            while j + 1 < len(s) and inside[j + 1]:
                j += 1
            a = s[0] if i0 == 0 else brentq(lambda x: g(x)[0], s[i0 - 1], s[i0], xtol=1e-15)
            b = s[-1] if j == len(s) - 1 else brentq(lambda x: g(x)[0], s[j], s[j + 1], xtol=1e-15)
            spans.append([a, b])
        periodic = branch != "smooth" and float(cycles).is_integer()
        if periodic and len(spans) > 1 and spans[0][0] == s[0] and spans[-1][1] == s[-1]:
            # one near-dwell across the cycle boundary: report it once, ending past the window
            spans[-1][1] = spans.pop(0)[1] + cycles * Lc
        for a, b in spans:
            xs = np.linspace(a, b, 401)
            st = self.state(xs, branch, +1, start_branch)
            ph = np.unwrap(st["phi"])
            piece = self.path.pieces[int(self.path.piece_index(np.array(0.5 * (a + b))))]
            rows.append(dict(branch=branch, kind="near", segment_name=piece.name,
                             start_drive_angle_rad=a / r1, end_drive_angle_rad=b / r1,
                             duration_drive_angle_rad=(b - a) / r1, crank_angle_rad=float(np.mean(ph)) % (2 * math.pi),
                             crank_excursion_rad=float(ph.max() - ph.min()),
                             max_abs_crank_accel_rad_s2=float(np.nanmax(np.abs(st["d2phi"]))) * (r1 * w) ** 2))
        return pd.DataFrame(rows, columns=["branch", "kind", "segment_name", "start_drive_angle_rad",
                                           "end_drive_angle_rad", "duration_drive_angle_rad", "crank_angle_rad",
                                           "crank_excursion_rad", "max_abs_crank_accel_rad_s2"])

    def event_angles(self, cycles: float = 1.0, start_angle: float = 0.0) -> np.ndarray:
        """Driving angles (rad) of piece junctions and singular points in the window, sorted."""
        Lc, r1 = self.path.length, self.r1
        base = np.concatenate([self.path.boundaries[:-1], [p.s for p in self.singular]])
        s_lo, s_hi = start_angle * r1, (start_angle + cycles * self.cycle_angle) * r1
        out = [b + c * Lc for c in range(int(math.floor(s_lo / Lc)), int(math.ceil(s_hi / Lc)) + 1) for b in base]
        out = np.array(sorted(x for x in out if s_lo <= x <= s_hi))
        return out / r1


# ----------------------------------------------------------------------------------------------------------
# tables
# ----------------------------------------------------------------------------------------------------------


def _as_mechanism(m) -> ChainDwellMechanism:
    return m if isinstance(m, ChainDwellMechanism) else ChainDwellMechanism(m)


def kinematics_table(mechanism, branch: str = "leading", drive_angle=None, cycles: float = 1.0,
                     n: int = 3601, omega1: float | None = None, start_branch: str = "leading",
                     events: bool = True) -> pd.DataFrame:
    """Kinematic history at constant driving speed as a DataFrame with `<quantity>_<unit>` columns (SI).

    drive_angle: theta1 samples (rad); default n points over `cycles` chain cycles from 0. With events=True
    every piece junction and singular point in the range is added twice (limit before, then after), so
    jumps in speed/acceleration show as vertical steps. Columns: t_s, drive_angle_rad, drive_speed_rad_s,
    chain_travel_m, chain_position_m, chain_speed_m_s, joint_B_x_m, joint_B_y_m, crank_tip_x_m,
    crank_tip_y_m, crank_angle_rad (continuous), crank_speed_rad_s, crank_accel_rad_s2, coupler_angle_rad,
    coupler_speed_rad_s, coupler_accel_rad_s2, stretch_margin_m (R+L-|QB|), segment, segment_name, branch
    (root actually followed), closes, dwell.
    """
    mech = _as_mechanism(mechanism)
    w = mech.omega1 if omega1 is None else float(omega1)
    if drive_angle is None:
        drive_angle = np.linspace(0.0, cycles * mech.cycle_angle, n)
    th = np.asarray(drive_angle, float)
    parts = [(th, np.zeros(th.shape, int), +1)]
    if events and th.size:
        ev = mech.event_angles((th.max() - th.min()) / mech.cycle_angle, th.min())
        before, after = ev[ev > th.min()], ev[ev < th.max()]
        if after.size:   # grid points on an event are replaced by its before/after pair
            snap = mech.path.SNAP * mech.cycle_angle
            th = th[np.min(np.abs(th[:, None] - after[None, :]), axis=1) > snap]
        parts = [(before, np.zeros(before.shape, int), -1), (th, np.ones(th.shape, int), +1),
                 (after, np.full(after.shape, 2), +1)]
    frames = []
    for ang, order, side in parts:
        if ang.size == 0:
            continue
        r = mech.rates(ang, branch, side, w, start_branch)
        frames.append(pd.DataFrame(dict(
            _order=order, drive_angle_rad=ang, chain_travel_m=ang * mech.r1,
            chain_position_m=np.mod(ang * mech.r1, mech.path.length),
            joint_B_x_m=r["B"][..., 0], joint_B_y_m=r["B"][..., 1],
            crank_tip_x_m=r["A"][..., 0], crank_tip_y_m=r["A"][..., 1],
            crank_angle_rad=r["phi"], crank_speed_rad_s=r["crank_speed"], crank_accel_rad_s2=r["crank_accel"],
            coupler_angle_rad=r["theta"], coupler_speed_rad_s=r["coupler_speed"],
            coupler_accel_rad_s2=r["coupler_accel"], stretch_margin_m=r["stretch"],
            segment=r["piece"], segment_name=[mech.path.pieces[k].name for k in r["piece"]],
            branch=[_NAME[int(x)] for x in r["sigma"]], closes=r["closes"])))
    df = pd.concat(frames, ignore_index=True)
    df = df.sort_values(["drive_angle_rad", "_order"], kind="stable").drop(columns="_order")
    df = df.reset_index(drop=True)
    df.insert(0, "t_s", df["drive_angle_rad"] / w)
    df.insert(2, "drive_speed_rad_s", w)
    df.insert(5, "chain_speed_m_s", mech.r1 * w)
    for col in ("crank_angle_rad", "coupler_angle_rad"):
        df[col] = _unwrap_runs(df[col].to_numpy(), df["closes"].to_numpy())
    dw = mech.dwells(branch, (th.max() - th.min()) / mech.cycle_angle if th.size else 0.0,
                     th.min() if th.size else 0.0, start_branch)
    inside = np.zeros(len(df), bool)
    ang = df["drive_angle_rad"].to_numpy()
    for _, d in dw.iterrows():
        inside |= (ang >= d.start_drive_angle_rad) & (ang <= d.end_drive_angle_rad)
    df["dwell"] = inside
    return df


def _unwrap_runs(x, ok):
    """Continuous angle column: unwrapped run by run across NaN gaps (where the dyad does not close), each
    run shifted by whole turns to start nearest to where the previous one ended."""
    x = x.copy()
    idx = np.flatnonzero(ok & np.isfinite(x))
    if idx.size == 0:
        return x
    runs = np.split(idx, np.flatnonzero(np.diff(idx) > 1) + 1)
    last = None
    for r in runs:
        u = np.unwrap(x[r])
        ref = 0.0 if last is None else last
        u += 2 * math.pi * round((ref - u[0]) / (2 * math.pi))
        x[r] = u
        last = u[-1]
    return x


def dwell_table(mechanism, branch: str = "leading", cycles: float = 1.0, start_angle: float = 0.0,
                start_branch: str = "leading") -> pd.DataFrame:
    """The `dwells` DataFrame (start/end/duration in driving angle, crank angle; SI)."""
    return _as_mechanism(mechanism).dwells(branch, cycles, start_angle, start_branch)


def kinematic_history(mechanism, branch: str = "leading", cycles: float = 1.0, n: int = 3601,
                      omega1: float | None = None, start_branch: str = "leading"):
    """(timeseries, dwells) DataFrames for one branch over `cycles` chain cycles from theta1 = 0."""
    mech = _as_mechanism(mechanism)
    return (kinematics_table(mech, branch, None, cycles, n, omega1, start_branch),
            dwell_table(mech, branch, cycles, 0.0, start_branch))
