"""How scenario values enter a mechanism's model, for the design sensitivities (docs/sensitivity.md).

The headline quantities' names; the traced scenario keys of the mechanism (its `ParameterMap`,
`Mechanism.parameter_map`: its parameters as jax formulas of the values, in mechanisms/<name>/sensitivity.py), the
drive's and the thermal model's (`sensitivity_thermal_map.py`); the seed of the forward sensitivities
(`make_seed`), the check of the map against the mechanism rebuilt with each value moved, and the check of a request
(`check_request`: which values and quantities are traced on a plan).
"""
from __future__ import annotations

from collections import OrderedDict

import numpy as np

from mechsim.mechanisms.parameter_map import ParameterMap
from mechsim.scenarios.schema import did_you_mean
from mechsim.scenarios.studies.sensitivity_thermal_map import (THERMAL_KEYS, THERMAL_MATERIAL_KEYS, check_thermal,
                                                               thermal_parameters, thermal_values)
from mechsim.scenarios.units import ScenarioError


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
#: the quantities that name one extremum of a mechanical peak column (summary.json peaks.<column>), by prefix: the
#: located maximum and minimum (the headline: the periodic regime's where the run settles), and the start-up's
#: (`peaks.<column>.startup`, held only where the run settles); `peak_<column>` is the one of larger magnitude
SIDES = {"max_": "max", "min_": "min", "startup_max_": "startup_max", "startup_min_": "startup_min"}


def named_peak(q: str) -> tuple[str, str] | None:
    """(column, side) of a quantity that names one extremum of a mechanical peak column (`SIDES`: 'max', 'min',
    'startup_max', 'startup_min'), or None."""
    for prefix, side in SIDES.items():
        if q.startswith(prefix) and q[len(prefix):] in PEAKS.values():
            return q[len(prefix):], side
    return None


def extremum(entry: dict, side: str) -> dict | None:
    """The extremum `side` ('max', 'min', 'startup_max', 'startup_min') of a summary.json peaks entry, or None where
    the entry has none (a start-up is held only where the run settles)."""
    regime, _, side = side.rpartition("_")
    return (entry.get(regime) or {} if regime else entry).get(side)


def named_quantities(peaks: tuple[str, ...]) -> tuple[str, ...]:
    """The named extrema (`SIDES`) of the columns of the peak quantities `peaks` (PEAKS' names)."""
    return tuple(prefix + PEAKS[q] for prefix in SIDES for q in peaks if q in PEAKS)


def cycle_quantities(pmap: ParameterMap) -> tuple[str, ...]:
    """The event-based quantities, where the mechanism indexes (a continuously turning linkage does not); the heat
    per index where it has a sliding contact."""
    return (CYCLE + ((HEAT,) if pmap.sliding else ())) if pmap.engage else ()


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


def _path(key: str) -> list:
    """'mechanism.sprockets[1][0]' -> ['mechanism', 'sprockets', 1, 0] (a list entry as the loader's messages name
    it)."""
    out = []
    for part in key.split("."):
        name, *idx = part.split("[")
        out.append(name)
        out += [int(i.rstrip("]")) for i in idx]
    return out


def _lookup(si: dict, key: str):
    node = si
    for part in _path(key):
        node = node[part]
    return node


def _set(si: dict, key: str, value) -> None:
    *path, last = _path(key)
    node = si
    for part in path:
        node = node[part]
    node[last] = value


def scenario_value(plan, key: str) -> float:
    """A scenario value (SI); a material value the scenario leaves to the library is the library's."""
    if key in THERMAL_MATERIAL_KEYS and plan.thermal is not None:
        return float(getattr(plan.thermal.setup.material, key.split(".")[1]))
    return float(_lookup(plan.scenario.si, key) or 0.0)


def _traced_keys(plan, pmap: ParameterMap) -> list[str]:
    """Every value the map is a function of: the mechanism's, the drive's, the thermal model's (with the initial
    speed, which sets the thermal model's nominal speed, thermal/network.py `nominal_speed`)."""
    keys = list(pmap.keys) + list(pmap.list_keys(plan.scenario.si) if pmap.list_keys else ())
    keys += list(DRIVE_KEYS.get(plan.drive.kind, ()))
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
            out.update(thermal_parameters(x, si, plan.thermal.setup, pmap, drive.kind))
        return {k: jnp.asarray(v, jnp.float64) for k, v in out.items()}
    return params


def _reference_values(si: dict, mech, drive, thermal: bool) -> dict:
    return {**mech.parameter_values(), **drive.parameter_values(0.0), **(thermal_values(si, mech) if thermal else {})}


