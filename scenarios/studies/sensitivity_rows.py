"""The contact temperature of an output row as a traced function (docs/sensitivity.md, "Temperatures"): the
row's contact state (the mechanism's `ParameterMap.contact_row` of its `contact_columns`), bulk temperatures, time
since the contact began and the flash formulas' inputs pushed through thermal/contact_row.py by their exact
Jacobian, checked against the run's own columns."""
from __future__ import annotations

import time

import numpy as np
import pandas as pd


FLASH_INPUTS = ("flash_mu", "flash_R", "flash_l", "flash_Estar", "flash_k", "flash_chi")
#: the 1-D wall-track model's extra inputs of the wall surface (sensitivity_thermal_map.py): the first cell's
#: width, the track area, the share's reference time; then the share's floor half-width b0 (a constant)
WALL_INPUTS = ("flash_dz0", "flash_track_area", "flash_t_ref")


def row_state_columns(names) -> set[str]:
    """The thermal states a row's contact temperature reads: the bulk temperatures and, with the 1-D wall-track
    model, every track's surface cell (temp_wall_<track>_0_K)."""
    return {c for c in names if c.startswith("temp_bulk_") or (c.startswith("temp_wall_") and c.endswith("_0_K"))}


def _row_temperatures(u, pmap, distribution: str, xp=np, wall: bool = False):
    """(flash rise K, contact temperature degC[, wall surface K]) of one row from u = [contact columns, base_pin,
    base_wheel, t_on_pin, FLASH_INPUTS] (+ [WALL_INPUTS, b0] with `wall`): the mechanism's contact state of the row
    (`ParameterMap.contact_row` of its `contact_columns`) with the contact radius traced, then
    thermal/contact_row.py `contact_temperature` (docs/theory.md §G3-§G4.6). With `wall` (thermal.model = "1d")
    base_wheel is the surface cell T_0 of the track in contact and the wheel's base temperature is the track's
    surface, T_0 + q dz_0/(2k) with q = (1 - gamma) Q / A the heat into the track per area (thermal/plan.py
    `_wall_surface`; gamma the DAE's smooth share, thermal/coupling.py `heat_share_pin`, docs/thermal.md
    "Coupling"; Q = mu |N| |u_slip|, docs/theory.md §G4.1)."""
    from mechsim.thermal.contact_row import KELVIN, contact_temperature
    nc = len(pmap.contact_columns)
    base_pin, base_wheel, t_on, mu, R, length, estar, k, chi = (u[i] for i in range(nc, nc + 9))
    contact = pmap.contact_row([u[i] for i in range(nc)], R, xp)
    N, slip = contact["normal_force"], contact["slip_speed"]
    if wall:
        from mechsim.thermal.coupling import heat_share_pin
        dz0, area, t_ref, b0 = (u[i] for i in range(nc + 9, nc + 13))
        P = {"th_R": R, "th_l": length, "th_Estar": estar, "th_b0": b0, "th_k_pin": k, "th_k_wheel": k,
             "th_chi_pin": chi, "th_chi_wheel": chi, "th_t_ref": t_ref}
        gamma = heat_share_pin(contact, P.__getitem__, distribution, xp)
        q = (1 - gamma) * (mu * xp.abs(N) * xp.abs(slip)) / area
        base_wheel = base_wheel + q * dz0 / (2 * k)
    out = contact_temperature(contact, t_on, base_pin, base_wheel, mu, R, length, estar, k, chi, distribution, xp)
    values = [out["temp_flash_rise_K"], out["temp_contact_K"] - KELVIN] + ([base_wheel] if wall else [])
    return xp.stack(values)


_ROW_JACOBIANS: dict = {}


def _row_jacobian(pmap, distribution: str, wall: bool = False):
    """(u -> (values, Jacobian) of `_row_temperatures`, seconds spent compiling it now): compiled ahead of time once
    per process, mechanism's contact row, distribution and model (bulk/ambient base or the 1-D wall's surface)."""
    import jax
    import jax.numpy as jnp
    key = (pmap.contact_row, pmap.contact_columns, distribution, wall)
    fn = _ROW_JACOBIANS.get(key)
    if fn is not None:
        return fn, 0.0
    wall_time = time.perf_counter()

    def f(u):
        return _row_temperatures(u, pmap, distribution, jnp, wall)
    size = len(pmap.contact_columns) + (13 if wall else 9)
    fn = _ROW_JACOBIANS[key] = jax.jit(lambda u: (f(u), jax.jacfwd(f)(u))).lower(
        np.ones(size)).compile()
    return fn, time.perf_counter() - wall_time


