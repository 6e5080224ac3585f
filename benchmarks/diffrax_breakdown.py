"""Where mechsim diffrax's warm time goes on the benchmark's case A: the compiled calls alone against the whole run,
for the compiled whole-run loop (`dynamics/backends/diffrax_run.py`, the default) and the segment loop (one compiled
solve per segment) (docs/benchmarks.md, "diffrax: the compiled run, and what bounds it").

    python -m mechsim.benchmarks.diffrax_breakdown [--rounds 7]

Each compiled call is timed (process CPU time, the result fetched to the host) and the calls and steps counted;
the loop and every other part of the run are unchanged. The two paths alternate round by round.
"""
from __future__ import annotations

import argparse
import time

import jax
import numpy as np

from mechsim.benchmarks.bench import BenchConfig, make_problem, reference
from mechsim.benchmarks.bench_methods import METHODS
from mechsim.benchmarks.peer_bench import CASES
from dataclasses import replace

from mechsim.dynamics import hybrid
from mechsim.dynamics.backends.diffrax_backend import DiffraxBackend, compiled_solve, default_options


class TimedDiffrax(DiffraxBackend):
    """The diffrax backend, with the CPU time of its compiled calls added up."""

    def __init__(self, settings):
        super().__init__(settings, replace(default_options(settings), compiled_run=False))
        self.cpu, self.calls, self.steps = 0.0, 0, 0

    def integrate(self, request):
        entry, jmod, _ = compiled_solve(request.model, self.o)
        args, n_chunk = self.arguments(request, jmod)
        started = time.process_time()
        out = jax.device_get(entry.fn(*args))
        self.cpu += time.process_time() - started
        self.calls += 1
        self.steps += int(out["steps"])
        return self.segment(request, jmod, out, n_chunk)


class TimedRun(DiffraxBackend):
    """The diffrax backend on its compiled whole-run path, with the CPU time of its compiled calls added up."""

    def __init__(self, settings):
        super().__init__(settings)
        self.cpu, self.calls, self.steps = 0.0, 0, 0

    def call_compiled(self, fn, args):
        started = time.process_time()
        out = super().call_compiled(fn, args)
        self.cpu += time.process_time() - started
        if "st" in out:                       # the step loop (not its row function)
            self.calls += 1
        return out


def measure(rtol: float, rounds: int) -> list[dict]:
    problem = make_problem(BenchConfig(scenario="geneva-motor", duration=5.0, overrides=CASES["A"]))
    ref = reference(problem)
    settings = METHODS["diffrax-Tsit5"].settings(problem, rtol, rtol * 1e-2)

    def once(cls):
        backend = cls(settings)
        started = time.process_time()
        traj = hybrid.simulate(problem.mech, problem.drive, settings, problem.duration, problem.dt_out,
                               problem.angle0, problem.speed0, backend=backend)
        return traj, time.process_time() - started, backend

    out = []
    firsts = {cls: once(cls) for cls in (TimedRun, TimedDiffrax)}     # compiles
    runs = {cls: [] for cls in firsts}
    for _ in range(rounds):
        for cls in firsts:
            runs[cls].append(once(cls))
    for cls, (traj, _, _) in firsts.items():
        t = np.concatenate([p.t for p in traj.pieces])
        ix = traj.model.modes[traj.pieces[0].mode].index["q"]
        angle = np.concatenate([p.coordinates(ix)[:, problem.mech.drive_coordinate] for p in traj.pieces])
        error = float(np.max(np.abs(angle - np.interp(t, ref["t"], ref["angle"]))))
        whole = float(np.median([r[1] for r in runs[cls]]))
        compiled = float(np.median([r[2].cpu for r in runs[cls]]))
        out.append(dict(path="whole run in one call" if cls is TimedRun else "segment loop", rtol=rtol,
                        error_rad=error, run_cpu_s=whole, compiled_cpu_s=compiled, share=compiled / whole,
                        calls=runs[cls][0][2].calls, steps=runs[cls][0][0].stats["steps"],
                        compile_s=traj.stats["compile_time_s"]))
    return out


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--rounds", type=int, default=7)
    args = ap.parse_args()
    for rtol in (1e-6, 1e-8):
        for r in measure(rtol, args.rounds):
            print(f"{r['path']}, rtol {r['rtol']:g}: error {r['error_rad']:.2e} rad; whole run "
                  f"{r['run_cpu_s'] * 1e3:.1f} ms CPU, compiled calls {r['compiled_cpu_s'] * 1e3:.1f} ms "
                  f"({100 * r['share']:.0f} %) in {r['calls']} calls, {r['steps']} steps; compiled at first use in "
                  f"{r['compile_s']:.1f} s", flush=True)


if __name__ == "__main__":
    main()
