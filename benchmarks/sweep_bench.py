"""Sweep throughput (not a test): geneva-lc1 over friction x wheel torque x crank speed, three crank turns each.

    python benchmarks/sweep_bench.py                       # 10 x 10 x 10 = 1000 cases, pool and Dask
    python benchmarks/sweep_bench.py --per-axis 5 --method dae --runners pool

Each case runs for 3 turns of its own crank speed (duration = 6 pi / w, a per-case override). The scenario's
prescribed speed lets the runner use the closed form (method auto); --method dae integrates the DAE on IDA
instead. --scenario geneva-motor: the motor-driven Geneva over friction x wheel torque x no-load speed, 5 s
each (the scenario's duration), always a DAE (--backend picks the integrator). Thermal: lumped (bulk pin/crank/wheel temperatures alongside) when the schema has it, else none.
Output rows every 5 ms (a sweep wants summary figures; peaks move by < 1e-5 relative against 1 ms here).

Reports, per runner: the time to validate every case (the loader, in this process), the wall time of the run
(worker start-up, model derivation per worker, cases, table), the total from making the runner to the table
(the runner is made first, as `mechsim sweep` does, so a pool's start-up overlaps the validation), cases per
second, the CPU time of this (main) process and of the cases (median, mean), the load average before and after;
and checks that every runner produced the same table. Results are printed and written as JSON next to this file
(sweep_bench.json); --table PATH also keeps the last runner's sweep table (Parquet; benchmarks/scaling.py).
"""
from __future__ import annotations

import argparse
import json
import os
import platform
import shutil
import sys
import tempfile
import time
from pathlib import Path

import numpy as np
import pandas as pd

from mechsim.scenarios.loader import sections_for
from mechsim.scenarios.studies.sweep.execute import DaskRunner, PoolRunner, SerialRunner
from mechsim.scenarios.studies.sweep.run import plan, run_sweep
from mechsim.scenarios.studies.sweep.spec import SweepSpec, parse_vary

TARGET_S = 30.0
COMPARE = ("peak_max_contact_force_N", "peak_max_drive_torque_N_m", "cycle_time_s", "work_drive_per_cycle_J",
           "peak_max_temp_contact_C")


def build(per_axis: int, method: str, thermal: str, backend: str, scenario: str = "geneva-lc1"):
    """The sweep spec and per-case overrides. geneva-lc1: crank speed prescribed, 3 turns per case;
    geneva-motor: the motor's no-load speed 6-10 rad/s, the scenario's 5 s per case (always a DAE)."""
    motor = scenario == "geneva-motor"
    axes = (parse_vary(f"contact.friction=0.05:0.3:{per_axis}"),
            parse_vary(f"load.wheel_torque=2:12:{per_axis} N*m"),
            parse_vary(f"drive.no_load_speed=6:10:{per_axis} rad/s") if motor
            else parse_vary(f"drive.speed=3:8:{per_axis} rad/s"))
    base = ['output_step="5 ms"', f'thermal.model="{thermal}"', f'solver.method="{method}"',
            f'solver.backend="{backend}"']
    spec = SweepSpec(scenario, axes, "grid", tuple(base))
    if motor:
        return spec, None
    speeds = [float(v.split()[0]) for v in axes[2].values]
    extra = [[f'duration="{6 * np.pi / speeds[idx[2]]!r} s"'] for idx in spec.indices()]
    return spec, extra


