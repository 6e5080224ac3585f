"""Chain loop over n sprockets: pieces (tangent lines, wrapped arcs) and joint B located by chain travel s.

Source: El-Shakery (1991) eqs. (12)-(22) and (31)-(32), restated with a quadrant-safe construction in
`docs/theory.md §K1.1` (the paper's eqs. (14)-(19), (32) are wrong, §1.6 E1-E6).

Conventions (docs/theory.md §K1.1): sprockets (O_i, r_i) are listed counter-clockwise; the chain wraps the
convex hull of their discs from outside and moves counter-clockwise. s = 0 is the tangent point where the
chain leaves sprocket 1 towards sprocket 2; the pieces follow in the order
line 1->2, arc 2, line 2->3, arc 3, ..., line n->1, arc 1. Piece names use the paper's 1-based sprocket
numbers; attributes (`sprocket`, `index`) are 0-based.

Every piece gives B(s) and its s-derivatives in closed form on [s0, s1] (and analytically beyond), plus the
two radial quantities the dyad needs without cancellation near a stretched or folded dyad:
|B - Q|^2 - c^2 and (B - Q).B'.
"""
from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

TWO_PI = 2.0 * math.pi


def cross(a, b):
    """z-component of a x b for arrays of 2-vectors (last axis)."""
    a = np.asarray(a, float)
    b = np.asarray(b, float)
    return a[..., 0] * b[..., 1] - a[..., 1] * b[..., 0]


def unit(angle):
    """(cos, sin) of `angle` along a new last axis."""
    angle = np.asarray(angle, float)
    return np.stack([np.cos(angle), np.sin(angle)], axis=-1)


def rot90(v):
    """v turned counter-clockwise by 90 degrees."""
    v = np.asarray(v, float)
    return np.stack([-v[..., 1], v[..., 0]], axis=-1)


def circle_circle_intersection(c1, r1: float, c2, r2: float):
    """The two intersection points of circle(c1, r1) and circle(c2, r2), as (P_right, P_left).

    P_right lies clockwise of the ray c1 -> c2, P_left counter-clockwise. Raises ValueError when the circles
    do not meet. Plain textbook construction (radical line); used as an independent check of the dyad.
    """
    c1 = np.asarray(c1, float)
    c2 = np.asarray(c2, float)
    d = c2 - c1
    rho = float(np.hypot(*d))
    if rho == 0.0 or rho > r1 + r2 or rho < abs(r1 - r2):
        raise ValueError(f"circles do not intersect (centre distance {rho:g}, radii {r1:g}, {r2:g})")
    a = (r1 * r1 - r2 * r2 + rho * rho) / (2.0 * rho)
    h = math.sqrt(max(r1 * r1 - a * a, 0.0))
    e = d / rho
    m = c1 + a * e
    n = rot90(e)
    return m - h * n, m + h * n


# ----------------------------------------------------------------------------------------------------------
# pieces
# ----------------------------------------------------------------------------------------------------------


