"""Design sensitivities of a run's headline results (`mechsim sensitivity`, `mechsim.sensitivity`).

The derivatives come from `dynamics/sensitivity.py` (forward sensitivities through the events, Hiskens & Pai
2000); this module maps scenario values to the model's parameters (exactly: jax differentiates the same formulas
the mechanism evaluates, and the map is checked against the mechanism at the scenario's values), defines the
headline quantities on the run, and builds the table, the tornado chart and the summary entry (docs/sensitivity.md).

Quantities (the run's reported numbers, so that a finite difference of `mechsim run` checks them):
- peaks: the largest |value| over the output rows, as summary.json's `peaks` (signed value). The output times are
  fixed, so its derivative is the row's derivative at the arg-max row (the envelope rule of a maximum over a fixed
  set). A warning names the change of a value at which another row becomes the maximum (a neighbouring row, or
  the same peak of another cycle, within PEAK_MARGIN), or at which an event next to the row reaches it, where that
  change is smaller than the stated one: there the maximum has a kink.
- index_time_s: the last complete engagement (entry to exit); cycle_time_s: between the last two entries (one
  drive revolution); energy_per_cycle_J: the drive's work over that cycle; heat_per_index_J: the frictional heat
  of the last complete engagement (minus the friction work over it). Event times are differentiated by the
  implicit-function rule, the work at an event as W(tau) with the state's total derivative.
"""
from __future__ import annotations

import dataclasses
import time
from dataclasses import dataclass
from typing import Callable

import numpy as np
import pandas as pd

from mechsim.scenarios.units import ScenarioError

#: a second peak within this relative distance of the first is reported (the maximum may switch between them)
PEAK_MARGIN = 1e-2

PEAKS = {
    "peak_contact_force_N": "contact_force_N",
    "peak_drive_torque_N_m": "drive_torque_N_m",
    "peak_wheel_accel_rad_s2": "wheel_accel_rad_s2",
    "peak_wheel_speed_rad_s": "wheel_speed_rad_s",
    "peak_coupler_force_N": "coupler_force_N",
    "peak_crank_accel_rad_s2": "crank_accel_rad_s2",
    "peak_crank_speed_rad_s": "crank_speed_rad_s",
}
#: the thermal peaks (a thermal model on): the run's columns, evaluated after the run (thermal/plan.py) from the
#: traced state at the peak's row by the same formulas in jax (thermal/contact_row.py)
THERMAL_PEAKS = {"peak_temp_contact_C": "temp_contact_C", "peak_temp_flash_rise_K": "temp_flash_rise_K"}
CYCLE = ("index_time_s", "cycle_time_s", "energy_per_cycle_J")
#: the frictional heat of the last complete index: minus the friction work (a work state) from engage to release
HEAT = "heat_per_index_J"
QUANTITIES = tuple(PEAKS) + tuple(THERMAL_PEAKS) + CYCLE + (HEAT,)
#: thermal models whose temperatures are traced (the bulk states in the DAE, the flash rise after it); the others
#: are refused, with the reason
THERMAL_TRACED = ("lumped", "flash")
#: [thermal] values traced: the material (library value unless the scenario overrides it), the surroundings, and
#: the body geometry where the scenario sets it (its defaults follow from the mechanism's values: traced through them)
THERMAL_MATERIAL_KEYS = ("thermal.conductivity", "thermal.density", "thermal.specific_heat", "thermal.E",
                         "thermal.nu")
THERMAL_KEYS = THERMAL_MATERIAL_KEYS + (
    "thermal.ambient_temperature", "thermal.convection_pin", "thermal.convection_wheel",
    "thermal.pin_crank_conductance", "thermal.pin_exposed_length", "thermal.crank_volume", "thermal.crank_area",
    "thermal.wheel_radius", "thermal.wheel_thickness")


@dataclass(frozen=True)
class ParameterMap:
    """How the scenario values of one mechanism type enter the model.

    keys: the supported scenario keys (SI). parameters(x, si, mech): the model parameters they set, as
    jax-traceable formulas of the dict x (key -> value); each is checked against the mechanism's own
    `parameter_values()`. speed_key: the initial-speed key (the initial velocities are linear in it). discrete:
    parameters that transitions may change, whose values do not depend on any of `keys` (integers, signs, or
    geometry that is not traced). engage/release: the event kinds that start and end an index (the cycle runs from
    one `engage` to the next; empty for a mechanism that does not index). peaks: its peak quantities.
    """

    keys: tuple[str, ...]
    parameters: Callable
    speed_key: str
    discrete: frozenset
    engage: str
    release: str
    peaks: tuple[str, ...] = tuple(PEAKS)
    sliding: bool = False

    @property
    def cycle(self) -> tuple[str, ...]:
        """The event-based quantities, where the mechanism indexes (a continuously turning linkage does not); the
        heat per index where it has a sliding contact."""
        return (CYCLE + ((HEAT,) if self.sliding else ())) if self.engage else ()


def _geneva_parameters(x: dict, si: dict, mech) -> dict:
    """Geneva: c = r / sin(pi/n) (tangential entry, docs/theory.md §G1); the others enter as they are."""
    import jax.numpy as jnp
    n = si["mechanism"]["slots"]
    r = x["mechanism.crank_radius"]
    return {"r": r, "c": r / jnp.sin(jnp.pi / n), "R": x["mechanism.pin_radius"],
            "J1": x["mechanism.crank_inertia"], "J2": x["mechanism.wheel_inertia"], "T_L": x["load.wheel_torque"],
            "mu": x["contact.friction"], "c1": x["mechanism.crank_damping"], "c2": x["mechanism.wheel_damping"]}


def _thermal_parameters(x: dict, si: dict, setup, speed_key: str, drive_kind: str) -> dict:
    """The thermal model's values as formulas of the scenario values (Geneva), checked against the run's own
    (`_thermal_values`): the flash formulas' inputs `flash_*` (friction, contact radius R = pin radius and length
    l = thickness, E* = E/(2 (1 - nu^2)) of two equal bodies (docs/theory.md §G3), k, chi = k/(rho c_p), ambient)
    and, with bulk states, the DAE network's `th_*` (thermal/network.py `bulk_bodies`, `assemble`;
    docs/theory.md §G5): pin V = pi R^2 l_pin, A = 2 pi R l_pin + pi R^2 (l_pin = 2.5 l unless set), crank bar
    r x 4R x l (unless set), conductance G = k pi R^2/(l_pin/2) (unless set), wheel disc of radius c cos(pi/n)
    and thickness l (unless set); C = rho c_p V, K = diag(h A) + G coupling, s = h A T_amb, loss = h A; the share's
    t_ref = 2 alpha0 / (nominal speed) (thermal/network.py `nominal_speed`)."""
    import jax.numpy as jnp
    th = si["thermal"]
    n = si["mechanism"]["slots"]
    r, R, l = x["mechanism.crank_radius"], x["mechanism.pin_radius"], x["mechanism.thickness"]
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
    radius_w = given("wheel_radius", r / jnp.sin(jnp.pi / n) * jnp.cos(jnp.pi / n))
    thick_w = given("wheel_thickness", l)
    bodies["wheel"] = (jnp.pi * radius_w**2 * thick_w, 2 * jnp.pi * radius_w**2 + 2 * jnp.pi * radius_w * thick_w,
                       x["thermal.convection_wheel"])
    names = [b.name for b in setup.bodies]
    G = given("pin_crank_conductance", k * jnp.pi * R**2 / (0.5 * l_pin))
    K = {}
    for i, name in enumerate(names):
        V, A, h = bodies[name]
        out[f"th_C_{i}"] = rho_c * V
        out[f"th_s_{i}"] = h * A * t_amb
        out[f"th_loss_{i}"] = h * A
        K[(i, i)] = h * A
    if len(names) == 3:                 # pin and crank joined by G (network.assemble)
        K[(0, 0)], K[(1, 1)], K[(0, 1)], K[(1, 0)] = K[(0, 0)] + G, K[(1, 1)] + G, -G, -G
    out.update({f"th_K_{i}_{j}": v for (i, j), v in K.items()})
    out.update({"th_R": R, "th_l": l, "th_Estar": estar, "th_k_pin": k, "th_k_wheel": k, "th_chi_pin": chi,
                "th_chi_wheel": chi, "th_t_ref": 2 * (jnp.pi / 2 - jnp.pi / n) / w_nom})
    return out


