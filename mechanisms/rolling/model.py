"""The rolling-pair 4-bar (Kar & Sen) as a mechsim multibody model: crank, coupler and rolling link as rigid
bodies, gravity, a drive on the crank or on the rolling link, dead points as guards.

Coordinates q = (theta2, theta3, phi): crank angle (A0 -> A), coupler angle (A -> B), and the absolute rotation
phi of the rolling link (docs/theory.md §K2.1). Two loop-closure constraints (metres)

    Phi = A0 + l2 e^{i theta2} + l3 e^{i theta3} - B(phi) = 0,
    B(phi) = B0(u(phi)) + l4 e^{i theta4(phi)},  theta4 = nu0 + psi + phi,

where B0(u) and u(phi) are the corrected no-slip rolling relations of `rolling_pair` (docs/theory.md §K2.1,
gamma = gamma0 + phi r/(R + r); a line: s = -r phi). The rolling constraint is holonomic and explicit in the
rolling parameter, so it is embedded in the coordinates (the rolling link's pose is a function of phi alone)
instead of being carried as two more constraint rows. Why these coordinates and not the 9 Cartesian ones of
docs/theory.md §K3 (8 constraints): nq + m = 5 (6 with a prescribed speed) instead of 17, a residual of 10-13
rows instead of 34-40, and the KKT guard substitution of dynamics/model.py stays within its symbolic limit.
The price is a configuration-dependent mass matrix, whose velocity-product (Christoffel) terms are part of
the applied force here.

The multipliers are the force of the coupler on the rolling link at B (N, x and y): the constraint is the cut
between the coupler's end and link 4's point B, so the generalized force -G^T lam is that of +lam on link 4 and
-lam on the coupler. The rolling contact force then follows from link 4's Newton equation,
F_P = m4 a_G4 - m4 g - lam, split into the normal (along B0 - P) and tangential parts.

Dead points (docs/theory.md §K4, point 4). With the rolling link as input the singular configurations are the
stretched/folded dyad, sin(theta3 - theta2) = 0; with the crank as input the coupler's line passes through the
contact point P (the rolling link's instantaneous centre), w . B'(phi) = 0 (w = B - A; also at every cusp,
where B' = 0). There the driven coordinate's speed must vanish: the configuration curve is smooth and the
torque-driven DAE (G of full rank) passes through, the driven link reversing; a prescribed speed cannot be kept
(the KKT matrix is singular there) and the run stops short of it, at |transmission| = dead_point_margin.
"""
from __future__ import annotations

import itertools
import math
import types
from dataclasses import dataclass
from typing import Mapping

import numpy as np
from scipy.optimize import brentq

from mechsim.mechanisms.base import (DriveCycle, Field, Guard, InitialState, Mechanism, Mode, TransitionRule,
                                     ValidityCondition)
from mechsim.mechanisms.rolling.pair import CircleOnCircle, CircleOnLine, RollingFourBar, closure_intervals, rolling_span

DRIVEN_LINKS = ("rolling", "crank")
#: friction coefficient available at the rolling contact when the scenario gives none: dry steel on steel, static,
#: at the low end of the handbook range (about 0.3-0.8), so that a design relying on more is flagged
DEFAULT_FRICTION = 0.3


@dataclass(frozen=True)
class Bodies:
    """Mass properties (SI). Centres of mass: crank at c2 from A0 along A0A, coupler at c3 from A along AB,
    rolling link at c4 from B0 at angle d4 from the arm B0B. Inertias about the centres of mass."""

    m2: float
    c2: float
    I2: float
    m3: float
    c3: float
    I3: float
    m4: float
    c4: float
    d4: float
    I4: float

    @classmethod
    def uniform(cls, kin: RollingFourBar, crank_mass: float, coupler_mass: float, disc_mass: float,
                arm_mass: float = 0.0) -> "Bodies":
        """Slender rods for crank and coupler (m l^2/12 at mid-length); the rolling link a uniform disc
        (m r^2/2 about B0) welded to a slender arm B0B (m l4^2/3 about B0), moved to the joint centre of mass
        (docs/theory.md §K3: 0.5 kg disc + 0.1 kg arm, l4 = 1.6 -> c4 = 0.13333, I = 0.324667)."""
        r, l4 = kin.pair.r, kin.l4
        m4 = disc_mass + arm_mass
        c4 = arm_mass * l4 / 2 / m4
        I4 = disc_mass * r**2 / 2 + arm_mass * l4**2 / 3 - m4 * c4**2
        return cls(crank_mass, kin.l2 / 2, crank_mass * kin.l2**2 / 12,
                   coupler_mass, kin.l3 / 2, coupler_mass * kin.l3**2 / 12, m4, c4, 0.0, I4)


def _point(x: float, y: float) -> complex:
    return complex(x, y)


def _c_pow(x: float, y):
    """C's pow, as numpy's float64 scalars and Python floats raise to a power (inf or nan where it has no float)."""
    try:
        return math.pow(x, y)
    except (OverflowError, ValueError):
        with np.errstate(all="ignore"):
            return float(np.float64(x) ** y)


class _Rows(np.ndarray):
    """A column of many instants for a model function that was written for one instant's scalars: the same numbers,
    row for row. Its `**` is C's pow element by element, as on scalars; numpy's own array power rounds differently
    in the last bit for some values (x*x for x**2, a vectorised pow otherwise)."""

    _pow = np.frompyfunc(_c_pow, 2, 1)

    def __pow__(self, other):
        x = np.asarray(self)
        if np.ndim(other) == 0:      # the model's powers: a number
            try:
                return np.fromiter(map(math.pow, x.ravel().tolist(), itertools.repeat(float(other))), float,
                                   x.size).reshape(x.shape).view(_Rows)
            except (OverflowError, ValueError):
                pass
        return _Rows._pow(x, other).astype(float).view(_Rows)


