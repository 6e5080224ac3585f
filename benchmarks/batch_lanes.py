"""Batched diffrax lanes against single compiled runs, from 64 lanes up (docs/sweeps.md, "Batching").

    python benchmarks/batch_lanes.py [--lanes 64,256,1024,4096,16384,65536] [--budget 420] [--duration 0.8]
                                     [--single 64] [--set section.key=value ...] [--out DIR]

The integration alone, as a sweep's cases pay for it: N geneva-motor cases (contact friction 0.05-0.3 and wheel
torque 2-12 N*m, a fixed pseudo-random spread, the scenario's solver settings on diffrax) integrated by
`simulate_batch` (one vmapped segment solve per round, on JAX's default device: an accelerator where JAX has one),
for each N of --lanes in turn, stopping before an N whose predicted time (the last one's, scaled by the lanes)
would pass --budget seconds. Per N: the compilation (once per batch size), the solve's wall time, the part of it
inside the vmapped calls (waited for: the device's share, transfers included) and the rest (each lane's hybrid loop
in Python between rounds: transitions, arguments, the segments' rows), the rounds, the failed lanes.

Beside them, --single of the same cases run one after another as single compiled whole runs (`hybrid.simulate` on
diffrax, the path a sweep's pool worker takes) in a child process on the CPU (JAX_PLATFORMS=cpu): the median wall
and CPU time a case, so one core's rate; a pool of W workers does at most W times that (ideal scaling, stated as
such). The crank angle at the end of each such case is compared with its lane's (they agree to the tolerances:
the batch runs the segment loop, the single run the compiled whole run, docs/diffrax.md "The compiled run").

--whole 64,256,...: also the compiled whole run (transitions inside the program) vmapped over that many lanes, its
first call per case against the same calls one by one on the same device, within --memory-gb of step buffers: the
kernel a batched whole run would call (no such runner is built yet: docs/sweeps.md).

Writes batch_lanes.csv (one row per N, and the single runs' row), batch_lanes.json (the rows, the device, JAX's
version, the host's cores) and batch_lanes.png (cases per second against lanes) into --out (default: a folder
`batch_lanes` beside this file), and prints the table.

On the lent GPU machine (no network; what this needs is there: JAX with CUDA, diffrax, equinox, sympy, numpy,
scipy, pandas, pyarrow, matplotlib; pint and SUNDIALS are not imported on this path), from the repository's root
(the package's own folder, made importable as `mechsim`):

    mkdir -p /tmp/p && ln -sfn "$PWD" /tmp/p/mechsim && export PYTHONPATH=/tmp/p;
    PYTHONUNBUFFERED=1 python3 benchmarks/batch_lanes.py --budget 300 --whole 256,1024,4096,16384 --memory-gb 100 \
        --out $OUT
"""
from __future__ import annotations

import argparse
import json
import os
import statistics
import subprocess
import sys
import time
from pathlib import Path

import numpy as np

HERE = Path(__file__).resolve().parent
LANES = (64, 256, 1024, 4096, 16384, 65536)
FRICTION = (0.05, 0.3)
TORQUE_N_M = (2.0, 12.0)


def cases(n: int, duration: float, sets: list[str]) -> list[tuple]:
    """n (mechanism, drive, settings, t_end, dt_out, angle0, speed0) of geneva-motor on diffrax, friction and wheel
    torque spread by a fixed pseudo-random draw (the first n of the same draw for every n)."""
    from mechsim.scenarios.loader import build_mechanism, load
    from mechsim.scenarios.runner import make_drive, solver_settings
    si = load("geneva-motor", ["solver.backend='diffrax'", f'duration="{duration} s"', *sets]).si
    drive, settings = make_drive(si), solver_settings(si)
    draw = np.random.default_rng(2026).uniform(size=(max(n, 1), 2))
    friction = FRICTION[0] + (FRICTION[1] - FRICTION[0]) * draw[:n, 0]
    torque = TORQUE_N_M[0] + (TORQUE_N_M[1] - TORQUE_N_M[0]) * draw[:n, 1]
    out = []
    for mu, tau in zip(friction.tolist(), torque.tolist()):
        one = dict(si, contact=dict(si["contact"], friction=mu), load=dict(si["load"], wheel_torque=tau))
        mech = build_mechanism(one)
        angle_key, speed_key = mech.initial_keys
        out.append((mech, drive, settings, si["duration"], si["output_step"], si["initial"][angle_key],
                    si["initial"][speed_key]))
    return out


