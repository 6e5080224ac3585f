"""Roller-chain dwell mechanism (El-Shakery 1991, Part II) as a mechsim multibody model.

Coordinates q = (drive, crank, coupler): the driving-sprocket angle theta1 (rad; chain travel s = r1 theta1,
so the drive torque is in N*m and the initial angle/speed in rad, rad/s), the crank angle phi about the pivot Q
and the coupler angle theta (docs/theory.md §K1.1). Joint B rides on the chain path B(s), which is C1 but not C2,
so every line/arc junction ends a mode (docs/theory.md §K1.5 point 5); each piece's geometry is a mode parameter.

Constraints. On lines and on arcs without an exact dwell the loop closure (docs/theory.md §K1.5)

    g = Q + R e(phi) + L e(theta) - B(s) = 0                    (2 rows, m; multipliers = force on the chain at B)

is regular except where the dyad is stretched or folded. On the wrap of a tuned sprocket (|QO_i| = R, r_i = L,
paper eq. 35) the solution set of g is two curves crossing at the apex, where rank G = 1 (docs/theory.md §K1.5
point 1): the dwell curve D (A = O_i) and the reflected curve F (A = O_i mirrored in QB). There each curve gets
its own regular pair of rows, both equivalent to g on that curve (docs/chain_dwell.md §7):

    dwell (D):  n(theta).g = 0,  R sin(phi - alpha_i) = 0          (the crank held at alpha_i = arg(O_i - Q))
    swing (F):  n(theta).g = 0,  (e(phi) + e(alpha_i)) x (B - Q) = 0

so no mode ever integrates through a rank-deficient Jacobian. The branch choice at the apex is explicit
(`apex`): "stop" (a crank stop at alpha_i: Newton impact with restitution e, then the crank dwells against it),
"smooth" (F continues through the apex: the exact inertial motion, docs/theory.md §K1.5 point 2) or "detuned"
(coupler L + delta, delta != 0: no exact apex; delta < 0 gives folds where the chain stalls or reverses,
detected by the `reversal`/`dead_centre` guards and reported, never integrated through).

Bodies: chain + sprockets as one inertia reflected to sprocket 1 (J1 = m_chain r1^2 + sum J_i (r1/r_i)^2);
crank about Q (J_Q); coupler of mass m3, centre c3 from A, inertia J3 about its centre. The mass matrix depends
on phi - theta, so its velocity-product (Christoffel) terms are part of the applied force (as in rolling_model).
Loads: a constant torque T_L resisting the crank's counter-clockwise rotation, viscous damping on sprocket 1
and on the crank.
"""
from __future__ import annotations

import math
from pathlib import Path
from typing import Callable, Mapping

import numpy as np
import pandas as pd

from mechsim.mechanisms.base import (DriveCycle, Field, Guard, InitialState, Mechanism, Mode, Transition,
                                     ValidityCondition)
from mechsim.mechanisms.chain.dwell import ChainDwellMechanism, ChainDwellParams

APEX_LAWS = ("stop", "smooth", "detuned")
_ROOT = {"leading": -1, "lagging": +1}
#: the modes of the chain model, in the order of `ChainDwell._modes_along`'s indices
MODE_NAMES = np.array(["line", "arc", "dwell", "swing"], dtype=object)
_SYM_CACHE: dict = {}
#: |sin(theta - phi)| below which the two-row loop closure of a line or arc mode counts as at a dead centre (the
#: dyad stretched or folded): the same sine-like margin as the rolling pair's dead_point_margin default
DEAD_CENTRE_MARGIN = 0.01


def _entries(fns: list, shape: tuple) -> Callable:
    """One function of the entries' functions `fns` (each of the same arguments, arrays over the samples), returning
    their values as an array of `shape` per sample (samples first)."""
    def f(*a):
        n = np.shape(a[0])[1:]
        out = np.empty(n + (len(fns),))
        for j, fn in enumerate(fns):
            out[..., j] = fn(*a)
        return out.reshape(n + shape)
    return f


def _e(angle):
    import sympy as sp
    return sp.Matrix([sp.cos(angle), sp.sin(angle)])