def _thermal_values(si: dict, mech) -> dict:
    """The thermal model's values as the run computes them (thermal/network.py `prepare`): the DAE extension's
    parameters and the flash formulas' inputs (names as `_thermal_parameters`)."""
    from mechsim.thermal.hertz import effective_modulus
    from mechsim.thermal.models import MODELS
    from mechsim.thermal.network import prepare
    setup = prepare(si, mech, MODELS[si["thermal"]["model"]])
    mat, geo = setup.material, setup.geometry
    out = {"flash_mu": float(si["contact"]["friction"]), "flash_R": geo.contact_radius,
           "flash_l": geo.contact_length, "flash_Estar": effective_modulus(mat), "flash_k": mat.conductivity,
           "flash_chi": mat.diffusivity, "flash_T_amb": setup.temp_ambient}
    if setup.extension is not None:
        out.update({k: v for k, v in setup.extension.parameter_values().items() if not k.startswith("th_B_")
                    and k != "th_b0"})
    return out


def _chain_parameters(x: dict, si: dict, mech) -> dict:
    """Chain dwell mechanism (mechanisms/chain/model.py): the drive's inertia reduced to the driving sprocket,
    J1 = m_chain r1^2 + sum_i J_i (r1 / r_i)^2, the crank a uniform rod J_Q = m R^2 / 3 and the coupler one of length
    L, J_3 = m L^2 / 12, unless their inertias are given. The geometry (r1, r_i, R, L) is not traced: constants."""
    m = si["mechanism"]
    r1, radii = mech.path.r1, np.asarray(mech.path.radii, float)
    sprockets = float(np.sum(np.asarray(m["sprocket_inertias"], float) * (r1 / radii) ** 2))
    R, L = mech.kin.R, mech.kin.L
    jq = x["mechanism.crank_mass"] * R**2 / 3 if m["crank_inertia"] is None else x["mechanism.crank_inertia"]
    j3 = x["mechanism.coupler_mass"] * L**2 / 12 if m["coupler_inertia"] is None else x["mechanism.coupler_inertia"]
    return {"J1": x["mechanism.chain_mass"] * r1**2 + sprockets, "JQ": jq, "m3": x["mechanism.coupler_mass"],
            "J3": j3, "T_L": x["load.crank_torque"], "c1": x["mechanism.drive_damping"],
            "c2": x["mechanism.crank_damping"]}


def _rolling_parameters(x: dict, si: dict, mech) -> dict:
    """Rolling-pair four-bar (mechanisms/rolling/model.py `Bodies.uniform`): slender crank and coupler rods
    (I = m l^2 / 12 at mid-length), the rolling link a uniform disc (m r^2 / 2 about B0) welded to a slender arm
    (m l4^2 / 3 about B0), moved to the joint centre of mass c4 = m_arm l4 / 2 / m4 (docs/theory.md §K3), unless
    the scenario gives the inertias and centres itself (then those are traced). The geometry is not traced."""
    m = si["mechanism"]
    kin = mech.kin
    l2, l3, l4, r = kin.l2, kin.l3, kin.l4, kin.pair.r
    m2, m3 = x["mechanism.crank_mass"], x["mechanism.coupler_mass"]
    disc, arm = x["mechanism.disc_mass"], x["mechanism.arm_mass"]
    m4 = disc + arm
    c4 = arm * l4 / 2 / m4 if m["rolling_com"] is None else m["rolling_com"]
    i4 = (disc * r**2 / 2 + arm * l4**2 / 3 - m4 * c4**2) if m["rolling_inertia"] is None else (
        x["mechanism.rolling_inertia"])
    out = {"m2": m2, "I2": m2 * l2**2 / 12 if m["crank_inertia"] is None else x["mechanism.crank_inertia"],
           "m3": m3, "I3": m3 * l3**2 / 12 if m["coupler_inertia"] is None else x["mechanism.coupler_inertia"],
           "m4": m4, "I4": i4, "g": x["load.gravity"], "b2": x["load.crank_damping"],
           "b4": x["load.rolling_damping"]}
    if m["rolling_com"] is None:
        out["c4"] = c4
    return out


MAPS = {
    "rolling_pair": ParameterMap(
        keys=("mechanism.crank_mass", "mechanism.crank_inertia", "mechanism.coupler_mass", "mechanism.coupler_inertia",
              "mechanism.disc_mass", "mechanism.arm_mass", "mechanism.rolling_inertia", "load.gravity",
              "load.crank_damping", "load.rolling_damping"),
        parameters=_rolling_parameters, speed_key="initial.drive_speed",
        discrete=frozenset({"dead_sign"}), engage="", release="",
        peaks=("peak_contact_force_N", "peak_drive_torque_N_m", "peak_coupler_force_N", "peak_crank_accel_rad_s2",
               "peak_crank_speed_rad_s")),
    "chain_dwell": ParameterMap(
        keys=("mechanism.chain_mass", "mechanism.crank_mass", "mechanism.crank_inertia", "mechanism.coupler_mass",
              "mechanism.coupler_inertia", "mechanism.drive_damping", "mechanism.crank_damping", "load.crank_torque"),
        parameters=_chain_parameters, speed_key="initial.drive_speed",
        # the chain path's pieces (segment, its geometry, the apex, the dyad's branch) follow from the geometry
        discrete=frozenset({"seg", "s0", "s1", "Px", "Py", "tx", "ty", "Ox", "Oy", "rr", "psi0", "alpha", "s_apex",
                            "sigma"}),
        engage="dwell end", release="stop impact",
        peaks=("peak_drive_torque_N_m", "peak_coupler_force_N", "peak_crank_accel_rad_s2", "peak_crank_speed_rad_s")),
    "geneva": ParameterMap(
        keys=("mechanism.crank_radius", "mechanism.pin_radius", "mechanism.thickness", "mechanism.crank_inertia",
              "mechanism.wheel_inertia", "mechanism.crank_damping", "mechanism.wheel_damping", "load.wheel_torque",
              "contact.friction"),
        parameters=_geneva_parameters, speed_key="initial.crank_speed",
        discrete=frozenset({"slot", "lock_angle", "flank", "slide", "slot_base"}), engage="entry", release="exit",
        sliding=True,
        peaks=("peak_contact_force_N", "peak_drive_torque_N_m", "peak_wheel_accel_rad_s2", "peak_wheel_speed_rad_s")),
}
DRIVE_KEYS = {"torque": ("drive.torque",), "motor": ("drive.stall_torque", "drive.no_load_speed"),
              "speed": ("drive.speed",)}