@dataclass(frozen=True)
class LinePiece:
    """Straight run from sprocket `sprocket` to `to_sprocket`: B(s) = P0 + (s - s0) t, B' = t, B'' = 0.

    Source: external common tangent, docs/theory.md §K1.1 (the paper's eq. (21) with S = s - s0).
    """

    index: int
    s0: float
    s1: float
    start: tuple[float, float]
    direction: tuple[float, float]
    sprocket: int
    to_sprocket: int

    kind = "line"

    @property
    def name(self) -> str:
        return f"line {self.sprocket + 1}-{self.to_sprocket + 1}"

    @property
    def length(self) -> float:
        return self.s1 - self.s0

    @property
    def end(self) -> np.ndarray:
        return np.asarray(self.start) + self.length * np.asarray(self.direction)

    def derivative(self, s, order: int = 0) -> np.ndarray:
        """d^k B / ds^k at chain travel s (array), shape s.shape + (2,)."""
        s = np.asarray(s, float)
        t = np.asarray(self.direction)
        if order == 0:
            return np.asarray(self.start) + (s - self.s0)[..., None] * t
        if order == 1:
            return np.broadcast_to(t, s.shape + (2,)).copy()
        return np.zeros(s.shape + (2,))

    def _foot(self, Q):
        """(p, s_f): distance from Q to the line and the travel s_f of the foot of the perpendicular."""
        w = np.asarray(self.start) - np.asarray(Q, float)
        t = np.asarray(self.direction)
        return abs(float(cross(t, w))), self.s0 - float(w @ t)

    def sq_dist_minus(self, s, Q, c: float):
        """|B(s) - Q|^2 - c^2 = (p - c)(p + c) + (s - s_f)^2 (no cancellation at |B - Q| = c tangency)."""
        p, sf = self._foot(Q)
        s = np.asarray(s, float)
        return (p - c) * (p + c) + (s - sf) ** 2

    def radial_rate(self, s, Q):
        """(B - Q).B'(s) = s - s_f, i.e. rho * d rho/ds."""
        _, sf = self._foot(Q)
        return np.asarray(s, float) - sf

    def sq_dist_extrema(self, Q):
        """Interior critical points of |B - Q|^2 on the piece: [(s, 'min')] at the foot of the perpendicular."""
        _, sf = self._foot(Q)
        return [(sf, "min")] if self.s0 < sf < self.s1 else []

    def sq_dist_roots(self, Q, c: float):
        """Travel values on [s0, s1] where |B - Q| = c (closed form)."""
        p, sf = self._foot(Q)
        if c < p:
            return []
        w = math.sqrt((c - p) * (c + p))
        return sorted({x for x in (sf - w, sf + w) if self.s0 <= x <= self.s1})

    def sympy_B(self, s):
        """B(s) on this piece as a sympy 2x1 Matrix (numeric constants), for the symbolic dynamics model."""
        import sympy as sp

        P0 = np.asarray(self.start)
        t = np.asarray(self.direction)
        return sp.Matrix([sp.Float(P0[0]) + (s - sp.Float(self.s0)) * sp.Float(t[0]),
                          sp.Float(P0[1]) + (s - sp.Float(self.s0)) * sp.Float(t[1])])


