"""Each mechanism's parameters, start and refusals as traced formulas of its scenario values, for the design
sensitivities (docs/sensitivity.md, "Values traced" and "Geometry of the chain and the rolling pair"): the Geneva's,
the chain dwell mechanism's (its path pieces included) and the rolling pair's, each checked against the mechanism by
`sensitivity_map.py`."""
from __future__ import annotations

import numpy as np

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


def chain_list_keys(si: dict) -> tuple[str, ...]:
    """The chain's list entries: sprocket centres and radii, the pivot, the sprocket inertias where set."""
    m = si["mechanism"]
    n = len(m["sprockets"])
    keys = [f"mechanism.sprockets[{i}][{c}]" for i in range(n) for c in (0, 1)]
    keys += [f"mechanism.sprocket_radii[{i}]" for i in range(n)] + ["mechanism.pivot[0]", "mechanism.pivot[1]"]
    if m.get("sprocket_inertias") is not None:
        keys += [f"mechanism.sprocket_inertias[{i}]" for i in range(n)]
    return tuple(keys)


def chain_geometry(x: dict, si: dict) -> tuple:
    """(centres, radii, Q, R, L, loop) of the chain as jax values of x: L = coupler + detuning
    (ChainDwellParams.detuned), the loop's pieces by the path's own formulas (mechanisms/chain/path.py
    `loop_geometry`, docs/theory.md §K1.1)."""
    from mechsim.mechanisms.chain.path import jax_math, loop_geometry
    n = len(si["mechanism"]["sprockets"])
    centres = [(x[f"mechanism.sprockets[{i}][0]"], x[f"mechanism.sprockets[{i}][1]"]) for i in range(n)]
    radii = [x[f"mechanism.sprocket_radii[{i}]"] for i in range(n)]
    Q = (x["mechanism.pivot[0]"], x["mechanism.pivot[1]"])
    L = x["mechanism.coupler_length"] + x["mechanism.detuning"]
    return centres, radii, Q, x["mechanism.crank_radius"], L, loop_geometry(centres, radii, jax_math())


def chain_parameters(x: dict, si: dict, mech) -> dict:
    """Chain dwell mechanism (mechanisms/chain/model.py): the geometry (pivot Q, crank R, coupler L, driving radius
    r1, the coupler's centre c3 = L/2), the drive's inertia reduced to the driving sprocket,
    J1 = m_chain r1^2 + sum_i J_i (r1 / r_i)^2, the crank a uniform rod J_Q = m R^2 / 3 and the coupler one of length
    L, J_3 = m L^2 / 12, unless their inertias are given; and the first piece's path values (`chain_piece`)."""
    import jax.numpy as jnp
    m = si["mechanism"]
    centres, radii, Q, R, L, _ = chain_geometry(x, si)
    r1 = radii[0]
    n = len(radii)
    inertias = ([x[f"mechanism.sprocket_inertias[{i}]"] for i in range(n)] if m["sprocket_inertias"] is not None
                else [0.0] * n)
    sprockets = sum(inertias[i] * (r1 / radii[i]) ** 2 for i in range(n))
    jq = x["mechanism.crank_mass"] * R**2 / 3 if m["crank_inertia"] is None else x["mechanism.crank_inertia"]
    j3 = x["mechanism.coupler_mass"] * L**2 / 12 if m["coupler_inertia"] is None else x["mechanism.coupler_inertia"]
    out = {"Qx": Q[0], "Qy": Q[1], "R": R, "L": L, "r1": r1, "c3": L / 2,
           "J1": x["mechanism.chain_mass"] * r1**2 + sprockets, "JQ": jq, "m3": x["mechanism.coupler_mass"],
           "J3": j3, "T_L": x["load.crank_torque"], "c1": x["mechanism.drive_damping"],
           "c2": x["mechanism.crank_damping"]}
    out.update(chain_piece(x, si, mech, mech.parameter_values()))
    return {k: jnp.asarray(v, jnp.float64) for k, v in out.items()}