def _drive_parameters(x: dict, kind: str) -> dict:
    """The drive's T = T0 - slope w (dynamics/drives.py): motor T0 = stall torque, slope = stall / no-load speed;
    a prescribed speed enters as itself (the constraint q = angle0 + speed (t - time0))."""
    if kind == "speed":
        return {"drive_speed": x["drive.speed"]}
    if kind == "motor":
        return {"drive_T0": x["drive.stall_torque"], "drive_slope": x["drive.stall_torque"] / x["drive.no_load_speed"]}
    return {"drive_T0": x["drive.torque"]}


def _lookup(si: dict, key: str):
    node = si
    for part in key.split("."):
        node = node[part]
    return node


def _value(plan, key: str) -> float:
    """A scenario value (SI); a material value the scenario leaves to the library is the library's."""
    if key in THERMAL_MATERIAL_KEYS and plan.thermal is not None:
        return float(getattr(plan.thermal.setup.material, key.split(".")[1]))
    return float(_lookup(plan.scenario.si, key) or 0.0)


def _traced_keys(plan, pmap: ParameterMap) -> list[str]:
    """Every value the map is a function of: the mechanism's, the drive's, the thermal model's (with the initial
    speed, which sets the thermal model's nominal speed, thermal/network.py `nominal_speed`)."""
    keys = list(pmap.keys) + list(DRIVE_KEYS.get(plan.drive.kind, ()))
    if plan.thermal is not None:
        keys += [k for k in THERMAL_KEYS if k in THERMAL_MATERIAL_KEYS or _lookup(plan.scenario.si, k) is not None]
        if not plan.drive.is_prescribed:
            keys.append(pmap.speed_key)
    return keys


def _mapped(plan, pmap: ParameterMap, keys: list[str]):
    """params(xs): the model's parameters (and the thermal formulas' inputs) as jax formulas of the values."""
    import jax.numpy as jnp
    si, mech, drive = plan.scenario.si, plan.mechanism, plan.drive

    def params(xs):
        x = dict(zip(keys, xs))
        out = {**pmap.parameters(x, si, mech), **_drive_parameters(x, drive.kind)}
        if plan.thermal is not None:
            out.update(_thermal_parameters(x, si, plan.thermal.setup, pmap.speed_key, drive.kind))
        return {k: jnp.asarray(v, jnp.float64) for k, v in out.items()}
    return params


def _reference_values(si: dict, mech, drive, thermal: bool) -> dict:
    return {**mech.parameter_values(), **drive.parameter_values(0.0), **(_thermal_values(si, mech) if thermal else {})}


def _seed(plan, model, wrt: list[str], pmap: ParameterMap):
    """(Seed with columns scaled by each value, scales, flash: name -> (n,) derivatives of the thermal formulas'
    inputs per scaled value): columns are d/d(ln theta) (theta for theta = 0), so that every sensitivity has the
    state's own units and one error control serves them all."""
    import jax
    from mechsim.dynamics.sensitivity import Seed
    si, mech, drive = plan.scenario.si, plan.mechanism, plan.drive
    keys = _traced_keys(plan, pmap)
    x0 = {k: _value(plan, k) for k in keys}
    params = _mapped(plan, pmap, keys)
    values = _reference_values(si, mech, drive, plan.thermal is not None)
    mapped = params([x0[k] for k in keys])
    for name, v in mapped.items():
        if not np.isclose(float(v), values[name], rtol=1e-13, atol=0.0):
            raise RuntimeError(f"sensitivity map of '{name}' gives {float(v)!r}, the mechanism {values[name]!r}")
    names = list(model.parameter_names)
    jac = jax.jacfwd(lambda xs: list(params(xs).values()))(np.array([x0[k] for k in keys]))
    scales = np.array([abs(_value(plan, k)) or 1.0 for k in wrt])
    n = len(wrt)
    nq = len(model.coordinates)
    dp = np.zeros((len(names), n))
    dq0, dv0 = np.zeros((nq, n)), np.zeros((nq, n))
    dx0 = np.zeros((len(model.extension_names), n))
    flash = {name: np.zeros(n) for name in mapped if name.startswith("flash_")}
    for j, key in enumerate(wrt):
        if key == pmap.speed_key or (drive.is_prescribed and key == "drive.speed"):
            # the initial velocities are linear in the drive's initial speed (Mechanism.initial_state): checked
            angle = si["initial"][mech.initial_keys[0]]
            speed = drive.speed if drive.is_prescribed else si["initial"][mech.initial_keys[1]]
            unit_v = np.asarray(mech.initial_state(angle, 1.0).v, float)
            v = np.asarray(mech.initial_state(angle, speed).v, float)
            if not np.allclose(v, speed * unit_v, rtol=1e-12, atol=1e-15 * max(1.0, float(np.max(np.abs(v))))):
                raise ScenarioError(key, "the initial velocities of this mechanism are not linear in the initial "
                                    "speed here: not traced")
            dv0[:, j] = unit_v * scales[j]
        if key == "thermal.ambient_temperature" and plan.thermal.setup.system is not None:
            # the bulk states start at the ambient (ThermalSetup.initial)
            dx0[:plan.thermal.setup.system.size, j] = scales[j]
        if key not in keys:
            continue
        col = keys.index(key)
        for name, row in zip(mapped, jac):
            d = float(np.asarray(row)[col]) * scales[j]
            if name in flash:
                flash[name][j] = d
            else:
                dp[names.index(name), j] = d
    _check_map(plan, wrt, keys, mapped, jac, pmap)
    return Seed(dp, dq0, dv0, pmap.discrete, dx0), scales, flash


def _check_map(plan, wrt: list[str], keys: list[str], mapped: dict, jac, pmap: ParameterMap) -> None:
    """The map must be complete and right: the mechanism (and thermal model) rebuilt with each traced value moved
    (central differences, 1e-5 relative) changes no parameter the map does not set, and those it sets by the map's
    derivative (to 1e-6 of the parameter's size: the differences' truncation is ~1e-10, their round-off ~1e-11). A
    RuntimeError otherwise: a map out of step with the mechanism is a bug, not a user error."""
    import copy

    from mechsim.scenarios.loader import build_mechanism
    from mechsim.scenarios.runner import make_drive
    si, drive = plan.scenario.si, plan.drive
    for key in wrt:
        if key not in keys:
            continue
        p = _value(plan, key)
        h = 1e-5 * abs(p) if p else 1e-5
        values = []
        for sign in (1, -1):
            moved = copy.deepcopy(si)
            node = moved
            *path, last = key.split(".")
            for part in path:
                node = node[part]
            node[last] = p + sign * h
            mech = build_mechanism(moved)
            values.append(_reference_values(moved, mech, make_drive(moved), plan.thermal is not None))
        col = keys.index(key)
        derivative = dict(zip(mapped, (float(np.asarray(row)[col]) for row in jac)))
        for name in values[0]:
            fd = (values[0][name] - values[1][name]) / (2 * h)
            exact = derivative.get(name, 0.0)
            size = max(abs(values[0][name]), abs(exact) * max(abs(p), 1.0), 1e-300)
            if abs(fd - exact) * max(abs(p), h) > 1e-6 * size:
                raise RuntimeError(f"sensitivity map: '{name}' moves by {fd:.6g} per unit of {key}, the map says "
                                   f"{exact:.6g} ({drive.kind} drive)")