def thermal_samples(plan, df: pd.DataFrame, events: pd.DataFrame, path, samples: list, flash: dict) -> None:
    """Add the flash rise and the contact temperature (values and gradients per scaled value) to the samples at
    thermal peak rows: the traced columns and bulk states at the row, the time since the contact began (the last
    entry or flank switch: its time's derivative from the implicit-function rule), and the thermal formulas'
    inputs, pushed through the row's formulas by their exact Jacobian (jax). The formulas are first checked to
    give the run's own columns at the row (they are the thermal finish's, thermal/plan.py); with the 1-D wall-track
    model the wheel's base is the surface of the track in contact, from its surface cell (`_check_wall_surface`)."""
    from mechsim.dynamics.sensitivity import SensitivityUnavailable
    setup = plan.thermal.setup
    distribution = setup.section["distribution"]
    wall = setup.mesh is not None
    pmap = plan.mechanism.parameter_map()
    starts = [e for e in path.events if e.kind in pmap.contact_starts]
    fn, path.stats["row_compile_time_s"] = _row_jacobian(pmap, distribution, wall)
    path.stats["compile_time_s"] += path.stats["row_compile_time_s"]
    t_all = df["t_s"].to_numpy(float)
    # the rows in contact: a sample next to an exit (a peak's one-sided limit) is checked on the row of its own
    # contact, not on the dwell's row after it (no contact temperature there)
    contact = np.flatnonzero(np.isfinite(df["temp_contact_C"].to_numpy(float)))
    for s in samples:
        prior = [e for e in starts if e.t <= s.t + 1e-12]
        if not prior:
            raise SensitivityUnavailable(f"the contact at t = {s.t:.6g} s began before the run started: the time "
                                         "since its start is not traced (start the run in a dwell)")
        start = prior[-1]
        n = len(start.dt)
        near = contact if len(contact) else np.arange(len(t_all))
        row = int(near[np.argmin(np.abs(t_all[near] - s.t))])
        if setup.system is not None:
            names = ("temp_bulk_pin_K", _wall_state(plan, df, row) if wall else "temp_bulk_wheel_K")
            base = [s.values[c] for c in names]
            dbase = [s.grads[c] for c in names]
        else:
            base = [setup.temp_ambient] * 2
            dbase = [flash["flash_T_amb"]] * 2
        extra = WALL_INPUTS if wall else ()
        u = np.array([s.values[c] for c in pmap.contact_columns] + base + [s.t - start.t]
                     + [_flash_value(setup, plan, name) for name in FLASH_INPUTS + extra]
                     + ([setup.extension.share.b0] if wall else []))
        du = np.vstack([s.grads[c] for c in pmap.contact_columns] + dbase + [-start.dt]
                       + [flash[name] for name in FLASH_INPUTS + extra] + ([np.zeros(len(dbase[0]))] if wall else []))
        # (rows a turn apart may hold no contact at all: the formulas are then checked on no row of this run, as
        # they are on every run that has one)
        if len(contact):
            _check_row_formula(plan, df, events, row, distribution)
        if wall and len(contact) and abs(float(t_all[row]) - s.t) <= 1e-9 * max(1.0, abs(s.t)):
            # the surface check needs the row's own contact with the sample's T_0: at a located instant between
            # rows it is made where a sample falls on a row (the formulas are the same at every instant)
            _check_wall_surface(plan, df, row, u, distribution)
        values, jac = (np.asarray(a) for a in fn(u))
        grads = jac @ du
        for i, column in enumerate(("temp_flash_rise_K", "temp_contact_C")):
            s.values[column], s.grads[column] = float(values[i]), grads[i][:n]


