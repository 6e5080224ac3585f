"""Cross-check the two integrators: run a scenario on IDA and on diffrax at tight tolerances, compare column by column.

Both runs integrate the DAE (solver.method = 'dae', also for a prescribed speed) from the same derived model, so
their difference is integration error (and event location) only. Per column: the maximum absolute difference,
the maximum relative difference (absolute difference over the column's peak |value| in the IDA run, so that
zero crossings do not blow it up), and the time and drive angle where the absolute difference peaks.

Tolerances (pass/fail) follow the requested rtol, relative to the column's peak |value|: angles 1e3 rtol,
speeds 1e4 rtol, contact force 1e5 rtol (at the default rtol 1e-10: 1e-7, 1e-6, 1e-5); every other column is
reported only. Why: each integrator keeps its local error per step below rtol |y| + atol; the global error
sums those over the run, so it scales with rtol and with the size of the quantity. An unwrapped angle's
error is a phase error that grows with the angle travelled, hence a bound relative to its peak (a fixed
1e-7 rad failed rolling-a-torque at 32 rad, where IDA's BDF is 1.5e-7 rad = 47 rtol |angle| off the
reduced-coordinate reference and diffrax 1.4e-10 rad: integration error, not a fault). Speeds and the contact
force (a multiplier) sit one and two differentiations further down the DAE, each losing about a decade.
"""
from __future__ import annotations

from dataclasses import dataclass

import numpy as np
import pandas as pd

from mechsim.dynamics.result import Result
from mechsim.dynamics.tables import coordinate_columns

from mechsim.scenarios.loader import Scenario, build_mechanism, from_raw, load
from mechsim.scenarios.runner import run


@dataclass(frozen=True)
class Tolerance:
    """A pass/fail bound: `kind` "abs" (in the column's unit) or "rel" (fraction of the column's peak)."""

    kind: str
    value: float


#: bound / rtol per toleranced kind of column (module docstring)
FACTORS = {"angle": 1e3, "speed": 1e4, "contact force": 1e5}


def tolerance_for(column: str, rtol: float = 1e-10) -> Tolerance | None:
    """The tolerance of a column at the runs' rtol, or None (reported only)."""
    if column.endswith("_angle_rad"):
        return Tolerance("rel", FACTORS["angle"] * rtol)
    if "_speed_" in column:
        return Tolerance("rel", FACTORS["speed"] * rtol)
    if column == "contact_force_N":
        return Tolerance("rel", FACTORS["contact force"] * rtol)
    return None


def _scenario(scenario: str | Scenario, overrides: list[str], backend: str, rtol: float, atol: float,
              solver: str | None) -> Scenario:
    extra = [f"solver.backend='{backend}'", "solver.method='dae'", f"solver.rtol={rtol!r}", f"solver.atol={atol!r}"]
    if solver:
        extra.append(f"solver.diffrax_solver='{solver}'")
    if isinstance(scenario, Scenario):
        return from_raw(scenario.raw, scenario.source, list(overrides) + extra)
    return load(scenario, list(overrides) + extra)


def column_table(ida: pd.DataFrame, dfx: pd.DataFrame, angle_column: str, rtol: float = 1e-10) -> pd.DataFrame:
    """The per-column comparison of two timeseries on the same output grid (IDA is the reference)."""
    n = min(len(ida), len(dfx))
    a, b = ida.iloc[:n].reset_index(drop=True), dfx.iloc[:n].reset_index(drop=True)
    rows = []
    if "mode" in a and "mode" in b:
        mism = int((a["mode"].to_numpy() != b["mode"].to_numpy()).sum())
        rows.append(dict(column="mode (rows differing)", max_abs_diff=float(mism), max_rel_diff=np.nan,
                         t_s=np.nan, drive_angle_rad=np.nan, tolerance="report", passed=None))
    for col in a.columns:
        if col in ("t_s", "mode") or col not in b or not np.issubdtype(a[col].dtype, np.number):
            continue
        x, y = a[col].to_numpy(float), b[col].to_numpy(float)
        diff = np.abs(x - y)
        diff = np.where(np.isnan(x) & np.isnan(y), 0.0, diff)
        i = int(np.nanargmax(diff)) if n and not np.all(np.isnan(diff)) else 0
        worst = float(diff[i]) if n else 0.0
        if n and np.isnan(diff).any():
            worst = np.inf
        finite = np.abs(x[~np.isnan(x)])          # a column NaN on every row (both runs) has no scale: 0
        scale = float(finite.max()) if len(finite) else 0.0
        rel = worst / scale if scale > 0 else (0.0 if worst == 0 else np.inf)
        tol = tolerance_for(col, rtol)
        if tol is None:
            tol_text, passed = "report", None
        else:
            measured = worst if tol.kind == "abs" else rel
            tol_text = f"{tol.kind} <= {tol.value:g}"
            passed = bool(measured <= tol.value)
        rows.append(dict(column=col, max_abs_diff=worst, max_rel_diff=rel,
                         t_s=float(a["t_s"].iloc[i]) if n else np.nan,
                         drive_angle_rad=float(a[angle_column].iloc[i]) if n and angle_column in a else np.nan,
                         tolerance=tol_text, passed=passed))
    return pd.DataFrame(rows)