def chain_piece(x: dict, si: dict, mech, values: dict) -> dict:
    """The path values a transition sets for the piece `values` describes (ChainDwell._piece_values): its travel
    range s0, s1 (the loop's s0 plus whole cycles of its length), a line's start P and direction t, an arc's centre
    O, radius and start angle psi0, on a tuned arc the stop angle alpha = arg(O - Q) and the apex travel (where the
    dyad is stretched: psi - arg(O - Q) = 0 mod 2 pi, `ArcPiece.apex_travel`), else s_apex = s1 + length (also once
    the apex is behind). The piece (an int), its cycle and whether the apex is behind are read from the numbers
    (discrete; they may be jax values, so that one compiled function serves every cycle of a piece)."""
    import jax
    import jax.numpy as jnp
    centres, radii, Q, _, _, geo = chain_geometry(x, si)
    n, path = len(radii), mech.path
    k = int(values["seg"])
    Lc = path.length
    cycle = jnp.round((values["s0"] - path.pieces[k].s0) / Lc)
    length = geo["s0"][-1]
    base = cycle * length
    out = {"s0": base + geo["s0"][k], "s1": base + geo["s0"][k + 1]}
    out["s_apex"] = out["s1"] + length
    i = k // 2
    if k % 2 == 0:
        out.update(Px=geo["starts"][i][0], Py=geo["starts"][i][1], tx=geo["directions"][i][0],
                   ty=geo["directions"][i][1])
        return out
    j = (i + 1) % n
    O, r, psi0 = centres[j], radii[j], geo["psi0"][j]
    out.update(Ox=O[0], Oy=O[1], rr=r, psi0=psi0)
    if j not in mech.tuned:
        return out
    alpha = jnp.arctan2(O[1] - Q[1], O[0] - Q[0])
    out["alpha"] = alpha
    d = psi0 - alpha
    dpsi0 = d - 2 * jnp.pi * jnp.round(d / (2 * jnp.pi))
    sg = jax.lax.stop_gradient
    turns = jnp.round(((values["s_apex"] - sg(out["s0"])) / sg(r) + sg(dpsi0)) / (2 * jnp.pi))
    behind = jnp.abs(values["s_apex"] - (values["s1"] + Lc)) <= 1e-9 * Lc
    out["s_apex"] = jnp.where(behind, out["s_apex"], out["s0"] + r * (2 * jnp.pi * turns - dpsi0))
    return out


def chain_pieces(mech) -> list[dict]:
    """Every piece's values (two cycles, and each tuned arc with its apex ahead and behind)."""
    out = []
    Lc = mech.path.length
    for cycle in (0, 1):
        for k in range(len(mech.path.pieces)):
            vals = mech._piece_values(k, cycle)
            out.append(vals)
            if "alpha" in vals:
                out.append({**vals, "s_apex": vals["s1"] + Lc})
    return out


def chain_refuse(plan, key: str) -> str | None:
    """A tuned sprocket (|QO_i| = R, r_i = L, paper eq. 35) makes the exact dwell and its stop: moving R, L, Q or
    that sprocket alone detunes it, the dwells and impacts disappear and the run changes its whole mode sequence, so
    the derivative does not exist there. The detuning exists only with apex = 'detuned'."""
    mech = plan.mechanism
    if key == "mechanism.detuning" and mech.apex != "detuned":
        return "the detuning exists only with apex = 'detuned' (it must be 0 here)"
    tuned = sorted(mech.tuned)
    if not tuned:
        return None
    touches = {"mechanism.crank_radius", "mechanism.coupler_length", "mechanism.pivot[0]", "mechanism.pivot[1]"}
    for i in tuned:
        touches |= {f"mechanism.sprockets[{i}][0]", f"mechanism.sprockets[{i}][1]", f"mechanism.sprocket_radii[{i}]"}
    if key in touches:
        return (f"sprocket(s) {', '.join(str(i + 1) for i in tuned)} are tuned for an exact dwell (|QO_i| = R, "
                "r_i = L, docs/theory.md §K1.2): this value alone detunes them, the dwells and stops disappear and "
                "the run changes its mode sequence, so the derivative does not exist; trace the other sprockets' "
                "geometry, or a detuned design (apex = 'detuned')")
    return None


def rolling_list_keys(si: dict) -> tuple[str, ...]:
    """The rolling pair's points: the crank's pivot, and the fixed circle's centre or the line's point."""
    point = "profile_centre" if si["mechanism"].get("profile", "circle") == "circle" else "line_point"
    return (f"mechanism.{point}[0]", f"mechanism.{point}[1]", "mechanism.crank_pivot[0]", "mechanism.crank_pivot[1]")