@dataclass(frozen=True)
class ArcPiece:
    """Wrap of sprocket `sprocket`: B(s) = O + r e(psi), psi = psi0 + (s - s0)/r (counter-clockwise).

    B' = e(psi + pi/2), B'' = -e(psi)/r, B''' = -e(psi + pi/2)/r^2.
    Source: the paper's eq. (22) with eps = psi, S = r_1 theta_1 (docs/theory.md §K1.1).
    """

    index: int
    s0: float
    s1: float
    centre: tuple[float, float]
    radius: float
    psi0: float
    sprocket: int

    kind = "arc"

    @property
    def name(self) -> str:
        return f"arc {self.sprocket + 1}"

    @property
    def length(self) -> float:
        return self.s1 - self.s0

    @property
    def wrap(self) -> float:
        """Wrap angle of the chain on the sprocket (rad)."""
        return self.length / self.radius

    def psi(self, s):
        return self.psi0 + (np.asarray(s, float) - self.s0) / self.radius

    def derivative(self, s, order: int = 0) -> np.ndarray:
        """d^k B / ds^k at chain travel s (array), shape s.shape + (2,)."""
        psi = self.psi(s)
        r = self.radius
        if order == 0:
            return np.asarray(self.centre) + r * unit(psi)
        # d^k/ds^k e(psi) = r^-k e(psi + k pi/2)
        return r ** (1 - order) * unit(psi + order * math.pi / 2.0)

    def _polar(self, Q):
        """(D, dpsi0): |O - Q| and the angle of the first point measured from the direction Q -> O, wrapped."""
        w = np.asarray(self.centre) - np.asarray(Q, float)
        D = float(np.hypot(*w))
        alpha = math.atan2(w[1], w[0]) if D > 0 else 0.0
        return D, math.remainder(self.psi0 - alpha, TWO_PI)

    def _dpsi(self, s, Q):
        D, dpsi0 = self._polar(Q)
        return D, dpsi0 + (np.asarray(s, float) - self.s0) / self.radius

    def sq_dist_minus(self, s, Q, c: float):
        """|B - Q|^2 - c^2 = (D + r - c)(D + r + c) - 4 D r sin^2(dpsi/2), dpsi measured from the apex.

        Exact rewrite of |O - Q + r e(psi)|^2 - c^2; it keeps full relative accuracy near the apex
        (dpsi = 0, |B - Q| = D + r), where the dwell design puts the stretched dyad (docs/theory.md §K1.2).
        """
        D, dpsi = self._dpsi(s, Q)
        r = self.radius
        return (D + r - c) * (D + r + c) - 4.0 * D * r * np.sin(0.5 * dpsi) ** 2

    def radial_rate(self, s, Q):
        """(B - Q).B'(s) = -D sin(dpsi), i.e. rho * d rho/ds."""
        D, dpsi = self._dpsi(s, Q)
        return -D * np.sin(dpsi)

    def apex_travel(self, Q, k: int = 0) -> float:
        """Travel s where dpsi = k*pi (k even: farthest from Q, the apex; k odd: nearest), maybe off-piece."""
        _, dpsi0 = self._polar(Q)
        return self.s0 + self.radius * (k * math.pi - dpsi0)

    def sq_dist_extrema(self, Q):
        """Interior critical points of |B - Q|^2: dpsi = 0 mod 2pi ('max') and pi mod 2pi ('min')."""
        D, dpsi0 = self._polar(Q)
        if D == 0.0:
            return []
        out = []
        k0 = math.ceil(dpsi0 / math.pi)
        k1 = math.floor((dpsi0 + self.wrap) / math.pi)
        for k in range(k0, k1 + 1):
            s = self.s0 + self.radius * (k * math.pi - dpsi0)
            if self.s0 < s < self.s1:
                out.append((s, "max" if k % 2 == 0 else "min"))
        return out

    def sq_dist_roots(self, Q, c: float):
        """Travel values on [s0, s1] where |B - Q| = c: sin^2(dpsi/2) = (D+r-c)(D+r+c)/(4Dr) (closed form)."""
        D, dpsi0 = self._polar(Q)
        r = self.radius
        if D == 0.0:
            return []
        x = (D + r - c) * (D + r + c) / (4.0 * D * r)
        if not 0.0 <= x <= 1.0:
            return []
        half = math.asin(math.sqrt(x))
        out = set()
        lo, hi = dpsi0, dpsi0 + self.wrap
        for base in (2.0 * half, -2.0 * half):
            m0 = math.ceil((lo - base) / TWO_PI)
            m1 = math.floor((hi - base) / TWO_PI)
            for m in range(m0, m1 + 1):
                s = self.s0 + r * (base + m * TWO_PI - dpsi0)
                if self.s0 <= s <= self.s1:
                    out.add(s)
        return sorted(out)

    def sympy_B(self, s):
        """B(s) on this piece as a sympy 2x1 Matrix (numeric constants), for the symbolic dynamics model."""
        import sympy as sp

        psi = sp.Float(self.psi0) + (s - sp.Float(self.s0)) / sp.Float(self.radius)
        return sp.Matrix([sp.Float(self.centre[0]) + sp.Float(self.radius) * sp.cos(psi),
                          sp.Float(self.centre[1]) + sp.Float(self.radius) * sp.sin(psi)])


# ----------------------------------------------------------------------------------------------------------
# the loop
# ----------------------------------------------------------------------------------------------------------


def _angle(v) -> float:
    return math.atan2(v[1], v[0])



# ----------------------------------------------------------------------------------------------------------
# the loop's geometry as formulas (numpy scalars for the path, jax arrays for the design sensitivities)
# ----------------------------------------------------------------------------------------------------------


class _ScalarMath:
    """The scalar functions the loop's formulas use, as ChainPath has always evaluated them (bit for bit)."""

    hypot = staticmethod(lambda x, y: np.hypot(x, y))
    asin, cos, sin, sqrt, atan2 = math.asin, math.cos, math.sin, math.sqrt, math.atan2
    where = staticmethod(lambda c, a, b: a if c else b)


def jax_math():
    """The same functions in jax (differentiable): for `loop_geometry(..., xp=jax_math())`."""
    import jax.numpy as jnp

    class _JaxMath:
        hypot, asin, cos, sin, sqrt, atan2, where = (jnp.hypot, jnp.arcsin, jnp.cos, jnp.sin, jnp.sqrt, jnp.arctan2,
                                                     jnp.where)
    return _JaxMath


