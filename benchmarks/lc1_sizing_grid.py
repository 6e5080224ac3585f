"""Cross-check of the seed's load case 1 sizing (docs/sensitivity.md, "A thermal sizing: the seed's load case 1"):
plain runs on a grid of crank radius x stall torque around the optimum `mechsim size` found, each giving the
peak contact temperature over the hour (the run's located peak, which the sizing limits) and the index time (the last complete index), so that a reader
can see that no grid point with a smaller crank radius meets both limits.

    python -m mechsim.benchmarks.lc1_sizing_grid RADIUS_MM STALL_TORQUE_NM [--out docs/lc1_sizing_grid.csv]
"""
from __future__ import annotations

import argparse

import pandas as pd

import mechsim
from mechsim.scenarios import runner

NAME = "geneva-seed-lc1-mu015"
#: the seed's load case 1 with the motor of geneva-motor's speed class (docs/sensitivity.md)
SETS = ["duration=1 h", "drive.type=motor", "drive.no_load_speed=8 rad/s", "thermal.averaging=cycle"]
RADIUS_FACTORS = (0.995, 0.999, 1.0, 1.001)
TORQUE_FACTORS = (0.98, 0.99, 0.995, 1.0, 1.005, 1.01, 1.02)
LIMIT_C, LIMIT_S = 60.0, 0.3
#: a limit counts as met within this fraction of it (scenarios/studies/sizing.py FEASIBLE)
FEASIBLE = 1e-8


def evaluate(radius_mm: float, torque_nm: float) -> dict:
    """Peak contact temperature of the periodic turn after the hour (°C) and the index time (s) of one design."""
    plan = runner.plan(mechsim.load(NAME, set=SETS + [f"mechanism.crank_radius={radius_mm!r} mm",
                                                     f"drive.stall_torque={torque_nm!r} N*m"]))
    result = runner.execute(plan)          # the whole hour: its located peak (scenarios/thermal_peaks.py)
    if result.failure is not None:
        raise RuntimeError(result.failure.message())
    ev = result.events[result.events["t_s"] <= result.summary["thermal"]["cycle"]["mechanics_simulated_until_s"]]
    entry = ev.loc[ev["kind"] == "entry", "t_s"].to_numpy(float)
    exit_ = ev.loc[ev["kind"] == "exit", "t_s"].to_numpy(float)[-1]
    return {"crank_radius_mm": radius_mm, "stall_torque_N_m": torque_nm,
            "peak_temp_contact_C": float(result.summary["peaks"]["temp_contact_C"]["max"]["value"]),
            "index_time_s": float(exit_ - entry[entry < exit_][-1])}


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("radius_mm", type=float)
    parser.add_argument("torque_nm", type=float)
    parser.add_argument("--out", default="docs/lc1_sizing_grid.csv")
    args = parser.parse_args()
    rows = []
    for fr in RADIUS_FACTORS:
        for ft in TORQUE_FACTORS:
            row = evaluate(args.radius_mm * fr, args.torque_nm * ft)
            row.update(radius_factor=fr, torque_factor=ft,
                       feasible=bool(row["peak_temp_contact_C"] <= LIMIT_C * (1 + FEASIBLE)
                                     and row["index_time_s"] <= LIMIT_S * (1 + FEASIBLE)))
            rows.append(row)
            print(row, flush=True)
    table = pd.DataFrame(rows)
    table.to_csv(args.out, index=False)
    cells = table.assign(cell=[f"{t:.3f}/{s:.5f}" + (" *" if f else "") for t, s, f in
                               zip(table["peak_temp_contact_C"], table["index_time_s"], table["feasible"])])
    grid = cells.pivot(index="radius_factor", columns="torque_factor", values="cell")
    print("| crank radius | " + " | ".join(f"T x {c:g}" for c in grid.columns) + " |")
    print("|---" * (len(grid.columns) + 1) + "|")
    for r, line in grid.iterrows():
        print(f"| r* x {r:g} | " + " | ".join(line) + " |")


if __name__ == "__main__":
    main()
