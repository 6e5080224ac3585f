"""The Geneva's parameters, start and contact as traced formulas of its scenario values, for the design
sensitivities (docs/sensitivity.md, "Values traced", "Temperatures"): its `ParameterMap`, checked against the
mechanism by scenarios/studies/sensitivity_map.py."""
from __future__ import annotations

from dataclasses import replace

import numpy as np

from mechsim.mechanisms.parameter_map import ParameterMap


def geneva_parameters(x: dict, si: dict, mech) -> dict:
    """Geneva: c = r / sin(pi/n) (tangential entry, docs/theory.md §G1); the others enter as they are."""
    import jax.numpy as jnp
    n = si["mechanism"]["slots"]
    r = x["mechanism.crank_radius"]
    return {"r": r, "c": r / jnp.sin(jnp.pi / n), "R": x["mechanism.pin_radius"],
            "J1": x["mechanism.crank_inertia"], "J2": x["mechanism.wheel_inertia"], "T_L": x["load.wheel_torque"],
            "mu": x["contact.friction"], "c1": x["mechanism.crank_damping"], "c2": x["mechanism.wheel_damping"]}


def geneva_initial_angle(mech, angle: float, speed: float) -> tuple[np.ndarray, np.ndarray]:
    """d(q0, v0)/d(crank angle) of `Geneva.initial_state`: in a dwell the wheel stays at its lock angle (dq = (1, 0),
    dv = 0); engaged, the wheel angle is beta(alpha) and its speed G(alpha) w, so dq = (1, G) and dv = (0, w G')
    (G = d beta / d alpha, the speed ratio, docs/theory.md §G1)."""
    from mechsim.mechanisms.geneva.kinematics import speed_ratio, speed_ratio_derivative
    g = mech.geometry
    alpha = angle - 2 * np.pi * np.floor((angle + np.pi) / (2 * np.pi))
    if -g.engagement_half_angle <= alpha < g.engagement_half_angle:
        return (np.array([1.0, float(speed_ratio(g.ratio, alpha))]),
                np.array([0.0, speed * float(speed_ratio_derivative(g.ratio, alpha))]))
    return np.array([1.0, 0.0]), np.array([0.0, 0.0])


def geneva_contact_geometry(x: dict, si: dict) -> dict:
    """mechanisms/geneva/contact.py `geometry` as formulas: pin radius R and thickness l make the line contact, the
    crank radius r is the pin's arm, the n slot walls are the tracks, each swept from the entry pin distance
    c cos(pi/n) to the nearest approach c - r (c = r / sin(pi/n)), the wheel is about a disc of radius c cos(pi/n),
    and one contact lasts 2 alpha0 = 2 (pi/2 - pi/n) of crank angle (docs/theory.md §G1)."""
    import jax.numpy as jnp
    n = si["mechanism"]["slots"]
    r = x["mechanism.crank_radius"]
    c = r / jnp.sin(jnp.pi / n)
    return {"contact_radius": x["mechanism.pin_radius"], "contact_length": x["mechanism.thickness"],
            "driver_arm": r, "tracks": n, "track_length": c * jnp.cos(jnp.pi / n) - (c - r),
            "driven_radius": c * jnp.cos(jnp.pi / n), "contact_angle": 2 * (jnp.pi / 2 - jnp.pi / n)}


def geneva_contact_row(columns, R, xp=np) -> dict:
    """mechanisms/geneva/contact.py `state` with the pin radius R traced: source speeds R (w1 + w2) over the pin and
    v_s over the wall, a_s = (w1' v_s + w1 (w1 + w2) w2 x)/w1 (docs/theory.md §G1, §G4.6)."""
    w1, w2, a1, v_s, x, N, slip = columns
    return {"normal_force": N, "slip_speed": slip, "source_speed_driver": R * (w1 + w2),
            "source_speed_driven": v_s, "sliding_accel": (a1 * v_s + w1 * (w1 + w2) * w2 * x) / w1}


MAP = ParameterMap(
    keys=("mechanism.crank_radius", "mechanism.pin_radius", "mechanism.thickness", "mechanism.crank_inertia",
          "mechanism.wheel_inertia", "mechanism.crank_damping", "mechanism.wheel_damping", "load.wheel_torque",
          "contact.friction"),
    parameters=geneva_parameters, speed_key="initial.crank_speed", initial_angle=geneva_initial_angle,
    discrete=frozenset({"slot", "lock_angle", "flank", "slide", "slot_base"}), engage="entry", release="exit",
    sliding=True,
    peaks=("peak_contact_force_N", "peak_drive_torque_N_m", "peak_wheel_accel_rad_s2", "peak_wheel_speed_rad_s"),
    contact_geometry=geneva_contact_geometry,
    contact_columns=("crank_speed_rad_s", "wheel_speed_rad_s", "crank_accel_rad_s2", "pin_sliding_speed_m_s",
                     "pin_distance_m", "contact_force_N", "slip_speed_m_s"),
    contact_row=geneva_contact_row, contact_starts=("entry", "flank switch"))


def clearance_parameters(x: dict, si: dict, mech) -> dict:
    """The Geneva with slot clearance (clearance.py): the exact-fit model's parameters, the clearance c_s and the
    restitution e entering as they are."""
    return dict(geneva_parameters(x, si, mech), clearance=x["mechanism.slot_clearance"],
                restitution=x["contact.restitution"])


#: the Geneva with slot clearance: its impacts' law is differentiated too (dynamics/sensitivity.py), and the peak
#: impulse of its impacts is a quantity (docs/sensitivity.md, "Impacts")
CLEARANCE_MAP = replace(MAP, keys=MAP.keys + ("mechanism.slot_clearance", "contact.restitution"),
                        parameters=clearance_parameters, peaks=MAP.peaks + ("peak_impulse_N_s",),
                        discrete=MAP.discrete | {"lock_end"})