def check_request(plan, wrt: list[str], of: list[str]) -> ParameterMap:
    """The mechanism's ParameterMap, after checking that every value in `wrt` and every quantity in `of` is traced
    on this plan (ScenarioError naming the first that is not; `mechsim size` checks its requests with it too)."""
    si = plan.scenario.si
    mtype = si["mechanism"]["type"]
    pmap = MAPS.get(mtype)
    if pmap is None:
        raise ScenarioError("mechanism.type", f"sensitivities are not traced for '{mtype}' (docs/sensitivity.md)")
    if plan.thermal is not None:
        _check_thermal(plan, mtype)
    allowed = _traced_keys(plan, pmap) + ([] if plan.drive.is_prescribed else [pmap.speed_key])
    allowed = list(dict.fromkeys(allowed))
    if not wrt:
        raise ScenarioError("--wrt", f"name at least one scenario value; traced here: {', '.join(allowed)}")
    for key in wrt:
        if (key in pmap.keys or key in THERMAL_KEYS) and key not in THERMAL_MATERIAL_KEYS and (
                _lookup_or_none(si, key) is None):
            raise ScenarioError(key, "not set in this scenario (it is derived from other values): set it to trace it")
        if key not in allowed:
            raise ScenarioError(key, f"not a value sensitivities are traced for here; traced: {', '.join(allowed)}")
    if len(set(wrt)) != len(wrt):
        raise ScenarioError("--wrt", "a key is named twice")
    known = _quantities(plan, pmap)
    for q in of:
        if q in THERMAL_PEAKS and plan.thermal is None:
            raise ScenarioError("--of", f"{q}: this scenario has no thermal model (set thermal.model = 'lumped' or "
                                "'flash')")
        if q not in known:
            raise ScenarioError("--of", f"unknown quantity {q!r} for this mechanism; one of {', '.join(known)}")
    return pmap


def _lookup_or_none(si: dict, key: str):
    try:
        return _lookup(si, key)
    except KeyError:
        return None


def _check_thermal(plan, mtype: str) -> None:
    """The thermal models and options whose temperatures are traced; one line naming the refused one otherwise."""
    th = plan.scenario.si["thermal"]
    if mtype != "geneva":
        raise ScenarioError("thermal.model", f"thermal sensitivities are traced for the Geneva only, not '{mtype}'")
    if th["model"] not in THERMAL_TRACED:
        raise ScenarioError("thermal.model", f"'{th['model']}' is not traced (its wall-track mesh is not in the "
                            "sensitivity map); traced: " + ", ".join(THERMAL_TRACED) + " (docs/sensitivity.md)")
    if th["flash"] != "jaeger":
        raise ScenarioError("thermal.flash", f"'{th['flash']}' (the seed's formula, for comparison only) is not "
                            "traced; use 'jaeger'")
    if plan.thermal.averaging == "cycle" and plan.method == "closed-form":
        raise ScenarioError("thermal.averaging", "cycle averaging at a prescribed speed is not traced (its closed form "
                            "is not differentiated, and the DAE's mechanics window differs): set drive.type = 'motor' "
                            "or 'torque', or thermal.averaging = 'resolved' (docs/sensitivity.md)")


def _quantities(plan, pmap: ParameterMap) -> tuple[str, ...]:
    thermal = tuple(THERMAL_PEAKS) if plan.thermal is not None else ()
    return pmap.peaks + thermal + pmap.cycle


def _peak_rows(values: np.ndarray) -> list[int]:
    """Row of the largest |value|, then the rows that could take its place: the rows next to it (the output step
    samples the peak) and other local maxima of |value| (a repeating motion repeats its peaks) within PEAK_MARGIN.
    NaN rows (no contact; outside the periodic turn) are no candidates."""
    y = np.abs(values)
    i = int(np.nanargmax(y))
    rows = [i]
    if np.nanmax(y) - np.nanmin(y) <= 1e-12 * y[i]:
        return rows                       # a constant column (a constant drive torque): every row is the peak
    inner = np.zeros(len(y), bool)
    inner[1:-1] = (y[1:-1] > y[:-2]) & (y[1:-1] >= y[2:])       # the first row of a plateau counts once
    inner[[j for j in (i - 1, i + 1) if 0 <= j < len(y)]] = True
    inner[i] = False
    rows += [int(j) for j in np.flatnonzero(inner) if y[j] >= (1 - PEAK_MARGIN) * y[i]]
    return rows


def _near_peaks(q: str, wrt: list[str], relative: list[bool], df, rows: list[int], by_time: dict, column: str,
                change: float) -> str | None:
    """A warning where another candidate row (`_peak_rows`) becomes the maximum within the stated change of a value
    (relative, or absolute for a value at zero): there the maximum's derivative jumps (a non-smooth point), so
    the first-order change is not to be trusted that far. Gradients are per relative change (per unit for a value
    at zero), see `_seed`."""
    first = by_time[float(df["t_s"].iloc[rows[0]])]
    y, g = first.values[column], first.grads[column]
    nearest = {}
    for j in rows[1:]:
        other = by_time[float(df["t_s"].iloc[j])]
        y2, g2 = other.values[column], other.grads[column]
        gap = abs(y) - abs(y2)
        rate = np.sign(y2) * g2 - np.sign(y) * g     # d(|y2| - |y|) per relative change of each value
        for key, r in zip(wrt, rate):
            if r != 0 and gap / abs(r) < nearest.get(key, (np.inf, 0, 0.0))[0]:
                nearest[key] = (gap / abs(r), np.sign(r), other.t)
    rel = dict(zip(wrt, relative))
    swap = [f"{key} {'+' if s > 0 else '-'}" + (f"{d * 100:.2g}%" if rel[key] else f"{d:.2g} (absolute)")
            + f" (to t = {t2:.6g} s)" for key, (d, s, t2) in nearest.items() if d < change]
    if not swap:
        return None
    return (f"{q}: the peak at t = {first.t:.6g} s is the largest of {len(rows)} nearly equal output rows (the rows "
            "next to it, or the same peak of another cycle); another one takes over, and the derivative jumps, "
            "within the stated change: " + ", ".join(swap))


def _event_crosses_row(q: str, wrt: list[str], relative: list[bool], t_row: float, events, change: float):
    """A warning where the events next to a peak's row (the last before it, the first after it) move past the row
    within the stated change of a value: the row then lies in another mode, where the quantity may jump (a
    non-smooth point; the derivative holds only for smaller changes). Event-time gradients are per relative change."""
    before = [e for e in events if e.t <= t_row]
    after = [e for e in events if e.t > t_row]
    near = ([before[-1]] if before else []) + ([after[0]] if after else [])
    rel = dict(zip(wrt, relative))
    found = []
    for e in near:
        for key, d in zip(wrt, e.dt):
            if d == 0:
                continue
            step = (t_row - e.t) / d              # the change of the value that brings the event to the row
            if abs(step) < change:
                amount = f"{step * 100:+.2g}%" if rel[key] else f"{step:+.2g} (absolute)"
                found.append(f"{key} {amount} ('{e.kind}' at t = {e.t:.6g} s)")
    if not found:
        return None
    return (f"{q}: its row t = {t_row:.6g} s is next to a mode change that reaches it within the stated change; "
            "beyond it the row lies in the other mode, where the quantity may jump (the derivative holds up to "
            "there): " + ", ".join(found))


