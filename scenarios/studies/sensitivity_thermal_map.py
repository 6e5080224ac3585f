"""The thermal model's values as traced formulas of the scenario values, for the design sensitivities
(docs/sensitivity.md, "Temperatures"): which thermal models and keys are traced, the flash formulas' inputs and the
bulk network's parameters as jax formulas (`thermal_parameters`), the same as the run computes them
(`thermal_values`), and the check that refuses a model or option that is not traced (`check_thermal`)."""
from __future__ import annotations

import numpy as np

from mechsim.scenarios.units import ScenarioError


#: thermal models whose temperatures are traced (the bulk states and the 1-D wall-track meshes in the DAE, the
#: flash rise after it); the others are refused, with the reason
THERMAL_TRACED = ("lumped", "flash", "1d")
#: [thermal] values traced: the material (library value unless the scenario overrides it), the surroundings, and
#: the body geometry where the scenario sets it (its defaults follow from the mechanism's values: traced through them)
THERMAL_MATERIAL_KEYS = ("thermal.conductivity", "thermal.density", "thermal.specific_heat", "thermal.E",
                         "thermal.nu")
THERMAL_KEYS = THERMAL_MATERIAL_KEYS + (
    "thermal.ambient_temperature", "thermal.convection_pin", "thermal.convection_wheel",
    "thermal.pin_crank_conductance", "thermal.pin_exposed_length", "thermal.crank_volume", "thermal.crank_area",
    "thermal.wheel_radius", "thermal.wheel_thickness")