#: compiled programs by their lowered text (`compiled_once`), the most recently used last
_COMPILED: OrderedDict = OrderedDict()
_COMPILED_KEPT = 64


def compiled_once(lowered):
    """The executable of a lowered jax program, compiled once per process for each distinct program: the key is its
    StableHLO text (every operation, and every constant the closure baked in, printed exactly: a value that differs
    in its last bit is another program) and its argument and result pytrees. `make_seed` builds its closure anew for
    every plan, and jax.jit caches by the function object: a sizing, which evaluates the same formulas at a new
    design each iteration (the design values are the program's arguments), compiled the same program every time
    (docs/sensitivity.md has the measured cost)."""
    text = lowered.as_text()
    main = next(line for line in text.splitlines() if "func.func public @main(" in line)
    if main.split("->")[0].count("%arg") != lowered.in_tree.num_leaves:
        # constants hoisted into arguments (jax_use_simplified_jaxpr_constants) or arguments pruned: the text does
        # not say all that the program computes with, so it is not shared
        return lowered.compile()
    key = (text, str(lowered.in_tree), str(lowered.out_tree))
    hit = _COMPILED.get(key)
    if hit is None:
        hit = _COMPILED[key] = lowered.compile()
        if len(_COMPILED) > _COMPILED_KEPT:
            _COMPILED.popitem(last=False)
    else:
        _COMPILED.move_to_end(key)
    return hit


def make_seed(plan, model, wrt: list[str], pmap: ParameterMap):
    """(Seed with columns scaled by each value, scales, flash: name -> (n,) derivatives of the thermal formulas'
    inputs per scaled value): columns are d/d(ln theta) (theta for theta = 0), so that every sensitivity has the
    state's own units and one error control serves them all."""
    import jax
    from mechsim.dynamics.sensitivity import Seed
    si, mech, drive = plan.scenario.si, plan.mechanism, plan.drive
    keys = _traced_keys(plan, pmap)
    x0 = {k: scenario_value(plan, k) for k in keys}
    params = _mapped(plan, pmap, keys)
    values = _reference_values(si, mech, drive, plan.thermal is not None)
    # one compiled evaluation of the formulas and their Jacobian (op by op, jax would compile every operation)
    xs0 = np.array([x0[k] for k in keys])
    mapped, jac = compiled_once(jax.jit(lambda xs: (params(xs), jax.jacfwd(params)(xs))).lower(xs0))(xs0)
    jac = [jac[name] for name in mapped]
    for name, v in mapped.items():
        if not np.isclose(float(v), values[name], rtol=1e-13, atol=0.0):
            raise RuntimeError(f"sensitivity map of '{name}' gives {float(v)!r}, the mechanism {values[name]!r}")
    names = list(model.parameter_names)
    scales = np.array([abs(scenario_value(plan, k)) or 1.0 for k in wrt])
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
        if key == angle_key(mech):
            dq, dv = initial_angle_seed(plan, pmap, key)
            dq0[:, j], dv0[:, j] = dq * scales[j], dv * scales[j]
            if drive.is_prescribed:
                # the prescribed motion q = angle0 + speed (t - time0) starts at the initial angle
                dp[names.index("drive_angle0"), j] = scales[j]
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
    piece_dp = _piece_derivatives(plan, pmap, keys, x0, wrt, scales) if pmap.piece_parameters else None
    _check_map(plan, wrt, keys, mapped, jac, pmap)
    hold = mech.drive_coordinate if pmap.hold_drive else None
    return Seed(dp, dq0, dv0, pmap.discrete, dx0, piece_dp=piece_dp, hold=hold), scales, flash


#: the change of the initial angle within which the start must keep its mode (the default stated change of
#: `mechsim sensitivity`, 1 %, of the angle, or 0.01 rad for a start at zero)
INITIAL_CHANGE = 0.01


def angle_key(mech) -> str:
    """The scenario key of the drive coordinate's initial angle ('initial.crank_angle', 'initial.drive_angle')."""
    return f"initial.{mech.initial_keys[0]}"


def _start_mode(mech, angle: float, speed: float):
    """The initial mode and its discrete values at this angle, or why there is no start."""
    try:
        init = mech.initial_state(angle, speed)
    except ValueError as exc:
        return f"no start ({exc})"
    return init.mode, dict(init.updates)


