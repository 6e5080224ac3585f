"""The contact temperature of a Geneva output row as a traced function (docs/sensitivity.md, "Temperatures"):
the row's contact state, bulk temperatures, time since the contact began and the flash formulas' inputs pushed
through thermal/contact_row.py by their exact Jacobian, checked against the run's own columns."""
from __future__ import annotations

import time

import numpy as np
import pandas as pd


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


def thermal_samples(plan, df: pd.DataFrame, events: pd.DataFrame, path, samples: list, flash: dict) -> None:
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