class ChainDwell(Mechanism):
    """Roller-chain dwell mechanism driven at sprocket 1, loaded at the crank (docs/theory.md §K1)."""

    name = "chain_dwell"
    coordinates = ("drive", "crank", "coupler")
    max_constraints = 2
    drive_coordinate = 0
    angle_coordinates = (0, 1, 2)
    initial_keys = ("drive_angle", "drive_speed")
    has_sliding_contact = False
    peak_columns = ("drive_torque_N_m", "crank_speed_rad_s", "crank_accel_rad_s2", "coupler_force_N")
    drawing = "mechsim.mechanisms.chain.drawing:ChainDrawing"
    sensitivity_map = "mechsim.mechanisms.chain.sensitivity:MAP"
    parameter_names = (
        "Qx", "Qy", "R", "L", "r1", "J1", "JQ", "m3", "c3", "J3", "T_L", "c1", "c2",
        # discrete (mode) parameters: piece index, cumulative travel range, line/arc data, tuned-arc data
        "seg", "s0", "s1", "Px", "Py", "tx", "ty", "Ox", "Oy", "rr", "psi0", "alpha", "s_apex", "sigma",
    )

    schema = {
        "mechanism": {
            "sprockets": Field("points", "m", required=True,
                               help="sprocket centres O_i [[x, y], ...], counter-clockwise; sprocket 1 drives"),
            "sprocket_radii": Field("list", "m", required=True, help="pitch radii r_i, one per sprocket"),
            "pivot": Field("list", "m", default=[0.0, 0.0], help="crank pivot Q as [x, y]"),
            "crank_radius": Field("quantity", "m", required=True, positive=True, help="crank R = |QA|"),
            "coupler_length": Field("quantity", "m", required=True, positive=True, help="coupler L = |AB|"),
            "detuning": Field("quantity", "m", default=0.0,
                              help="delta = (R + L) - (L_i + r_i): the coupler is made L + delta (apex = detuned)"),
            "apex": Field("str", default="stop", choices=APEX_LAWS,
                          help="branch law at a dwell apex: stop (crank stop, impact), smooth, detuned"),
            "restitution": Field("float", default=0.0, nonnegative=True, maximum=1.0,
                                 why="e > 1 would create energy at every impact",
                                 help="coefficient of restitution e of the crank stop (apex = stop), 0..1"),
            "branch": Field("str", default="leading", choices=tuple(_ROOT),
                            help="assembly root at the start: leading (paper case I) or lagging (case II)"),
            "chain_mass": Field("quantity", "kg", default=0.0, nonnegative=True, help="mass of the chain loop"),
            "sprocket_inertias": Field("list", "kg*m^2", default=None,
                                       help="moment of inertia of each sprocket (default 0)"),
            "crank_mass": Field("quantity", "kg", required=True, positive=True, help="crank mass"),
            "crank_inertia": Field("quantity", "kg*m^2", default=None, positive=True,
                                   help="crank inertia about Q (default slender rod m R^2/3)"),
            "coupler_mass": Field("quantity", "kg", required=True, positive=True, help="coupler mass"),
            "coupler_inertia": Field("quantity", "kg*m^2", default=None, positive=True,
                                     help="coupler inertia about its centre (default slender rod m L^2/12)"),
            "drive_damping": Field("quantity", "N*m*s/rad", default=0.0, nonnegative=True,
                                   help="viscous damping on sprocket 1"),
            "crank_damping": Field("quantity", "N*m*s/rad", default=0.0, nonnegative=True,
                                   help="viscous damping on the crank shaft"),
        },
        "load": {
            "crank_torque": Field("quantity", "N*m", default=0.0,
                                  help="constant torque T_L on the crank, resisting counter-clockwise rotation"),
        },
    }

    # -- construction ---------------------------------------------------------------------------------
    @classmethod
    def from_config(cls, config: dict[str, dict]) -> "ChainDwell":
        m, load = config["mechanism"], config.get("load", {})
        centres = [tuple(p) for p in m["sprockets"]]
        radii = list(m["sprocket_radii"])
        if len(radii) != len(centres):
            raise ValueError(f"mechanism.sprocket_radii: {len(radii)} radii for {len(centres)} sprockets")
        pivot = m.get("pivot") or [0.0, 0.0]
        if len(pivot) != 2:
            raise ValueError(f"mechanism.pivot: expected [x, y], got {len(pivot)} values")
        inertias = m.get("sprocket_inertias")
        if inertias is not None and len(inertias) != len(centres):
            raise ValueError(f"mechanism.sprocket_inertias: {len(inertias)} values for {len(centres)} sprockets")
        params = ChainDwellParams("scenario", tuple(centres), tuple(radii), m["crank_radius"], m["coupler_length"],
                                  tuple(pivot))
        mech = cls(params, crank_mass=m["crank_mass"], coupler_mass=m["coupler_mass"],
                   chain_mass=m.get("chain_mass", 0.0), sprocket_inertias=inertias,
                   crank_inertia=m.get("crank_inertia"), coupler_inertia=m.get("coupler_inertia"),
                   crank_torque=load.get("crank_torque", 0.0), drive_damping=m.get("drive_damping", 0.0),
                   crank_damping=m.get("crank_damping", 0.0), apex=m.get("apex", "stop"),
                   restitution=m.get("restitution", 0.0), branch=m.get("branch", "leading"),
                   detuning=m.get("detuning", 0.0))
        mech.check_run(config)
        return mech

    def check_run(self, config: dict[str, dict]) -> None:
        """Before any work (closed form, cheap): the dyad assembles at the initial drive angle, and a prescribed
        speed never carries the chain to a fold, where |QB| leaves [|R - L|, R + L] and it jams (ValueError)."""
        initial, drive = config.get("initial", {}), config.get("drive", {})
        angle0 = initial.get(self.initial_keys[0]) or 0.0
        st = self.kin.state(np.array([self.path.r1 * angle0]), self.branch, +1)
        if not bool(np.asarray(st["closes"])[0]):
            raise ValueError(f"initial.drive_angle: the dyad cannot assemble at drive angle {math.degrees(angle0):.6g} "
                             f"deg: |QB| lies outside [|R - L|, R + L] = [{self.kin.c_in:.6g}, {self.kin.c_out:.6g}] m "
                             "(mechanism.crank_radius and coupler_length cannot reach the chain there)")
        speed, duration = drive.get("speed"), config.get("duration")
        if drive.get("type") != "speed" or not speed or not duration:
            return
        folds = self.kin.folds().drive_angle_rad.to_numpy()
        cycle = self.kin.cycle_angle
        a0, a1 = sorted((angle0, angle0 + speed * duration))
        hits = [f + math.ceil((a0 - f) / cycle) * cycle for f in folds]
        hits = [x for x in hits if x <= a1]
        if hits:
            raise ValueError(
                f"mechanism.coupler_length: the prescribed chain motion reaches a fold (dead centre) at drive angle "
                f"{math.degrees(min(hits)):.6g} deg, where |QB| leaves [|R - L|, R + L] = [{self.kin.c_in:.6g}, "
                f"{self.kin.c_out:.6g}] m and a position-driven chain jams; change crank_radius/coupler_length, "
                "shorten the run, or use a torque drive to see it stall")

    def __init__(self, params: ChainDwellParams, crank_mass: float, coupler_mass: float, chain_mass: float = 0.0,
                 sprocket_inertias=None, crank_inertia: float | None = None, coupler_inertia: float | None = None,
                 crank_torque: float = 0.0, drive_damping: float = 0.0, crank_damping: float = 0.0,
                 apex: str = "stop", restitution: float = 0.0, branch: str = "leading",
                 detuning: float = 0.0) -> None:
        super().__init__()
        if apex not in APEX_LAWS:
            raise ValueError(f"mechanism.apex: must be one of {', '.join(APEX_LAWS)}; got {apex!r}")
        if branch not in _ROOT:
            raise ValueError(f"mechanism.branch: must be leading or lagging; got {branch!r}")
        if not 0.0 <= restitution <= 1.0:
            raise ValueError(f"mechanism.restitution: must lie in [0, 1], got {restitution!r}")
        if apex == "detuned" and detuning == 0.0:
            raise ValueError("mechanism.detuning: apex = 'detuned' needs a non-zero detuning delta")
        if apex != "detuned" and detuning != 0.0:
            raise ValueError(f"mechanism.detuning: must be 0 for apex = '{apex}' (set apex = 'detuned' to run a "
                             "detuned design)")
        self.params = params.detuned(detuning) if detuning else params
        self.kin = ChainDwellMechanism(self.params)        # geometry, closure and singular points (ValueError)
        self.path = self.kin.path
        self.apex, self.restitution, self.branch, self.detuning = apex, float(restitution), branch, float(detuning)
        R, L = self.kin.R, self.kin.L
        self.crank_mass, self.coupler_mass = float(crank_mass), float(coupler_mass)
        self.crank_inertia = crank_mass * R**2 / 3 if crank_inertia is None else float(crank_inertia)
        self.coupler_inertia = coupler_mass * L**2 / 12 if coupler_inertia is None else float(coupler_inertia)
        inertias = np.zeros(self.path.n) if sprocket_inertias is None else np.asarray(sprocket_inertias, float)
        r1 = self.path.r1
        self.drive_inertia = float(chain_mass * r1**2 + np.sum(inertias * (r1 / self.path.radii) ** 2))
        if not self.drive_inertia > 0:
            raise ValueError("mechanism.chain_mass: the chain and sprockets need some inertia (chain_mass or "
                             "sprocket_inertias > 0)")
        self.chain_mass = float(chain_mass)
        self.crank_torque, self.drive_damping, self.crank_damping = crank_torque, drive_damping, crank_damping
        self.tuned = set(self.kin.dwell_sprockets())
        if self.tuned and not self.kin.L < self.kin.R:
            raise ValueError("mechanism.coupler_length: a dwell sprocket needs L < R (else the reflected curve "
                             "passes a point where its regular constraint degenerates)")
        self._event_rows: dict = {}     # _prescribed_events' rows by junction/apex, for this mechanism's runs

    # -- geometry helpers -----------------------------------------------------------------------------
    @property
    def chain_length(self) -> float:
        return self.path.length

    def _piece_at(self, s: float, side: int = +1) -> tuple[int, int]:
        """(piece index, cycle) of cumulative travel s."""
        k, _ = self.path.locate(np.array([s]), side)
        k = int(k[0])
        cycle = int(math.floor((s - self.path.pieces[k].s0) / self.path.length + 1e-12))
        return k, cycle

    def _apex_on(self, k: int) -> float | None:
        """Travel (within one cycle) of the stretched touch on piece k, if the piece is a tuned arc."""
        p = self.path.pieces[k]
        if p.kind != "arc" or p.sprocket not in self.tuned:
            return None
        for s, kind in zip(self.kin.touches, self.kin.touch_kind):
            if kind > 0 and p.s0 - 1e-12 <= s <= p.s1 + 1e-12:
                return float(s)
        return None

    def stop_angle(self, sprocket: int) -> float:
        O = self.path.centres[sprocket] - self.kin.Q
        return math.atan2(O[1], O[0])

    def _piece_values(self, k: int, cycle: int) -> dict[str, float]:
        p = self.path.pieces[k]
        base = cycle * self.path.length
        s0, s1 = base + p.s0, base + p.s1
        out = {"seg": float(k), "s0": s0, "s1": s1, "s_apex": s1 + self.path.length}
        if p.kind == "line":
            out.update(Px=p.start[0], Py=p.start[1], tx=p.direction[0], ty=p.direction[1])
        else:
            out.update(Ox=p.centre[0], Oy=p.centre[1], rr=p.radius, psi0=p.psi0)
            if p.sprocket in self.tuned:
                out["alpha"] = self.stop_angle(p.sprocket)
                apex = self._apex_on(k)
                if apex is not None:
                    out["s_apex"] = base + apex
        return out

    def _crank_tip(self, q) -> np.ndarray:
        return self.kin.Q + self.kin.R * np.array([math.cos(q[1]), math.sin(q[1])])

    def _mode_for(self, k: int, q, crank_rate: float | None = None) -> str:
        """Mode of piece k with the dyad at q: line, arc, or on a tuned wrap dwell (A = O_i) / swing. At the apex
        both curves have A = O_i; there the crank rate (dphi/ds, if given) tells them apart (0 on D)."""
        p = self.path.pieces[k]
        if p.kind == "line":
            return "line"
        if p.sprocket not in self.tuned:
            return "arc"
        gap = float(np.hypot(*(self._crank_tip(q) - np.asarray(p.centre))))
        still = crank_rate is None or abs(crank_rate) * self.kin.R <= 1e-6
        return "dwell" if gap <= 1e-6 * self.kin.R and still else "swing"

    def _modes_along(self, pieces: np.ndarray, q: np.ndarray, crank_rate: np.ndarray) -> np.ndarray:
        """`_mode_for` of every instant at once (pieces, q of shape (3, n), crank rates dphi/ds), as indices into
        MODE_NAMES: the same tests on the same numbers."""
        kind = np.array([0 if p.kind == "line" else 1 if p.sprocket not in self.tuned else 2
                         for p in self.path.pieces], int)[pieces]
        code = np.minimum(kind, 1)
        tuned = np.flatnonzero(kind == 2)
        if tuned.size:
            centre = np.array([p.centre if p.kind == "arc" else (np.nan, np.nan) for p in self.path.pieces])
            c = centre[pieces[tuned]]
            tip = self.kin.Q[:, None] + self.kin.R * np.stack([np.cos(q[1, tuned]), np.sin(q[1, tuned])])
            gap = np.hypot(tip[0] - c[:, 0], tip[1] - c[:, 1])
            still = np.abs(crank_rate[tuned]) * self.kin.R <= 1e-6
            code[tuned] = np.where((gap <= 1e-6 * self.kin.R) & still, 2, 3)
        return code

    @staticmethod
    def _root_sign(q) -> float:
        """-1 on the leading root (A clockwise of QB: sin(theta - phi) > 0), +1 on the lagging root."""
        return -1.0 if math.sin(q[2] - q[1]) >= 0 else 1.0

    # -- symbolic model -------------------------------------------------------------------------------
    def _model(self) -> dict:
        import sympy as sp
        key = self.structure_key()
        if key in _SYM_CACHE:
            return _SYM_CACHE[key]
        s, P = self.symbols, self.symbols.p
        th1, phi, th = s.q
        v = list(s.v)
        lam = s.lam[:2]
        Q = sp.Matrix([P("Qx"), P("Qy")])
        R, L, r1 = P("R"), P("L"), P("r1")
        travel = r1 * th1
        B_line = sp.Matrix([P("Px") + (travel - P("s0")) * P("tx"), P("Py") + (travel - P("s0")) * P("ty")])
        psi = P("psi0") + (travel - P("s0")) / P("rr")
        B_arc = sp.Matrix([P("Ox"), P("Oy")]) + P("rr") * _e(psi)
        e_phi, e_th = _e(phi), _e(th)
        n_th = sp.Matrix([-sp.sin(th), sp.cos(th)])
        A = Q + R * e_phi

        # mass matrix: sprocket 1 (reflected chain + sprockets), crank about Q, coupler centre at A + c3 e(theta)
        # (the coupler centre G3 = A + c3 e(theta) has velocity R phi' n(phi) + c3 theta' n(theta))
        m3, c3 = P("m3"), P("c3")
        k13 = m3 * R * c3 * sp.cos(phi - th)
        M = sp.Matrix([[P("J1"), 0, 0], [0, P("JQ") + m3 * R**2, k13], [0, k13, P("J3") + m3 * c3**2]])
        q = list(s.q)
        h = [sum((sp.diff(M[i, j], q[k]) - sp.diff(M[j, k], q[i]) / 2) * v[j] * v[k]
                 for j in range(3) for k in range(3)) for i in range(3)]
        applied = [-P("c1") * v[0], -P("T_L") - P("c2") * v[1], sp.Integer(0)]
        force = tuple(sp.expand(applied[i] - h[i]) for i in range(3))
        powers = {"load": -P("T_L") * v[1], "damping": -P("c1") * v[0] ** 2 - P("c2") * v[1] ** 2}

        def constraints(kind):
            B = B_line if kind == "line" else B_arc
            g = Q + R * e_phi + L * e_th - B
            if kind in ("line", "arc"):
                return B, (g[0], g[1])
            tangential = (n_th.T * g)[0]
            if kind == "dwell":
                return B, (tangential, R * sp.sin(phi - P("alpha")))
            reflect = (sp.cos(phi) + sp.cos(P("alpha"))) * (B[1] - Q[1]) \
                - (sp.sin(phi) + sp.sin(P("alpha"))) * (B[0] - Q[0])
            return B, (tangential, reflect)

        def readouts(kind, B, cons):
            zero = sp.Integer(0)
            if kind in ("line", "arc"):
                f = sp.Matrix(lam)                           # force of the coupler on the chain at B
                tension, shear = -(f.T * e_th)[0], -(f.T * n_th)[0]
                holding = zero
            elif kind == "dwell":
                tension, shear = zero, -lam[0]               # axial force indeterminate with the stop: 0
                holding = -R * sp.cos(phi - P("alpha")) * lam[1]
            else:
                Fc = -sp.Matrix(cons).jacobian(q).T * sp.Matrix(lam)   # generalized constraint force
                b = -Fc[2] / L
                a = (-Fc[1] / R - b * sp.cos(th - phi)) / sp.sin(th - phi)
                tension, shear = -a, -b
                holding = zero
            rho = sp.sqrt((B[0] - Q[0]) ** 2 + (B[1] - Q[1]) ** 2)
            return {
                "chain_travel_m": travel, "chain_speed_m_s": r1 * v[0],
                "segment": P("seg"), "branch": P("sigma"),
                "joint_B_x_m": B[0], "joint_B_y_m": B[1], "crank_tip_x_m": A[0], "crank_tip_y_m": A[1],
                "stretch_margin_m": R + L - rho,
                "coupler_force_N": tension, "coupler_shear_N": shear,
                "joint_force_N": sp.sqrt(tension ** 2 + shear ** 2),
                "holding_torque_N_m": holding,
            }

        end = Guard("end", travel - P("s1"), +1)
        reversal = Guard("reversal", v[0], -1)
        modes = {}
        for kind in ("line", "arc", "dwell", "swing"):
            B, cons = constraints(kind)
            if kind in ("line", "arc"):
                guards = (end, reversal, Guard("dead_centre", -P("sigma") * sp.sin(th - phi), -1))
            else:
                guards = (end, reversal, Guard("apex", travel - P("s_apex"), +1))
            modes[kind] = Mode(kind, cons, force, guards, powers, readouts(kind, B, cons))
        out = dict(M=M, modes=modes, h=h, force=force)
        _SYM_CACHE[key] = out
        return out

    def mass_matrix(self) -> sp.Matrix:
        return self._model()["M"]

    def modes(self) -> dict[str, Mode]:
        return dict(self._model()["modes"])

    # -- numbers --------------------------------------------------------------------------------------
    def parameter_values(self) -> dict[str, float]:
        k = self.kin
        vals = {"Qx": k.Q[0], "Qy": k.Q[1], "R": k.R, "L": k.L, "r1": self.path.r1,
                "J1": self.drive_inertia, "JQ": self.crank_inertia, "m3": self.coupler_mass, "c3": k.L / 2,
                "J3": self.coupler_inertia, "T_L": self.crank_torque, "c1": self.drive_damping,
                "c2": self.crank_damping,
                "Px": 0.0, "Py": 0.0, "tx": 1.0, "ty": 0.0, "Ox": 0.0, "Oy": 0.0, "rr": 1.0, "psi0": 0.0,
                "alpha": 0.0, "sigma": _ROOT[self.branch]}
        vals.update(self._piece_values(0, 0))
        return vals

    def _kinematic_state(self, s: float, branch: str):
        st = self.kin.state(np.array([s]), branch, +1)
        if not bool(st["closes"][0]):
            raise ValueError(f"initial state: the dyad cannot assemble at drive angle "
                             f"{math.degrees(s / self.path.r1):.4f} deg (|QB| out of [|R-L|, R+L])")
        return st

    def initial_state(self, angle: float, speed: float) -> InitialState:
        r1 = self.path.r1
        s = r1 * angle
        k, cycle = self._piece_at(s)
        st = self._kinematic_state(s, self.branch)
        q = np.array([angle, float(st["phi"][0]), float(st["theta"][0])])
        v = speed * r1 * np.array([1.0 / r1, float(st["dphi"][0]), float(st["dtheta"][0])])
        mode = self._mode_for(k, q)
        vals = self._piece_values(k, cycle)
        if mode in ("dwell", "swing") and s >= vals["s_apex"] - 1e-12 * self.path.length:
            vals["s_apex"] = vals["s1"] + self.path.length       # apex already behind
            if mode == "swing" and self.apex == "stop":
                raise ValueError("initial state: the crank is past its stop (lagging root after the apex with "
                                 "apex = 'stop'); start before the apex or on the leading branch")
        vals["sigma"] = float(st["sigma"][0])
        return InitialState(mode, vals, q, v)

    def on_guard(self, mode: str, guard: str, values: Mapping[str, float], t: float,
                 q: np.ndarray, v: np.ndarray) -> Transition:
        deg = math.degrees(q[0])
        if guard == "reversal":
            stretch = self.kin.c_out - float(np.hypot(*(self._B(values, q) - self.kin.Q)))
            where = (" at a dead centre (dyad stretched, |QB| = R + L: a fold of the detuned design)"
                     if abs(stretch) <= 1e-6 * self.kin.c_out else "")
            return Transition(mode, stop=(
                f"chain stalled and would reverse at drive angle {deg:.5f} deg{where} ({mode}, segment "
                f"{self.path.pieces[int(values['seg'])].name}); the drive cannot carry the mechanism past this "
                "point"), kind="reversal",
                hint="raise the sprocket torque (drive.torque; a motor's drive.stall_torque) or lower the crank "
                     "load (load.crank_torque); with a detuned design (detuning < 0) the fold cannot be passed at all")
        if guard == "dead_centre":
            folded = math.cos(q[2] - q[1]) < 0
            return Transition(mode, stop=(
                f"dyad {'folded' if folded else 'stretched'} (dead centre) at drive angle {deg:.5f} deg on "
                f"{self.path.pieces[int(values['seg'])].name}: a fold, where the chain must stall and reverse "
                f"(chain speed {v[0] * self.path.r1:.3g} m/s); the run is not continued through it"),
                kind="dead centre",
                hint="set mechanism.detuning >= 0, or mechanism.apex = 'stop' / 'smooth' for an exact design")
        if guard == "apex":
            far = values["s1"] + self.path.length
            if mode == "swing" and self.apex == "stop":
                return Transition("dwell", {"s_apex": far, "sigma": -1.0}, restitution=self.restitution,
                                  kind="stop impact", message=None)
            return Transition(mode, {"s_apex": far, "sigma": -values["sigma"]}, kind="apex")
        if guard == "end":
            k = int(values["seg"])
            cycle = int(round((values["s0"] - self.path.pieces[k].s0) / self.path.length))
            k += 1
            if k == len(self.path.pieces):
                k, cycle = 0, cycle + 1
            new = self._mode_for(k, q)
            vals = self._piece_values(k, cycle)
            vals["sigma"] = self._root_sign(q)
            kind = {"dwell": "dwell start", "swing": "arc entry", "arc": "arc entry"}.get(new, "arc exit")
            if mode == "dwell":
                kind = "dwell end"
            return Transition(new, vals, kind=kind)
        raise KeyError(f"unknown guard {guard!r} in mode {mode!r}")

    def _B(self, values: Mapping[str, float], q) -> np.ndarray:
        s = self.path.r1 * q[0]
        if self.path.pieces[int(values["seg"])].kind == "line":
            return np.array([values["Px"] + (s - values["s0"]) * values["tx"],
                             values["Py"] + (s - values["s0"]) * values["ty"]])
        psi = values["psi0"] + (s - values["s0"]) / values["rr"]
        return np.array([values["Ox"] + values["rr"] * math.cos(psi), values["Oy"] + values["rr"] * math.sin(psi)])

    def structure_key(self) -> tuple:
        return (type(self).__name__, 1)

    def validity_conditions(self) -> tuple[ValidityCondition, ...]:
        """Distance from the dead centres (docs/chain_dwell.md, "Validity"): on lines and arcs the loop closure
        is regular only while the dyad is neither stretched nor folded, |sin(theta - phi)| >= DEAD_CENTRE_MARGIN;
        near there the coupler force grows without bound. The dwell and swing modes carry their own regular rows
        (not evaluated there)."""
        def signed_sine(c):
            values = np.sin(np.asarray(c["coupler_angle_rad"], dtype=float)
                            - np.asarray(c["crank_angle_rad"], dtype=float))
            modes = np.asarray(c["mode"], dtype=object)
            return np.where((modes == "line") | (modes == "arc"), values, np.nan)

        def sine(c):
            return np.abs(signed_sine(c))
        return (ValidityCondition(
            "dead_centre_distance", f"|sin(theta - phi)| >= {DEAD_CENTRE_MARGIN:g} on the chain's lines and arcs: "
            "away from the dead centres (dyad stretched or folded), where the loop closure is singular and the "
            "coupler force grows without bound", sine, DEAD_CENTRE_MARGIN, "min", "",
            "docs/theory.md §K1.5; docs/chain_dwell.md, 'Validity'", ("coupler_angle_rad", "crank_angle_rad", "mode"),
            signed_sine),)

    def drive_cycle(self) -> DriveCycle:
        """A chain circuit of the driving sprocket (El-Shakery eq. 31)."""
        return DriveCycle("drive_angle_rad", self.kin.cycle_angle, 0.0,
                          "drive sprocket angle within the chain circuit (deg)")

    def extra_figures(self, timeseries, tables: dict) -> dict:
        """El-Shakery's kinematics figures (`mechanisms/chain/plots.py` `extra_figures`)."""
        from mechsim.mechanisms.chain.plots import extra_figures
        return extra_figures(self, timeseries, tables)

    def describe(self) -> dict:
        k = self.kin
        sp_df = k.singular_points()
        return {
            "chain_length_m": self.path.length, "cycle_drive_angle_rad": k.cycle_angle,
            "drive_inertia_kg_m2": self.drive_inertia, "crank_inertia_kg_m2": self.crank_inertia,
            "coupler_inertia_kg_m2": self.coupler_inertia,
            "dwell_sprockets": sorted(i + 1 for i in self.tuned),
            "apex_law": self.apex, "restitution": self.restitution, "detuning_m": self.detuning,
            "apex_drive_angles_rad": [float(a) for a, kind in zip(sp_df.drive_angle_rad, sp_df.kind)
                                      if kind == "stretched touch"],
            "fold_drive_angles_rad": [float(a) for a, kind in zip(sp_df.drive_angle_rad, sp_df.kind)
                                      if kind.endswith("fold")],
        }

    # -- prescribed constant drive speed: closed-form kinematics, inverse dynamics, no DAE ------------------
    def _numeric(self) -> dict:
        """numpy functions of the symbolic model: M(q), Q(q, v) at zero drive torque and, per mode, the
        constraint Jacobian and the read-outs; each returns arrays broadcast to the sample shape. Made once per
        model structure (the numbers are arguments), like the symbolic model, and kept between processes
        (`function_store`): a later process loads them without sympy."""
        key = ("numeric",) + self.structure_key()
        if key in _SYM_CACHE:
            return _SYM_CACHE[key]
        got = self.stored_functions(("chain closed form",) + key, self._numeric_functions)
        fns, meta = got
        out = {"M": _entries([fns[f"M.{j}"] for j in range(9)], (3, 3)),
               "Q": _entries([fns[f"Q.{j}"] for j in range(3)], (3,)), "modes": {}}
        for name, names in meta["readouts"].items():
            out["modes"][name] = dict(G=_entries([fns[f"{name}.G.{j}"] for j in range(6)], (2, 3)),
                                      readouts=fns[f"{name}.readouts"], names=list(names))
        _SYM_CACHE[key] = out
        return out

    def _numeric_functions(self) -> tuple[dict, dict]:
        """`_numeric`'s lambdified functions, each entry of M, Q and every mode's G its own function, and the modes'
        read-out names: ({name: function}, {"readouts": {mode: names}})."""
        import sympy as sp
        from mechsim.dynamics.codegen import lambdify
        s, md = self.symbols, self._model()
        qa, va, pa = list(s.q), list(s.v), list(s.params)
        fns = {f"M.{j}": lambdify([qa, pa], e, "numpy") for j, e in enumerate(md["M"])}
        fns.update({f"Q.{j}": lambdify([qa, va, pa], e, "numpy") for j, e in enumerate(md["force"])})
        for name, mode in md["modes"].items():
            G = sp.Matrix(mode.constraints).jacobian(qa)
            fns.update({f"{name}.G.{j}": lambdify([qa, pa], e, "numpy") for j, e in enumerate(G)})
            fns[f"{name}.readouts"] = lambdify([s.t, qa, va, list(s.a), list(s.lam[:2]), pa],
                                               list(mode.readouts.values()), "numpy")
        return fns, {"readouts": {name: list(mode.readouts) for name, mode in md["modes"].items()}}

    def prescribed_branch(self, s: np.ndarray, s_start: float, side=+1) -> dict:
        """Closed-form dyad state along the motion a prescribed chain speed produces under the apex law.

        stop: the starting root up to the first apex, the leading root after it (a stop turns F into D, and D
        is never left at an apex); smooth: the analytic continuation (chain_dwell 'smooth') from the start;
        detuned: the starting root (no apex exists). side: at a junction or apex, the limit from before (-1) or
        after (+1), one for all values or one per value (`ChainDwellMechanism.sides_of`). Sources: docs/theory.md
        §K1.2, §1.5; docs/chain_dwell.md §7.
        """
        k = self.kin
        if self.apex == "smooth":
            st = k.state(s, "smooth", side, self.branch, s_start)
        else:
            st = k.state(s, self.branch, side)
            if self.apex == "stop" and self.branch != "leading" and len(k.touches):
                apexes = k.touches[k.touch_kind > 0]
                Lc = self.path.length
                later = [a + c * Lc for c in range(int(s_start // Lc), int(s_start // Lc) + 2) for a in apexes
                         if a + c * Lc >= s_start - 1e-12 * Lc]
                if later:
                    first = min(later)
                    # (a value snapped onto the apex from before it, or the apex read from before: not yet after)
                    after = np.where(np.asarray(side) < 0, s > first, s >= first - 1e-12 * Lc)
                    lead = k.state(s, "leading", side)
                    st = {key: (np.where(after.reshape(after.shape + (1,) * (np.ndim(val) - 1)), lead[key], val)
                                if isinstance(val, np.ndarray) and np.shape(val)[:1] == s.shape else val)
                          for key, val in st.items()}
        if not np.all(st["closes"]):
            bad = float(s[np.flatnonzero(~np.asarray(st["closes"]))[0]] / self.path.r1)
            folds = [math.degrees(a) for a in self.kin.folds().drive_angle_rad]
            raise ValueError(
                f"the prescribed chain motion reaches a fold (dead centre) near drive angle {math.degrees(bad):.4f} "
                f"deg (folds of one cycle at {', '.join(f'{a:.4f}' for a in folds)} deg): a position-driven chain "
                "jams there; use a torque drive to see it stall or reverse")
        return st

    def closed_form(self, t: np.ndarray, angle0: float, speed: float) -> dict[str, np.ndarray]:
        """Columns at constant drive speed: chain_dwell's closed-form kinematics on the branch the apex law
        selects, then forces by inverse dynamics, M a + G^T lam = Q + T e_drive solved for (lam, T) at every
        instant with the constraints of the instant's mode (docs/chain_dwell.md §7)."""
        t = np.asarray(t, float)
        r1 = self.path.r1
        th1 = angle0 + speed * (t - t[0])
        s = r1 * th1
        # each instant's own side of a junction or apex it lies a snap from (an interval's end read just inside it)
        st = self.prescribed_branch(s, s[0] if len(s) else 0.0, self.kin.sides_of(s))
        w = r1 * speed
        n = len(t)
        q = np.stack([th1, st["phi"], st["theta"]])
        v = np.stack([np.full(n, speed), st["dphi"] * w, st["dtheta"] * w])
        a = np.stack([np.zeros(n), st["d2phi"] * w * w, st["d2theta"] * w * w])
        q[1:] = np.unwrap(q[1:], axis=1)       # continuous angles, like the DAE's coordinates
        num = self._numeric()
        names = list(self.parameter_names)
        base = self.parameter_values()
        # piece, cycle and mode of every instant
        pieces = np.asarray(st["piece"], int)
        cycles = np.floor((s - self.path.boundaries[pieces]) / self.path.length + 1e-12).astype(int)
        code = self._modes_along(pieces, q, st["dphi"])
        modes = MODE_NAMES[code]
        sig = np.asarray(st["sigma"], float)
        lam = np.zeros((2, n))
        torque = np.zeros(n)
        ro: dict[str, np.ndarray] = {}
        # the parameters of every instant: the base values, its piece's on its cycle, its root sign
        span = (cycles - (cycles.min() if n else 0)) * len(self.path.pieces) + pieces
        _, first, inverse = np.unique(span, return_index=True, return_inverse=True)
        table = [{**base, **self._piece_values(int(pieces[i]), int(cycles[i]))} for i in first]
        P = list(np.array([[vals[nm] for nm in names] for vals in table], float).reshape(-1, len(names))[inverse]
                 .T.copy())
        P[names.index("sigma")] = sig
        # M and Q of every instant (the same in every mode), then each mode's constraints and read-outs; the
        # operands keep the layout of q[:, idx] (numpy's einsum rounds differently for differently strided ones)
        every = np.arange(n)
        M_all = num["M"](q[:, every], P)
        rhs = num["Q"](q[:, every], v[:, every], P) - np.einsum("nij,nj->ni", M_all, a[:, every].T)
        for m in np.unique(code):
            idx = np.flatnonzero(code == m)
            fm = num["modes"][MODE_NAMES[m]]
            Pi = [x[idx] for x in P]
            qi, vi, ai = q[:, idx], v[:, idx], a[:, idx]
            Gm = fm["G"](qi, Pi)
            A = np.zeros(idx.shape + (3, 3))
            A[..., :, :2] = np.swapaxes(Gm, -1, -2)
            A[..., 0, 2] = -1.0
            x = np.linalg.solve(A, rhs[idx][..., None])[..., 0]
            lam[:, idx], torque[idx] = x[:, :2].T, x[:, 2]
            # (a read-out with a pole at an apex, the coupler force read from before a crank stop, is inf there: the
            # value, which the peaks report as unbounded (docs/theory.md §K5), not a fault)
            with np.errstate(divide="ignore"):
                vals_ro = fm["readouts"](t[idx], qi, vi, ai, lam[:, idx], Pi)
            for nm, val in zip(fm["names"], vals_ro):
                ro.setdefault(nm, np.zeros(n))[idx] = np.broadcast_to(np.asarray(val, float), idx.shape)
        ke = 0.5 * np.einsum("in,nij,jn->n", v, M_all, v)
        B = np.stack([ro["joint_B_x_m"], ro["joint_B_y_m"]])
        A_tip = self.kin.Q[:, None] + self.kin.R * np.stack([np.cos(q[1]), np.sin(q[1])])
        closure = A_tip + self.kin.L * np.stack([np.cos(q[2]), np.sin(q[2])]) - B
        cols = {"mode": modes,
                "drive_angle_rad": q[0], "drive_speed_rad_s": v[0], "drive_accel_rad_s2": a[0],
                "crank_angle_rad": q[1], "crank_speed_rad_s": v[1], "crank_accel_rad_s2": a[1],
                "coupler_angle_rad": q[2], "coupler_speed_rad_s": v[2], "coupler_accel_rad_s2": a[2]}
        cols.update(ro)
        cols["events"] = self._prescribed_events(th1, speed, t[0] if n else 0.0, num)
        cols.update({"drive_torque_N_m": torque, "kinetic_energy_J": ke,
                     "constraint_residual_m": np.max(np.abs(closure), axis=0),
                     "powers": {"drive": torque * speed, "load": -self.crank_torque * v[1],
                                "damping": -self.drive_damping * speed**2 - self.crank_damping * v[1] ** 2}})
        return cols

    def _prescribed_events(self, th1: np.ndarray, speed: float, t0: float, num: dict) -> list[dict]:
        """Events-table rows of a closed-form run: every junction and apex passed, with the mode before/after
        and the kinetic energy of the one-sided limits (a stop impact loses 1/2 w^2 (tF M tF - tD M tD)). A
        mark's row depends on the motion's start and speed only, so it is kept for the next evaluation of the
        same motion (a located peak reads the closed form many times)."""
        if len(th1) < 2 or speed <= 0:
            return []
        r1, Lc = self.path.r1, self.path.length
        s_lo, s_hi = r1 * th1[0], r1 * th1[-1]
        base = list(self.path.boundaries[:-1]) + [float(a) for a, k in zip(self.kin.touches, self.kin.touch_kind)
                                                    if k > 0]
        marks = sorted(b + c * Lc for c in range(int(s_lo // Lc) - 1, int(s_hi // Lc) + 2) for b in base
                       if s_lo < b + c * Lc <= s_hi)
        s0 = r1 * th1[0]
        new = [sm for sm in marks if (sm, s0, speed) not in self._event_rows]
        if new:
            self._event_rows.update(zip([(sm, s0, speed) for sm in new], self._mark_rows(new, s0, speed, num)))
        return [dict(self._event_rows[(sm, s0, speed)], t_s=t0 + (sm / r1 - th1[0]) / speed) for sm in marks]

    def _mark_rows(self, marks: list, s_start: float, speed: float, num: dict) -> list[dict]:
        """`_prescribed_events`' rows (t_s left None) at the junctions/apexes `marks` (travel) of the motion from
        s_start, all at once: the limit before (the branch of the instant just before, the rates from that side)
        and after."""
        r1, Lc = self.path.r1, self.path.length
        at = np.array(marks, float)
        after = self.prescribed_branch(at, s_start)
        lagging = self.prescribed_branch(at - 1e-9 * Lc, s_start)["sigma"] >= 0
        before = {}
        for root, sel in (("leading", ~lagging), ("lagging", lagging)):
            if sel.any():
                st = self.kin.state(at[sel], root, -1)
                before.update({int(i): (st, j) for j, i in enumerate(np.flatnonzero(sel))})
        pieces = {side: self.path.locate(at, side)[0] for side in (-1, +1)}
        limits = []                     # (side, mark, q, v, dphi) of both sides of every mark
        for i, sm in enumerate(marks):
            for side, (st, j) in ((-1, before[i]), (+1, (after, i))):
                q = np.array([sm / r1, st["phi"][j], st["theta"][j]])
                v = speed * np.array([1.0, r1 * st["dphi"][j], r1 * st["dtheta"][j]])
                limits.append((side, i, q, v, st["dphi"][j]))
        values = self.parameter_values()
        P = [np.array([values[nm]], float) for nm in self.parameter_names]
        M = num["M"](np.stack([x[2] for x in limits], 1), P)
        sides = {}
        for (side, i, q, v, dphi), Mi in zip(limits, M):
            sides[side, i] = (self._mode_for(int(pieces[side][i]), q, dphi), 0.5 * float(v @ Mi @ v), q)
        rows = []
        for i in range(len(marks)):
            (m0, e0, q0), (m1, e1, _) = sides[-1, i], sides[+1, i]
            if m0 == "swing" and m1 == "dwell":
                kind = "stop impact"
            elif m0 == m1:
                kind = "apex"
            else:
                kind = {"dwell": "dwell start", "swing": "arc entry", "arc": "arc entry"}.get(m1, "arc exit")
                kind = "dwell end" if m0 == "dwell" else kind
            rows.append(dict(t_s=None, from_mode=m0, to_mode=m1, kind=kind, guard="prescribed", drive_q=q0[0],
                             crank_q=q0[1], coupler_q=q0[2], kinetic_energy_before_J=e0, kinetic_energy_after_J=e1,
                             message="", energy_lost_J=e0 - e1))
        return rows

    # -- extra tables and plots -----------------------------------------------------------------------------
    def extra_outputs(self, timeseries: pd.DataFrame, events: pd.DataFrame) -> dict[str, pd.DataFrame]:
        """dwells.csv: every dwell of the run (mode 'dwell': the crank held at alpha_i) and every near-dwell
        (|crank speed| <= 1% of the drive speed elsewhere, e.g. a detuned design), with its ends in time and
        drive angle. Ends come from the events table (exact, DAE runs) or from the path geometry (apex, arc
        entry/exit: closed-form runs); the crank excursion over the rows inside shows how still it stood."""
        return {"dwells": dwell_rows(self, timeseries, events)}


def _runs(mask: np.ndarray) -> list[tuple[int, int]]:
    """(first, last) index of every run of True."""
    idx = np.flatnonzero(mask)
    if not idx.size:
        return []
    cuts = np.flatnonzero(np.diff(idx) > 1)
    return list(zip(np.r_[idx[0], idx[cuts + 1]], np.r_[idx[cuts], idx[-1]]))


def dwell_rows(mech: ChainDwell, ts: pd.DataFrame, events: pd.DataFrame, near_tol: float = 0.01) -> pd.DataFrame:
    """The dwells table of a run (see ChainDwell.extra_outputs)."""
    cols = ["sprocket", "kind", "start_event", "end_event", "start_t_s", "end_t_s", "start_drive_angle_rad",
            "end_drive_angle_rad", "duration_drive_angle_rad", "crank_angle_rad", "crank_excursion_rad", "rows"]
    if not len(ts):
        return pd.DataFrame(columns=cols)
    t = ts["t_s"].to_numpy(float)
    th = ts["drive_angle_rad"].to_numpy(float)
    phi = ts["crank_angle_rad"].to_numpy(float)
    mode = ts["mode"].to_numpy(object)
    seg = ts["segment"].to_numpy(float).astype(int)
    r1, Lc = mech.path.r1, mech.path.length
    has_events = events is not None and len(events) and "to_mode" in events and "drive_q" in events
    if has_events:
        ev_t, ev_q = events["t_s"].to_numpy(float), events["drive_q"].to_numpy(float)
        ev = {key: events[key].to_numpy(object) for key in ("to_mode", "from_mode", "kind")}

    def event(lo, hi, key, value):
        """(t, drive angle, kind) of the first event with `key` == value in (lo, hi], or None."""
        if not has_events:
            return None
        hit = np.flatnonzero((ev[key] == value) & (ev_t > lo) & (ev_t <= hi))
        return (ev_t[hit[0]], ev_q[hit[0]], ev["kind"][hit[0]]) if hit.size else None

    def geometric(i_in, i_out, start):
        """(t, drive angle, label) of a dwell end from the path geometry, between rows i_out and i_in."""
        k = int(seg[i_in])
        piece = mech.path.pieces[k]
        cycle = math.floor((r1 * th[i_in] - piece.s0) / Lc + 1e-12)
        if start:
            apex = mech._apex_on(k)
            prev = mode[i_out]
            s = (apex if prev == "swing" and apex is not None else piece.s0) + cycle * Lc
            label = "stop impact" if prev == "swing" else "arc entry"
        else:
            s, label = piece.s1 + cycle * Lc, "arc exit"
        ang = s / r1
        return float(np.interp(ang, th[[i_out, i_in]] if start else th[[i_in, i_out]],
                               t[[i_out, i_in]] if start else t[[i_in, i_out]])), ang, label

    rows = []
    for i0, i1 in _runs(mode == "dwell"):
        if i0 == 0:
            start = (t[0], th[0], "run start")
        else:
            e = event(t[i0 - 1], t[i0], "to_mode", "dwell")
            start = e if e is not None else geometric(i0, i0 - 1, True)
        if i1 == len(t) - 1:
            e = event(t[i1], np.inf, "from_mode", "dwell")
            end = e if e is not None else (t[i1], th[i1], "run end")
        else:
            e = event(t[i1], t[i1 + 1], "from_mode", "dwell")
            end = e if e is not None else geometric(i1, i1 + 1, False)
        rows.append(dict(sprocket=mech.path.pieces[seg[i0]].sprocket + 1, kind="exact", start_event=start[2],
                         end_event=end[2], start_t_s=float(start[0]), end_t_s=float(end[0]),
                         start_drive_angle_rad=float(start[1]), end_drive_angle_rad=float(end[1]),
                         duration_drive_angle_rad=float(end[1] - start[1]),
                         crank_angle_rad=float(np.mean(phi[i0:i1 + 1])),
                         crank_excursion_rad=float(np.ptp(phi[i0:i1 + 1])), rows=int(i1 - i0 + 1)))
    w = ts["crank_speed_rad_s"].to_numpy(float)
    w1 = np.abs(ts["drive_speed_rad_s"].to_numpy(float))
    slow = (np.abs(w) <= near_tol * w1) & (mode != "dwell")
    for i0, i1 in _runs(slow):
        if i1 - i0 < 2 or (i0 > 0 and mode[i0 - 1] == "dwell") or (i1 + 1 < len(t) and mode[i1 + 1] == "dwell"):
            continue   # too short to tell, or the ramp next to an exact dwell

        def edge(i_in, i_out):
            if i_out < 0 or i_out >= len(t):
                return t[i_in], th[i_in]
            f_in, f_out = abs(w[i_in]) - near_tol * w1[i_in], abs(w[i_out]) - near_tol * w1[i_out]
            x = f_in / (f_in - f_out) if f_in != f_out else 0.0
            return t[i_in] + x * (t[i_out] - t[i_in]), th[i_in] + x * (th[i_out] - th[i_in])
        (ta, aa), (tb, ab) = edge(i0, i0 - 1), edge(i1, i1 + 1)
        rows.append(dict(sprocket=mech.path.pieces[seg[i0]].sprocket + 1, kind="near",
                         start_event=f"|crank speed| <= {near_tol:g} drive speed", end_event="",
                         start_t_s=float(ta), end_t_s=float(tb), start_drive_angle_rad=float(aa),
                         end_drive_angle_rad=float(ab), duration_drive_angle_rad=float(ab - aa),
                         crank_angle_rad=float(np.mean(phi[i0:i1 + 1])),
                         crank_excursion_rad=float(np.ptp(phi[i0:i1 + 1])), rows=int(i1 - i0 + 1)))
    return pd.DataFrame(rows, columns=cols).sort_values("start_t_s").reset_index(drop=True)