def loop_geometry(centres, radii, xp=_ScalarMath) -> dict:
    """The closed loop's pieces as formulas of the sprocket centres and radii (docs/theory.md §K1.1).

    For sprocket i and the next j: Z = |O_j - O_i|, u = (O_j - O_i)/Z, g = asin((r_i - r_j)/Z); the external
    common tangent's direction t = u turned by g, its outward normal n = (t_y, -t_x) (right of the travel of the
    counter-clockwise loop), its start O_i + r_i n and length sqrt((Z - (r_i - r_j))(Z + (r_i - r_j))); the wrap of
    sprocket i runs from the normal of the incoming line to that of the outgoing, w_i = (arg n_i - arg n_(i-1))
    mod 2 pi, its arc starts at psi0 = arg n_(i-1) and is r_i w_i long. s0: the pieces' start travel (line 1->2,
    arc 2, ..., line n->1, arc 1) and the loop's length last.

    Array-neutral: `xp` gives the scalar functions (hypot, asin, cos, sin, sqrt, atan2, where); ChainPath passes
    Python's, the design sensitivities jax's (`jax_math`), so that both differentiate the same formulas. No checks
    here: ChainPath validates the layout.
    """
    n = len(radii)
    directions, normals, starts, lengths = [], [], [], []
    for i in range(n):
        j = (i + 1) % n
        dx, dy = centres[j][0] - centres[i][0], centres[j][1] - centres[i][1]
        Z = xp.hypot(dx, dy)
        ux, uy = dx / Z, dy / Z
        g = xp.asin((radii[i] - radii[j]) / Z)
        tx, ty = ux * xp.cos(g) - uy * xp.sin(g), ux * xp.sin(g) + uy * xp.cos(g)
        nx, ny = ty, -tx
        directions.append((tx, ty))
        normals.append((nx, ny))
        starts.append((centres[i][0] + radii[i] * nx, centres[i][1] + radii[i] * ny))
        lengths.append(xp.sqrt((Z - (radii[i] - radii[j])) * (Z + (radii[i] - radii[j]))))
    angles = [xp.atan2(nm[1], nm[0]) for nm in normals]
    wraps, psi0 = [], []
    for i in range(n):
        w = (angles[i] - angles[i - 1]) % TWO_PI
        wraps.append(xp.where(w > TWO_PI - 1e-12, w - TWO_PI, w))
        psi0.append(angles[i - 1])
    s0, s = [], 0.0
    for i in range(n):
        j = (i + 1) % n
        s0.append(s)
        s = s + lengths[i]
        s0.append(s)
        s = s + radii[j] * wraps[j]
    s0.append(s)
    return dict(directions=directions, normals=normals, starts=starts, lengths=lengths, wraps=wraps, psi0=psi0,
                s0=s0)