def thermal_available() -> bool:
    return "lumped" in sections_for("geneva")["thermal"]["model"].choices


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--per-axis", type=int, default=10, help="points per axis (cases = per-axis^3)")
    ap.add_argument("--method", default="auto", choices=("auto", "dae"))
    ap.add_argument("--scenario", default="geneva-lc1", choices=("geneva-lc1", "geneva-motor"))
    ap.add_argument("--backend", default="ida")
    ap.add_argument("--thermal", default=None, help="thermal model (default: lumped if available, else none)")
    ap.add_argument("--runners", default="pool,dask", help="comma list of pool, dask, serial")
    ap.add_argument("--workers", type=int, default=len(os.sched_getaffinity(0)))
    ap.add_argument("--json", default=str(Path(__file__).with_name("sweep_bench.json")))
    ap.add_argument("--table", default=None, help="write the (last runner's) sweep table here (Parquet)")
    args = ap.parse_args()
    thermal = args.thermal or ("lumped" if thermal_available() else "none")
    runners = args.runners.split(",")
    results = []
    tables = {}
    for name in runners:
        backend, method = args.backend, args.method
        spec, extra = build(args.per_axis, method, thermal, backend, args.scenario)
        load_before = os.getloadavg()[0]
        start, cpu0 = time.perf_counter(), time.process_time()
        if name == "pool":          # first, as mechsim sweep does: the pool's fork server starts while cases validate
            runner = PoolRunner(args.workers)
        elif name == "dask":
            runner = DaskRunner(local_workers=args.workers)
        elif name == "serial":
            runner = SerialRunner()
        else:
            sys.exit(f"unknown runner {name!r}")
        t0 = time.perf_counter()
        pl = plan(spec, extra)
        t_plan = time.perf_counter() - t0
        out = Path(tempfile.mkdtemp(prefix=f"sweep-bench-{name}-"))
        try:
            t0 = time.perf_counter()
            report = run_sweep(pl, out / "sweep", runner, plots=False)
            t_run = time.perf_counter() - t0
            total = time.perf_counter() - start
            main_cpu = time.process_time() - cpu0
            df = pd.read_parquet(out / "sweep" / "sweep.parquet")
            if args.table:
                shutil.copyfile(out / "sweep" / "sweep.parquet", args.table)
        finally:
            shutil.rmtree(out, ignore_errors=True)
        tables[name] = df
        n = len(pl.cases)
        row = {"runner": name, "describe": runner.describe(), "scenario": args.scenario, "cases": n, "method": method,
               "backend": backend,
               "thermal": thermal, "failed": int((~df["success"]).sum()), "validate_s": round(t_plan, 2),
               "run_s": round(t_run, 2), "total_s": round(total, 2), "cases_per_s": round(n / total, 1),
               "median_case_s": round(float(df["case_wall_time_s"].median()), 4),
               "median_case_cpu_s": round(float(df["case_cpu_time_s"].median()), 4),
               "mean_case_cpu_s": round(float(df["case_cpu_time_s"].mean()), 4),
               "sum_case_cpu_s": round(float(df["case_cpu_time_s"].sum()), 2),
               "main_process_cpu_s": round(main_cpu, 2),
               "first_case_per_worker_s": round(float(df.groupby("worker")["case_wall_time_s"].max().mean()), 2),
               "extrapolated_1000_s": round(total * 1000 / n, 1) if n != 1000 else None,
               "load_average_before": round(load_before, 1),
               "load_average": round(os.getloadavg()[0], 1), "batching": "none (docs/sweeps.md)",
               "computed": report.computed}
        results.append(row)
        print(json.dumps(row), flush=True)
    if len(tables) > 1:
        ref_name, ref = next(iter(tables.items()))
        for name, df in tables.items():
            cols = [c for c in COMPARE if c in df and c in ref]
            diff = max(float(np.nanmax(np.abs(df[c].to_numpy(float) - ref[c].to_numpy(float))
                                       / np.maximum(np.abs(ref[c].to_numpy(float)), 1e-12))) for c in cols)
            print(f"{name} vs {ref_name}: max relative difference over {cols}: {diff:.3g}")
    load = os.getloadavg()
    meta = {"machine": f"{platform.machine()}, {os.cpu_count()} cores", "load_average_after": load,
            "target_s": TARGET_S, "python": platform.python_version()}
    Path(args.json).write_text(json.dumps({"meta": meta, "results": results}, indent=1))
    print(f"load average after the run: {load[0]:.1f} (other jobs on the machine slow every figure)")


if __name__ == "__main__":
    main()