def compare(scenario: str | Scenario, overrides: list[str] | None = None, rtol: float = 1e-10,
            atol: float | None = None, diffrax_solver: str | None = None) -> pd.DataFrame:
    """Run `scenario` (name, file or loaded Scenario, plus --set style overrides) on IDA and diffrax; compare.

    Returns one row per column (see module docstring). `df.attrs` holds "passed" (every toleranced column
    within bounds, same number of rows and events, neither run failed), "rows", "events" (counts per backend),
    "event_time_max_diff_s", "failures" (messages) and "solver" (each run's solver statistics).
    Raises ScenarioError / ValueError for user errors (as `load` and `run` do).
    """
    overrides = list(overrides or [])
    atol = rtol * 1e-2 if atol is None else atol
    results: dict[str, Result] = {}
    for backend in ("ida", "diffrax"):
        results[backend] = run(_scenario(scenario, overrides, backend, rtol, atol, diffrax_solver))
    ida, dfx = results["ida"], results["diffrax"]
    si = ida.scenario
    mech = build_mechanism(si)
    k = mech.drive_coordinate
    angle_column = coordinate_columns(mech.coordinates[k], k in mech.angle_coordinates)[0]
    table = column_table(ida.timeseries, dfx.timeseries, angle_column, rtol)
    ev_a, ev_b = ida.events, dfx.events
    same_events = len(ev_a) == len(ev_b) and (len(ev_a) == 0 or
                                               list(ev_a["kind"]) == list(ev_b["kind"]))
    ev_dt = float(np.max(np.abs(ev_a["t_s"].to_numpy(float) - ev_b["t_s"].to_numpy(float)))) \
        if same_events and len(ev_a) else (0.0 if same_events else np.inf)
    failures = {b: r.failure.message() for b, r in results.items() if r.failure is not None}
    toleranced = table["passed"].dropna()
    passed = (bool(toleranced.astype(bool).all()) and len(ida.timeseries) == len(dfx.timeseries)
              and same_events and not failures)
    table.attrs.update(
        passed=passed, scenario=si["name"], rtol=rtol, atol=atol,
        rows={"ida": len(ida.timeseries), "diffrax": len(dfx.timeseries)},
        events={"ida": len(ev_a), "diffrax": len(ev_b)}, same_event_sequence=same_events,
        event_time_max_diff_s=ev_dt, failures=failures,
        solver={b: r.summary["solver"] for b, r in results.items()},
        diffrax_solver=dfx.summary["solver"].get("solver"),
    )
    return table


def render(table: pd.DataFrame, fmt: str) -> str:
    """The comparison as text: "csv" (the table, full precision), "json" (the run facts and the table's rows)
    or "text" (aligned plain columns, full precision; for pipes, where a rich table would cut the numbers)."""
    if fmt == "csv":
        return table.to_csv(index=False, float_format="%.17g")
    if fmt == "json":
        import json
        from mechsim.scenarios.output.atomic import json_default
        rows = [{k: (None if isinstance(v, float) and np.isnan(v) else v) for k, v in row.items()}
                for row in table.to_dict(orient="records")]
        return json.dumps({**table.attrs, "columns": rows}, indent=2, default=json_default) + "\n"
    if fmt != "text":
        raise ValueError(f"format must be csv, json or text, got {fmt!r}")
    cells = [["column", "max_abs_diff", "max_rel_diff", "t_s", "drive_angle_rad", "tolerance", "ok"]]
    for r in table.itertuples():
        cells.append([r.column, f"{r.max_abs_diff:.17g}", f"{r.max_rel_diff:.17g}", f"{r.t_s:.17g}",
                      f"{r.drive_angle_rad:.17g}", r.tolerance, "" if r.passed is None else ("yes" if r.passed else "NO")])
    return aligned(cells, left=(0, 5))


def aligned(cells: list[list[str]], left: tuple[int, ...] = (0,)) -> str:
    """Rows of text cells as plain aligned columns (those in `left` left-aligned, the rest right-aligned)."""
    widths = [max(len(row[i]) for row in cells) for i in range(len(cells[0]))]
    return "".join("  ".join(c.ljust(w) if i in left else c.rjust(w) for i, (c, w) in enumerate(zip(row, widths)))
                   .rstrip() + "\n" for row in cells)