class ChainPath:
    """The closed chain loop over sprockets listed counter-clockwise (docs/theory.md §K1.1).

    centres: (n, 2) sprocket centres O_i (m); radii: (n,) r_i (m). Raises ValueError naming the problem when
    the layout is not a convex counter-clockwise chain loop.

    Attributes: pieces (line 1->2, arc 2, ..., line n->1, arc 1), boundaries (n_pieces + 1 travel values,
    0 ... length), length (chain length, m), r1 (driving-sprocket radius).
    """

    #: two travel values closer than this (relative to the chain length) are the same point
    SNAP = 1e-12

    def __init__(self, centres, radii):
        centres = np.asarray(centres, float)
        radii = np.asarray(radii, float)
        if centres.ndim != 2 or centres.shape[1] != 2:
            raise ValueError(f"sprocket centres must be an (n, 2) array, got shape {centres.shape}")
        n = len(centres)
        if radii.shape != (n,):
            raise ValueError(f"need one radius per sprocket: {n} centres but radii of shape {radii.shape}")
        if n < 2:
            raise ValueError(f"a chain loop needs at least 2 sprockets, got {n}")
        if not (np.all(np.isfinite(centres)) and np.all(np.isfinite(radii))):
            raise ValueError("sprocket centres and radii must be finite")
        for i in range(n):
            if radii[i] <= 0:
                raise ValueError(f"sprocket {i + 1}: radius must be positive, got {radii[i]:g}")
        for i in range(n):
            for j in range(i + 1, n):
                Z = float(np.hypot(*(centres[j] - centres[i])))
                if Z < (radii[i] + radii[j]) * (1.0 - 1e-12):
                    raise ValueError(
                        f"sprockets {i + 1} and {j + 1} overlap: centre distance {Z:g} m < r{i + 1} + r{j + 1} = "
                        f"{radii[i] + radii[j]:g} m")
        self.centres = centres
        self.radii = radii
        self.n = n

        geo = loop_geometry(centres, radii)
        t_dir = [np.array(t) for t in geo["directions"]]
        normals = [np.array(nm) for nm in geo["normals"]]
        starts = [np.array(st) for st in geo["starts"]]
        lengths, wraps = geo["lengths"], geo["wraps"]
        turns = [math.remainder(_angle(normals[i]) - _angle(normals[i - 1]), TWO_PI) for i in range(n)]
        total = sum(wraps)
        if abs(total - TWO_PI) > 1e-9:
            bad = [i + 1 for i in range(n) if turns[i] < 0]
            area = 0.5 * sum(float(cross(centres[i], centres[(i + 1) % n])) for i in range(n))
            if n >= 3 and area < 0 and len(bad) == n:
                raise ValueError(
                    "not a convex chain loop: the sprockets are listed clockwise; list them counter-clockwise")
            hint = (f"; sprocket(s) {bad} would be wrapped from inside (they lie inside the hull or break the "
                    f"counter-clockwise order)") if bad else ""
            raise ValueError(
                f"not a convex chain loop: the chain direction turns {total / TWO_PI:.3f} times instead of once "
                f"counter-clockwise{hint}")
        for i in range(n):
            if wraps[i] < 1e-9:
                raise ValueError(f"not a convex chain loop: sprocket {i + 1} is not wrapped by the chain "
                                 f"(wrap angle {math.degrees(wraps[i]):.3g} deg); remove it or move it outwards")
        # every disc must lie inside the loop: support function of disc k <= that of the wrapped arc i
        for i in range(n):
            a0 = _angle(normals[i - 1])
            for k in range(n):
                if k == i:
                    continue
                w = centres[i] - centres[k]
                A = float(np.hypot(*w))
                cands = [a0, a0 + wraps[i]]
                if A > 0:
                    crit = _angle(w) + math.pi  # minimum of A cos(nu - angle(w))
                    m = (crit - a0) % TWO_PI
                    if m <= wraps[i]:
                        cands.append(a0 + m)
                gmin = min(A * math.cos(c - _angle(w)) if A > 0 else 0.0 for c in cands) + radii[i] - radii[k]
                if gmin < -1e-12 * (radii[i] + radii[k] + A):
                    raise ValueError(
                        f"not a convex chain loop: sprocket {k + 1} sticks out of the chain loop at the wrap of "
                        f"sprocket {i + 1}; the listed order is not the counter-clockwise order of the hull")

        # pieces from s = 0 where the chain leaves sprocket 1 towards sprocket 2
        pieces = []
        for i in range(n):
            j = (i + 1) % n
            pieces.append(LinePiece(2 * i, geo["s0"][2 * i], geo["s0"][2 * i + 1], tuple(starts[i]),
                                    tuple(t_dir[i]), i, j))
            pieces.append(ArcPiece(2 * i + 1, geo["s0"][2 * i + 1], geo["s0"][2 * i + 2], tuple(centres[j]),
                                   float(radii[j]), geo["psi0"][j], j))
        s = geo["s0"][-1]
        self.pieces: tuple = tuple(pieces)
        self.length = s
        self.boundaries = np.array([p.s0 for p in pieces] + [s])
        self.wraps = np.array(wraps)
        self.tangent_lengths = np.array(lengths)
        self.r1 = float(radii[0])

    # --- lookup ----------------------------------------------------------------------------------------------

    @property
    def piece_names(self) -> list[str]:
        return [p.name for p in self.pieces]

    def arc_of(self, sprocket: int) -> ArcPiece:
        """The arc piece of sprocket `sprocket` (0-based)."""
        return next(p for p in self.pieces if p.kind == "arc" and p.sprocket == sprocket)

    def locate(self, s, side=+1):
        """(piece index, local travel in [s0, s1]) for chain travel s (any real, wrapped by the length).

        At a junction side=+1 picks the piece starting there, side=-1 the piece ending there (side: one for all
        values, or one per value). Values within SNAP*length of a junction are snapped onto it.
        """
        s = np.asarray(s, float)
        sm = self._snapped(s)
        b = self.boundaries
        after = np.searchsorted(b, sm, side="right") - 1
        before = np.searchsorted(b, sm, side="left") - 1
        k = np.where(np.asarray(side) >= 0, np.where(after >= len(self.pieces), 0, after),
                     np.where(before < 0, len(self.pieces) - 1, before))
        sm = np.where(np.asarray(side) >= 0, np.where(sm >= self.length, 0.0, sm),
                      np.where(before < 0, self.length, sm))
        return k.astype(int), sm

    def _snapped(self, s: np.ndarray) -> np.ndarray:
        """The travel s wrapped into [0, length], each value within SNAP*length of a junction put onto it."""
        Lc = self.length
        sm = np.mod(s, Lc)
        b = self.boundaries
        j = np.clip(np.searchsorted(b, sm), 0, len(b) - 1)
        near = np.abs(b[j] - sm) <= self.SNAP * Lc
        jm = np.clip(j - 1, 0, len(b) - 1)
        near_m = np.abs(b[jm] - sm) <= self.SNAP * Lc
        return np.where(near, b[j], np.where(near_m, b[jm], sm))

    def snap_shift(self, s) -> np.ndarray:
        """How far each travel value s is moved by its snap onto a junction (`locate`): positive for a value just
        before one, negative just after, zero on one or near none."""
        s = np.asarray(s, float)
        return self._snapped(s) - np.mod(s, self.length)

    def _by_piece(self, k, sm, fns):
        """Apply each fn(piece, s_local) of `fns` piecewise; each returns arrays shaped like s_local (+ trailing
        dims). One array per fn."""
        outs = [None] * len(fns)
        for idx in np.unique(k):
            m = k == idx
            x = sm[m]
            for j, fn in enumerate(fns):
                val = fn(self.pieces[idx], x)
                if outs[j] is None:
                    outs[j] = np.zeros(sm.shape + np.shape(val)[1:])
                outs[j][m] = val
        return [np.zeros(sm.shape + (2,)) if out is None else out for out in outs]

    def derivatives(self, s, order: int = 2, side=+1):
        """B and its s-derivatives up to `order` at travel s: list [B, B', B'', ...], each shape s.shape+(2,)."""
        s = np.asarray(s, float)
        k, sm = self.locate(s.ravel(), np.broadcast_to(side, s.shape).ravel())
        res = self._by_piece(k, sm, [lambda p, x, o=o: p.derivative(x, o) for o in range(order + 1)])
        return [r.reshape(s.shape + (2,)) for r in res]

    def B(self, s, side: int = +1):
        """Position of joint B (m) at chain travel s."""
        return self.derivatives(s, 0, side)[0]

    def piece_index(self, s, side=+1):
        return self.locate(np.asarray(s, float), side)[0]

    def radial(self, s, Q, c_outer: float, c_inner: float, side=+1):
        """(c_outer^2 - |B-Q|^2, |B-Q|^2 - c_inner^2, (B-Q).B') at travel s, cancellation-free per piece."""
        s = np.asarray(s, float)
        k, sm = self.locate(s.ravel(), np.broadcast_to(side, s.shape).ravel())
        gp, gm, rr = self._by_piece(k, sm, [lambda p, x: p.sq_dist_minus(x, Q, c_outer),
                                            lambda p, x: p.sq_dist_minus(x, Q, c_inner),
                                            lambda p, x: p.radial_rate(x, Q)])
        gp = -gp
        return gp.reshape(s.shape), gm.reshape(s.shape), rr.reshape(s.shape)

    def piece_table(self):
        """One row per piece: name, kind, travel range (m), driving-angle range (rad) and the closed-form data."""
        import pandas as pd

        rows = []
        for p in self.pieces:
            row = dict(segment=p.index, segment_name=p.name, kind=p.kind, s0_m=p.s0, s1_m=p.s1,
                       length_m=p.length, start_drive_angle_rad=p.s0 / self.r1, end_drive_angle_rad=p.s1 / self.r1)
            if p.kind == "line":
                row.update(start_x_m=p.start[0], start_y_m=p.start[1], dir_x=p.direction[0], dir_y=p.direction[1])
            else:
                row.update(centre_x_m=p.centre[0], centre_y_m=p.centre[1], radius_m=p.radius, psi0_rad=p.psi0,
                           wrap_rad=p.wrap)
            rows.append(row)
        return pd.DataFrame(rows)

    def sample(self, n: int = 721) -> np.ndarray:
        """n points along the closed loop (first == last), for drawing."""
        s = np.linspace(0.0, self.length, n)
        s[-1] = self.length
        return self.B(s, side=-1)