def initial_angle_seed(plan, pmap: ParameterMap, key: str) -> tuple[np.ndarray, np.ndarray]:
    """(dq, dv) per radian of the initial angle: the derivative of the mechanism's initial guess
    (`ParameterMap.initial_angle`; with `hold_drive` the drive coordinate's unit vector, the assembly's hold
    completing the rest by the implicit-function rule on Phi(q) = 0 and G v + Phi_t = 0, dynamics/sensitivity.py
    `_ModePieces.hold`; without it the guess is consistent and the projection passes its exact derivative through).

    Refused (ScenarioError naming the key) where the start changes its mode or its discrete values (slot, flank,
    slip direction, dyad side, path piece) within INITIAL_CHANGE of the angle: the initial state jumps there and the
    derivative does not exist (or holds only for a smaller change). The guess's derivative is checked against central
    differences of `initial_state` (the coordinates the hold does not recompute; a mismatch is a bug: RuntimeError)."""
    mech, si, drive = plan.mechanism, plan.scenario.si, plan.drive
    angle = float(si["initial"][mech.initial_keys[0]])
    speed = drive.speed if drive.is_prescribed else float(si["initial"][mech.initial_keys[1]])
    delta = INITIAL_CHANGE * (abs(angle) or 1.0)
    try:
        here = _start_mode(mech, angle, speed)
        for side in (-delta, delta):
            there = _start_mode(mech, angle + side, speed)
            if there != here:
                if isinstance(there, str):
                    what = there
                else:
                    moved = [k for k in sorted(set(here[1]) | set(there[1])) if here[1].get(k) != there[1].get(k)]
                    what = f"mode '{there[0]}'" + (f", {', '.join(moved)} changed" if moved else "")
                raise ScenarioError(key, f"the start at {angle:.6g} rad (mode '{here[0]}') lies within {delta:.3g} "
                                    f"rad ({INITIAL_CHANGE:.0%}) of a change of the initial mode (at "
                                    f"{angle + side:.6g} rad: {what}): the initial state jumps there, so the "
                                    "derivative does not exist; move the start away from the boundary")
        nq = len(mech.coordinates)
        if pmap.initial_angle is not None:
            dq, dv = (np.asarray(a, float) for a in pmap.initial_angle(mech, angle, speed))
            check = np.ones(nq, bool)
        else:
            dq, dv = np.zeros(nq), np.zeros(nq)
            dq[mech.drive_coordinate] = 1.0
            check = np.arange(nq) == mech.drive_coordinate
        # central differences of the guess: truncation h^2 |q'''| / 6 ~ 1e-13, round-off eps |q| / h ~ 1e-10
        h = 1e-6
        plus, minus = mech.initial_state(angle + h, speed), mech.initial_state(angle - h, speed)
        for name, exact, fd in (("q", dq, (np.asarray(plus.q, float) - np.asarray(minus.q, float)) / (2 * h)),
                                ("v", dv, (np.asarray(plus.v, float) - np.asarray(minus.v, float)) / (2 * h))):
            size = max(1.0, float(np.max(np.abs(fd))))
            if not np.all(np.abs(exact - fd)[check] <= 1e-7 * size):
                raise RuntimeError(f"sensitivity map: the initial {name} moves by {fd} per radian of {key}, the map "
                                   f"says {exact}")
    finally:
        mech.initial_state(angle, speed)         # a mechanism that keeps its start's discrete state gets it back
    return dq, dv


_PIECE_FUNCTIONS: dict = {}


def _piece_function(plan, pmap: ParameterMap, x0: dict, cols: list[str]):
    """values -> ({parameter: value}, {parameter: (len(cols),) derivative}) of the parameters a transition sets for
    the mode whose values are `values` (`ParameterMap.piece_parameters`), in the values `cols`. One jitted function
    gives every piece's (compiled once per plan and columns: the travel numbers that say a piece's cycle and apex
    are its arguments)."""
    import jax
    si, mech = plan.scenario.si, plan.mechanism
    key = (id(mech), tuple(cols), tuple(sorted(x0.items())))
    hit = _PIECE_FUNCTIONS.get(key)
    if hit is not None and hit[0] is mech:
        return hit[1]
    segments = sorted({int(v["seg"]) for v in pmap.pieces(mech)})
    xw0 = np.array([x0[k] for k in cols], float)

    def f(xw, num):
        x = {**x0, **dict(zip(cols, xw))}
        return [pmap.piece_parameters(x, si, mech, {**num, "seg": k}) for k in segments]

    @jax.jit
    def value_and_jacobian(xw, num):
        return f(xw, num), jax.jacfwd(f)(xw, num)

    def evaluate(values: dict):
        i = segments.index(int(values["seg"]))
        num = {name: float(values[name]) for name in ("s0", "s1", "s_apex")}
        got, jac = value_and_jacobian(xw0, num)
        return ({name: float(v) for name, v in got[i].items()},
                {name: np.asarray(d, float).reshape(len(cols)) for name, d in jac[i].items()})
    _PIECE_FUNCTIONS.clear()
    _PIECE_FUNCTIONS[key] = (mech, evaluate)
    return evaluate


