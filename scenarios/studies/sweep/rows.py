"""One sweep-table row from one run: varied parameters (SI), summary figures, cycle figures, solver statistics.

Column names follow the house rule `<quantity>_<unit>`; a varied key keeps its scenario path and gets its SI
unit appended (`load.wheel_torque_N_m`, `contact.friction`).
"""
from __future__ import annotations

import hashlib
import json
import math

import numpy as np
import pandas as pd

from mechsim.dynamics.tables import TableColumns
from mechsim.scenarios.keys import field_unit, lookup, unit_suffix
from mechsim.scenarios.loader import Scenario

#: figures plotted against each varied parameter (those present in the table)
KEY_FIGURES = ("peak_max_contact_force_N", "peak_max_drive_torque_N_m", "peak_min_drive_torque_N_m",
               "peak_max_wheel_accel_rad_s2", "peak_min_wheel_accel_rad_s2", "peak_max_slip_speed_m_s",
               "peak_min_slip_speed_m_s", "peak_max_friction_power_W", "peak_max_temp_contact_C", "cycle_time_s",
               "work_drive_per_cycle_J",
               "work_friction_per_cycle_J", "peak_impulse_N_s", "impacts_per_turn_max", "case_wall_time_s")


def parameter_columns(sc: Scenario, keys: list[str]) -> dict:
    """The varied keys' resolved (SI) values, keyed by column name."""
    out = {}
    for key in keys:
        unit = field_unit(sc.si, key)
        out[f"{key}_{unit_suffix(unit)}" if unit else key] = lookup(sc.si, key)
    return out


def case_key(sc: Scenario, overrides: list[str], base_raw: dict) -> str:
    """The case's identity: a hash of the base scenario as written and the case's overrides resolved to SI.

    Resolving makes '5 N*m' and '5000 N*mm' one case; leaving out the defaults the loader fills in keeps finished
    cases valid when the schema gains a defaulted key. A changed scenario file changes every key.
    """
    from mechsim.scenarios.loader import parse_override
    resolved = {}
    for text in overrides:
        path, value = parse_override(text)
        key = ".".join(path)
        try:
            resolved[key] = lookup(sc.si, key)
        except (KeyError, TypeError):
            resolved[key] = value
    text = json.dumps({"scenario": base_raw, "overrides": resolved}, sort_keys=True, default=str)
    return hashlib.sha256(text.encode()).hexdigest()[:16]


def cycle_figures(df: pd.DataFrame, angle_col: str | None, regime: dict | None = None,
                  speed_col: str | None = None) -> dict:
    """Figures of the last complete drive revolution: its duration and the work of each power flow over it.

    The revolution boundaries are the first instants the drive angle has advanced 2 pi k from its start. The last
    one is used because the first may hold a start-up transient (a motor running up). Where the run reached a
    periodic regime (`regime`, the summary's), its last turn is this one, located on the continuous solution with
    the works read there (scenarios/peaks.py `periodic_regime`); otherwise the boundaries are the roots of the
    cubic Hermite interpolant of the angle and its speed (`speed_col`) between rows and the works the cubic through
    the rows around them (scenarios/turns.py: O(h^4) in the output step h), linear between rows only without the
    speed. Not defined (NaN, cycles = 0) when the drive is not an angle or has not completed a turn.
    """
    from mechsim.scenarios.turns import crossings, cubic_at
    out = {"cycles": 0, "cycle_time_s": math.nan}
    work_cols = [c for c in df.columns if c.startswith("work_") and c.endswith("_J")]
    for c in work_cols:
        out[f"{c[:-2]}_per_cycle_J"] = math.nan
    if angle_col is None or angle_col not in df or len(df) < 2:
        return out
    cols = TableColumns(df)                         # each column read once, from the frame's blocks
    t = np.asarray(cols["t_s"], dtype=float)
    theta = np.asarray(cols[angle_col], dtype=float)
    advance = theta - theta[0]
    sign = 1.0 if advance[-1] >= 0 else -1.0
    advance = sign * advance
    turns = int(np.floor(np.nanmax(advance) / (2 * np.pi) + 1e-12))
    if turns < 1:
        return out
    out["cycles"] = turns
    located = (regime or {}).get("last_turn")
    if located is not None and "last_turn_work_J" in regime:
        t0, t1 = (float(x) for x in located)
        out["cycle_time_s"] = t1 - t0
        for c in work_cols:
            out[f"{c[:-2]}_per_cycle_J"] = float(regime["last_turn_work_J"].get(c[5:-2], math.nan))
        return out
    speed = sign * np.asarray(cols[speed_col], dtype=float) if speed_col is not None and speed_col in df else None
    ends = crossings(t, advance, speed, 0.0)
    if len(ends) >= turns:
        t0, t1 = (float(t[0]) if turns == 1 else float(ends[turns - 2])), float(ends[turns - 1])
    else:                                           # the angle not increasing throughout: the first crossings
        def crossing(level: float) -> float:
            if level == 0.0:
                return t[0]
            j = int(np.argmax(advance >= level))
            a0, a1 = advance[j - 1], advance[j]
            return float(t[j - 1] + (level - a0) / (a1 - a0) * (t[j] - t[j - 1])) if a1 != a0 else float(t[j])
        t0, t1 = crossing(2 * np.pi * (turns - 1)), crossing(2 * np.pi * turns)
    out["cycle_time_s"] = t1 - t0
    for c in work_cols:
        w0, w1 = cubic_at(t, np.asarray(cols[c], dtype=float), np.array([t0, t1]))
        out[f"{c[:-2]}_per_cycle_J"] = float(w1 - w0)
    return out