def thermal_parameters(x: dict, si: dict, setup, pmap, drive_kind: str) -> dict:
    """The thermal model's values as formulas of the scenario values, checked against the run's own
    (`thermal_values`), from the mechanism's traced contact geometry (`ParameterMap.contact_geometry`: contact
    radius R, length l, the driver's arm r, the tracks, the driven body's radius, the contact angle): the flash
    formulas' inputs `flash_*` (friction, R, l, E* = E/(2 (1 - nu^2)) of two equal bodies (docs/theory.md §G3), k,
    chi = k/(rho c_p), ambient) and, with bulk states, the DAE network's `th_*` (thermal/network.py `bulk_bodies`,
    `assemble`; docs/theory.md §G5): pin V = pi R^2 l_pin, A = 2 pi R l_pin + pi R^2 (l_pin = 2.5 l unless set),
    crank bar r x 4R x l (unless set), conductance G = k pi R^2/(l_pin/2) (unless set), wheel disc of the driven
    radius and thickness l (unless set); C = rho c_p V, K = diag(h A) + G coupling, s = h A T_amb, loss = h A; the
    share's t_ref = contact angle / (nominal speed) (thermal/network.py `nominal_speed`). With the 1-D wall-track model
    (thermal.model = "1d") also the meshes' C, K and far-face conductances and the driven body's volume less the
    meshes' (`_wall_track`, `_add_wall_network`), and the wall surface's inputs `flash_dz0`, `flash_track_area`,
    `flash_t_ref`; the network's loss K^T 1 is the column sums of K in the run's order (zero at a mesh cell)."""
    import jax.numpy as jnp
    th = si["thermal"]
    speed_key = pmap.speed_key
    geo = pmap.contact_geometry(x, si)
    r, R, l = geo["driver_arm"], geo["contact_radius"], geo["contact_length"]
    k, rho_c = x["thermal.conductivity"], x["thermal.density"] * x["thermal.specific_heat"]
    E, nu = x["thermal.E"], x["thermal.nu"]
    estar = E / (2.0 * (1.0 - nu**2))
    chi = k / rho_c
    t_amb = x["thermal.ambient_temperature"]
    out = {"flash_mu": x["contact.friction"], "flash_R": R, "flash_l": l, "flash_Estar": estar, "flash_k": k,
           "flash_chi": chi, "flash_T_amb": t_amb}
    if setup.system is None:
        return out

    def given(key, default):
        return x[f"thermal.{key}"] if th.get(key) is not None else default
    if drive_kind == "speed":
        w_nom = x["drive.speed"]
    elif abs(float(si["initial"][speed_key.split(".")[1]])) > 0:
        w_nom = jnp.abs(x[speed_key])
    elif drive_kind == "motor" and si["drive"].get("no_load_speed"):
        w_nom = x["drive.no_load_speed"]
    else:
        w_nom = 1.0
    l_pin = given("pin_exposed_length", 2.5 * l)
    width = 4.0 * R
    bodies = {"pin": (jnp.pi * R**2 * l_pin, 2 * jnp.pi * R * l_pin + jnp.pi * R**2, x["thermal.convection_pin"]),
              "crank": (given("crank_volume", r * width * l),
                        given("crank_area", 2 * r * width + 2 * (r + width) * l), x["thermal.convection_pin"])}
    radius_w = given("wheel_radius", geo["driven_radius"])
    thick_w = given("wheel_thickness", l)
    bodies["wheel"] = (jnp.pi * radius_w**2 * thick_w, 2 * jnp.pi * radius_w**2 + 2 * jnp.pi * radius_w * thick_w,
                       x["thermal.convection_wheel"])
    names = [b.name for b in setup.bodies]
    G = given("pin_crank_conductance", k * jnp.pi * R**2 / (0.5 * l_pin))
    wall = _wall_track(si, setup, geo, k, rho_c, w_nom) if setup.mesh is not None else None
    if wall is not None:                # the driven body loses the track meshes' volume (network.track_mesh)
        V, A, h = bodies["wheel"]
        bodies["wheel"] = (V - geo["tracks"] * wall["area"] * wall["depth"], A, h)
    K = {}
    for i, name in enumerate(names):
        V, A, h = bodies[name]
        out[f"th_C_{i}"] = rho_c * V
        out[f"th_s_{i}"] = h * A * t_amb
        K[(i, i)] = h * A
    if len(names) == 3:                 # pin and crank joined by G (network.assemble)
        K[(0, 0)], K[(1, 1)], K[(0, 1)], K[(1, 0)] = K[(0, 0)] + G, K[(1, 1)] + G, -G, -G
    if wall is not None:
        _add_wall_network(out, K, wall, setup)
    # loss = K^T 1, summed over the rows in order as the run does (coupling.ThermalExtension); a mesh cell's is
    # zero (its run value is round-off, held: `thermal_values` leaves it out)
    for j in range(len(names)):
        out[f"th_loss_{j}"] = sum((K[(i, jj)] for (i, jj) in sorted(K) if jj == j), 0.0)
    out.update({f"th_K_{i}_{j}": v for (i, j), v in K.items()})
    t_ref = geo["contact_angle"] / w_nom
    out.update({"th_R": R, "th_l": l, "th_Estar": estar, "th_k_pin": k, "th_k_wheel": k, "th_chi_pin": chi,
                "th_chi_wheel": chi, "th_t_ref": t_ref})
    if wall is not None:                # the wall surface's inputs for the contact temperature (sensitivity_rows)
        out.update({"flash_dz0": wall["widths"][0], "flash_track_area": wall["area"], "flash_t_ref": t_ref})
    return out


def _wall_track(si: dict, setup, geo: dict, k, rho_c, w_nom) -> dict:
    """The 1-D wall-track mesh of a track (a Geneva's slot wall) as formulas of the scenario values
    (thermal/network.py `track_mesh`, thermal/conduction1d.py `graded_mesh_cells`; docs/theory.md §G6), with the
    run's cell count and growth held (a discretisation choice, integer): faces z_i = H (g^i - 1)/(g^n - 1), the
    depth H = 3 sqrt(chi n_tracks P/pi) (P = 2 pi / nominal speed) unless the scenario sets it, so every face moves
    with chi and the nominal speed exactly as the rebuilt mesh does (its first cell only picks n); the track area
    A = l x track length (`ParameterMap.contact_geometry`)."""
    import jax.numpy as jnp
    from mechsim.thermal.network import MESH_DEPTH_PENETRATIONS
    th, n = si["thermal"], geo["tracks"]
    chi = k / rho_c
    period = 2 * jnp.pi / w_nom
    depth = (float(th["mesh_depth"]) if th.get("mesh_depth") is not None
             else MESH_DEPTH_PENETRATIONS * jnp.sqrt(chi * n * period / jnp.pi))
    cells, growth = setup.mesh.n_cells, float(setup.section["mesh_growth"])
    i = np.arange(cells + 1)
    faces = depth * i / cells if growth == 1.0 else depth * (growth**i - 1.0) / (growth**cells - 1.0)
    return {"depth": depth, "widths": jnp.diff(faces), "centres": 0.5 * (faces[1:] + faces[:-1]),
            "area": geo["contact_length"] * geo["track_length"], "k": k, "rho_c": rho_c}


