"""How cost grows (not a test): CPU time against simulated duration, output density, 1-D thermal mesh size and
sweep size, with the fitted exponent p of cost ~ size^p (least squares on log-log).

    python benchmarks/scaling.py                 # everything, writes docs/benchmarks_scaling.csv and the sweep
                                                 # figure docs/benchmarks_sweep.png (+ .csv); ~10 minutes
    python benchmarks/scaling.py --only duration,output

Case A (`peer_bench.CASE_A`: geneva-motor, no-load 6 rad/s, no friction) at rtol 1e-7 (atol 1e-9):
- duration 1, 5, 20, 100 s at 1 ms outputs: mechsim IDA index-2, diffrax Tsit5 (warm) and the CasADi peer;
- output step 100, 10, 1, 0.1 ms over 5 s: the same three methods;
- 1-D thermal mesh (thermal.model = "1d", friction 0.15, mesh growth 1.4 ... 1.03): mechsim IDA only (the
  peer's symbolic solve of the network rows is not built for hundreds of states);
- sweep size: geneva-lc1 sweeps (`sweep_bench.build`) of 8, 125 and 1000 cases on a 2-worker pool, closed form
  and DAE (IDA, lumped thermal), each in a fresh process (`sweep_bench.py`): the wall time of the whole sweep
  (validation + run), fitted as fixed + per-case cost too, and the CPU time per case.

Every point is the median CPU time of `rounds` warm runs, the methods interleaved within each round (the
machine is shared: bursts of load hit every method alike). Closed-form sweeps are the median of 3 runs, DAE
sweeps are timed once (a 1000-case DAE sweep takes minutes); the per-case CPU time is in the figure.
"""
from __future__ import annotations

import argparse
import json
import shutil
import subprocess
import sys
import tempfile
import time
from pathlib import Path

import numpy as np
import pandas as pd

from mechsim.benchmarks.bench import BenchConfig, make_problem
from mechsim.benchmarks.bench_methods import METHODS, quiet_sundials
from mechsim.benchmarks.peer_bench import CASE_A

DOCS = Path(__file__).resolve().parents[1] / "docs"
RTOL = 1e-7
#: issue 13's sweep target: 1000 closed-form geneva-lc1 cases (sweep_bench's) on 2 cores
TARGET_1000_S = 6.0
METHODS_SCALED = ("ida-compiled-index2", "ida-index2", "diffrax-Tsit5", "casadi-idas")


def exponent(size, cost) -> float:
    """Least-squares slope of log(cost) on log(size)."""
    return float(np.polyfit(np.log(np.asarray(size, float)), np.log(np.asarray(cost, float)), 1)[0])


def _median_cpu(problems: dict, names, rounds: int) -> list[dict]:
    """Median CPU time of warm runs of each method on each problem, methods interleaved within rounds."""
    rows = []
    for label, (size, problem) in problems.items():
        handles = {}
        for n in names:
            if not METHODS[n].available() or not METHODS[n].supports_problem(problem):
                continue
            with quiet_sundials():
                handles[n] = METHODS[n].setup(problem, RTOL, RTOL * 1e-2)
                METHODS[n].run(handles[n][0], problem, RTOL, RTOL * 1e-2)
        cpu = {n: [] for n in handles}
        live = list(handles)
        for k in range(rounds):
            for n in live[k % len(live):] + live[:k % len(live)]:
                c = time.process_time()
                with quiet_sundials():
                    METHODS[n].run(handles[n][0], problem, RTOL, RTOL * 1e-2)
                cpu[n].append(time.process_time() - c)
        for n, v in cpu.items():
            rows.append(dict(size=size, label=label, method=n, cpu_time_s=float(np.median(v)), rounds=len(v)))
            print(f"{label:<24} {n:<14} {1e3 * np.median(v):9.1f} ms", flush=True)
    return rows


def duration_scaling(rounds: int) -> pd.DataFrame:
    problems = {f"{d:g} s": (d, make_problem(BenchConfig(scenario="geneva-motor", duration=d, overrides=CASE_A)))
                for d in (1.0, 5.0, 20.0, 100.0)}
    return pd.DataFrame(_median_cpu(problems, METHODS_SCALED, rounds)).assign(axis="duration_s")