def _scalar(v) -> bool:
    return v is None or isinstance(v, (bool, int, float, str, np.floating, np.integer))


def summary_row(summary: dict) -> dict:
    """The summary flattened: peaks with time and drive angle, each column's mean over the last turn, energy, events,
    solver statistics, model."""
    row: dict = {"success": bool(summary.get("success")), "failure": summary.get("failure") or ""}
    model = summary.get("model", {})
    for k in ("drive", "method", "backend", "formulation", "thermal"):
        row[f"model_{k}"] = model.get(k)
    for col, pk in summary.get("peaks", {}).items():
        # the located maximum and minimum (summary.json peaks), signed: the headline (the periodic regime's where
        # the run settles) and, where it settles, the start-up's (`startup`)
        for prefix, sides in (("", pk), ("startup_", pk.get("startup") or {})):
            for side in ("max", "min"):
                if side in sides:
                    row[f"{prefix}peak_{side}_{col}"] = sides[side]["value"]
                    row[f"{prefix}peak_{side}_{col}_at_t_s"] = sides[side]["t_s"]
                    row[f"{prefix}peak_{side}_{col}_at_drive_angle_deg"] = sides[side]["drive_angle_wrapped_deg"]
        turn = pk.get("periodic") or pk.get("cycle")
        if turn is not None:                # the located mean over the last turn (None: unbounded, or not defined)
            row[f"cycle_mean_{col}"] = turn["mean"]
    energy = summary.get("energy") or {}
    for name, w in (energy.get("work_J") or {}).items():
        row[f"work_{name}_J"] = w
    if "closure_error_relative" in energy:
        row["energy_closure_error_relative"] = energy["closure_error_relative"]
    for kind, n in (summary.get("events") or {}).items():
        row[f"events_{kind.replace(' ', '_')}"] = n
    impacts = summary.get("impacts")
    if impacts:                                     # contacts with impacts (slot clearance)
        row["peak_impulse_N_s"] = impacts["peak_impulse_N_s"]
        row["impacts_per_turn_max"] = impacts["impacts_per_turn_max"]
        row["impacts_per_turn_mean"] = impacts["impacts_per_turn_mean"]
        row["impacts_energy_lost_J"] = impacts["energy_lost_J"]
        if "peak_force_N" in impacts:               # the compliant contact's located peak force
            row["peak_impact_force_N"] = impacts["peak_force_N"]
    lock = summary.get("lock_impacts")
    if lock:                                        # the wheel's impacts in its locking play (lock clearance)
        row["lock_peak_impulse_N_s"] = lock["peak_impulse_N_s"]
        row["lock_impacts"] = lock["count"]
        row["lock_impacts_energy_lost_J"] = lock["energy_lost_J"]
    for k, v in (summary.get("solver") or {}).items():
        if _scalar(v) and not k.endswith("_note"):
            row[f"solver_{k}"] = v
    row["max_constraint_residual_m"] = summary.get("max_constraint_residual_m")
    row["warnings"] = len(summary.get("warnings") or [])
    return row