def _flash_value(setup, plan, name: str) -> float:
    from mechsim.thermal.hertz import effective_modulus
    mat, geo = setup.material, setup.geometry
    return {"flash_mu": float(plan.scenario.si["contact"]["friction"]), "flash_R": geo.contact_radius,
            "flash_l": geo.contact_length, "flash_Estar": effective_modulus(mat), "flash_k": mat.conductivity,
            "flash_chi": mat.diffusivity, "flash_dz0": float(setup.mesh.widths[0]) if setup.mesh else None,
            "flash_track_area": setup.track_area,
            "flash_t_ref": setup.extension.share.t_ref if setup.extension else None}[name]


def _track(plan, df: pd.DataFrame, row: int) -> int:
    """The track in contact at the row (its slot wall; thermal/coupling.py `heat_inputs`)."""
    track = plan.mechanism.contact_state(df.iloc[[row]])["track"]
    return int(np.mod(np.rint(np.asarray(track, float)[0]), plan.thermal.setup.geometry.tracks))


def _wall_state(plan, df: pd.DataFrame, row: int) -> str:
    """The DAE state of the surface cell of the track in contact at the row."""
    setup = plan.thermal.setup
    return setup.system.state_names[setup.mesh_states[_track(plan, df, row)][0]]


def _check_wall_surface(plan, df: pd.DataFrame, row: int, u: np.ndarray, distribution: str) -> None:
    """The traced wall surface (from the pass's surface cell T_0 at the row) equals the run's own finish on the same
    T_0: the DAE's heat inputs of the row (`ThermalExtension.inputs_numeric`) and thermal/plan.py `_wall_surface`
    (to 1e-9), so that the surface correction cannot drift from the run's unnoticed. (The run's table does not
    keep T_0; its temp_wall_surface_C enters `_check_row_formula` as the wheel's base.)"""
    from mechsim.dynamics.sensitivity import SensitivityUnavailable
    setup = plan.thermal.setup
    contact = plan.mechanism.contact_state(df.iloc[[row]])
    inputs, _, _ = setup.extension.inputs_numeric(contact)
    states = np.zeros((1, setup.system.size + 3))
    pmap = plan.mechanism.parameter_map()
    states[0, setup.mesh_states[_track(plan, df, row)][0]] = u[len(pmap.contact_columns) + 1]   # the wheel's base
    theirs = float(plan.thermal._wall_surface(states, inputs, contact["track"])[0])
    mine = float(_row_temperatures(u, pmap, distribution, np, wall=True)[2])
    if not abs(mine - theirs) <= 1e-9 * max(1.0, abs(theirs)):
        raise SensitivityUnavailable(f"the traced wall surface gives {mine!r} K at t = {float(df['t_s'].iloc[row]):.6g} "
                                     f"s, the run's finish {theirs!r} K: not the run's 1-D wall model")


def _check_row_formula(plan, df: pd.DataFrame, events: pd.DataFrame, row: int, distribution: str) -> None:
    """The row formulas evaluated on the run's own row give the run's flash and contact temperature columns (to
    1e-9): the differentiated formulas cannot drift away from the thermal finish unnoticed. With the 1-D wall the
    wheel's base is the run's temp_wall_surface_C (its own formula is `_check_wall_surface`'s)."""
    from mechsim.dynamics.sensitivity import SensitivityUnavailable
    setup = plan.thermal.setup
    r = df.iloc[row]
    t = float(r["t_s"])
    starts = plan.mechanism.contact_starts(df, events)
    start = starts[np.searchsorted(starts, t + 1e-12, side="right") - 1]
    if setup.system is not None:
        wheel = "temp_wall_surface_C" if setup.mesh is not None else "temp_bulk_wheel_C"
        base = [float(r["temp_bulk_pin_C"]) + 273.15, float(r[wheel]) + 273.15]
    else:
        base = [setup.temp_ambient] * 2
    pmap = plan.mechanism.parameter_map()
    u = np.array([float(r[c]) for c in pmap.contact_columns] + base + [t - start]
                 + [_flash_value(setup, plan, name) for name in FLASH_INPUTS])
    mine = _row_temperatures(u, pmap, distribution, np)
    theirs = np.array([float(r["temp_flash_rise_K"]), float(r["temp_contact_C"])])
    if not np.all(np.abs(mine - theirs) <= 1e-9 * np.maximum(1.0, np.abs(theirs))):
        raise SensitivityUnavailable(f"the traced thermal formulas give {mine} at t = {t:.6g} s, the run "
                                     f"{theirs}: not the run's thermal model")