def crank_end(traj) -> float:
    """The crank angle at the run's last row (rad)."""
    piece = traj.pieces[-1]
    return float(piece.y[-1, traj.model.modes[piece.mode].index["q"].start] + np.asarray(piece.offset)[0])


def batch(n: int, duration: float, sets: list[str]) -> dict:
    """One batch of n lanes: its figures (module docstring)."""
    import jax

    from mechsim.dynamics.backends import diffrax_batch
    made = cases(n, duration, sets)
    wall = time.perf_counter()
    trajs = diffrax_batch.simulate_batch(*[[c[i] for c in made] if i not in (2, 4) else made[0][i] for i in range(7)])
    wall = time.perf_counter() - wall
    last = dict(diffrax_batch.last_batch)
    solve, device = last["solve_time_s"], last["calls_time_s"]
    ok = [t for t in trajs if t.failure is None]
    return {"what": "batch", "lanes": n, "device": str(jax.devices()[0]), "compile_s": last["compile_time_s"],
            "solve_wall_s": solve, "inside_vmapped_calls_s": device, "host_loops_s": solve - device,
            "rounds": last["rounds"], "failed": n - len(ok), "wall_s": wall,
            "cases_per_s": n / solve if solve > 0 else float("nan"),
            "cases_per_s_inside_calls": n / device if device > 0 else float("nan"),
            "crank_end_rad": [crank_end(t) if t.failure is None else float("nan") for t in trajs]}


def whole(n: int, duration: float, sets: list[str], memory_gb: float) -> dict | None:
    """The compiled whole run (`diffrax_run.make_run`: transitions inside, no Python between events) vmapped over n
    lanes, each lane the first call of its case's run, against the same n calls one by one on the same device: the
    kernel a batched whole run would call (no such runner is built; docs/sweeps.md). None where the lanes' step
    buffers would take more than memory_gb."""
    import jax

    from mechsim.dynamics import kkt
    from mechsim.dynamics.backends import diffrax_run
    from mechsim.dynamics.backends.diffrax_backend import DiffraxBackend
    from mechsim.dynamics.backends.diffrax_common import DT0_FIRST, mode_z
    from mechsim.dynamics.backends.jax_transitions import jax_transitions
    from mechsim.dynamics.hybrid import prepare
    made = cases(n, duration, sets)
    o = DiffraxBackend(made[0][2]).o
    args, entry = [], None
    for mech, drive, settings, t_end, dt_out, angle0, speed0 in made:
        start = prepare(mech, drive, settings, t_end, dt_out, angle0, speed0)
        model = start.model                             # (one structure: every case's is the same model)
        entry = entry or diffrax_run.compiled_run(mech, model, o)[0]
        args.append(diffrax_run.run_arguments(entry.jmod.index(start.mode), 0.0, t_end,
                                              mode_z(start.model.modes[start.mode], start.y), start.p, DT0_FIRST,
                                              (o.rtol, o.atol), o.max_steps, 0))
    lane_bytes = (diffrax_run.STEPS_PER_CALL + 1) * entry.steps.width * 8
    if n * lane_bytes > memory_gb * 2**30:
        return None
    stacked = tuple(np.stack([a[j] for a in args]) for j in range(len(args[0])))
    run = diffrax_run.make_run(entry.jmod, jax_transitions(made[0][0], model, entry.jmod), o,
                               diffrax_run.EVENTS_PER_CALL, diffrax_run.STEPS_PER_CALL, entry.steps.record)
    compile_s = time.perf_counter()
    with kkt.unrolled_solves():     # as the single run's program is traced (diffrax_run.compiled_run)
        vmapped = jax.jit(jax.vmap(lambda *a: entry.outputs.pack(run(*a)))).lower(*stacked).compile()
    compile_s = time.perf_counter() - compile_s
    batched, one_by_one = [], []
    for _ in range(3):              # alternated, medians
        t = time.perf_counter()
        out = jax.device_get(vmapped(*stacked))
        batched.append(time.perf_counter() - t)
        t = time.perf_counter()
        singles = [jax.device_get(entry.fn(*a)) for a in args]
        one_by_one.append(time.perf_counter() - t)
    ends = np.asarray(out["floats"])                    # the lanes' packed floats against each single call's
    worst = float(np.nanmax(np.abs(ends - np.stack([np.asarray(x["floats"]) for x in singles]))
                            / np.maximum(1.0, np.abs(ends))))
    vm, ob = statistics.median(batched), statistics.median(one_by_one)
    return {"what": "vmapped whole run (first call of each case)", "lanes": n, "device": str(jax.devices()[0]),
            "compile_s": compile_s, "vmapped_call_s": vm, "one_by_one_s": ob, "cases_per_s": n / vm,
            "cases_per_s_one_by_one": n / ob, "step_buffer_mb_a_lane": lane_bytes / 2**20,
            "largest_relative_difference_of_outputs": worst}