def sensitivity(scenario, wrt: list[str], of: list[str] | None = None, change: float = 0.01) -> pd.DataFrame:
    """The table of derivatives of the headline quantities `of` (default: all) with respect to the scenario values
    `wrt` (a loaded Scenario). One row per (quantity, value): value, t_s (the peak's output row, or the end of the
    cycle), derivative (SI), elasticity (p/y) dy/dp, and the first-order change of y for a change of p by `change`
    (relative). attrs: cost, warnings, scenario."""
    from mechsim.dynamics.hybrid import prepare
    from mechsim.dynamics.sensitivity import path_sensitivities
    from mechsim.scenarios import runner
    from mechsim.scenarios.sweep.rows import field_unit
    if not 0 < change < 1:
        raise ScenarioError("--change", f"must be a relative change in (0, 1), got {change}")
    plan = runner.plan(scenario)
    notes = []
    cycle = plan.thermal is not None and plan.thermal.averaging == "cycle"
    if cycle:
        check_request(plan, list(wrt), list(of or []))
        plan = cycle_window(plan)
    if plan.method == "closed-form":
        # the closed form is not differentiated: the same motion as a DAE with the speed as a constraint (and the
        # thermal states in it)
        plan = dataclasses.replace(plan, method="dae", settings=dataclasses.replace(plan.settings, method="dae"),
                                   why="sensitivities follow the DAE path",
                                   thermal=plan.thermal and dataclasses.replace(plan.thermal, method="dae"))
        notes.append("prescribed speed: the run and its derivatives follow the DAE with the speed as a constraint "
                     "(solver.method = 'dae'); the closed form gives the same motion to the solver's tolerance")
    wrt = list(wrt)
    pmap = check_request(plan, wrt, list(of or []))
    of = list(of) if of else list(_quantities(plan, pmap))
    si, mech, drive, settings, thermal = scenario.si, plan.mechanism, plan.drive, plan.settings, plan.thermal
    wall = time.perf_counter()
    result = runner.execute(plan)
    run_wall = time.perf_counter() - wall
    if result.failure is not None:
        raise ScenarioError("scenario", f"the run failed ({result.failure.message()}): no derivatives of a run that "
                            "did not reach its end")
    df, events = result.timeseries, result.events
    warnings: list[str] = list(notes)
    angle_key, speed_key = mech.initial_keys
    angle0 = si["initial"][angle_key]
    speed0 = drive.speed if drive.is_prescribed else si["initial"][speed_key]
    ext, ext_initial = (thermal.extension, thermal.ext_initial) if thermal is not None else (None, None)
    t_end = plan.mechanics_duration
    model = prepare(mech, drive, settings, t_end, si["output_step"], angle0, speed0, ext, ext_initial).model
    seed, scales, flash = _seed(plan, model, wrt, pmap)

    peak_columns = {**PEAKS, **THERMAL_PEAKS}
    turn = cycle_temperatures(plan, df) if cycle else None
    if cycle and turn is None:
        raise ScenarioError("thermal.averaging", "the mechanics window holds no full crank turn to average")

    def peak_values(q):
        if turn is not None and q in THERMAL_PEAKS:       # the periodic turn's rows, at their last time in the run
            y = np.full(len(df), np.nan)
            y[turn["rows"]] = turn[THERMAL_PEAKS[q]]
            return y
        return df[peak_columns[q]].to_numpy(float)
    peak_rows = {q: _peak_rows(peak_values(q)) for q in of if q in peak_columns and peak_columns[q] in df
                 and np.nanmax(np.abs(peak_values(q)), initial=0.0) > 0}
    sample_times = sorted({float(df["t_s"].iloc[i]) for rows in peak_rows.values() for i in rows})
    thermal_times = sorted({float(df["t_s"].iloc[i]) for q, rows in peak_rows.items() if q in THERMAL_PEAKS
                            for i in rows})
    columns = {PEAKS[q] for q in peak_rows if q in PEAKS} | {"work_drive_J"}
    if thermal_times:
        # with bulk states, the columns of the cycle bulk too (read only with cycle averaging), so that both
        # averagings share one compiled set of read-outs
        columns |= set(CONTACT_COLUMNS) | {c for c in model.extension_names if c.startswith("temp_bulk_")}
        columns |= set(CYCLE_COLUMNS) if ext is not None else set()
    if turn is not None and thermal_times and ext is not None:
        # the cycle-averaged bulk depends on every row of the turn (its input) and on the rows at its ends
        sample_times = sorted(set(sample_times) | {float(x) for x in df["t_s"].to_numpy(float)[turn["layout"].rows]})
    wall = time.perf_counter()
    path = path_sensitivities(mech, drive, settings, events.to_dict("records"), seed, sample_times, sorted(columns),
                              t_end, si["output_step"], angle0, speed0, ext, ext_initial)
    by_time = {s.t: s for s in path.samples}
    if turn is not None and thermal_times and ext is not None:       # (the flash model's base is the ambient)
        _cycle_bulk_samples(plan, df, turn, by_time, seed, model, [by_time[t] for t in thermal_times], path.stats)
    if thermal_times:
        _thermal_samples(plan, df, events, path, [by_time[t] for t in thermal_times], flash)
    sens_wall = time.perf_counter() - wall

    results: dict[str, tuple[float, np.ndarray]] = {}
    relative = [_value(plan, key) != 0.0 for key in wrt]
    for q in of:
        if q in peak_columns:
            column = peak_columns[q]
            if q not in peak_rows:
                warnings.append(f"{q}: this run has no column {column}" if column not in df else
                                f"{q}: zero on every row (no contact, or no frictional heat): no peak to differentiate")
                continue
            rows = peak_rows[q]
            first = by_time[float(df["t_s"].iloc[rows[0]])]
            y, g = first.values[column], first.grads[column]
            results[q] = (y, g, first.t)
            if turn is not None and q in THERMAL_PEAKS:
                results[q] = (y, g, first.t + turn["layout"].periods * turn["period"])
                note = _event_crosses_turn_row(q, wrt, relative, turn, path.events, change)
                if note and q == "peak_temp_contact_C" and ext is not None:
                    warnings.append(note)
            if len(rows) > 1:
                note = _near_peaks(q, wrt, relative, df, rows, by_time, column, change)
                if note:
                    warnings.append(note)
            note = _event_crosses_row(q, wrt, relative, first.t, path.events, change)
            if note:
                warnings.append(note)
        else:
            got = _cycle_quantity(q, path.events, pmap, model)
            if got is None:
                index = q in ("index_time_s", HEAT)
                warnings.append(f"{q}: the run has no complete {'index' if index else 'cycle'} "
                                f"({pmap.engage} to {pmap.release if index else pmap.engage}); lengthen duration")
                continue
            results[q] = got
    rows = []
    for q, (y, g, at) in results.items():
        for j, key in enumerate(wrt):
            p = _value(plan, key)
            deriv = float(g[j]) / scales[j]
            unit = field_unit(si, key)
            elasticity = p / y * deriv if y != 0 else float("nan")
            dp = change * abs(p) if p != 0 else float("nan")
            rows.append(dict(quantity=q, value=y, t_s=at, wrt=key, wrt_unit=unit, parameter=p, derivative=deriv,
                             elasticity=elasticity, parameter_change=dp, quantity_change=deriv * dp))
    table = pd.DataFrame(rows, columns=["quantity", "value", "t_s", "wrt", "wrt_unit", "parameter", "derivative",
                                        "elasticity", "parameter_change", "quantity_change"])
    table.attrs.update(
        scenario=scenario.name, change=change, warnings=warnings,
        cost={"run_wall_time_s": run_wall, "run_backend": settings.backend,
              "sensitivity_wall_time_s": sens_wall, "sensitivity_compile_time_s": path.stats["compile_time_s"],
              # the pass without its one-off compilation, per run of the scenario's backend
              "sensitivity_per_run": (sens_wall - path.stats["compile_time_s"]) / run_wall if run_wall > 0 else None,
              "sensitivity_steps": path.stats["steps"], "values": len(wrt)})
    return table


