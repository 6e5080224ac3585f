"""Validity monitors: the conditions a run's model needs (declared as data by the mechanism,
`Mechanism.validity_conditions`, and by the thermal model, `thermal/model_validity.py`), evaluated on every output row.

`section` is the summary's `validity`: per condition the share of the run's time it is violated, its worst value
(and when), the first violation; `stop` cuts a run at the first violating row for `output.on_invalid = "stop"`
(a Failure with code model_invalid: exit 3, what ran written). docs/theory.md, "Validity".
"""
from __future__ import annotations

from collections.abc import Mapping

import numpy as np
import pandas as pd

from mechsim.dynamics.result import Failure, FailureCode
from mechsim.mechanisms.base import ValidityCondition


def conditions(mech, thermal=None) -> list[ValidityCondition]:
    """The mechanism's conditions, then the thermal model's (plain dicts there, made ValidityCondition here)."""
    out = list(mech.validity_conditions())
    if thermal is not None:
        out += [ValidityCondition(**c) for c in thermal.validity_conditions()]
    return out


def _row_weights(t: np.ndarray) -> np.ndarray:
    """Each row's share of the run's time: half the intervals on either side (all equal for a single row)."""
    if len(t) < 2:
        return np.ones(len(t))
    dt = np.diff(t)
    w = np.zeros(len(t))
    w[:-1] += 0.5 * dt
    w[1:] += 0.5 * dt
    return w


def evaluate(conds: list[ValidityCondition], columns: Mapping[str, np.ndarray]) -> dict:
    """The summary's `validity` section of a table (`columns`: name -> array, a DataFrame's TableColumns):
    `valid` (no condition violated on any row), `violated` (their names) and per condition its bound, the time
    share violated, the worst value with its time, and the first violation's time (None if none)."""
    t = np.asarray(columns["t_s"], dtype=float) if "t_s" in columns else np.zeros(0)
    weights = _row_weights(t)
    total = float(weights.sum()) or 1.0
    rows = []
    for c in conds:
        row = {"name": c.name, "description": c.description, "bound": c.bound,
               "sense": "<=" if c.sense == "max" else ">=", "unit": c.unit, "source": c.source}
        missing = [n for n in c.needs if n not in columns]
        if missing or not len(t):
            rows.append({**row, "evaluated": False, "why": f"the table has no {', '.join(missing)}" if missing
                         else "no output rows"})
            continue
        values = np.broadcast_to(np.asarray(c.quantity(columns), dtype=float), t.shape)
        margin = c.margin(values)
        applies = np.isfinite(margin)
        bad = applies & (margin < 0)
        first = int(np.argmax(bad)) if bad.any() else None
        row.update(evaluated=True, applies_share=float(weights[applies].sum() / total),
                   violated_share=float(weights[bad].sum() / total), violated_rows=int(bad.sum()),
                   first_violation_t_s=None if first is None else float(t[first]),
                   first_violation_value=None if first is None else float(values[first]), worst=None)
        if applies.any():
            i = int(np.nanargmin(np.where(applies, margin, np.nan)))
            row["worst"] = {"value": float(values[i]), "t_s": float(t[i]), "margin": float(margin[i])}
        rows.append(row)
    violated = [r["name"] for r in rows if r.get("violated_rows")]
    return {"valid": not violated, "violated": violated, "conditions": rows}


def describe(row: dict) -> str:
    """One line of a violated condition: its share of time, worst value and when, the bound."""
    unit = f" {row['unit']}" if row["unit"] else ""
    w = row["worst"]
    return (f"{row['name']} violated {100 * row['violated_share']:.3g} % of the time (first at t = "
            f"{row['first_violation_t_s']:.6g} s; worst {w['value']:.4g}{unit} at t = {w['t_s']:.6g} s, must be "
            f"{row['sense']} {row['bound']:g}{unit}): {row['description']}")


def violation_lines(section: dict | None) -> list[str]:
    """The console's lines for a run's `validity` section: one warning per violated condition."""
    if not section:
        return []
    return [f"warning: the model leaves its validity: {describe(r)}" for r in section["conditions"]
            if r.get("violated_rows")]


def stop(section: dict, df: pd.DataFrame, events: pd.DataFrame, failure: Failure | None, mode_column: str = "mode"):
    """(table, events, failure) cut after the first row that violates a condition, that violation the run's
    failure (code model_invalid) unless an earlier failure stands; unchanged where every condition holds. The
    violating row is kept: it is a valid solution of the model that shows where the model stops holding."""
    firsts = [(r["first_violation_t_s"], r) for r in section["conditions"] if r.get("first_violation_t_s") is not None]
    if not firsts:
        return df, events, failure
    t_v, row = min(firsts, key=lambda item: item[0])
    if failure is not None and failure.time <= t_v:
        return df, events, failure
    t = df["t_s"].to_numpy(float)
    keep = t <= t_v
    mode = str(df[mode_column].to_numpy()[np.flatnonzero(keep)[-1]]) if mode_column in df and keep.any() else "?"
    unit = f" {row['unit']}" if row["unit"] else ""
    failure = Failure(time=t_v, mode=mode, reason=(
        f"the model leaves its validity: {row['name']} = {row['first_violation_value']:.4g}{unit}, must be "
        f"{row['sense']} {row['bound']:g}{unit} ({row['description']})"), kind="physics",
        code=FailureCode.MODEL_INVALID,
        hint="output.on_invalid = 'warn' runs on and lists every violation in summary.json (validity)")
    df = df[keep].reset_index(drop=True)
    if len(events):
        events = events[events["t_s"].to_numpy(float) <= t_v].reset_index(drop=True)
    return df, events, failure
