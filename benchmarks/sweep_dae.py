"""DAE sweeps now against the recorded ones (not a test): docs/benchmarks_sweep_dae.csv and .png.

    python benchmarks/sweep_dae.py                       # 8, 125, 1000 cases of each sweep; long (minutes)
    python benchmarks/sweep_dae.py --sizes 2,5           # 8 and 125 cases

Sweeps on a 2-worker process pool, each in a fresh process (`scaling.one_sweep`, i.e. `sweep_bench.py
--runners pool`), lumped thermal, 5 ms rows, timed once each:
- `geneva-lc1` as a DAE on IDA (3 crank turns per case): the same sweeps as the DAE rows recorded in
  docs/benchmarks_sweep.csv, which are drawn beside them as "recorded";
- `geneva-motor` (5 s per case, the motor's no-load speed varied) on the chosen backends.
The figure: sweep wall time against cases (left) and the CPU time per case of the largest sweeps (right).
"""
from __future__ import annotations

import argparse
import os

import numpy as np
import pandas as pd

from mechsim.benchmarks.scaling import DOCS, case_cost_histogram, one_sweep

RECORDED = DOCS / "benchmarks_sweep.csv"


def measure(sizes, backends, workers: int = 2) -> tuple[pd.DataFrame, dict]:
    rows, tables = [], {}
    plan = [("geneva-lc1", "ida")] + [("geneva-motor", b) for b in backends]
    for per_axis in sizes:
        for scenario, backend in plan:
            r, df = one_sweep(per_axis, "dae", workers, scenario, backend)
            label = f"{scenario} DAE ({backend}), now"
            rows.append(dict(label=label, scenario=scenario, backend=backend, cases=r["cases"],
                             wall_time_s=r["total_s"], process_wall_s=r["process_wall_s"],
                             median_case_cpu_s=r["median_case_cpu_s"], mean_case_cpu_s=r["mean_case_cpu_s"],
                             median_case_wall_s=r["median_case_s"], sum_case_cpu_s=r["sum_case_cpu_s"],
                             load_before=r["load_average_before"], load_after=r["load_average"],
                             failed=r["failed"]))
            print(f"{label:<34} {r['cases']:5d} cases: {r['total_s']:7.1f} s wall, case CPU median "
                  f"{1e3 * r['median_case_cpu_s']:.0f} ms, mean {1e3 * r['mean_case_cpu_s']:.0f} ms, "
                  f"load {r['load_average_before']}-{r['load_average']}, failed {r['failed']}", flush=True)
            if per_axis == max(sizes):
                tables[label] = df
    return pd.DataFrame(rows), tables


def recorded() -> pd.DataFrame:
    d = pd.read_csv(RECORDED)
    d = d[d.method.str.startswith("DAE")]
    return pd.DataFrame(dict(label="geneva-lc1 DAE (ida), recorded", scenario="geneva-lc1", backend="ida",
                             cases=d["size"], wall_time_s=d.wall_time_s, median_case_cpu_s=d.median_case_cpu_s,
                             mean_case_cpu_s=d.mean_case_cpu_s, median_case_wall_s=d.median_case_wall_s,
                             load_before=d.load_before, load_after=d.load_after, failed=d.failed))


def figure(df: pd.DataFrame, tables: dict, path) -> None:
    import matplotlib
    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    fig, (ax1, ax2) = plt.subplots(1, 2, figsize=(11, 4.4))
    for label, d in df.groupby("label", sort=False):
        d = d.sort_values("cases")
        style = "s--" if label.endswith("recorded") else "o-"
        fit = ""
        if len(d) > 1:
            fixed, per_case = np.polyfit(d["cases"], d.wall_time_s, 1)[::-1]
            fit = f": {fixed:.1f} s + {1e3 * per_case:.0f} ms/case"
        ax1.plot(d["cases"], d.wall_time_s, style, label=label + fit)
    ax1.set_xscale("log")
    ax1.set_yscale("log")
    ax1.set_xlabel("cases in the sweep")
    ax1.set_ylabel("wall time of the sweep (s)")
    now = df[~df.label.str.endswith("recorded")]
    loads = now[["load_before", "load_after"]].to_numpy(float)
    ax1.set_title("DAE sweeps, 2-worker pool, lumped thermal (fresh process each)\n"
                  f"2-core machine shared, load average now {np.nanmin(loads):.1f}-{np.nanmax(loads):.1f}", fontsize=9)
    ax1.grid(True, which="both", alpha=0.3)
    ax1.legend(fontsize=7)
    for d_label, r in df[df.label.str.endswith("recorded")].sort_values("cases").tail(1).iterrows():
        ax2.axvline(1e3 * r.median_case_cpu_s, color="k", ls="--",
                    label=f"recorded geneva-lc1, {int(r.cases)} cases: median {1e3 * r.median_case_cpu_s:.0f} ms")
    case_cost_histogram(ax2, {label.replace(", now", ""): t for label, t in tables.items()},
                        f"largest sweeps now ({max(len(t) for t in tables.values())} cases): cost per case",
                        floor_ms=1e-1, digits=0)
    fig.tight_layout()
    fig.savefig(path, dpi=110)
    plt.close(fig)


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--sizes", default="2,5,10", help="points per axis (cases = n^3)")
    ap.add_argument("--backends", default="ida", help="geneva-motor's backends, comma list")
    ap.add_argument("--workers", type=int, default=2)
    ap.add_argument("--out", default=str(DOCS))
    args = ap.parse_args()
    now, tables = measure([int(x) for x in args.sizes.split(",")], args.backends.split(","), args.workers)
    df = pd.concat([recorded(), now], ignore_index=True)
    df.to_csv(os.path.join(args.out, "benchmarks_sweep_dae.csv"), index=False)
    figure(df, tables, os.path.join(args.out, "benchmarks_sweep_dae.png"))


if __name__ == "__main__":
    main()