def _piece_derivatives(plan, pmap: ParameterMap, keys: list[str], x0: dict, wrt: list[str], scales):
    """values -> {parameter: (n,) derivative per scaled value} of the parameters a transition sets
    (`_piece_function`), checked against those values (a piece the formulas do not reproduce stops the
    computation)."""
    cols = [k for k in wrt if k in keys]
    evaluate = _piece_function(plan, pmap, x0, cols)
    size = plan.mechanism.path.length if hasattr(plan.mechanism, "path") else 1.0

    def piece_dp(values: dict) -> dict:
        got, jac = evaluate(values)
        out = {}
        for name, v in got.items():
            ref = values[name]
            if not abs(v - ref) <= 1e-12 * max(abs(ref), size):
                raise RuntimeError(f"sensitivity map of the transition's '{name}' gives {v!r}, the mechanism {ref!r}")
            out[name] = np.zeros(len(wrt))
            for c, key in enumerate(cols):
                j = wrt.index(key)
                out[name][j] = jac[name][c] * scales[j]
        return out
    return piece_dp


def _check_map(plan, wrt: list[str], keys: list[str], mapped: dict, jac, pmap: ParameterMap) -> None:
    """The map must be complete and right: the mechanism (and thermal model) rebuilt with each traced value moved
    (central differences, 1e-5 relative) changes no parameter the map does not set, and those it sets by the map's
    derivative (to 1e-6 of the parameter's size: the differences' truncation is ~1e-10, their round-off ~1e-11). A
    RuntimeError otherwise: a map out of step with the mechanism is a bug, not a user error."""
    import copy

    from mechsim.scenarios.loader import build_mechanism
    from mechsim.scenarios.runner import make_drive
    si, drive = plan.scenario.si, plan.drive
    moved_pieces = {}
    for key in wrt:
        if key not in keys:
            continue
        p = scenario_value(plan, key)
        h = 1e-5 * abs(p) if p else 1e-5
        values, pieces = [], []
        for sign in (1, -1):
            moved = copy.deepcopy(si)
            _set(moved, key, p + sign * h)
            mech = build_mechanism(moved)
            values.append(_reference_values(moved, mech, make_drive(moved), plan.thermal is not None))
            pieces.append(pmap.pieces(mech) if pmap.pieces else [])
        col = keys.index(key)
        derivative = dict(zip(mapped, (float(np.asarray(row)[col]) for row in jac)))
        for name in values[0]:
            fd = (values[0][name] - values[1][name]) / (2 * h)
            exact = derivative.get(name, 0.0)
            size = max(abs(values[0][name]), abs(exact) * max(abs(p), 1.0), 1e-300)
            if abs(fd - exact) * max(abs(p), h) > 1e-6 * size:
                raise RuntimeError(f"sensitivity map: '{name}' moves by {fd:.6g} per unit of {key}, the map says "
                                   f"{exact:.6g} ({drive.kind} drive)")
        moved_pieces[key] = (pieces, p, h)
    _check_pieces(plan, keys, pmap, moved_pieces)


def _check_pieces(plan, keys: list[str], pmap: ParameterMap, moved: dict) -> None:
    """The values transitions set (`ParameterMap.pieces`) checked like the parameters: the formulas' derivative
    against the central difference of the mechanism rebuilt with each value moved (moved: key -> (the rebuilt
    mechanisms' pieces at +h and -h, the value, h)), to the same tolerance."""
    if not pmap.pieces or not moved:
        return
    cols = list(moved)
    evaluate = _piece_function(plan, pmap, {k: scenario_value(plan, k) for k in keys}, cols)
    for idx, values in enumerate(pmap.pieces(plan.mechanism)):
        _, jac = evaluate(values)
        for c, key in enumerate(cols):
            (plus, minus), p, h = moved[key]
            for name in values:
                if name in pmap.discrete:
                    continue
                fd = (plus[idx][name] - minus[idx][name]) / (2 * h)
                exact = float(jac[name][c]) if name in jac else 0.0
                size = max(abs(values[name]), abs(exact) * max(abs(p), 1.0), 1e-300)
                if abs(fd - exact) * max(abs(p), h) > 1e-6 * size:
                    raise RuntimeError(f"sensitivity map: the transition's '{name}' (piece {int(values['seg'])}) "
                                       f"moves by {fd:.6g} per unit of {key}, the map says {exact:.6g}")


