"""The internal Geneva's `ParameterMap` (mechanisms/parameter_map.py), for the design sensitivities and the sizing:
the external Geneva's (mechanisms/geneva/sensitivity.py: the same scenario keys and model parameters, c = r/sin(pi/n))
with the internal drive's start, contact geometry and contact state (docs/internal_geneva.md)."""
from __future__ import annotations

from dataclasses import replace

import numpy as np

from mechsim.mechanisms.geneva.sensitivity import MAP as EXTERNAL


def initial_angle(mech, angle: float, speed: float) -> tuple[np.ndarray, np.ndarray]:
    """d(q0, v0)/d(crank angle) of `Geneva.initial_state` with the internal geometry: in a dwell (dq, dv) = ((1, 0),
    0); engaged, the wheel angle is beta(alpha) and its speed G(alpha) w, so dq = (1, G), dv = (0, w G')
    (`InternalGenevaGeometry.wheel_motion`)."""
    g = mech.geometry
    alpha = angle - 2 * np.pi * np.floor((angle + np.pi) / (2 * np.pi))
    if -g.engagement_half_angle <= alpha < g.engagement_half_angle:
        _, G, Gp, _ = g.wheel_motion(g.ratio, alpha)
        return np.array([1.0, float(G)]), np.array([0.0, speed * float(Gp)])
    return np.array([1.0, 0.0]), np.array([0.0, 0.0])


def contact_geometry(x: dict, si: dict) -> dict:
    """mechanisms/geneva/contact.py `geometry` of the internal drive as formulas: the wall track from the entry
    distance c cos(pi/n) out to c + r, the wheel about a disc of radius c + r, one contact lasting
    2 alpha0 = 2 (pi/2 + pi/n) of crank angle (c = r / sin(pi/n), docs/internal_geneva.md)."""
    import jax.numpy as jnp
    n = si["mechanism"]["slots"]
    r = x["mechanism.crank_radius"]
    c = r / jnp.sin(jnp.pi / n)
    return {"contact_radius": x["mechanism.pin_radius"], "contact_length": x["mechanism.thickness"],
            "driver_arm": r, "tracks": n, "track_length": c + r - c * jnp.cos(jnp.pi / n),
            "driven_radius": c + r, "contact_angle": 2 * (jnp.pi / 2 + jnp.pi / n)}


def contact_row(columns, R, xp=np) -> dict:
    """mechanisms/geneva/contact.py `state` of the internal drive with the pin radius R traced: the wheel turns
    against the pin at w2 - w1, so the source speed over the pin is R (w2 - w1) and the wall's sliding acceleration
    a_s = (w1' v_s + w1 (w2 - w1) w2 x)/w1 (docs/internal_geneva.md, 'Slip')."""
    w1, w2, a1, v_s, x, N, slip = columns
    return {"normal_force": N, "slip_speed": slip, "source_speed_driver": R * (w2 - w1),
            "source_speed_driven": v_s, "sliding_accel": (a1 * v_s + w1 * (w2 - w1) * w2 * x) / w1}


MAP = replace(EXTERNAL, initial_angle=initial_angle, contact_geometry=contact_geometry, contact_row=contact_row)
