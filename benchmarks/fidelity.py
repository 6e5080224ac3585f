"""Model no more than a scene needs: what each fidelity level of the Geneva scenarios costs and changes.

- drive/method: at a prescribed crank speed the closed forms (docs/theory.md §G1-2) against the DAE with the speed
  as a rheonomic constraint (solver.method = dae): wall time against the largest column difference;
- thermal: none / flash (algebraic) / lumped (+3 states) / 1d (+ a mesh per slot wall): wall time against the
  peak contact temperature, on geneva-lc1 (closed form) and geneva-motor (DAE).

Cold = first run of that model in the process (symbolic derivation, code generation); warm = a second run.
Run `python -m scenarios.fidelity` to print the tables of docs/fidelity.md.
"""
from __future__ import annotations

import time

import numpy as np
import pandas as pd

COMPARED = ("wheel_angle_rad", "wheel_speed_rad_s", "wheel_accel_rad_s2", "contact_force_N", "drive_torque_N_m",
            "slip_speed_m_s", "friction_power_W")
THERMAL_MODELS = ("none", "flash", "lumped", "1d")


def _timed(scenario: str, overrides: list[str]):
    from mechsim.scenarios.loader import load
    from mechsim.scenarios.runner import run
    walls = []
    for _ in range(2):
        wall = time.perf_counter()
        result = run(load(scenario, overrides))
        walls.append(time.perf_counter() - wall)
    return result, walls


def method_levels(scenario: str = "geneva-lc1") -> pd.DataFrame:
    """Closed form against the DAE (IDA index2 and index1) at the scenario's prescribed speed."""
    closed, w_closed = _timed(scenario, ["solver.method=closed-form"])
    rows = [dict(scenario=scenario, level="closed form", cold_s=w_closed[0], warm_s=w_closed[1],
                 rows=len(closed.timeseries), largest_motion_force_difference="(reference)",
                 drive_torque_max_N_m=0.0, drive_torque_p99_N_m=0.0)]
    ref = closed.timeseries.set_index("t_s")
    for formulation in ("index2", "index1"):
        dae, walls = _timed(scenario, ["solver.method=dae", f"solver.formulation={formulation}"])
        df = dae.timeseries.set_index("t_s")
        common = ref.index.intersection(df.index)
        worst, worst_rel = "", -1.0
        for col in COMPARED:
            diff = np.abs(df.loc[common, col].to_numpy() - ref.loc[common, col].to_numpy())
            rel = diff.max() / max(np.max(np.abs(ref[col].to_numpy())), 1e-300)
            if col == "drive_torque_N_m":
                torque = (float(diff.max()), float(np.quantile(diff, 0.99)))
            elif rel > worst_rel:
                worst, worst_rel = f"{col}: {diff.max():.2g} ({rel:.1e} of its peak)", rel
        rows.append(dict(scenario=scenario, level=f"DAE ({formulation}, rtol {dae.summary['model']['rtol']:g})",
                         cold_s=walls[0], warm_s=walls[1], rows=len(df), largest_motion_force_difference=worst,
                         drive_torque_max_N_m=torque[0], drive_torque_p99_N_m=torque[1]))
    return pd.DataFrame(rows)


def thermal_levels(scenario: str) -> pd.DataFrame:
    """Peak contact temperature and cost for every thermal model; differences against the 1d model."""
    rows = []
    for model in THERMAL_MODELS:
        result, walls = _timed(scenario, [f"thermal.model={model}"])
        th = result.summary.get("thermal") or {}
        peak = result.summary["peaks"].get("temp_contact_C", {}).get("max", {}).get("value", np.nan)
        rows.append(dict(scenario=scenario, thermal=model, method=result.summary["model"]["method"],
                         thermal_states=th.get("states", 0), cold_s=walls[0], warm_s=walls[1],
                         peak_contact_temp_C=peak, success=result.success))
    df = pd.DataFrame(rows)
    top = df.loc[df.thermal == "1d", "peak_contact_temp_C"].iloc[0]
    df["difference_to_1d_K"] = df.peak_contact_temp_C - top
    return df


def markdown(df: pd.DataFrame) -> str:
    """A markdown table (numbers to 3 significant digits)."""
    def cell(v):
        return f"{v:.3g}" if isinstance(v, (float, np.floating)) else str(v)
    lines = ["| " + " | ".join(df.columns) + " |", "|" + "---|" * len(df.columns)]
    lines += ["| " + " | ".join(cell(v) for v in row) + " |" for row in df.itertuples(index=False)]
    return "\n".join(lines)


def main() -> None:
    print(markdown(method_levels()))
    for scenario in ("geneva-lc1", "geneva-motor"):
        print()
        print(markdown(thermal_levels(scenario)))


if __name__ == "__main__":
    main()