#: the rolling pair's geometry: scenario key -> model parameter (mechanisms/rolling/model.py `parameter_values`)
ROLLING_GEOMETRY = {"mechanism.disc_radius": "r", "mechanism.crank_length": "l2", "mechanism.coupler_length": "l3",
                     "mechanism.arm_length": "l4", "mechanism.arm_angle": "psi", "mechanism.crank_pivot[0]": "A0x",
                     "mechanism.crank_pivot[1]": "A0y", "mechanism.coupler_point_distance": "lc",
                     "mechanism.coupler_point_angle": "alpha"}
ROLLING_CIRCLE = {"mechanism.fixed_radius": "R", "mechanism.profile_centre[0]": "Ox",
                   "mechanism.profile_centre[1]": "Oy", "mechanism.contact_angle": "gamma0"}
ROLLING_LINE = {"mechanism.line_point[0]": "Px", "mechanism.line_point[1]": "Py", "mechanism.line_angle": "tangent"}


def rolling_parameters(x: dict, si: dict, mech) -> dict:
    """Rolling-pair four-bar (mechanisms/rolling/model.py `Bodies.uniform`, `from_config`): the geometry enters the
    model as itself (the profile's R, O, gamma0 or line point and angle, the disc's r, the links l2, l3, l4, the arm's
    angle, the pivot A0, the coupler point); slender crank and coupler rods (centre at mid-length, I = m l^2 / 12),
    the rolling link a uniform disc (m r^2 / 2 about B0) welded to a slender arm (m l4^2 / 3 about B0), moved to the
    joint centre of mass c4 = m_arm l4 / 2 / m4 (docs/theory.md §K3), unless the scenario gives the inertias and
    centres itself (then those enter as themselves: crank_com c2, coupler_com c3, rolling_com c4; a given rolling_com
    does not move the uniform I4, which keeps the uniform c4, as `from_config` does); the centre's direction from
    the arm, rolling_com_angle, is d4."""
    m = si["mechanism"]
    circle = m.get("profile", "circle") == "circle"
    geometry = {**ROLLING_GEOMETRY, **(ROLLING_CIRCLE if circle else ROLLING_LINE)}
    out = {name: x[key] for key, name in geometry.items()}
    l2, l3, l4, r = out["l2"], out["l3"], out["l4"], out["r"]
    m2, m3 = x["mechanism.crank_mass"], x["mechanism.coupler_mass"]
    disc, arm = x["mechanism.disc_mass"], x["mechanism.arm_mass"]
    m4 = disc + arm
    uniform_c4 = arm * l4 / 2 / m4
    i4 = (disc * r**2 / 2 + arm * l4**2 / 3 - m4 * uniform_c4**2) if m["rolling_inertia"] is None else (
        x["mechanism.rolling_inertia"])
    out.update({"m2": m2, "I2": m2 * l2**2 / 12 if m["crank_inertia"] is None else x["mechanism.crank_inertia"],
                "m3": m3, "I3": m3 * l3**2 / 12 if m["coupler_inertia"] is None else x["mechanism.coupler_inertia"],
                "m4": m4, "I4": i4, "g": x["load.gravity"], "b2": x["load.crank_damping"],
                "b4": x["load.rolling_damping"], "d4": x["mechanism.rolling_com_angle"],
                "c2": l2 / 2 if m["crank_com"] is None else x["mechanism.crank_com"],
                "c3": l3 / 2 if m["coupler_com"] is None else x["mechanism.coupler_com"],
                "c4": uniform_c4 if m["rolling_com"] is None else x["mechanism.rolling_com"]})
    return out


def rolling_refuse(plan, key: str) -> str | None:
    """The other profile's values do not enter the model; the start's assembly choice is not a continuous value."""
    if key == "mechanism.start_rolling_angle":
        return ("it only chooses which assembly a crank-driven start takes (the one whose rolling angle is nearest "
                "it): the start does not move with it (zero derivative) except where two assemblies are equally near, "
                "where it jumps to the other branch")
    circle = plan.scenario.si["mechanism"].get("profile", "circle") == "circle"
    other = ROLLING_LINE if circle else ROLLING_CIRCLE
    if key in other:
        return f"it belongs to the {'line' if circle else 'circle'} profile; this design rolls on a " \
               f"{'circle' if circle else 'line'}"
    return None
