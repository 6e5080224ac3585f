"""Where mechsim diffrax's warm time goes on the benchmark's case A: the compiled segment solves alone against the
whole run (docs/benchmarks.md, "diffrax: what bounds it").

    python -m mechsim.benchmarks.diffrax_breakdown [--rounds 7]

A backend subclass times each compiled call (process CPU time, the result fetched to the host) and counts the
calls and steps; the loop and every other part of the run are unchanged.
"""
from __future__ import annotations

import argparse
import time

import jax
import numpy as np

from mechsim.benchmarks.bench import BenchConfig, make_problem, reference
from mechsim.benchmarks.bench_methods import METHODS
from mechsim.benchmarks.peer_bench import CASES
from mechsim.dynamics import hybrid
from mechsim.dynamics.diffrax_backend import DiffraxBackend, compiled_solve


class TimedDiffrax(DiffraxBackend):
    """The diffrax backend, with the CPU time of its compiled calls added up."""

    def __init__(self, settings):
        super().__init__(settings)
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


def measure(rtol: float, rounds: int) -> dict:
    problem = make_problem(BenchConfig(scenario="geneva-motor", duration=5.0, overrides=CASES["A"]))
    ref = reference(problem)
    settings = METHODS["diffrax-Tsit5"].settings(problem, rtol, rtol * 1e-2)

    def once():
        backend = TimedDiffrax(settings)
        started = time.process_time()
        traj = hybrid.simulate(problem.mech, problem.drive, settings, problem.duration, problem.dt_out,
                               problem.angle0, problem.speed0, backend=backend)
        return traj, time.process_time() - started, backend

    traj, _, _ = once()                              # compiles
    t = np.concatenate([p.t for p in traj.pieces])
    ix = traj.model.modes[traj.pieces[0].mode].index["q"]
    angle = np.concatenate([p.coordinates(ix)[:, problem.mech.drive_coordinate] for p in traj.pieces])
    error = float(np.max(np.abs(angle - np.interp(t, ref["t"], ref["angle"]))))
    runs = [once() for _ in range(rounds)]
    whole = float(np.median([r[1] for r in runs]))
    compiled = float(np.median([r[2].cpu for r in runs]))
    return dict(rtol=rtol, error_rad=error, run_cpu_s=whole, compiled_cpu_s=compiled, share=compiled / whole,
                calls=runs[0][2].calls, steps=runs[0][2].steps)


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--rounds", type=int, default=7)
    args = ap.parse_args()
    for rtol in (1e-5, 1e-6):
        r = measure(rtol, args.rounds)
        print(f"rtol {r['rtol']:g}: error {r['error_rad']:.2e} rad; whole run {r['run_cpu_s'] * 1e3:.1f} ms CPU, "
              f"compiled calls {r['compiled_cpu_s'] * 1e3:.1f} ms ({100 * r['share']:.0f} %) in {r['calls']} calls, "
              f"{r['steps']} steps")


if __name__ == "__main__":
    main()
