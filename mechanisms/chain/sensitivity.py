"""The chain dwell mechanism's parameters, path pieces and refusals as traced formulas of its scenario values, for
the design sensitivities (docs/sensitivity.md, "Geometry of the chain and the rolling pair"): its `ParameterMap`,
checked against the mechanism by scenarios/studies/sensitivity_map.py."""
from __future__ import annotations

from mechsim.mechanisms.parameter_map import ParameterMap


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


MAP = ParameterMap(
    keys=("mechanism.chain_mass", "mechanism.crank_mass", "mechanism.crank_inertia", "mechanism.coupler_mass",
          "mechanism.coupler_inertia", "mechanism.drive_damping", "mechanism.crank_damping", "load.crank_torque",
          "mechanism.crank_radius", "mechanism.coupler_length", "mechanism.detuning"),
    parameters=chain_parameters, speed_key="initial.drive_speed",
    # the piece index and the dyad's branch; the pieces' geometry is traced (`chain_piece`)
    discrete=frozenset({"seg", "sigma"}),
    list_keys=chain_list_keys, piece_parameters=chain_piece, pieces=chain_pieces, refuse=chain_refuse,
    hold_drive=True,
    engage="dwell end", release="stop impact",
    peaks=("peak_drive_torque_N_m", "peak_coupler_force_N", "peak_crank_accel_rad_s2", "peak_crank_speed_rad_s"))