def _row_array(entries):
    """`numpy.array` for a lambdified model function evaluated on `_Rows`: its nested entries (columns, or
    numbers that do not depend on the instant) broadcast to the columns' shape, the instants on the last axis."""
    leaves = []

    def walk(e):
        if isinstance(e, (list, tuple)):
            for x in e:
                walk(x)
        else:
            leaves.append(np.shape(e))
    walk(entries)
    shape = np.broadcast_shapes(*leaves)

    def fill(e):
        if isinstance(e, (list, tuple)):
            return [fill(x) for x in e]
        return np.broadcast_to(np.asarray(e, float), shape)
    return np.array(fill(entries), float)


def _over_rows(fn):
    """The lambdified `fn` with `_row_array` for its `numpy.array`: called on `_Rows` it returns its array of one
    instant for all of them at once, instants last (the same code object: the same operations in the same order)."""
    return types.FunctionType(fn.__code__, {**fn.__globals__, "array": _row_array}, fn.__name__)


_MODEL_CACHE: dict = {}


class RollingPairFourBar(Mechanism):
    """Kar & Sen's 4-bar with a rolling pair adjacent to the ground, driven at the crank or the rolling link."""

    name = "rolling_pair"
    coordinates = ("crank", "coupler", "rolling")
    max_constraints = 2
    angle_coordinates = (0, 1, 2)
    parameter_names = (
        "R", "r", "Ox", "Oy", "gamma0", "Px", "Py", "tangent",       # profile (circle | line)
        "l2", "l3", "l4", "psi", "A0x", "A0y", "lc", "alpha",       # linkage and coupler point
        "m2", "c2", "I2", "m3", "c3", "I3", "m4", "c4", "d4", "I4",  # bodies
        "g", "b2", "b4",                                            # gravity, viscous damping
        "dead_sign", "dead_margin",                                 # discrete: side of the dead point
    )
    initial_keys = ("drive_angle", "drive_speed")
    has_sliding_contact = False   # pure rolling: no slip, no friction heat
    peak_columns = ("contact_force_N", "drive_torque_N_m", "crank_speed_rad_s", "crank_accel_rad_s2", "coupler_force_N")
    drawing = "mechsim.mechanisms.rolling.drawing:RollingDrawing"
    sensitivity_map = "mechsim.mechanisms.rolling.sensitivity:MAP"

    schema = {
        "mechanism": {
            "profile": Field("str", default="circle", choices=("circle", "line"),
                             help="fixed profile the disc rolls on: outside a circle, or on a line"),
            "fixed_radius": Field("quantity", "m", default=None, positive=True, only_if=("profile", "circle"),
                                  help="R, radius of the fixed circle"),
            "disc_radius": Field("quantity", "m", required=True, positive=True, help="r, radius of the rolling disc"),
            "profile_centre": Field("list", "m", default=[0.0, 0.0], only_if=("profile", "circle"),
                                    help="O, centre of the fixed circle [x, y]"),
            "contact_angle": Field("quantity", "rad", default=0.0,
                                   only_if=("profile", "circle"),
                                   help="gamma0, polar angle of the initial contact on the circle"),
            "line_point": Field("list", "m", default=[0.0, 0.0], only_if=("profile", "line"),
                                help="P0, initial contact on the line [x, y]"),
            "line_angle": Field("quantity", "rad", default=0.0,
                                only_if=("profile", "line"),
                                help="direction of the line's tangent (the disc lies on its left)"),
            "crank_pivot": Field("list", "m", default=[0.0, 0.0], help="A0, fixed pivot of the crank [x, y]"),
            "crank_length": Field("quantity", "m", required=True, positive=True, help="l2 = A0A"),
            "coupler_length": Field("quantity", "m", required=True, positive=True, help="l3 = AB"),
            "arm_length": Field("quantity", "m", required=True, positive=True, help="l4 = B0B on the rolling link"),
            "arm_angle": Field("quantity", "rad", default=0.0,
                               help="psi, arm B0B from the outward normal at the initial contact"),
            "coupler_point_distance": Field("quantity", "m", default=0.0, nonnegative=True, help="lc = AC"),
            "coupler_point_angle": Field("quantity", "rad", default=0.0, help="alpha, AC from AB"),
            "branch": Field("int", default=1, choices=(1, -1),
                            help="assembly branch sigma of Kar & Sen eq. (18): +1 puts A right of A0->B"),
            "driven_link": Field("str", default="rolling", choices=DRIVEN_LINKS,
                                 help="where the drive acts: the rolling link (phi) or the crank (theta2)"),
            "start_rolling_angle": Field("quantity", "rad", default=0.0,
                                         help="crank drive: start in the assembly whose phi is nearest this"),
            "crank_mass": Field("quantity", "kg", required=True, positive=True),
            "crank_com": Field("quantity", "m", default=None, help="A0 to the crank's centre of mass (l2/2)"),
            "crank_inertia": Field("quantity", "kg*m^2", default=None, nonnegative=True,
                                   help="about the centre of mass (slender rod: m l2^2/12)"),
            "coupler_mass": Field("quantity", "kg", required=True, positive=True),
            "coupler_com": Field("quantity", "m", default=None, help="A to the coupler's centre of mass (l3/2)"),
            "coupler_inertia": Field("quantity", "kg*m^2", default=None, nonnegative=True,
                                     help="about the centre of mass (slender rod: m l3^2/12)"),
            "disc_mass": Field("quantity", "kg", required=True, positive=True, help="uniform disc of the rolling link"),
            "arm_mass": Field("quantity", "kg", default=0.0, nonnegative=True, help="slender arm B0B"),
            "rolling_com": Field("quantity", "m", default=None, nonnegative=True,
                                 help="B0 to the rolling link's centre of mass (disc + arm)"),
            "rolling_com_angle": Field("quantity", "rad", default=0.0, help="its direction from the arm B0B"),
            "rolling_inertia": Field("quantity", "kg*m^2", default=None, positive=True,
                                     help="rolling link about its centre of mass (disc + arm)"),
            "dead_point_margin": Field("float", default=0.01, positive=True, maximum=1.0,
                                       why="a margin on a sine-like transmission ratio; near 1 a run would stop at once",
                                       help="prescribed speed: stop where |transmission| falls to this"),
            "atlas_span": Field("list", "rad", default=None, help="curves: phi range [start, end] to tabulate"),
            "atlas_revolutions": Field("int", default=10, minimum=1, maximum=1000,
                                       why="each revolution is tabulated at hundreds of samples",
                                       help="curves: turns of B0 about O for an irrational R/r"),
        },
        "contact": {
            "friction": Field("float", default=DEFAULT_FRICTION, nonnegative=True, maximum=2.0,
                              help="friction coefficient available at the rolling contact (static): rolling without "
                                   "slip needs friction_demand <= this (validity only; the model does not slip)",
                              why="Coulomb coefficients of engineering material pairs lie below about 1.5"),
        },
        "load": {
            "gravity": Field("quantity", "m/s^2", default=0.0, nonnegative=True, help="acceleration of gravity, -y"),
            "crank_damping": Field("quantity", "N*m*s/rad", default=0.0, nonnegative=True),
            "rolling_damping": Field("quantity", "N*m*s/rad", default=0.0, nonnegative=True,
                                     help="viscous torque on the rolling link's absolute rotation"),
        },
    }

    # -- construction ----------------------------------------------------------------------------------
    def __init__(self, kinematics: RollingFourBar, bodies: Bodies, branch: int = 1, driven_link: str = "rolling",
                 gravity: float = 0.0, crank_damping: float = 0.0, rolling_damping: float = 0.0,
                 prescribed: bool = False, dead_point_margin: float = 0.01, start_rolling_angle: float = 0.0):
        super().__init__()
        if driven_link not in DRIVEN_LINKS:
            raise ValueError(f"driven_link must be one of {DRIVEN_LINKS}, got {driven_link!r}")
        if branch not in (1, -1):
            raise ValueError(f"branch must be +1 or -1, got {branch!r}")
        self.kin = kinematics
        self.bodies = bodies
        self.branch = int(branch)
        self.driven_link = driven_link
        self.drive_coordinate = 2 if driven_link == "rolling" else 0
        self.gravity = gravity
        self.crank_damping = crank_damping
        self.rolling_damping = rolling_damping
        self.prescribed = prescribed
        self.dead_point_margin = dead_point_margin
        self.start_rolling_angle = start_rolling_angle
        self.friction = DEFAULT_FRICTION
        self._dead_sign = 1.0

    @staticmethod
    def kinematics_from_config(m: dict) -> RollingFourBar:
        """The numeric `RollingFourBar` of a [mechanism] table (SI); ValueError names the field."""
        def pair2(key):
            v = m.get(key)
            if v is None or len(v) != 2:
                raise ValueError(f"mechanism.{key}: expected [x, y], got {v!r}")
            return (float(v[0]), float(v[1]))

        if m.get("profile", "circle") == "circle":
            if m.get("fixed_radius") is None:
                raise ValueError("mechanism.fixed_radius: missing (required for profile = 'circle')")
            pair = CircleOnCircle(R=m["fixed_radius"], r=m["disc_radius"], O=pair2("profile_centre"),
                                  gamma0=m.get("contact_angle", 0.0))
        else:
            pair = CircleOnLine(r=m["disc_radius"], P0=pair2("line_point"), tangent=m.get("line_angle", 0.0))
        span = m.get("atlas_span")
        if span is not None:
            if len(span) != 2 or not span[1] > span[0]:
                raise ValueError(f"mechanism.atlas_span: expected [start, end] with end > start, got {span!r}")
            span = (float(span[0]), float(span[1]))
        elif pair.kind == "line":
            span = None
        return RollingFourBar(pair, l2=m["crank_length"], l3=m["coupler_length"], l4=m["arm_length"],
                              psi=m.get("arm_angle", 0.0), lc=m.get("coupler_point_distance", 0.0),
                              alpha=m.get("coupler_point_angle", 0.0), A0=pair2("crank_pivot"), span=span,
                              n_revolutions=m.get("atlas_revolutions", 10) or 10, name=m.get("name", ""))

    @classmethod
    def from_config(cls, config: dict[str, dict]) -> "RollingPairFourBar":
        m, load = config["mechanism"], config.get("load", {})
        kin = cls.kinematics_from_config(m)
        b = Bodies.uniform(kin, m["crank_mass"], m["coupler_mass"], m["disc_mass"], m.get("arm_mass", 0.0) or 0.0)
        over = {k: m.get(key) for k, key in (("c2", "crank_com"), ("I2", "crank_inertia"), ("c3", "coupler_com"),
                                             ("I3", "coupler_inertia"), ("c4", "rolling_com"),
                                             ("I4", "rolling_inertia"))}
        fields = {k: (v if v is not None else getattr(b, k)) for k, v in over.items()}
        bodies = Bodies(b.m2, fields["c2"], fields["I2"], b.m3, fields["c3"], fields["I3"], b.m4, fields["c4"],
                        m.get("rolling_com_angle", 0.0) or 0.0, fields["I4"])
        drive = config.get("drive", {})
        mech = cls(kin, bodies, branch=m.get("branch", 1), driven_link=m.get("driven_link", "rolling"),
                   gravity=load.get("gravity", 0.0), crank_damping=load.get("crank_damping", 0.0),
                   rolling_damping=load.get("rolling_damping", 0.0), prescribed=drive.get("type") == "speed",
                   dead_point_margin=m.get("dead_point_margin", 0.01),
                   start_rolling_angle=m.get("start_rolling_angle", 0.0))
        mech.friction = config.get("contact", {}).get("friction", DEFAULT_FRICTION)
        initial = config.get("initial", {})
        angle0 = initial.get(cls.initial_keys[0], 0.0)
        if mech.prescribed and mech.driven_link == "rolling" and "duration" in config:
            mech.check_prescribed_motion(angle0, drive.get("speed") or 0.0, config["duration"])
        mech.initial_state(angle0, initial.get(cls.initial_keys[1], 0.0))   # assembles? (ValueError if not)
        return mech

    def structure_key(self) -> tuple:
        return (type(self).__name__, self.kin.pair.kind, self.driven_link)

    # -- symbolic model -------------------------------------------------------------------------------
    def _symbolic_linkage(self) -> RollingFourBar:
        """The colleague's `RollingFourBar` with sympy symbols for every number (lib=sympy primitives)."""
        P = self.symbols.p
        if self.kin.pair.kind == "circle":
            pair = CircleOnCircle(R=P("R"), r=P("r"), O=(P("Ox"), P("Oy")), gamma0=P("gamma0"))
        else:
            pair = CircleOnLine(r=P("r"), P0=(P("Px"), P("Py")), tangent=P("tangent"))
        return RollingFourBar(pair, l2=P("l2"), l3=P("l3"), l4=P("l4"), psi=P("psi"), lc=P("lc"),
                              alpha=P("alpha"), A0=(P("A0x"), P("A0y")))

    def _model(self) -> dict:
        """Positions, mass matrix, forces and read-outs as sympy expressions (cached per structure)."""
        import sympy as sp
        from sympy.simplify.fu import TR5, TR10i
        key = self.structure_key()
        if key in _MODEL_CACHE:
            return _MODEL_CACHE[key]
        s, P = self.symbols, self.symbols.p
        q, v, a = list(s.q), list(s.v), list(s.a)
        th2, th3, phi = q
        lam = s.lam[:2]
        lin = self._symbolic_linkage()
        pair = lin.pair

        def e(angle):
            return sp.Matrix([sp.cos(angle), sp.sin(angle)])

        u = pair.u_of_phi(phi)
        A0 = sp.Matrix([P("A0x"), P("A0y")])
        A = A0 + P("l2") * e(th2)
        B_coupler = A + P("l3") * e(th3)
        B = sp.Matrix(lin.point_B(phi, sp))
        B0 = sp.Matrix(pair.centre(u, sp))
        contact = sp.Matrix(pair.contact(u, sp))
        th4 = lin.theta4(phi)
        G2 = A0 + P("c2") * e(th2)
        G3 = A + P("c3") * e(th3)
        G4 = B0 + P("c4") * e(th4 + P("d4"))
        C = A + P("lc") * e(th3 + P("alpha"))

        # kinetic energy 1/2 v^T M v: translation of the centres of mass + rotation (omega4 = phi')
        M = sp.zeros(3, 3)
        for mass, G in ((P("m2"), G2), (P("m3"), G3), (P("m4"), G4)):
            J = G.jacobian(q)
            M += mass * J.T * J
        M += sp.diag(P("I2"), P("I3"), P("I4"))
        # sin^2 -> 1 - cos^2, then products back to cos(a - b): the trigsimp result at 1/100 of its cost
        M = M.applyfunc(lambda x: TR10i(sp.expand(TR5(sp.expand(x)))))
        # velocity-product forces h_i = sum_jk (dM_ij/dq_k - 1/2 dM_jk/dq_i) v_j v_k
        h = [sp.Integer(0)] * 3
        for i in range(3):
            h[i] = sum((sp.diff(M[i, j], q[k]) - sp.diff(M[j, k], q[i]) / 2) * v[j] * v[k]
                       for j in range(3) for k in range(3))
        V = P("g") * (P("m2") * G2[1] + P("m3") * G3[1] + P("m4") * G4[1])
        dV = [sp.diff(V, qi) for qi in q]
        damping = [-P("b2") * v[0], sp.Integer(0), -P("b4") * v[2]]
        force = tuple(-h[i] - dV[i] + damping[i] for i in range(3))

        phi_loop = list(B_coupler - B)
        dB = B.diff(phi)
        w = B - A
        trans_rolling = sp.sin(th3 - th2)                          # u x w / (l2 l3)
        trans_crank = (sp.cos(th3) * dB[0] + sp.sin(th3) * dB[1]) / (P("r") + P("l4"))  # w . B' / (l3 (r + l4))

        # rolling contact force on link 4 from its Newton equation: F_P = m4 a_G4 - m4 g - lam
        dG4 = G4.diff(phi)
        aG4 = dG4 * a[2] + G4.diff(phi, 2) * v[2] ** 2
        F_P = P("m4") * aG4 + sp.Matrix([0, P("m4") * P("g")]) - sp.Matrix(lam)
        n_hat = (B0 - contact) / P("r")
        t_hat = sp.Matrix([-n_hat[1], n_hat[0]])
        normal = (F_P.T * n_hat)[0]
        traction = (F_P.T * t_hat)[0]
        readouts = {
            "coupler_point_x_m": C[0], "coupler_point_y_m": C[1],
            "contact_x_m": contact[0], "contact_y_m": contact[1],
            "contact_force_N": normal,
            "traction_force_N": traction,
            "friction_demand": sp.Abs(traction) / sp.Abs(normal),
            "coupler_force_N": sp.sqrt(lam[0] ** 2 + lam[1] ** 2),
            "potential_energy_J": V,
            "branch": sp.sign(trans_rolling),
            "transmission_rolling": trans_rolling,
            "transmission_crank": trans_crank,
        }
        powers = {"gravity": -sum(dV[i] * v[i] for i in range(3)),
                  "damping": -P("b2") * v[0] ** 2 - P("b4") * v[2] ** 2}
        out = dict(M=M, force=force, constraints=tuple(phi_loop), readouts=readouts, powers=powers,
                   trans_rolling=trans_rolling, trans_crank=trans_crank, V=V, w=w,
                   points=dict(A=A, B=B, B0=B0, P=contact, C=C, G4=G4))
        _MODEL_CACHE[key] = out
        return out

    def mass_matrix(self) -> sp.Matrix:
        return self._model()["M"]

    def modes(self) -> dict[str, Mode]:
        md, P = self._model(), self.symbols.p
        trans = md["trans_rolling"] if self.driven_link == "rolling" else md["trans_crank"]
        mode = Mode(
            name="rolling",
            constraints=md["constraints"],
            force=md["force"],
            # written relative to the side the motion is on (dead_sign), falling only: after the transition flips
            # dead_sign the value starts at ~0 and rises, so the guard cannot fire again from the restart point
            guards=(Guard("dead_point", P("dead_sign") * trans - P("dead_margin"), -1),),
            powers=md["powers"],
            readouts=md["readouts"],
        )
        return {"rolling": mode}

    # -- numbers --------------------------------------------------------------------------------------
    def parameter_values(self) -> dict[str, float]:
        k, b = self.kin, self.bodies
        p = k.pair
        circle = p.kind == "circle"
        return {
            "R": p.R if circle else 0.0, "r": p.r, "Ox": p.O[0] if circle else 0.0, "Oy": p.O[1] if circle else 0.0,
            "gamma0": p.gamma0 if circle else 0.0, "Px": 0.0 if circle else p.P0[0],
            "Py": 0.0 if circle else p.P0[1], "tangent": 0.0 if circle else p.tangent,
            "l2": k.l2, "l3": k.l3, "l4": k.l4, "psi": k.psi, "A0x": k.A0[0], "A0y": k.A0[1],
            "lc": k.lc, "alpha": k.alpha,
            "m2": b.m2, "c2": b.c2, "I2": b.I2, "m3": b.m3, "c3": b.c3, "I3": b.I3,
            "m4": b.m4, "c4": b.c4, "d4": b.d4, "I4": b.I4,
            "g": self.gravity, "b2": self.crank_damping, "b4": self.rolling_damping,
            "dead_sign": self._dead_sign, "dead_margin": self.dead_point_margin if self.prescribed else 0.0,
        }

    def _p_tuple(self, values: Mapping[str, float] | None = None) -> tuple:
        values = values or self.parameter_values()
        return tuple(float(values[n]) for n in self.parameter_names)

    # -- numeric helpers (numpy, from the same symbolic model) -----------------------------------------
    def _numeric(self) -> dict:
        """numpy functions of the symbolic model (M, Q, G, phi, the read-outs, V, the powers, the points), made once
        per model structure and kept between processes (`function_store`): a later process loads them without
        sympy."""
        key = ("numeric",) + self.structure_key()
        if key in _MODEL_CACHE:
            return _MODEL_CACHE[key]
        got = self.stored_functions(("rolling pair closed form",) + key, self._numeric_functions)
        out = dict(got[0], readout_names=list(got[1]["readouts"]), power_names=list(got[1]["powers"]))
        out["rows"] = {name: _over_rows(out[name]) for name in ("M", "Q", "G", "phi")}
        _MODEL_CACHE[key] = out
        return out

    def _numeric_functions(self) -> tuple[dict, dict]:
        """`_numeric`'s lambdified functions, and the names of the read-outs and powers they return:
        ({name: function}, {"readouts": names, "powers": names})."""
        import sympy as sp
        from mechsim.dynamics.codegen import lambdify
        s, md = self.symbols, self._model()
        q, v, a, lam = list(s.q), list(s.v), list(s.a), list(s.lam[:2])
        pars = list(s.params)

        def lamb(args, expr):
            return lambdify(args, expr, "numpy")

        Gm = sp.Matrix(md["constraints"]).jacobian(q)
        return dict(
            M=lamb([q, pars], md["M"]), Q=lamb([q, v, pars], sp.Matrix(md["force"])), G=lamb([q, pars], Gm),
            phi=lamb([q, pars], sp.Matrix(md["constraints"])),
            readouts=lamb([s.t, q, v, a, lam, pars], list(md["readouts"].values())),
            V=lamb([q, pars], md["V"]),
            powers=lamb([q, v, pars], list(md["powers"].values())),
            points=lamb([q, pars], [sp.Matrix(pt) for pt in md["points"].values()]),
        ), {"readouts": list(md["readouts"]), "powers": list(md["powers"])}

    def transmissions(self, q) -> tuple[float, float]:
        """(sin(theta3 - theta2), w . B'/(l3 (r + l4))): zero at the rolling-input / crank-input dead points."""
        th2, th3, phi = (float(x) for x in q)
        dB = complex(self.kin.trochoid(np.array([phi]))["dB"][0])
        return math.sin(th3 - th2), (math.cos(th3) * dB.real + math.sin(th3) * dB.imag) / (self.kin.pair.r + self.kin.l4)

    def _driven_transmission(self, q) -> float:
        tr = self.transmissions(q)
        return tr[0] if self.driven_link == "rolling" else tr[1]

    # -- initial state ----------------------------------------------------------------------------------
    def _assemble_from_crank(self, theta2: float) -> float:
        """phi of the assembly with crank angle theta2 on `branch`, nearest `start_rolling_angle`.

        |B(phi) - A|^2 = l3^2 is solved for phi (a circle meets a trochoid: no closed form) by bracketing on a
        grid over one turn of B0 about O (or +-4 pi on a line) about the start angle, refined by Brent's method.
        """
        k = self.kin
        A = k.a0 + k.l2 * np.exp(1j * theta2)
        reach = k.pair.phi_per_revolution() / 2 if k.pair.kind == "circle" else 4 * math.pi
        c = self.start_rolling_angle
        grid = np.linspace(c - reach, c + reach, 4001)

        def f(x):
            return np.abs(k.trochoid(np.atleast_1d(x))["B"] - A) ** 2 - k.l3 ** 2

        fx = f(grid)
        roots = [brentq(lambda x: float(f(x)[0]), grid[i], grid[i + 1], xtol=1e-15, rtol=8.9e-16)
                 for i in np.flatnonzero(fx[:-1] * fx[1:] < 0)] + list(grid[fx == 0.0])
        cand = []
        for x in roots:
            B = k.trochoid(np.array([x]))["B"][0]
            sigma = 1 if (np.conj(A - k.a0) * (B - A)).imag > 0 else -1   # sign of u x w
            if sigma == self.branch:
                cand.append(x)
        if not cand:
            raise ValueError(f"initial.drive_angle: the mechanism cannot assemble with crank angle "
                             f"{theta2:.6g} rad on branch {self.branch:+d} (within {reach:.4g} rad of "
                             f"mechanism.start_rolling_angle = {c:.6g} rad)")
        return float(min(cand, key=lambda x: abs(x - c)))

    def start(self, angle: float, speed: float) -> tuple[np.ndarray, np.ndarray]:
        """Consistent q0, v0 from the driven link's angle and speed (ValueError if it cannot assemble)."""
        k = self.kin
        if self.driven_link == "rolling":
            st = k.solve(np.array([angle]), self.branch)
            if not st.closes[0]:
                d = float(k.dyad_distance(np.array([angle]))[0][0])
                raise ValueError(
                    f"initial.drive_angle: the dyad cannot close at rolling angle {angle:.6g} rad: |A0B| = {d:.6g} m "
                    f"is outside [{k.d_folded:.6g}, {k.d_stretched:.6g}] m (|l2 - l3|, l2 + l3)")
            q = np.array([st.theta2[0], st.theta3[0], angle])
            v = np.array([st.dtheta2[0], st.dtheta3[0], 1.0]) * speed
            return q, v
        phi = self._assemble_from_crank(angle)
        B = k.trochoid(np.array([phi]))
        A = k.a0 + k.l2 * np.exp(1j * angle)
        q = np.array([angle, float(np.angle(B["B"][0] - A)), phi])
        # velocities: i u w2 + i w w3 - B' wphi = 0 with w2 = speed
        u, w, dB = A - k.a0, B["B"][0] - A, B["dB"][0]
        K = np.array([[-w.imag, -dB.real], [w.real, -dB.imag]])
        rhs = -speed * np.array([-u.imag, u.real])
        if abs(np.linalg.det(K)) < 1e-12 * abs(w) * max(abs(dB), 1e-300):
            raise ValueError(f"initial.drive_angle: crank angle {angle:.6g} rad is a dead point of the crank input")
        w3, wphi = np.linalg.solve(K, rhs)
        return q, np.array([speed, w3, wphi])

    def initial_state(self, angle: float, speed: float) -> InitialState:
        q, v = self.start(angle, speed)
        tr = self._driven_transmission(q)
        if tr == 0.0:
            raise ValueError(f"initial.drive_angle: {angle:.6g} rad is a dead point of the {self.driven_link} input")
        if self.prescribed and abs(tr) <= self.dead_point_margin:
            raise ValueError(f"initial.drive_angle: {angle:.6g} rad is within the dead-point margin "
                             f"(|transmission| = {abs(tr):.3g} <= {self.dead_point_margin:g}) of the {self.driven_link} "
                             "input: a prescribed speed cannot be kept there")
        self._dead_sign = 1.0 if tr > 0 else -1.0
        return InitialState("rolling", {"dead_sign": self._dead_sign}, q, v)

    def check_prescribed_motion(self, phi0: float, speed: float, duration: float) -> None:
        """A prescribed rolling-link speed must keep the dyad closed over the whole run (docs/theory.md §K2.2):
        at a stretched/folded end phi would have to reverse. ValueError naming drive.speed otherwise."""
        phi1 = phi0 + speed * duration
        if phi1 <= phi0:
            return
        ivs = closure_intervals(self.kin, span=(phi0, phi1), periodic=False)
        if len(ivs) == 1 and ivs[0].start_kind == "span" and ivs[0].end_kind == "span":
            return
        ends = [(iv.end, iv.end_kind) for iv in ivs if iv.end_kind != "span"]
        if ivs and ivs[0].start_kind == "span" and ends:
            x, kind = ends[0]
            raise ValueError(
                f"drive.speed: at {speed:.6g} rad/s the rolling link reaches a {kind} dyad at phi = {x:.6g} rad "
                f"(t = {(x - phi0) / speed:.6g} s < duration {duration:.6g} s), where it would have to reverse; "
                "shorten the run or drive it with a torque")
        raise ValueError(f"drive.speed: the dyad does not close over phi in [{phi0:.6g}, {phi1:.6g}] rad")

    # -- transitions --------------------------------------------------------------------------------------
    def transitions(self) -> dict[tuple[str, str], TransitionRule]:
        """The dead point: under a torque it flips `dead_sign` and the motion goes on in the same mode, the driven
        link reversing; under a prescribed speed it is a stop."""
        link = "rolling link" if self.driven_link == "rolling" else "crank"
        k = self.drive_coordinate

        def fields(q, v, p):
            if self.driven_link == "rolling":
                where = ("stretched" if math.cos(q[1] - q[0]) > 0 else "folded") + " dyad (sin(theta3 - theta2) = 0)"
            else:
                where = "coupler line through the contact point, the rolling link's instantaneous centre (w . B' = 0)"
            return dict(link=link, where=where, th2=q[0], phi=q[2], speed=v[k], margin=p["dead_margin"])
        at = "crank angle {th2:.6g} rad, rolling angle {phi:.6g} rad"
        if self.prescribed:
            return {("rolling", "dead_point"): TransitionRule(kind="dead point", fields=fields, stop=(
                "the prescribed {link} speed cannot be kept past the dead point ahead: {where}, |transmission| fell "
                "to {margin:g} at " + at + "; the drive torque grows without bound there (drive it with a torque to "
                "let the {link} reverse)"),
                hint="use drive.type = 'torque' or 'motor' so the {link} can reverse at the dead point, or keep the "
                     "prescribed motion inside the closure interval")}
        return {("rolling", "dead_point"): TransitionRule(
            "rolling", lambda q, v, p, xp: {"dead_sign": -p["dead_sign"]}, kind="dead point", fields=fields,
            message=("dead point of the {link} input ({where}) at " + at + ": the {link} reverses (its speed "
                     "{speed:.3g} rad/s) and the motion goes on"))}

    # -- prescribed rolling-link speed: no DAE ----------------------------------------------------------
    def closed_form(self, t: np.ndarray, angle0: float, speed: float) -> dict[str, np.ndarray] | None:
        """Columns at constant rolling-link speed from `RollingFourBar.solve` (docs/theory.md §K2.2), forces from
        the model's own balance: M a - Q + G^T lam = tau e_phi solved for (lam, tau) row by row.
        None for a crank drive (the crank input has no closed form). Rows where the dyad cannot close are nan."""
        if self.driven_link != "rolling":
            return None
        t = np.asarray(t, float)
        phi = angle0 + speed * (t - t[0])
        st = self.kin.solve(phi, self.branch)
        th2, th3 = st.theta2.copy(), st.theta3.copy()
        ok = st.closes
        th2[ok], th3[ok] = np.unwrap(th2[ok]), np.unwrap(th3[ok])   # continuous angles, as the DAE's
        q = np.stack([th2, th3, phi])
        v = np.stack([st.dtheta2, st.dtheta3, np.ones_like(phi)]) * speed
        a = np.stack([st.ddtheta2, st.ddtheta3, np.zeros_like(phi)]) * speed ** 2
        num, p = self._numeric(), self._p_tuple()
        n = len(t)
        lam = np.full((2, n), np.nan)
        tau = np.full(n, np.nan)
        ke = np.full(n, np.nan)
        resid = np.full(n, np.nan)
        idx = np.flatnonzero(st.closes)
        if idx.size:   # all closing instants at once, each with the numbers of its own M a - Q + G^T lam = tau e_phi
            rows = num["rows"]
            qi, vi = [x.view(_Rows) for x in q[:, idx]], [x.view(_Rows) for x in v[:, idx]]
            vt, at = v[:, idx].T, a[:, idx].T
            M = np.ascontiguousarray(np.moveaxis(rows["M"](qi, p), -1, 0))   # blas's products, as on one M
            Q = np.moveaxis(rows["Q"](qi, vi, p), -1, 0).reshape(idx.size, 3)
            K = np.empty((idx.size, 3, 3))
            K[:, :, :2] = np.moveaxis(rows["G"](qi, p), -1, 0).swapaxes(1, 2)
            K[:, :, 2] = -np.eye(3)[:, 2]
            sol = np.linalg.solve(K, (Q - np.matmul(M, at[:, :, None])[:, :, 0])[:, :, None])[:, :, 0]
            lam[:, idx], tau[idx] = sol[:, :2].T, sol[:, 2]
            ke[idx] = np.matmul(np.matmul((0.5 * vt)[:, None, :], M), vt[:, :, None])[:, 0, 0]
            resid[idx] = np.max(np.abs(rows["phi"](qi, p)), axis=(0, 1))
        ro = num["readouts"](t, q, v, a, lam, p)
        cols = {"mode": np.where(st.closes, "rolling", "open").astype(object)}
        for j, name in enumerate(self.coordinates):
            cols[f"{name}_angle_rad"], cols[f"{name}_speed_rad_s"], cols[f"{name}_accel_rad_s2"] = q[j], v[j], a[j]
        for name, val in zip(num["readout_names"], ro):
            cols[name] = np.broadcast_to(np.asarray(val, float), t.shape).copy()
        cols["drive_torque_N_m"] = tau
        cols["kinetic_energy_J"] = ke
        cols["constraint_residual_m"] = resid
        pw = num["powers"](q, v, p)
        cols["powers"] = {"drive": tau * speed,
                          **{k: np.broadcast_to(np.asarray(x, float), t.shape) for k, x in
                             zip(num["power_names"], pw)}}
        return cols

    def reference_solution(self, drive, t_eval, angle0, speed0, rtol=1e-12):
        """Rolling angle phi from the minimal-coordinate equation (`rolling_reduced`, docs/theory.md §K3) on
        DOP853; torque and motor drives on the rolling link only."""
        if drive.is_prescribed or self.driven_link != "rolling":
            return None
        import mechsim.mechanisms.rolling.reduced as rolling_reduced
        dv = drive.parameter_values(angle0)
        return rolling_reduced.integrate(self, dv["drive_T0"], dv["drive_slope"], angle0, speed0,
                                         np.asarray(t_eval, float), rtol=rtol, atol=rtol)[0]

    def validity_conditions(self) -> tuple[ValidityCondition, ...]:
        """What the idealisation needs on every row (docs/rolling_pair.md, "Validity"): the disc only rests on the
        profile, so the contact must press (the model holds it bilaterally); rolling without slip needs the
        friction demand |F_t|/|N| within the friction available (contact.friction); and the driven link stays
        off its dead points, |transmission| >= dead_point_margin (docs/theory.md §K4 point 4)."""
        trans = "transmission_rolling" if self.driven_link == "rolling" else "transmission_crank"
        where = ("the dyad stretched or folded, sin(theta3 - theta2) = 0" if self.driven_link == "rolling" else
                 "the coupler line through the contact point, w . B'(phi) = 0")
        return (
            ValidityCondition(
                "contact_in_compression", "the rolling contact presses (normal force >= 0): the disc only rests on "
                "the profile, a pull would lift it off (the model holds the contact both ways)",
                lambda c: np.asarray(c["contact_force_N"], dtype=float), 0.0, "min", "N",
                "docs/rolling_pair.md, 'Forces read back' and 'Validity'", ("contact_force_N",)),
            ValidityCondition(
                "rolling_without_slip", f"friction demand |F_t|/|N| within the friction available, contact.friction "
                f"= {self.friction:g}: rolling without slip needs it (the model does not slip)",
                lambda c: np.asarray(c["friction_demand"], dtype=float), float(self.friction), "max", "",
                "Coulomb's law of static friction; docs/rolling_pair.md, 'Validity'",
                ("friction_demand", "traction_force_N"), lambda c: np.asarray(c["traction_force_N"], dtype=float)),
            ValidityCondition(
                "dead_point_distance", f"|{trans}| >= mechanism.dead_point_margin = {self.dead_point_margin:g}: "
                f"away from the dead points ({where}), where the driven link's speed must vanish and the joint "
                "forces grow without bound",
                lambda c: np.abs(np.asarray(c[trans], dtype=float)), float(self.dead_point_margin), "min", "",
                "docs/theory.md §K4 point 4; docs/rolling_pair.md, 'Validity'", (trans,),
                lambda c: np.asarray(c[trans], dtype=float)),
        )

    def drive_cycle(self) -> DriveCycle:
        """A crank turn if the crank is driven; else the trochoid's period (docs/theory.md §K2) when it closes,
        or no period (the rolling link's angle over the run, one line)."""
        if self.driven_link != "rolling":
            return DriveCycle("crank_angle_rad", 2 * math.pi, -math.pi, "crank angle within its turn (deg)")
        try:
            (a, b), periodic = rolling_span(self.kin)
        except ValueError:
            periodic = False
        if periodic:
            return DriveCycle("rolling_angle_rad", b - a, a, "rolling link angle within the trochoid period (deg)")
        return DriveCycle("rolling_angle_rad", None, 0.0, "rolling link angle (deg; the motion has no period)")

    def describe(self) -> dict:
        k = self.kin
        out = {"profile": k.pair.kind, "driven_link": self.driven_link, "branch": self.branch,
               "dyad_range_m": [k.d_folded, k.d_stretched],
               "rolling_link_mass_kg": self.bodies.m4, "rolling_link_com_m": self.bodies.c4,
               "rolling_link_inertia_kg_m2": self.bodies.I4}
        try:
            (a, b), periodic = rolling_span(k)
            out["span_rad"] = [a, b]
            out["periodic"] = periodic
            out["closure_intervals_rad"] = [dict(start=iv.start, end=iv.end, start_kind=iv.start_kind,
                                                 end_kind=iv.end_kind) for iv in closure_intervals(k, (a, b), periodic)]
        except ValueError:
            pass
        return out

    # -- geometry for drawings and checks --------------------------------------------------------------------
    def points(self, q) -> dict[str, np.ndarray]:
        """Named points (x, y in m) at coordinates q = (crank, coupler, rolling): A (crank tip), B (coupler-arm
        joint), B0 (disc centre), P (contact point), C (coupler point), G4 (rolling link's centre of mass)."""
        pts = self._numeric()["points"](np.asarray(q, float), self._p_tuple())
        return {name: np.asarray(pt, float).ravel() for name, pt in zip(self._model()["points"], pts)}