#: the columns the contact temperature of a Geneva row is made of (mechanisms/geneva/contact.py `state`)
CONTACT_COLUMNS = ("crank_speed_rad_s", "wheel_speed_rad_s", "crank_accel_rad_s2", "pin_sliding_speed_m_s",
                   "pin_distance_m", "contact_force_N", "slip_speed_m_s")
#: the events at which a contact begins (the pin's transient floor counts from there; mechanisms/geneva/contact.py)
CONTACT_STARTS = ("entry", "flank switch")
FLASH_INPUTS = ("flash_mu", "flash_R", "flash_l", "flash_Estar", "flash_k", "flash_chi")


def _geneva_row_temperatures(u, distribution: str, xp=np):
    """(flash rise K, contact temperature degC) of one Geneva row from u = [CONTACT_COLUMNS, base_pin, base_wheel,
    t_on_pin, FLASH_INPUTS]: the contact state of mechanisms/geneva/contact.py `state` (source speeds R (w1 + w2)
    over the pin and v_s over the wall, a_s = (w1' v_s + w1 (w1 + w2) w2 x)/w1, docs/theory.md §G1, §G4.6) with the
    pin radius traced, then thermal/contact_row.py `contact_temperature` (docs/theory.md §G3-§G4.6)."""
    from mechsim.thermal.contact_row import KELVIN, contact_temperature
    w1, w2, a1, v_s, x, N, slip, base_pin, base_wheel, t_on, mu, R, length, estar, k, chi = (u[i] for i in range(16))
    contact = {"normal_force": N, "slip_speed": slip, "source_speed_driver": R * (w1 + w2),
               "source_speed_driven": v_s, "sliding_accel": (a1 * v_s + w1 * (w1 + w2) * w2 * x) / w1}
    out = contact_temperature(contact, t_on, base_pin, base_wheel, mu, R, length, estar, k, chi, distribution, xp)
    return xp.stack([out["temp_flash_rise_K"], out["temp_contact_K"] - KELVIN])


_ROW_JACOBIANS: dict = {}


def _row_jacobian(distribution: str):
    """(u -> (values, Jacobian) of `_geneva_row_temperatures`, seconds spent compiling it now): compiled ahead of
    time once per process and distribution."""
    import jax
    import jax.numpy as jnp
    fn = _ROW_JACOBIANS.get(distribution)
    if fn is not None:
        return fn, 0.0
    wall = time.perf_counter()

    def f(u):
        return _geneva_row_temperatures(u, distribution, jnp)
    fn = _ROW_JACOBIANS[distribution] = jax.jit(lambda u: (f(u), jax.jacfwd(f)(u))).lower(np.ones(16)).compile()
    return fn, time.perf_counter() - wall


def _thermal_samples(plan, df: pd.DataFrame, events: pd.DataFrame, path, samples: list, flash: dict) -> None:
    """Add the flash rise and the contact temperature (values and gradients per scaled value) to the samples at
    thermal peak rows: the traced columns and bulk states at the row, the time since the contact began (the last
    entry or flank switch: its time's derivative from the implicit-function rule), and the thermal formulas'
    inputs, pushed through the row's formulas by their exact Jacobian (jax). The formulas are first checked to
    give the run's own columns at the row (they are the thermal finish's, thermal/plan.py)."""
    from mechsim.dynamics.sensitivity import SensitivityUnavailable
    setup = plan.thermal.setup
    distribution = setup.section["distribution"]
    starts = [e for e in path.events if e.kind in CONTACT_STARTS]
    fn, path.stats["row_compile_time_s"] = _row_jacobian(distribution)
    path.stats["compile_time_s"] += path.stats["row_compile_time_s"]
    t_all = df["t_s"].to_numpy(float)
    for s in samples:
        prior = [e for e in starts if e.t <= s.t + 1e-12]
        if not prior:
            raise SensitivityUnavailable(f"the contact at t = {s.t:.6g} s began before the run started: the time "
                                         "since its start is not traced (start the run in a dwell)")
        start = prior[-1]
        n = len(start.dt)
        if setup.system is not None:
            names = ("temp_bulk_pin_K", "temp_bulk_wheel_K")
            base = [s.values[c] for c in names]
            dbase = [s.grads[c] for c in names]
        else:
            base = [setup.temp_ambient] * 2
            dbase = [flash["flash_T_amb"]] * 2
        u = np.array([s.values[c] for c in CONTACT_COLUMNS] + base + [s.t - start.t]
                     + [_flash_value(setup, plan, name) for name in FLASH_INPUTS])
        du = np.vstack([s.grads[c] for c in CONTACT_COLUMNS] + dbase + [-start.dt]
                       + [flash[name] for name in FLASH_INPUTS])
        row = int(np.argmin(np.abs(t_all - s.t)))
        _check_row_formula(plan, df, events, row, distribution)
        values, jac = (np.asarray(a) for a in fn(u))
        grads = jac @ du
        for i, column in enumerate(("temp_flash_rise_K", "temp_contact_C")):
            s.values[column], s.grads[column] = float(values[i]), grads[i][:n]


def _flash_value(setup, plan, name: str) -> float:
    from mechsim.thermal.hertz import effective_modulus
    mat, geo = setup.material, setup.geometry
    return {"flash_mu": float(plan.scenario.si["contact"]["friction"]), "flash_R": geo.contact_radius,
            "flash_l": geo.contact_length, "flash_Estar": effective_modulus(mat), "flash_k": mat.conductivity,
            "flash_chi": mat.diffusivity}[name]


def _check_row_formula(plan, df: pd.DataFrame, events: pd.DataFrame, row: int, distribution: str) -> None:
    """The row formulas evaluated on the run's own row give the run's flash and contact temperature columns (to
    1e-9): the differentiated formulas cannot drift away from the thermal finish unnoticed."""
    from mechsim.dynamics.sensitivity import SensitivityUnavailable
    setup = plan.thermal.setup
    r = df.iloc[row]
    t = float(r["t_s"])
    starts = plan.mechanism.contact_starts(df, events)
    start = starts[np.searchsorted(starts, t + 1e-12, side="right") - 1]
    if setup.system is not None:
        base = [float(r["temp_bulk_pin_C"]) + 273.15, float(r["temp_bulk_wheel_C"]) + 273.15]
    else:
        base = [setup.temp_ambient] * 2
    u = np.array([float(r[c]) for c in CONTACT_COLUMNS] + base + [t - start]
                 + [_flash_value(setup, plan, name) for name in FLASH_INPUTS])
    mine = _geneva_row_temperatures(u, distribution, np)
    theirs = np.array([float(r["temp_flash_rise_K"]), float(r["temp_contact_C"])])
    if not np.all(np.abs(mine - theirs) <= 1e-9 * np.maximum(1.0, np.abs(theirs))):
        raise SensitivityUnavailable(f"the traced thermal formulas give {mine} at t = {t:.6g} s, the run "
                                     f"{theirs}: not the run's thermal model")


