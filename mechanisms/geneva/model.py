"""External Geneva drive as a two-mode multibody model (engaged: pin in slot; dwell: wheel locked).

Coordinates q = (crank, wheel): the crank angle theta (unwrapped, 0 at the first mid-engagement, growing
with the drive) and the wheel angle psi (unwrapped, positive in the indexing direction, +2 pi/n per index).
During engagement k the local angles are alpha = theta - 2 pi k and beta = psi - k 2 pi/n, the pin centre is
P = (c - r cos alpha, r sin alpha) in the wheel-centre frame of docs/theory.md §G1, and the constraint is that P
lies on the slot centre line (signed lateral offset, metres):

    Phi = r sin(alpha) cos(beta) - (c - r cos(alpha)) sin(beta) = 0.

Its multiplier is the normal force N on the driving flank (N > 0 pushes the wheel forward). Friction acts
along the slot at the contact point, with the slip u = v_s + flank R (theta' + psi') including the pin's spin
(docs/theory.md §G1 'Pin spin', §2); its generalized force -mu |N| sign(u) du/dv dissipates exactly mu |N| |u|.
During the dwell the locking arcs hold the wheel: Phi = r (psi - psi_lock) (a length, so the residual has one
unit); the load torque is then carried by the lock and locking friction is neglected (docs/theory.md §G2).
"""
from __future__ import annotations

from dataclasses import replace
from typing import TYPE_CHECKING, Mapping

import numpy as np

from mechsim.mechanisms.base import (Breakpoint, DriveCycle, Field, Guard, InitialState, Mechanism, Mode,
                                     TransitionRule, piecewise_linear)
from mechsim.mechanisms.base import load as load_ref
import mechsim.mechanisms.geneva.contact as geneva_contact
import mechsim.mechanisms.geneva.kinematics as gk
from mechsim.mechanisms.geneva.kinematics import GenevaGeometry

if TYPE_CHECKING:                      # the symbolic model imports sympy when it is built (a closed form needs none)
    import sympy as sp

#: the closed form's mode names by engaged (0/1): a row's name is taken from here, not made anew per row
MODE_NAMES = np.array(["dwell", "engaged"], dtype=object)