def _add_wall_network(out: dict, K: dict, wall: dict, setup) -> None:
    """One mesh per track (thermal/conduction1d.py `conduction_system` with h = 0 and the far face fixed, per
    unit area, times the track area; thermal/network.py `assemble`): C_i = rho c_p dz_i A, neighbours joined by
    k A/(z_{i+1} - z_i), the far face by g_far = 2 k A/dz_n to the driven body's bulk node (the last body)."""
    import jax.numpy as jnp
    k, A, dz = wall["k"], wall["area"], wall["widths"]
    g_int = k / jnp.diff(wall["centres"])
    g_far = 2.0 * k / dz[-1]
    cells = dz.shape[0]
    diag = [0.0] * cells
    for i in range(cells - 1):
        diag[i] = diag[i] + g_int[i]
        diag[i + 1] = diag[i + 1] + g_int[i]
    diag[-1] = diag[-1] + g_far
    cap = wall["rho_c"] * dz
    iw = len(setup.bodies) - 1
    for idx in setup.mesh_states.values():
        for m, state in enumerate(idx):
            out[f"th_C_{state}"] = cap[m] * A
            K[(state, state)] = diag[m] * A
            if m + 1 < cells:
                K[(state, idx[m + 1])] = -g_int[m] * A
                K[(idx[m + 1], state)] = -g_int[m] * A
        K[(idx[-1], iw)] = -(g_far * A)
        K[(iw, idx[-1])] = -(g_far * A)
        K[(iw, iw)] = K[(iw, iw)] + g_far * A


def thermal_values(si: dict, mech) -> dict:
    """The thermal model's values as the run computes them (thermal/network.py `prepare`): the DAE extension's
    parameters and the flash formulas' inputs (names as `thermal_parameters`)."""
    from mechsim.thermal.hertz import effective_modulus
    from mechsim.thermal.models import MODELS
    from mechsim.thermal.network import prepare
    setup = prepare(si, mech, MODELS[si["thermal"]["model"]])
    mat, geo = setup.material, setup.geometry
    out = {"flash_mu": float(si["contact"]["friction"]), "flash_R": geo.contact_radius,
           "flash_l": geo.contact_length, "flash_Estar": effective_modulus(mat), "flash_k": mat.conductivity,
           "flash_chi": mat.diffusivity, "flash_T_amb": setup.temp_ambient}
    if setup.extension is not None:
        n_bulk = len(setup.bodies)
        out.update({k: v for k, v in setup.extension.parameter_values().items() if not k.startswith("th_B_")
                    and k != "th_b0" and not (k.startswith("th_loss_") and int(k[8:]) >= n_bulk)})
    if setup.mesh is not None:
        out.update({"flash_dz0": float(setup.mesh.widths[0]), "flash_track_area": setup.track_area,
                    "flash_t_ref": setup.extension.share.t_ref})
    return out


def check_thermal(plan, pmap, mtype: str) -> None:
    """The thermal models and options whose temperatures are traced; one line naming the refused one otherwise."""
    th = plan.scenario.si["thermal"]
    if pmap.contact_geometry is None or pmap.contact_row is None:
        raise ScenarioError("thermal.model", f"thermal sensitivities are not traced for '{mtype}' (its sensitivity "
                            "map has no contact geometry)")
    if th["model"] not in THERMAL_TRACED:
        raise ScenarioError("thermal.model", f"'{th['model']}' is not traced (its network is not in the sensitivity "
                            "map); traced: " + ", ".join(THERMAL_TRACED) + " (docs/sensitivity.md)")
    if th["flash"] != "jaeger":
        raise ScenarioError("thermal.flash", f"'{th['flash']}' (the seed's formula, for comparison only) is not "
                            "traced; use 'jaeger'")