def output_scaling(rounds: int) -> pd.DataFrame:
    problems = {}
    for step in (0.1, 0.01, 0.001, 0.0001):
        p = make_problem(BenchConfig(scenario="geneva-motor", duration=5.0, output_step=step, overrides=CASE_A))
        problems[f"{1e3 * step:g} ms"] = (len(p.grid), p)
    return pd.DataFrame(_median_cpu(problems, METHODS_SCALED, rounds)).assign(axis="output_points")


def mesh_scaling(rounds: int) -> pd.DataFrame:
    problems = {}
    for growth in (1.4, 1.2, 1.1, 1.05, 1.03):
        p = make_problem(BenchConfig(scenario="geneva-motor", duration=5.0, overrides=(
            "drive.no_load_speed=6 rad/s", "contact.friction=0.15", 'thermal.model="1d"',
            f"thermal.mesh_growth={growth}")))
        problems[f"growth {growth:g}"] = (len(p.ext.names), p)
    return pd.DataFrame(_median_cpu(problems, ("ida-compiled-index2", "ida-index2"), rounds)).assign(axis="thermal_states")


def sweep_scaling(workers: int = 2, sizes=(2, 5, 10), repeats: dict | None = None) -> tuple[pd.DataFrame, dict]:
    """geneva-lc1 sweeps of 8, 125, 1000 cases (closed form and DAE), each in a fresh process as a user's
    `mechsim sweep` would be (`sweep_bench.py --runners pool`): its wall time (validation + run), the process's
    wall time with interpreter start and imports, CPU per case, main-process CPU, load; the 1000-case tables.
    repeats: runs per method ({"auto": 3, "dae": 1} by default: a 1000-case DAE sweep takes minutes); the run
    with the median wall time is kept."""
    repeats = repeats or {"auto": 3, "dae": 1}
    rows, tables = [], {}
    for method in ("auto", "dae"):
        label = "closed form" if method == "auto" else "DAE (IDA)"
        for per_axis in sizes:
            runs = []
            for _ in range(max(1, repeats.get(method, 1))):
                runs.append(one_sweep(per_axis, method, workers))
                r = runs[-1][0]
                print(f"sweep {label:<12} {r['cases']:5d} cases: {r['total_s']:7.1f} s wall ({r['process_wall_s']:.1f} s "
                      f"with start-up), case CPU median {1e3 * r['median_case_cpu_s']:.1f} ms, mean "
                      f"{1e3 * r['mean_case_cpu_s']:.1f} ms, load {r['load_average_before']}-{r['load_average']}",
                      flush=True)
            runs.sort(key=lambda run: run[0]["total_s"])
            r, df = runs[len(runs) // 2]
            rows.append(dict(axis="sweep_cases", size=r["cases"], label=f"{r['cases']} cases", method=label,
                             wall_time_s=r["total_s"], runs=len(runs),
                             wall_time_all_runs_s=" ".join(f"{run[0]['total_s']:.2f}" for run in runs),
                             process_wall_s=r["process_wall_s"], validate_s=r["validate_s"],
                             median_case_cpu_s=r["median_case_cpu_s"], mean_case_cpu_s=r["mean_case_cpu_s"],
                             median_case_wall_s=r["median_case_s"], main_process_cpu_s=r["main_process_cpu_s"],
                             first_case_per_worker_s=r["first_case_per_worker_s"],
                             load_before=r["load_average_before"], load_after=r["load_average"], failed=r["failed"]))
            if per_axis == max(sizes):
                tables[label] = df
    return pd.DataFrame(rows), tables


def one_sweep(per_axis: int, method: str, workers: int, scenario: str = "geneva-lc1",
               backend: str = "ida") -> tuple[dict, pd.DataFrame]:
    """One sweep_bench.py run in a fresh process: its JSON row (+ process_wall_s) and its sweep table."""
    tmp = Path(tempfile.mkdtemp(prefix="scaling-sweep-"))
    try:
        wall = time.perf_counter()
        subprocess.run([sys.executable, "-m", "mechsim.benchmarks.sweep_bench", "--per-axis", str(per_axis),
                        "--method", method, "--runners", "pool", "--workers", str(workers),
                        "--scenario", scenario, "--backend", backend,
                        "--json", str(tmp / "row.json"), "--table", str(tmp / "table.parquet")],
                       check=True, stdout=subprocess.DEVNULL)
        process_wall = time.perf_counter() - wall
        row = json.loads((tmp / "row.json").read_text())["results"][0]
        row["process_wall_s"] = round(process_wall, 2)
        return row, pd.read_parquet(tmp / "table.parquet")
    finally:
        shutil.rmtree(tmp, ignore_errors=True)



def case_cost_histogram(ax, tables: dict, title: str, floor_ms: float, digits: int) -> None:
    """Each sweep table's CPU time per case as a histogram on a log axis, its median in the legend."""
    for label, df in tables.items():
        cpu = 1e3 * df["case_cpu_time_s"].to_numpy(float)
        ax.hist(cpu, bins=np.geomspace(max(cpu.min(), floor_ms), cpu.max() * 1.01, 40), alpha=0.6,
                label=f"{label}: median {np.median(cpu):.{digits}f} ms")
    ax.set_xscale("log")
    ax.set_xlabel("CPU time per case (ms)")
    ax.set_ylabel("cases")
    ax.set_title(title, fontsize=10)
    ax.legend(fontsize=8)
    ax.grid(True, which="both", alpha=0.3)

def sweep_figure(sweeps: pd.DataFrame, tables: dict, path: Path) -> None:
    import matplotlib
    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    fig, (ax1, ax2) = plt.subplots(1, 2, figsize=(11, 4.4))
    for label, d in sweeps.groupby("method", sort=False):
        d = d.sort_values("size")
        fixed, per_case = np.polyfit(d["size"], d.wall_time_s, 1)[::-1]
        ax1.plot(d["size"], d.wall_time_s, "o-", label=f"{label}: {fixed:.1f} s + {1e3 * per_case:.1f} ms/case")
    ax1.plot([1000], [TARGET_1000_S], "k*", ms=10, label=f"target: 1000 closed-form cases in {TARGET_1000_S:g} s")
    ax1.set_xscale("log")
    ax1.set_yscale("log")
    ax1.set_xlabel("cases in the sweep")
    ax1.set_ylabel("wall time of the sweep (s)")
    loads = sweeps[["load_before", "load_after"]].to_numpy(float) if "load_before" in sweeps else np.full((1, 2), np.nan)
    ax1.set_title("geneva-lc1 sweeps, 2-worker pool, lumped thermal (fresh process each)\n"
                  f"2-core machine shared, load average {np.nanmin(loads):.1f}-{np.nanmax(loads):.1f}", fontsize=9)
    ax1.grid(True, which="both", alpha=0.3)
    ax1.legend(fontsize=8)
    case_cost_histogram(ax2, tables, "1000-case sweeps: cost per case", floor_ms=1e-2, digits=1)
    fig.tight_layout()
    fig.savefig(path, dpi=110)
    plt.close(fig)


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--only", default="duration,output,mesh,sweep")
    ap.add_argument("--rounds", type=int, default=3)
    ap.add_argument("--out", type=Path, default=DOCS)
    args = ap.parse_args()
    args.out.mkdir(parents=True, exist_ok=True)     # before the minutes of measuring, not after
    parts = args.only.split(",")
    frames = []
    if "duration" in parts:
        frames.append(duration_scaling(args.rounds))
    if "output" in parts:
        frames.append(output_scaling(args.rounds))
    if "mesh" in parts:
        frames.append(mesh_scaling(args.rounds))
    if "sweep" in parts:
        sweeps, tables = sweep_scaling()
        sweeps.to_csv(args.out / "benchmarks_sweep.csv", index=False)
        sweep_figure(sweeps, tables, args.out / "benchmarks_sweep.png")
        frames.append(sweeps.rename(columns={"wall_time_s": "cpu_time_s"}).assign(note="wall time of the sweep"))
    df = pd.concat(frames, ignore_index=True)
    fits = [dict(axis=a, method=m, exponent=exponent(d["size"], d.cpu_time_s))
            for (a, m), d in df.groupby(["axis", "method"], sort=False) if len(d) > 1]
    print(pd.DataFrame(fits).to_string(index=False))
    name = "benchmarks_scaling.csv" if set(parts) >= {"duration", "output", "mesh"} else \
        f"benchmarks_scaling_{'_'.join(parts)}.csv"
    df.to_csv(args.out / name, index=False)
    pd.DataFrame(fits).to_csv(args.out / name.replace(".csv", "_exponents.csv"), index=False)


if __name__ == "__main__":
    main()