def _cycle_quantity(q: str, events, pmap: ParameterMap, model):
    """(value, gradient per scaled value, time of its end) of an event-based quantity, or None where the run has no
    such cycle."""
    entries = [e for e in events if e.kind == pmap.engage]
    if q in ("index_time_s", HEAT):
        pairs = []
        for i in range(len(events) - 1, -1, -1):
            if events[i].kind == pmap.release:
                start = [e for e in events[:i] if e.kind == pmap.engage]
                if start:
                    pairs = [(start[-1], events[i])]
                break
        if not pairs:
            return None
        a, b = pairs[0]
        if q == HEAT:       # the friction work is negative (dissipated): its drop over the index is the heat
            k = 2 * len(model.coordinates) + list(model.work_names).index("friction")
            return float(a.z[k] - b.z[k]), a.dz[k] - b.dz[k], b.t
        return b.t - a.t, b.dt - a.dt, b.t
    if len(entries) < 2:
        return None
    a, b = entries[-2], entries[-1]
    if q == "cycle_time_s":
        return b.t - a.t, b.dt - a.dt, b.t
    # the drive's work at each event (a work state: z = [q, v, work, ext]); dz holds S + f dtau
    k = 2 * len(model.coordinates) + list(model.work_names).index("drive")
    return float(b.z[k] - a.z[k]), b.dz[k] - a.dz[k], b.t


def _event_crosses_turn_row(q: str, wrt: list[str], relative: list[bool], turn: dict, events, change: float):
    """A warning where an event inside the periodic turn moves past an output row within the stated change of a
    value: that row's heat input (the turn's input is linear between rows) then changes mode, and the cycle-averaged
    bulk jumps by about one row's heat (the run's reported temperatures with it); the derivative holds up to there."""
    t = turn["layout"].t
    inner = t[turn["layout"].inner]
    rel = dict(zip(wrt, relative))
    found = {}
    for e in events:
        if not inner[0] <= e.t <= inner[-1]:
            continue
        gap = float(np.min(np.abs(inner - e.t)))
        for key, d in zip(wrt, e.dt):
            if d != 0 and gap / abs(d) < min(change, found.get(key, (np.inf,))[0]):
                found[key] = (gap / abs(d), e.kind, e.t)
    if not found:
        return None
    return (f"{q}: an event of the periodic turn crosses an output row within the stated change, where the turn's "
            "heat input (linear between rows) and with it the cycle-averaged bulk jump by about one row's heat: "
            + ", ".join(f"{key} " + (f"{d * 100:.2g}%" if rel[key] else f"{d:.2g} (absolute)")
                        + f" ('{kind}' at t = {te:.6g} s)" for key, (d, kind, te) in found.items()))


def tornado_figure(table: pd.DataFrame):
    """One panel per quantity: horizontal bars of the elasticities (p/y) dy/dp, largest on top."""
    from matplotlib.figure import Figure
    quantities = list(dict.fromkeys(table["quantity"]))
    fig = Figure(figsize=(8, 1.2 + 0.45 * len(table)), constrained_layout=True)
    heights = [max(1, (table["quantity"] == q).sum()) + 1 for q in quantities]
    axes = fig.subplots(len(quantities), 1, gridspec_kw={"height_ratios": heights}, squeeze=False)[:, 0]
    for ax, q in zip(axes, quantities):
        part = table[table["quantity"] == q].copy()
        part = part.iloc[np.argsort(np.abs(part["elasticity"].fillna(0).to_numpy()))]
        e = part["elasticity"].to_numpy(float)
        bars = ax.barh(part["wrt"], e, color=["C3" if v > 0 else "C0" for v in e])
        ax.bar_label(bars, labels=[f"{v:.3g}" for v in e], fontsize=7, padding=2)
        ax.axvline(0.0, color="k", lw=0.8)
        ax.set_title(f"{q} = {part['value'].iloc[0]:.6g}", fontsize=9, loc="left")
        ax.tick_params(labelsize=8)
        lim = max(1e-12, float(np.nanmax(np.abs(e)))) * 1.15
        ax.set_xlim(-lim, lim)
    axes[-1].set_xlabel("elasticity (p/y) dy/dp: % change of the quantity per % change of the value\n"
                        "(red: the value raises the quantity, blue: it lowers it)")
    fig.suptitle(f"{table.attrs.get('scenario', '')}: design sensitivities", fontsize=10)
    return fig


def write_sensitivity(table: pd.DataFrame, folder, force: bool = False):
    """sensitivity.csv, tornado.png and summary.json (entry `sensitivity`) into `folder`, atomically."""
    import json
    from pathlib import Path

    from mechsim.scenarios.output.atomic import atomic_folder, json_default
    from mechsim.scenarios.output.csv import write_csv
    folder = Path(folder)
    with atomic_folder(folder, force) as tmp:
        write_csv(table, tmp / "sensitivity.csv")
        fig = tornado_figure(table)
        fig.savefig(tmp / "tornado.png", dpi=110)
        summary = {"scenario": table.attrs.get("scenario"), "sensitivity": {
            "rows": table.to_dict("records"), "change_relative": table.attrs.get("change"),
            "cost": table.attrs.get("cost"), "warnings": table.attrs.get("warnings", []),
            "method": "forward sensitivities through the events (docs/sensitivity.md)"}}
        (tmp / "summary.json").write_text(json.dumps(summary, indent=2, default=json_default))
    return folder


# -- cycle averaging (thermal.averaging = "cycle"): the periodic turn's temperatures at their last time in the run
#: the columns the cycle-averaged bulk is made of: the drive angle (the turn's ends), the generated and pin energies
#: (the cycle means) and the contact of every row of the turn (its heat input, the ripple)
CYCLE_COLUMNS = CONTACT_COLUMNS + ("crank_angle_rad", "heat_generated_J", "heat_pin_J", "friction_power_W")
#: the contact columns of the network's heat input (thermal/coupling.py `heat_inputs`)
_INPUT_COLUMNS = ("contact_force_N", "crank_speed_rad_s", "wheel_speed_rad_s", "pin_sliding_speed_m_s",
                  "friction_power_W")


def cycle_window(plan):
    """The plan of a cycle-averaged scenario's mechanics window, resolved: the very run that cycle averaging
    averages (the runner integrates `plan.mechanics_duration`), with the DAE's bulk and bookkeeping states on every
    row and no periodic continuation."""
    return dataclasses.replace(plan, thermal=dataclasses.replace(plan.thermal, averaging="resolved"))


def _network(system, xp=np) -> dict:
    return {"capacity": xp.asarray(system.capacity), "conductance": xp.asarray(system.dense_conductance()),
            "source": xp.asarray(system.source), "input_matrix": xp.asarray(system.input_matrix)}


def cycle_temperatures(plan, df: pd.DataFrame) -> dict | None:
    """The contact temperature and flash rise of the periodic turn's rows at their last time in the run
    (docs/sensitivity.md, "Cycle averaging"): the rows inside the last full turn of the mechanics window (`df`,
    the run of `cycle_window(plan)`), each at t_k + M P in the last full turn of the scenario's duration, with the
    cycle-averaged bulk there (thermal/cycle_exact.py) under the row's flash rise and Blok share. None without a
    full turn. Keys: rows (indices into df), t_s, temp_contact_C, temp_flash_rise_K, layout, period, bulk."""
    from mechsim.thermal.contact_row import KELVIN
    from mechsim.thermal.cycle_exact import TurnLayout, turn_bulk, turn_ends
    setup, mech = plan.thermal.setup, plan.mechanism
    t = df["t_s"].to_numpy(float)
    angle = df["crank_angle_rad"].to_numpy(float)
    layout = TurnLayout.of(t, angle, float(plan.scenario.si["duration"]))
    if layout is None:
        return None
    inner, edges, data = layout.inner, layout.edges, layout.data()
    flash = df["temp_flash_rise_K"].to_numpy(float)[inner]
    share = df["heat_share_pin"].to_numpy(float)[inner]
    a, b = turn_ends(data["t_edges"], data["targets"], angle[edges])
    bulk = None
    if setup.system is None:
        base_pin = base_wheel = setup.temp_ambient
    else:
        u = setup.extension.inputs_numeric(mech.contact_state(df))[0].T
        bulk = turn_bulk(data, angle[edges], df["heat_generated_J"].to_numpy(float)[edges],
                         df["heat_pin_J"].to_numpy(float)[edges], u[edges], u[layout.padded],
                         _network(setup.system))[0][layout.pad:]
        names = list(setup.system.state_names)
        base_pin, base_wheel = bulk[:, names.index("temp_bulk_pin_K")], bulk[:, names.index("temp_bulk_wheel_K")]
    return {"rows": inner, "t_s": t[inner] + layout.periods * (b - a), "period": float(b - a), "layout": layout,
            "temp_flash_rise_K": flash, "bulk": bulk,
            "temp_contact_C": share * base_pin + (1.0 - share) * base_wheel + flash - KELVIN}