#: scenario keys that make a load or drive vary in time or by station: their runs are not traced
TIME_VARYING_KEYS = ("load.wheel_torque_per_station", "load.wheel_torque_profile", "drive.duty_on")


def check_request(plan, wrt: list[str], of: list[str]) -> ParameterMap:
    """The mechanism's ParameterMap, after checking that every value in `wrt` and every quantity in `of` is traced
    on this plan (ScenarioError naming the first that is not; `mechsim size` checks its requests with it too)."""
    si = plan.scenario.si
    mtype = si["mechanism"]["type"]
    pmap = plan.mechanism.parameter_map()
    if pmap is None:
        raise ScenarioError("mechanism.type", f"sensitivities are not traced for '{mtype}' (docs/sensitivity.md)")
    for key in TIME_VARYING_KEYS:
        section, name = key.split(".")
        if si.get(section, {}).get(name) is not None:
            raise ScenarioError(key, "sensitivities through a time-varying load or drive (per station, a profile, "
                                     "a duty cycle) are not traced; remove it to trace the others")
    if plan.thermal is not None:
        check_thermal(plan, pmap, mtype)
    allowed = _traced_keys(plan, pmap) + ([] if plan.drive.is_prescribed else [pmap.speed_key])
    allowed.append(angle_key(plan.mechanism))
    allowed = list(dict.fromkeys(allowed))
    if not wrt:
        raise ScenarioError("--wrt", f"name at least one scenario value; traced here: {', '.join(allowed)}")
    for key in wrt:
        why = pmap.refuse(plan, key) if pmap.refuse else None
        if key == angle_key(plan.mechanism) and plan.thermal is not None and plan.thermal.averaging == "cycle":
            why = ("with cycle averaging the periodic turn is measured from the start angle (thermal/cycle_exact.py "
                   "`TurnLayout`), and that dependence is not differentiated; use thermal.averaging = 'resolved'")
        if why:
            raise ScenarioError(key, f"not traced on this design: {why}")
        if (key in pmap.keys or key in THERMAL_KEYS) and key not in THERMAL_MATERIAL_KEYS and (
                _lookup_or_none(si, key) is None):
            raise ScenarioError(key, "not set in this scenario (it is derived from other values): set it to trace it")
        if key not in allowed:
            raise ScenarioError(key, f"not a value sensitivities are traced for here{did_you_mean(key, allowed)}; "
                                     f"traced: {', '.join(allowed)}")
    if len(set(wrt)) != len(wrt):
        raise ScenarioError("--wrt", "a key is named twice")
    known = traced_quantities(plan, pmap)
    named = named_quantities(pmap.peaks)
    for q in of:
        if q in THERMAL_PEAKS and plan.thermal is None:
            raise ScenarioError("--of", f"{q}: this scenario has no thermal model (set thermal.model = 'lumped' or "
                                "'flash')")
        if q in THERMAL_PEAKS and getattr(plan.mechanism, "impacts", False):
            raise ScenarioError("--of", f"{q}: the impacts' heat enters the thermal network after the run "
                                "(thermal/plan.py) and is not traced; the mechanical quantities are")
        if q not in known and q not in named:
            columns = ", ".join(PEAKS[p] for p in pmap.peaks if p in PEAKS)
            hint = did_you_mean(q, [*known, *named])
            raise ScenarioError("--of", f"unknown quantity {q!r} for this mechanism{hint}; one of {', '.join(known)}; "
                                f"or {'/'.join(SIDES)}<column> of the columns {columns}")
    return pmap


def _lookup_or_none(si: dict, key: str):
    try:
        return _lookup(si, key)
    except (KeyError, IndexError, TypeError):
        return None


def traced_quantities(plan, pmap: ParameterMap) -> tuple[str, ...]:
    """The quantities traced on this plan: the thermal peaks where a thermal model runs and no impact heats it
    (the impacts' heat is added to the network after the run, not traced)."""
    thermal = tuple(THERMAL_PEAKS) if plan.thermal is not None and not getattr(plan.mechanism, "impacts", False) else ()
    return pmap.peaks + thermal + cycle_quantities(pmap)