class Geneva(Mechanism):
    """External Geneva drive with n >= 3 slots, driven at the crank, loaded at the wheel."""

    name = "geneva"
    coordinates = ("crank", "wheel")
    max_constraints = 1
    drive_coordinate = 0
    angle_coordinates = (0, 1)
    parameter_names = (
        "r", "c", "R", "J1", "J2", "T_L", "mu", "c1", "c2", "pitch", "alpha0",
        # a wheel torque varying in time: T_L + T_L_rate (t - T_L_time0) on each piece of its profile
        "T_L_rate", "T_L_time0",
        # discrete (mode) parameters
        "slot", "lock_angle", "flank", "slide", "slot_base",
        # the creeping-rest guard: at rest once |theta'| + rest_time |theta''| < rest_speed
        "rest_speed", "rest_time",
    )
    #: a crank creeping to rest (speed and acceleration both vanishing, an exponential approach to the static
    #: equilibrium that never reaches theta' = 0) is stopped once theta' + REST_TIME |theta''| < REST_SPEED
    REST_SPEED = 1e-5   # rad/s
    REST_TIME = 1.0     # s
    #: a slip-reversal root with the crank slower than this is the crank stopping (see `_crank_stopped`):
    #: at a true stall the root's speed is at the integrator's error level (atol, 1e-6 rad/s and below), at a
    #: true reversal the crank turns at working speed (1-100 rad/s)
    STOPPED_SPEED = 1e-3   # rad/s

    has_sliding_contact = True
    #: the closed form at constant crank speed is a function of each instant (the angle from the first instant's)
    closed_form_pointwise = True
    peak_columns = ("contact_force_N", "drive_torque_N_m", "wheel_speed_rad_s", "wheel_accel_rad_s2", "slip_speed_m_s",
                    "friction_power_W", "crank_speed_rad_s", "crank_accel_rad_s2")
    drawing = "mechsim.mechanisms.geneva.drawing:GenevaDrawing"
    sensitivity_map = "mechsim.mechanisms.geneva.sensitivity:MAP"
    enumerated_keys = ("mechanism.slots",)
    #: the geometry `from_config` builds: it carries every formula in which the pin meets the slot
    #: (`GenevaGeometry.wheel_motion`, `pin_in_slot`, `crank_sense`); the internal Geneva swaps it
    geometry_class = GenevaGeometry
    #: "module:Class" of the model with slot clearance, built where mechanism.slot_clearance > 0
    clearance_model = "mechsim.mechanisms.geneva.clearance:GenevaClearance"
    #: "module:Class" of the model with slot clearance and a compliant contact (contact.model = "compliant")
    compliant_model = "mechsim.mechanisms.geneva.clearance_compliant:GenevaCompliant"
    schema = {
        "mechanism": {
            "slots": Field("int", required=True, minimum=3, maximum=72, help="number of slots n (>= 3)",
                           why="built Geneva wheels have 3 to about 24 slots; at 72 each index is 5 degrees"),
            "crank_radius": Field("quantity", "m", required=True, positive=True, help="crank radius r"),
            "pin_radius": Field("quantity", "m", required=True, positive=True, help="pin radius R"),
            "thickness": Field("quantity", "m", required=True, positive=True,
                               help="wheel thickness = pin-slot contact length"),
            "crank_inertia": Field("quantity", "kg*m^2", required=True, positive=True,
                                   help="crank + pin (+ drive side) moment of inertia J1"),
            "wheel_inertia": Field("quantity", "kg*m^2", required=True, positive=True,
                                   help="wheel (+ driven side) moment of inertia J2"),
            "crank_damping": Field("quantity", "N*m*s/rad", default=0.0, nonnegative=True,
                                   help="viscous damping on the crank shaft"),
            "wheel_damping": Field("quantity", "N*m*s/rad", default=0.0, nonnegative=True,
                                   help="viscous damping on the wheel shaft"),
            "slot_clearance": Field("quantity", "m", default=0.0, nonnegative=True,
                                    help="slot width - 2 R (0: the exact fit; > 0: the pin crosses a gap and "
                                         "strikes the flanks, mechanisms/geneva/clearance.py; external drive only)"),
            "lock_clearance": Field("quantity", "rad", default=0.0, nonnegative=True,
                                    help="angular play of the wheel about its nominal dwell angle in the locking arc "
                                         "(0: held exactly; > 0: free within +-play/2, striking the play's ends; "
                                         "needs mechanism.slot_clearance > 0)"),
        },
        "load": {
            "wheel_torque": Field("quantity", "N*m", default=0.0, nonnegative=True,
                                  help="resisting torque on the wheel while it indexes",
                                  replaces=("wheel_torque_per_station", "wheel_torque_profile")),
            "wheel_torque_per_station": Field("list", "N*m", default=None, help=(
                "the resisting torque of each station, one per slot: station i is the index made by slot i "
                "(slot 0 the one engaged at crank angle 0), the wheel torque while it indexes; in place of "
                "wheel_torque"), replaces=("wheel_torque", "wheel_torque_profile")),
            "wheel_torque_profile": Field("profile", "N*m", default=None, profile_key="torque", help=(
                "the resisting torque while the wheel indexes as a piecewise-linear function of time, "
                "{ t = [times], torque = [torques] } (times strictly increasing; held at the first value before "
                "the first time and at the last after the last); in place of wheel_torque"),
                replaces=("wheel_torque", "wheel_torque_per_station")),
        },
        "contact": {
            "friction": Field("float", default=0.0, nonnegative=True, maximum=2.0,
                              help="Coulomb friction coefficient, pin-slot",
                              why="Coulomb coefficients of engineering material pairs lie below about 1.5"),
            "restitution": Field("float", default=0.0, nonnegative=True, maximum=1.0,
                                 help="Newton's coefficient of restitution of the pin-flank impacts (with "
                                      "mechanism.slot_clearance > 0), 0..1",
                                 why="Newton's law: 0 plastic, 1 elastic"),
            "model": Field("str", default="rigid", choices=("rigid", "compliant"), help=(
                "the pin-flank contact with mechanism.slot_clearance > 0: 'rigid' (Newton impacts) or 'compliant' "
                "(a linear line-contact spring with Hunt-Crossley damping, finite impact forces; "
                "mechanisms/geneva/clearance_compliant.py)")),
            "stiffness": Field("quantity", "N/m", default=None, positive=True, only_if=("model", "compliant"),
                               help="the compliant contact's stiffness K (default: E* times the wheel thickness, "
                                    "E* of the thermal model's material)"),
        },
    }

    @classmethod
    def from_config(cls, config: dict[str, dict]) -> "Geneva":
        m, load, contact = config["mechanism"], config.get("load", {}), config.get("contact", {})
        geometry = cls.geometry_class(m["crank_radius"], int(m["slots"]), m["pin_radius"], m["thickness"])
        stations, profile = load.get("wheel_torque_per_station"), load.get("wheel_torque_profile")
        given = [k for k in ("wheel_torque_per_station", "wheel_torque_profile") if load.get(k) is not None]
        if len(given) > 1 or (given and load.get("wheel_torque", 0.0)):
            raise ValueError(f"load.{given[-1]}: give the wheel torque one way: wheel_torque, "
                             "wheel_torque_per_station or wheel_torque_profile")
        if stations is not None:
            if len(stations) != geometry.slots:
                raise ValueError(f"load.wheel_torque_per_station: {len(stations)} torques for {geometry.slots} "
                                 "slots; give one per station (slot)")
            for i, x in enumerate(stations):
                if x < 0:
                    raise ValueError(f"load.wheel_torque_per_station[{i}]: must not be negative, got {x:g} N*m")
        if profile is not None:
            for i, x in enumerate(profile["torque"]):
                if x < 0:
                    raise ValueError(f"load.wheel_torque_profile: torque[{i}] must not be negative, got {x:g} N*m")
        clearance = m.get("slot_clearance", 0.0)
        if contact.get("model", "rigid") != "rigid" and not clearance > 0:
            raise ValueError("contact.model: 'compliant' needs mechanism.slot_clearance > 0 (the pin in a wider slot)")
        if m.get("lock_clearance", 0.0) > 0 and not clearance > 0:
            raise ValueError("mechanism.lock_clearance: lock play needs slot clearance (mechanism.slot_clearance > 0): "
                             "an exact-fit slot turned off its nominal angle cannot take the pin")
        if clearance > 0:
            return cls._with_clearance(geometry, m, load, contact, clearance, given)
        return cls(geometry, m["crank_inertia"], m["wheel_inertia"], load.get("wheel_torque", 0.0),
                   contact.get("friction", 0.0), m.get("crank_damping", 0.0), m.get("wheel_damping", 0.0),
                   stations, profile)

    @classmethod
    def _with_clearance(cls, geometry, m, load, contact, clearance: float, given=()) -> "Geneva":
        """The clearance model (mechanisms/geneva/clearance.py), the pin and the widened slot checked: the
        clearance at most the pin radius, and the slot (half-width R + c_s/2) narrower than the rim allows
        (`GenevaGeometry.max_pin_radius`)."""
        if cls is not Geneva:
            raise ValueError(f"mechanism.slot_clearance: clearance is modelled for the external Geneva only "
                             f"(type = 'geneva'), not {cls.name!r}")
        if given:
            raise ValueError(f"load.{given[0]}: with mechanism.slot_clearance > 0 the wheel torque is one constant "
                             "(load.wheel_torque); per-station and time-varying loads are not modelled with clearance")
        if clearance > geometry.pin_radius:
            raise ValueError(f"mechanism.slot_clearance: {clearance:g} m is larger than the pin radius "
                             f"{geometry.pin_radius:g} m")
        if geometry.pin_radius + clearance / 2 >= geometry.max_pin_radius:
            raise ValueError(f"mechanism.slot_clearance: the slot's half-width R + c/2 = "
                             f"{geometry.pin_radius + clearance / 2:g} m makes neighbouring slots merge at the rim "
                             f"(it must stay below {geometry.max_pin_radius:.6g} m)")
        args = (geometry, m["crank_inertia"], m["wheel_inertia"], load.get("wheel_torque", 0.0),
                contact.get("friction", 0.0), m.get("crank_damping", 0.0), m.get("wheel_damping", 0.0))
        kw = dict(slot_clearance=clearance, restitution=contact.get("restitution", 0.0))
        if contact.get("model", "rigid") == "compliant":
            if m.get("lock_clearance", 0.0) > 0:
                raise ValueError("mechanism.lock_clearance: lock play is modelled with the rigid contact only "
                                 "(contact.model = 'rigid')")
            # K = E* l: the contact modulus of the thermal model's materials (the scenario loader puts it in
            # contact.modulus) over the contact length, the wheel thickness (docs/theory.md §G2.1)
            stiffness = contact.get("stiffness")
            if stiffness is None:
                if contact.get("modulus") is None:
                    raise ValueError("contact.stiffness: give it, or the contact modulus (contact.modulus, Pa)")
                stiffness = contact["modulus"] * geometry.thickness
            return load_ref(cls.compliant_model)(*args, **kw, stiffness=stiffness)
        if m.get("lock_clearance", 0.0) > 0:
            kw["lock_clearance"] = m["lock_clearance"]
        return load_ref(cls.clearance_model)(*args, **kw)

    def __init__(self, geometry: GenevaGeometry, crank_inertia: float, wheel_inertia: float,
                 wheel_torque: float = 0.0, friction: float = 0.0, crank_damping: float = 0.0,
                 wheel_damping: float = 0.0, wheel_torque_per_station=None, wheel_torque_profile=None) -> None:
        super().__init__()
        #: per-station wheel torques (one per slot) or None; a profile {"t": times, "torque": torques} or None
        self.station_torques = None if wheel_torque_per_station is None else tuple(
            float(x) for x in wheel_torque_per_station)
        self.torque_profile = wheel_torque_profile
        if self.station_torques is not None and len(self.station_torques) != geometry.slots:
            raise ValueError(f"load.wheel_torque_per_station: {len(self.station_torques)} torques for "
                             f"{geometry.slots} slots")
        self.geometry = geometry
        self.crank_inertia = crank_inertia
        self.wheel_inertia = wheel_inertia
        self.wheel_torque = wheel_torque
        self.friction = friction
        self.crank_damping = crank_damping
        self.wheel_damping = wheel_damping

    # -- symbolic model -------------------------------------------------------------------------------
    def mass_matrix(self) -> sp.Matrix:
        import sympy as sp
        P = self.symbols.p
        return sp.diag(P("J1"), P("J2"))

    def modes(self) -> dict[str, Mode]:
        import sympy as sp
        s, P = self.symbols, self.symbols.p
        t = s.t
        theta, psi = s.q
        w1, w2 = s.v
        a1, a2 = s.a
        rest = Guard("rest", w1 + P("rest_time") * sp.Abs(a1) - P("rest_speed"), -1)
        lam = s.lam[0]
        r, c, R, mu = P("r"), P("c"), P("R"), P("mu")
        c1, c2 = P("c1"), P("c2")
        T_L = P("T_L") + P("T_L_rate") * (t - P("T_L_time0"))     # the wheel torque (piecewise linear in t)
        k, flank, slide = P("slot"), P("flank"), P("slide")

        g = self.geometry
        alpha = theta - 2 * sp.pi * k
        beta = psi - k * P("pitch")
        phi_engaged, x, s_slide, _ = g.pin_in_slot(r, c, alpha, beta, sp)   # x: along-slot pin distance
        v_s = w1 * s_slide                                      # pin-centre sliding speed along the slot
        spin = R * (w2 - g.crank_sense * w1)                    # pin surface speed relative to the wheel
        u = v_s + flank * spin                                  # slip on the contact flank
        normal = lam                                            # N, signed (> 0: driving flank)
        fric_mag = mu * flank * lam                             # mu |N| with |N| = flank * N in this mode
        fric_force = [-fric_mag * slide * sp.diff(u, vi) for vi in (w1, w2)]
        damping = [-c1 * w1, -c2 * w2]

        engaged_readouts = {
            "contact_force_N": normal,
            "friction_force_N": fric_mag * slide,
            "slip_speed_m_s": u,
            "pin_sliding_speed_m_s": v_s,
            "pin_distance_m": x,
            "friction_power_W": fric_mag * slide * u,
            "flank": flank,
            "lock_force_N": sp.Integer(0),
        }
        engaged = Mode(
            name="engaged",
            constraints=(phi_engaged,),
            force=(damping[0] + fric_force[0], damping[1] + fric_force[1] - T_L),
            guards=(
                Guard("exit", theta - (2 * sp.pi * k + P("alpha0")), +1),
                # sign guards are written relative to the mode's own sign, falling only: the crossing that
                # started the mode (value ~ 0, rising) can never fire again from the restart point
                Guard("flank_switch", flank * lam, -1),
                Guard("slip_reversal", slide * u, -1),
                Guard("stall", w1, -1),
                rest,
            ),
            powers={"load": -T_L * w2, "friction": -fric_mag * slide * u, "damping": -c1 * w1**2 - c2 * w2**2},
            readouts=engaged_readouts,
            heat={"normal_force": normal, "slip_speed": u,
                  "source_speed_driver": spin, "source_speed_driven": v_s,
                  "heat_rate": fric_mag * slide * u, "track": k + P("slot_base")},
        )
        zero = sp.Integer(0)
        dwell = Mode(
            name="dwell",
            constraints=(r * (psi - P("lock_angle")),),
            force=tuple(damping),
            guards=(
                Guard("entry", theta - (2 * sp.pi * k - P("alpha0")), +1),
                Guard("stall", w1, -1),
                rest,
            ),
            powers={"load": zero, "friction": zero, "damping": -c1 * w1**2 - c2 * w2**2},
            readouts={
                "contact_force_N": zero, "friction_force_N": zero, "slip_speed_m_s": zero,
                "pin_sliding_speed_m_s": zero,
                "pin_distance_m": sp.sqrt(sum(p**2 for p in g.pin_position(r, c, alpha, sp))),
                "friction_power_W": zero, "flank": zero, "lock_force_N": lam,
            },
            heat={"normal_force": zero, "slip_speed": zero, "source_speed_driver": zero, "source_speed_driven": zero,
                  "heat_rate": zero, "track": k + P("slot_base")},
        )
        return {"engaged": engaged, "dwell": dwell}

    # -- numbers ----------------------------------------------------------------------------------------
    def parameter_values(self) -> dict[str, float]:
        g = self.geometry
        return {
            "r": g.crank_radius, "c": g.centre_distance, "R": g.pin_radius,
            "J1": self.crank_inertia, "J2": self.wheel_inertia, "T_L": self.wheel_torque,
            "T_L_rate": 0.0, "T_L_time0": 0.0,
            "mu": self.friction, "c1": self.crank_damping, "c2": self.wheel_damping,
            "pitch": g.pitch, "alpha0": g.engagement_half_angle,
            "slot": 0.0, "lock_angle": 0.0, "flank": 1.0, "slide": 1.0, "slot_base": 0.0,
            "rest_speed": self.REST_SPEED, "rest_time": self.REST_TIME,
            **(self._profile()[0] if self.torque_profile is not None else {}),
        }

    # -- a time-varying wheel torque (docs/theory.md, 'Time-varying loads and drives') ---------------------------
    @property
    def varying_load(self) -> bool:
        """True where the wheel torque varies by station or in time (no closed form, no reduced reference)."""
        return self.station_torques is not None or self.torque_profile is not None

    def _profile(self):
        return piecewise_linear(self.torque_profile["t"], self.torque_profile["torque"],
                                ("T_L", "T_L_rate", "T_L_time0"), "load breakpoint")

    def schedule(self, t_end: float) -> list[Breakpoint]:
        """The wheel-torque profile's knots (where it bends), as breakpoints."""
        return [] if self.torque_profile is None else [b for b in self._profile()[1] if b.time <= t_end]

    def station_torque(self, slot):
        """The wheel torque of the station that slot number `slot` (unwrapped, re-based count included) indexes."""
        return self.station_torques[int(round(float(slot))) % self.geometry.slots]

    def initial_state(self, angle: float, speed: float) -> InitialState:
        g = self.geometry
        k = float(np.floor((angle + np.pi) / (2 * np.pi)))
        alpha = angle - 2 * np.pi * k
        a0 = g.engagement_half_angle
        if -a0 <= alpha < a0:
            beta, G = (float(f) for f in g.wheel_motion(g.ratio, alpha)[:2])
            w2 = G * speed
            u = (speed * g.pin_in_slot(g.crank_radius, g.centre_distance, alpha, beta)[2]
                 + g.pin_radius * (w2 - g.crank_sense * speed))
            slide = 1.0 if u >= 0 else -1.0
            return InitialState("engaged", {"slot": k, "flank": 1.0, "slide": slide, **self._station(k)},
                                np.array([angle, k * g.pitch + beta]), np.array([speed, w2]))
        if alpha >= a0:   # past this slot's exit: wheel locked after index k, next slot k + 1
            lock = (k + 0.5) * g.pitch
            return InitialState("dwell", {"slot": k + 1, "lock_angle": lock, **self._station(k + 1)},
                                np.array([angle, lock]), np.array([speed, 0.0]))
        lock = (k - 0.5) * g.pitch
        return InitialState("dwell", {"slot": k, "lock_angle": lock, **self._station(k)}, np.array([angle, lock]),
                            np.array([speed, 0.0]))

    def _station(self, slot) -> dict:
        """{"T_L": the station's torque} for slot number `slot` with per-station torques, else {}."""
        return {} if self.station_torques is None else {"T_L": self.station_torque(slot)}

    def rebase(self, values: Mapping[str, float]):
        """Slot k in the angles (theta, psi) is slot 0 in (theta - 2 pi k, psi - k pitch) with the lock angle moved
        by k pitch; `slot_base` counts the slots re-based away (the contact's track is slot + slot_base)."""
        k = values["slot"]
        if k == 0:
            return None
        pitch = self.geometry.pitch
        return np.array([2 * np.pi * k, k * pitch]), {
            "slot": 0.0, "lock_angle": values["lock_angle"] - k * pitch, "slot_base": values["slot_base"] + k}

    # the rules that read the state and the parameters only, the same for every Geneva: built once (`transitions`)
    #: what a user changes after a stall: the scenario's own keys
    STALL_HINT = ("raise the drive's torque (drive.torque; a motor's drive.stall_torque) or lower the load on the "
                  "wheel (load.wheel_torque)")
    _STALL = TransitionRule(kind="stall", fields=lambda q, v, p: {"angle": np.degrees(q[0])}, stop=(
        "crank stalled: its speed fell to zero at crank angle {angle:.2f} deg ({mode}); the drive cannot "
        "carry the load past this point"), hint=STALL_HINT)
    _REST = TransitionRule(kind="rest", fields=lambda q, v, p: {"angle": np.degrees(q[0]), "speed": v[0]}, stop=(
        "crank stalled: it crept to rest at crank angle {angle:.4f} deg ({mode}), speed {speed:.2e} rad/s with "
        f"speed + {REST_TIME:g} s x |acceleration| below {REST_SPEED:g} rad/s; it settles where the "
        "drive's torque at zero speed balances the load"), hint=STALL_HINT)
    _EXIT = TransitionRule("dwell", lambda q, v, p, xp: {
        "slot": p["slot"] + 1, "lock_angle": (p["slot"] + 0.5) * p["pitch"]}, kind="exit")
    _SLIP_REVERSAL = TransitionRule("engaged", lambda q, v, p, xp: {"slide": -p["slide"]}, kind="slip reversal")

    def transitions(self) -> dict[tuple[str, str], TransitionRule | tuple[TransitionRule, ...]]:
        """Entry (flank 1, friction along the slip the pin meets), exit (next slot, the wheel locked half a pitch
        on), flank switch (friction re-chosen from the new flank's slip) and slip reversal; stall and rest are
        stops, and so is a slip reversal at a crank coming to rest (`_crank_stopped`)."""
        entry = TransitionRule("engaged", self._entry, kind="entry")
        if self.station_torques is not None:
            # the station's torque is a number of this scenario, not a parameter: a numeric rule (numpy only)
            entry = replace(entry, numeric=True, updates=lambda q, v, p, xp: {
                **self._entry(q, v, p, xp), "T_L": self.station_torque(p["slot"] + p["slot_base"])})
        table = {
            ("dwell", "entry"): entry,
            ("engaged", "exit"): self._EXIT,
            ("engaged", "flank_switch"): TransitionRule(
                "engaged", self._flank_switch, kind="flank switch", fields=lambda q, v, p: {
                    "angle": np.degrees(q[0] - 2 * np.pi * p["slot"]),
                    "side": "driving" if p["flank"] < 0 else "trailing"}, message=(
                    "normal force changed sign at crank angle {angle:.2f} deg (local): the pin crossed to the "
                    "{side} flank (with slot clearance this is a backlash impact)")),
            ("engaged", "slip_reversal"): (
                replace(self._STALL, when=self._crank_stopped), self._SLIP_REVERSAL),
        }
        for mode in ("engaged", "dwell"):
            table[(mode, "stall")] = self._STALL
            table[(mode, "rest")] = self._REST
        return table

    # the rules' state functions, (q, v, p, xp) for numpy and jax.numpy alike (`TransitionRule`): the geometry
    # gives the structure (its pin-in-slot formulas and crank_sense), p the numbers, so the internal Geneva's
    # transitions are its own
    def _entry(self, q, v, p, xp):
        """Flank 1; friction along the slip the pin meets. The wheel is at rest, so the slip is theta' (s -
        crank_sense R) with the pin's sliding speed per unit crank speed s at the wheel angle beta the pin meets
        (`GenevaGeometry.wheel_angle`, `slot_sliding`; docs/theory.md §G1 'Pin spin')."""
        g = self.geometry
        alpha = _local(q, p)[0]
        beta = g.wheel_angle(p["r"] / p["c"], alpha, xp)
        u = v[0] * (g.slot_sliding(p["r"], alpha, beta, xp) - g.crank_sense * p["R"])
        return {"flank": 1.0, "slide": xp.where(u >= 0, 1.0, -1.0)}

    def _flank_switch(self, q, v, p, xp):
        """The other flank. The slip u = v_s + flank R (w2 - crank_sense w1) changes with the flank (the pin's spin
        term changes sign), so the friction direction is re-chosen from it (kept where u = 0): keeping the old one
        can leave friction pointing along the slip, and the slip-reversal guard (falling only) would never fire
        from there."""
        g = self.geometry
        alpha, beta = _local(q, p)
        new = -p["flank"]
        u = (v[0] * g.slot_sliding(p["r"], alpha, beta, xp)
             + new * p["R"] * (v[1] - g.crank_sense * v[0]))
        return {"flank": new, "slide": xp.where(u == 0, p["slide"], xp.sign(u))}

    def _crank_stopped(self, q, v, p, xp):
        """> 0 where an engaged slip reversal is the crank coming to rest, not the slip changing sign.

        Engaged, the slip is u = theta' s(alpha) with s = s_slide + flank R (G(alpha) - crank_sense), s_slide =
        v_s / theta' (`GenevaGeometry.pin_in_slot`; r sin(alpha + beta) + flank R (1 + G) for the external drive;
        the wheel follows w2 = G theta', `wheel_motion`, docs/theory.md §G1-2), so u = 0 either where the
        kinematic factor s vanishes (a slip reversal, at a fixed crank angle) or where theta' does (a stall). The
        two roots coincide exactly, and the integrator may locate either first; the guard's position decides: s
        away from zero (more than 1e-3 (r + R); at a true reversal |s| is the position error of the root) with the
        crank's speed itself at rest level (below STOPPED_SPEED) means the crank stopped. A stall must win: after
        a slip reversal at rest the model that runs on (the crank turning backwards against a forward friction)
        no longer holds. The speed test matters at loose tolerances, where the root's position error exceeds
        1e-3 (r + R) (docs/stability.md). Both margins positive: their minimum.
        """
        g = self.geometry
        alpha, beta = _local(q, p)
        G = g.speed_ratio(p["r"] / p["c"], alpha, xp)
        s = g.slot_sliding(p["r"], alpha, beta, xp) + p["flank"] * p["R"] * (G - g.crank_sense)
        return xp.minimum(xp.abs(s) - 1e-3 * (p["r"] + p["R"]), self.STOPPED_SPEED - xp.abs(v[0]))

    def reference_solution(self, drive, t_eval, angle0, speed0, rtol=1e-12):
        """Crank angle from the reduced-coordinate equation (`geneva_reduced`, docs/theory.md §G2) on DOP853;
        torque and motor drives only."""
        if drive.is_prescribed or self.varying_load or getattr(drive, "has_duty", False):
            return None
        import mechsim.mechanisms.geneva.reduced as geneva_reduced
        dv = drive.parameter_values(angle0)
        return geneva_reduced.integrate(self, dv["drive_T0"], dv["drive_slope"], angle0, speed0,
                                        np.asarray(t_eval, float), rtol=rtol, atol=rtol)[0]

    # -- the pin-slot contact, for the thermal model (mechanisms/geneva/contact.py) ----------------------------
    def contact_geometry(self):
        return geneva_contact.geometry(self.geometry)

    def contact_state(self, table) -> dict[str, np.ndarray]:
        return geneva_contact.state(self.geometry, table)

    def contact_starts(self, table, events) -> np.ndarray:
        return geneva_contact.starts(self.geometry, table, events)

    def drive_cycle(self) -> DriveCycle:
        """A crank turn from mid-dwell (0 = mid-engagement, docs/theory.md §G1)."""
        return DriveCycle("crank_angle_rad", 2 * np.pi, -np.pi,
                          "crank angle within its turn (deg; 0 = mid-engagement)")

    def describe(self) -> dict:
        g = self.geometry
        return {
            "centre_distance_m": g.centre_distance,
            "min_pin_distance_m": g.min_pin_distance,
            "entry_pin_distance_m": g.entry_pin_distance,
            "engagement_half_angle_rad": g.engagement_half_angle,
            "dwell_fraction": g.dwell_fraction,
        }

    # -- prescribed constant crank speed: no DAE needed ------------------------------------------------
    def _closed_form_contact(self, t: np.ndarray, angle0: float, speed: float) -> tuple:
        """The closed form up to the contact (docs/theory.md §G1-2): (theta, kin, alpha, eng, beta, w2, x, s_slide,
        v_s, sigma, N, u, flank), N, u and flank zero out of contact; s_slide = v_s / theta' (`pin_in_slot`). `closed_form` goes on from here; the switch
        search (`closed_form_contact`) stops here."""
        g = self.geometry
        theta = angle0 + speed * (t - t[0])
        kin = gk.constant_speed_motion(g, theta, speed)
        alpha, eng = kin["alpha"], kin["engaged"]
        beta = kin["wheel_angle"] - np.floor((theta + np.pi) / (2 * np.pi)) * g.pitch
        w2, a2 = kin["wheel_speed"], kin["wheel_accel"]
        mu, R, r = self.friction, g.pin_radius, g.crank_radius
        x = kin["pin_distance"]
        s_slide = g.slot_sliding(r, alpha, beta)
        v_s = np.where(eng, speed * s_slide, 0.0)
        wheel_moment = self.wheel_inertia * a2 + self.wheel_damping * w2 + self.wheel_torque

        def balance(flank, v_s, w2, wheel_moment, x):
            u = v_s + flank * R * (w2 - g.crank_sense * speed)
            sigma = np.where(u >= 0, 1.0, -1.0)
            return u, sigma, wheel_moment / (x - mu * sigma * R)

        flank = np.ones_like(theta)
        u, sigma, N = balance(1.0, v_s, w2, wheel_moment, x)
        swap = eng & (N < 0)
        if swap.any():                               # the other flank, where it carries the load (elementwise)
            flank[swap] = -1.0
            u[swap], sigma[swap], N[swap] = balance(-1.0, v_s[swap], w2[swap], wheel_moment[swap], x[swap])
        N, u = np.where(eng, N, 0.0), np.where(eng, u, 0.0)
        flank = np.where(eng, flank, 0.0)
        return theta, kin, alpha, eng, beta, w2, x, s_slide, v_s, sigma, N, u, flank

    def closed_form_contact(self, t: np.ndarray, angle0: float, speed: float) -> dict[str, np.ndarray]:
        """What the thermal switch search reads of the closed form (thermal/exact.py `contact_code`): engaged,
        slip and normal force, the same numbers as `closed_form`'s columns without computing the others."""
        _, _, _, eng, _, _, _, _, _, _, N, u, _ = self._closed_form_contact(t, angle0, speed)
        return {"engaged": eng, "slip_speed_m_s": u, "contact_force_N": N}

    def closed_form_heat(self, t: np.ndarray, angle0: float, speed: float) -> dict[str, np.ndarray]:
        """The columns `contact_state` reads (contact.py `state`; a boolean `engaged` in place of `mode`), the
        same numbers as `closed_form`'s without computing the others: the closed-form thermal path's heat input
        at its quadrature nodes (thermal/exact.py)."""
        _, _, _, _, _, _, _, _, _, sigma, N, u, _ = parts = self._closed_form_contact(t, angle0, speed)
        theta, kin, eng, w2, x, v_s = parts[0], parts[1], parts[3], parts[5], parts[6], parts[8]
        fric = self.friction * np.abs(N) * sigma
        return {"engaged": eng, "crank_angle_rad": theta, "crank_speed_rad_s": np.full_like(theta, speed),
                "crank_accel_rad_s2": np.zeros_like(theta), "wheel_speed_rad_s": w2, "contact_force_N": N,
                "slip_speed_m_s": u, "pin_sliding_speed_m_s": v_s, "pin_distance_m": x, "friction_power_W": fric * u}

    def closed_form(self, t: np.ndarray, angle0: float, speed: float) -> dict[str, np.ndarray]:
        """Columns at constant crank speed from the closed forms of docs/theory.md §G1-2 (no integration); None
        with a time-varying wheel torque (the DAE then runs with the speed as a constraint).

        Normal force from the wheel's moment balance N (x - sigma mu R) = J2 beta'' + c2 beta' + T_L
        (docs/theory.md §G2, with the flank chosen by the sign of N); drive torque from the crank's balance
        T_in = c1 w1 + N a + mu |N| sigma du/dw1 with the normal force's arm a and du/dw1 = s_slide - crank_sense
        flank R (`GenevaGeometry.pin_in_slot`; a = r cos(alpha + beta), s_slide = r sin(alpha + beta) external).
        """
        if self.varying_load:
            return None
        g = self.geometry
        theta, kin, alpha, eng, beta, w2, x, s_slide, v_s, sigma, N, u, flank = self._closed_form_contact(
            t, angle0, speed)
        a2 = kin["wheel_accel"]
        mu, R, r = self.friction, g.pin_radius, g.crank_radius
        fric = mu * np.abs(N) * sigma
        arm = g.slot_arm(r, alpha, beta)
        torque = (self.crank_damping * speed + N * arm
                  + fric * (s_slide - g.crank_sense * flank * R))
        torque = np.where(eng, torque, self.crank_damping * speed)
        return {
            "mode": MODE_NAMES[eng.astype(np.intp)],
            "crank_angle_rad": theta, "crank_speed_rad_s": np.full_like(theta, speed),
            "crank_accel_rad_s2": np.zeros_like(theta),
            "wheel_angle_rad": kin["wheel_angle"], "wheel_speed_rad_s": w2, "wheel_accel_rad_s2": a2,
            "contact_force_N": N, "friction_force_N": fric, "slip_speed_m_s": u,
            "pin_sliding_speed_m_s": v_s, "pin_distance_m": x, "friction_power_W": fric * u,
            "flank": flank, "lock_force_N": np.zeros_like(theta), "drive_torque_N_m": torque,
            "kinetic_energy_J": 0.5 * (self.crank_inertia * speed**2 + self.wheel_inertia * w2**2),
            "constraint_residual_m": np.zeros_like(theta),
            "powers": {"drive": torque * speed, "load": -self.wheel_torque * w2 * eng,
                       "friction": -fric * u, "damping": -self.crank_damping * speed**2 - self.wheel_damping * w2**2},
        }

    def closed_form_events(self, t: np.ndarray, angle0: float, speed: float) -> list[dict]:
        """Events-table rows of a constant-speed run at their exact times: the pin enters slot k at crank angle
        2 pi k - alpha0 (the dwell ends) and leaves it at 2 pi k + alpha0 (the next dwell starts), alpha0 =
        pi/2 - pi/n (docs/theory.md §G1). Entry and exit are tangential, so no kinetic energy is lost.
        Only crossings after the first instant and up to the last are listed (as the DAE reports them)."""
        t = np.asarray(t, float)
        if len(t) < 2 or speed <= 0:
            return []
        g = self.geometry
        t0 = float(t[0])
        a0, lo, hi = g.engagement_half_angle, angle0, angle0 + speed * (float(t[-1]) - t0)
        ke = 0.5 * self.crank_inertia * speed**2
        rows = []
        for k in range(int(np.floor((lo - a0) / (2 * np.pi))), int(np.ceil((hi + a0) / (2 * np.pi))) + 1):
            for kind, angle, before, after, lock in (("entry", 2 * np.pi * k - a0, "dwell", "engaged", k - 0.5),
                                                      ("exit", 2 * np.pi * k + a0, "engaged", "dwell", k + 0.5)):
                if lo < angle <= hi:
                    rows.append(dict(t_s=t0 + (angle - lo) / speed, from_mode=before, to_mode=after, kind=kind,
                                     guard="closed form", crank_q=angle, wheel_q=lock * g.pitch,
                                     kinetic_energy_before_J=ke, kinetic_energy_after_J=ke, message="",
                                     energy_lost_J=0.0))
        return sorted(rows, key=lambda row: row["t_s"])


# -- the transitions' local angles, (q, p) for numpy and jax.numpy alike (`TransitionRule`) ------------------
def _local(q, p):
    """The local crank and wheel angles (alpha, beta) of the current slot."""
    return q[0] - 2 * np.pi * p["slot"], q[1] - p["slot"] * p["pitch"]