_CYCLE_FNS: dict = {}


def _cycle_bulk_fn(ext, distribution: str):
    """(x, data) -> (bulk, its jvp along the columns of dx) of the cycle-averaged bulk as a function of the traced
    values x (thermal/cycle_exact.py `turn_bulk`, the heat input of each row by thermal/coupling.py `heat_inputs`),
    jitted once per network and distribution (the turn's rows are padded, so a new design needs no new one)."""
    import jax
    import jax.numpy as jnp

    from mechsim.thermal.coupling import heat_inputs
    from mechsim.thermal.cycle_exact import turn_bulk
    B = np.asarray(ext.system.input_matrix)
    key = (ext.structure_key(), B.tobytes())
    fn = _CYCLE_FNS.get(key)
    if fn is not None:
        return fn, False

    def inputs(x, cols, engaged):
        contact = {"normal_force": cols[:, 0], "heat_rate": cols[:, 4],
                   "source_speed_driver": x["R"] * (cols[:, 1] + cols[:, 2]), "source_speed_driven": cols[:, 3]}
        u, _, _ = heat_inputs(contact, x.__getitem__, ext.inputs, distribution, jnp)
        return jnp.where(engaged[:, None], jnp.stack(u, axis=1), 0.0)

    def bulk(x, data):
        network = {"capacity": x["capacity"], "conductance": x["conductance"], "source": x["source"],
                   "input_matrix": jnp.asarray(B)}
        return turn_bulk(data, x["angle"], x["gen"], x["pin"], inputs(x, x["cols_edges"], data["engaged_edges"]),
                         inputs(x, x["cols_inner"], data["engaged_inner"]), network, jnp)[0]

    def both(x, dx, data):
        return bulk(x, data), jax.vmap(lambda d: jax.jvp(lambda y: bulk(y, data), (x,), (d,))[1])(dx)
    fn = _CYCLE_FNS[key] = jax.jit(both)
    return fn, True


def _cycle_bulk_samples(plan, df: pd.DataFrame, turn: dict, by_time: dict, seed, model, samples: list,
                        stats: dict) -> None:
    """Replace the bulk temperatures (values, gradients) of the samples at the turn's rows by the cycle-averaged
    ones: thermal/cycle_exact.py `turn_bulk` evaluated in jax on the run's rows and pushed forward (jvp) along the
    traced columns of every row of the turn (the drive angle and the energies at its ends, the contact that makes
    the heat input) and the network's and heat share's parameters. The jax evaluation must give the numpy one (to
    1e-9 K), as the row formulas must give the run's columns."""
    import jax.numpy as jnp

    from mechsim.dynamics.sensitivity import SensitivityUnavailable
    from mechsim.thermal.coupling import SHARE_PARAMETERS
    setup = plan.thermal.setup
    ext, sysm, layout = setup.extension, setup.system, turn["layout"]
    t = layout.t
    n = seed.n
    engaged = df["mode"].to_numpy() == "engaged"
    names = list(model.parameter_names)
    values = {**plan.mechanism.parameter_values(), **ext.parameter_values()}

    def parameter(name):
        return values[name], seed.dp[names.index(name)]

    def columns(cols, rows, contact=True):
        """The run's columns (primal) and the samples' gradients (tangent, rows x columns x n) at `rows`; with
        `contact`, rows without contact get 1 and no gradient (their heat input is masked to zero)."""
        x = np.ones((len(rows), len(cols)))
        dx = np.zeros((len(rows), len(cols), n))
        for r, i in enumerate(rows):
            if engaged[i] or not contact:
                x[r] = [float(df[c].iloc[i]) for c in cols]
                dx[r] = [by_time[float(t[i])].grads[c] for c in cols]
        return x, dx

    primal, tangent = {}, {}
    edges = layout.edges
    for key, col in (("angle", "crank_angle_rad"), ("gen", "heat_generated_J"), ("pin", "heat_pin_J")):
        x, dx = columns([col], edges, contact=False)
        primal[key], tangent[key] = x[:, 0], dx[:, 0]
    primal["cols_edges"], tangent["cols_edges"] = columns(_INPUT_COLUMNS, edges)
    primal["cols_inner"], tangent["cols_inner"] = columns(_INPUT_COLUMNS, layout.padded)
    for name in SHARE_PARAMETERS + ("R",):
        primal[name], tangent[name] = parameter(name)
    size = sysm.size
    for key, prefix, shape in (("capacity", "th_C_", (size,)), ("conductance", "th_K_", (size, size)),
                               ("source", "th_s_", (size,))):
        x, dx = np.zeros(shape), np.zeros(shape + (n,))
        for idx in np.ndindex(*shape):
            name = prefix + "_".join(map(str, idx))
            if name in values:
                x[idx], dx[idx] = parameter(name)
        primal[key], tangent[key] = x, dx
    reference = _network(sysm)
    for key in ("capacity", "conductance", "source"):
        if not np.allclose(primal[key], reference[key], rtol=1e-13, atol=0.0):
            raise SensitivityUnavailable(f"the network's {key} from the model's parameters is not the run's")
    data = {**layout.data(), "engaged_edges": engaged[edges], "engaged_inner": engaged[layout.padded]}
    x = {k: jnp.asarray(v, jnp.float64) for k, v in primal.items()}
    dx = {k: jnp.moveaxis(jnp.asarray(v, jnp.float64), -1, 0) for k, v in tangent.items()}
    fn, fresh = _cycle_bulk_fn(ext, setup.section["distribution"])
    wall = time.perf_counter()
    value, grads = fn(x, dx, data)
    if fresh:            # compiled on its first call (with a first evaluation of ~0.2 s): counted as compilation
        stats["compile_time_s"] += time.perf_counter() - wall
    value, grads = np.asarray(value)[layout.pad:], np.asarray(grads)[:, layout.pad:]      # grads: (n, rows, states)
    if not np.all(np.abs(value - turn["bulk"]) <= 1e-9 * np.maximum(1.0, np.abs(turn["bulk"]))):
        raise SensitivityUnavailable("the traced cycle-averaged bulk is not the one the quantity is read from "
                                     f"(difference {np.max(np.abs(value - turn['bulk'])):.2e} K)")
    state_names = list(sysm.state_names)
    where = {int(i): k for k, i in enumerate(layout.inner)}
    for s in samples:
        k = where[int(np.argmin(np.abs(t - s.t)))]
        for name in ("temp_bulk_pin_K", "temp_bulk_wheel_K"):
            j = state_names.index(name)
            s.values[name], s.grads[name] = float(value[k, j]), grads[:, k, j]