def single(n: int, duration: float, sets: list[str]) -> dict:
    """n of the same cases as single compiled whole runs one after another, in this process (the child's)."""
    from mechsim.dynamics.hybrid import simulate
    made = cases(n, duration, sets)
    simulate(*made[0])                                  # compiled (or loaded) and warm
    walls, cpus, ends = [], [], []
    for case in made:
        w, c = time.perf_counter(), time.process_time()
        traj = simulate(*case)
        walls.append(time.perf_counter() - w)
        cpus.append(time.process_time() - c)
        ends.append(crank_end(traj) if traj.failure is None else float("nan"))
    wall = statistics.median(walls)
    return {"what": "single (CPU, one core)", "lanes": n, "device": "cpu", "case_wall_s": wall,
            "case_cpu_s": statistics.median(cpus), "cases_per_s": 1.0 / wall, "crank_end_rad": ends}


def single_in_child(n: int, duration: float, sets: list[str]) -> dict:
    """`single` in a child process on the CPU (JAX_PLATFORMS=cpu), whatever device this process's JAX has."""
    command = [sys.executable, __file__, "--single-only", str(n), "--duration", str(duration)]
    for s in sets:
        command += ["--set", s]
    got = subprocess.run(command, capture_output=True, text=True, env=dict(os.environ, JAX_PLATFORMS="cpu"),
                         check=True)
    return json.loads(got.stdout.strip().splitlines()[-1])


def chart(rows: list[dict], cores: int, path: Path) -> None:
    """Cases per second against lanes: the batch, its vmapped calls alone, its lanes' Python loops alone (what bounds
    it however fast the device), one core's single runs and the ideal pool on this host's cores."""
    import matplotlib
    matplotlib.use("Agg")
    import matplotlib.pyplot as plt
    runs = [r for r in rows if r["what"] == "batch"]
    lanes = [r["lanes"] for r in runs]
    fig, ax = plt.subplots(figsize=(7.5, 5.6), layout="constrained")
    ax.loglog(lanes, [r["cases_per_s"] for r in runs], "o-", label=f"batch on {runs[0]['device']}: whole solve")
    ax.loglog(lanes, [r["cases_per_s_inside_calls"] for r in runs], "s--", label="batch: inside the vmapped calls")
    ax.loglog(lanes, [r["lanes"] / r["host_loops_s"] for r in runs], "^:",
              label="batch: the lanes' loops alone (its bound on any device)")
    kernel = [r for r in rows if r["what"].startswith("vmapped whole run")]
    if kernel:
        ax.loglog([r["lanes"] for r in kernel], [r["cases_per_s"] for r in kernel], "D-",
                  label="vmapped whole run: its first call (no runner built)")
    one = next((r for r in rows if r["what"].startswith("single")), None)
    if one is not None:
        ax.axhline(one["cases_per_s"], color="k", lw=1, label="single compiled runs, one CPU core")
        ax.axhline(cores * one["cases_per_s"], color="k", lw=1, ls=":",
                   label=f"ideal pool of {cores} workers (cores x one core)")
    ax.set_xlabel("lanes (cases in one batch)")
    ax.set_ylabel("cases integrated per second")
    ax.set_title("geneva-motor on diffrax: batched lanes against single runs")
    ax.grid(True, which="both", alpha=0.3)
    fig.legend(fontsize=8, loc="outside lower center", ncols=2)
    fig.savefig(path, dpi=120)
    plt.close(fig)


def main(argv: list[str] | None = None) -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--lanes", default=",".join(map(str, LANES)))
    parser.add_argument("--budget", type=float, default=420.0, help="seconds for the batches together")
    parser.add_argument("--duration", type=float, default=0.8, help="each case's simulated time (s)")
    parser.add_argument("--single", type=int, default=64, help="cases run one by one on the CPU (0: none)")
    parser.add_argument("--set", action="append", default=[], help="a scenario override, as `mechsim run --set`")
    parser.add_argument("--out", type=Path, default=HERE / "batch_lanes")
    parser.add_argument("--whole", default="", help="lane counts for the vmapped whole run's kernel (e.g. 64,256)")
    parser.add_argument("--memory-gb", type=float, default=4.0, help="the vmapped whole run's step buffers at most")
    parser.add_argument("--single-only", type=int, default=0, help=argparse.SUPPRESS)
    args = parser.parse_args(argv)
    if args.single_only:
        print(json.dumps(single(args.single_only, args.duration, args.set)))
        return
    from mechsim.dynamics.backends import diffrax_batch  # noqa: F401  (mechsim sets XLA's options before JAX starts)
    import jax
    started, rows, last = time.perf_counter(), [], None
    for n in sorted(int(x) for x in args.lanes.split(",")):
        spent = time.perf_counter() - started
        if last is not None and spent + last["wall_s"] * n / last["lanes"] > args.budget:
            print(f"stopped before {n} lanes: {last['lanes']} lanes took {last['wall_s']:.1f} s, "
                  f"{spent:.0f} s of the {args.budget:.0f} s budget spent", flush=True)
            break
        last = batch(n, args.duration, args.set)
        rows.append(last)
        print(f"{n:6d} lanes on {last['device']}: compile {last['compile_s']:.1f} s, solve {last['solve_wall_s']:.2f} s "
              f"({last['inside_vmapped_calls_s']:.2f} s inside {last['rounds']} vmapped calls, "
              f"{last['host_loops_s']:.2f} s in the lanes' loops), {last['cases_per_s']:.0f} cases/s, "
              f"{last['failed']} failed", flush=True)
    if args.single:
        one = single_in_child(args.single, args.duration, args.set)
        first = rows[0]["crank_end_rad"][:args.single] if rows else []
        one["largest_crank_end_difference_rad"] = float(np.nanmax(np.abs(np.subtract(
            first, one["crank_end_rad"][:len(first)])))) if first else float("nan")
        rows.append(one)
        print(f"single compiled runs on the CPU: {one['case_wall_s'] * 1e3:.2f} ms wall ({one['case_cpu_s'] * 1e3:.2f} "
              f"ms CPU) a case, {one['cases_per_s']:.0f} cases/s on one core; crank angle at the end within "
              f"{one['largest_crank_end_difference_rad']:.1e} rad of the batch's", flush=True)
    for n in sorted(int(x) for x in args.whole.split(",") if x):
        got = whole(n, args.duration, args.set, args.memory_gb)
        if got is None:
            print(f"vmapped whole run: {n} lanes' step buffers pass --memory-gb {args.memory_gb:g}", flush=True)
            break
        rows.append(got)
        print(f"vmapped whole run, {n} lanes on {got['device']}: compile {got['compile_s']:.1f} s, one call "
              f"{got['vmapped_call_s'] * 1e3:.1f} ms ({got['cases_per_s']:.0f} cases/s) against "
              f"{got['one_by_one_s'] * 1e3:.1f} ms one by one ({got['cases_per_s_one_by_one']:.0f} cases/s); outputs "
              f"within {got['largest_relative_difference_of_outputs']:.1e} relative", flush=True)
    args.out.mkdir(parents=True, exist_ok=True)
    table = [{k: v for k, v in r.items() if k != "crank_end_rad"} for r in rows]
    import pandas as pd
    pd.DataFrame(table).to_csv(args.out / "batch_lanes.csv", index=False)
    cores = os.cpu_count() or 1
    (args.out / "batch_lanes.json").write_text(json.dumps(
        {"rows": table, "jax": jax.__version__, "devices": [str(d) for d in jax.devices()], "host_cores": cores,
         "duration_s": args.duration, "sets": args.set}, indent=1))
    if any(r["what"] == "batch" for r in rows):
        chart(rows, cores, args.out / "batch_lanes.png")
    print(f"written to {args.out}")


if __name__ == "__main__":
    main()
