"""A warm `mechsim.run` end to end against the CasADi peer (docs/benchmarks.md, "A warm run end to end").

Case A (`peer_bench.CASES`, 5 s, 1 ms outputs, figures off), or another case, on diffrax (rtol 1e-5) and ida-compiled, ida and
the default backend (`auto`: ida-compiled once its callbacks are cached), index-1 at rtol 1e-7, all near 1e-6 rad
of crank-angle error on case A, the scenario's own solver settings (`default idx2`: auto, index-2 at rtol 1e-8), and the
CasADi IDAS peer of `peer_bench` at rtol 1e-6
(5.6e-7 rad). Interleaved rounds, the order shuffled anew each round (`peer_bench.round_orders`: no method always
runs after the same one), process CPU time, medians. Each run is split into the integration (`hybrid.simulate`,
its process CPU), the summary's located peaks (timed from inside each run: `peer_bench.located_peaks_timed`) and
the rest: tables, invariant checks and the summary's other entries; and the run without its located peaks is set
against the peer, which locates nothing.

    python benchmarks/warm_run.py [rounds] [case]

case: one of `peer_bench.CASES` (A, the default; A-mu0.15; A-mu0.15-lumped, the lumped thermal states, whose
thermal columns' located peaks are the largest part of its post-processing), the peer on the same case.
"""
from __future__ import annotations

import statistics
import sys
import time

import mechsim
from mechsim.benchmarks.bench import BenchConfig, make_problem
from mechsim.benchmarks.bench_methods import quiet_sundials
from mechsim.benchmarks.peer_bench import CASES, METHODS, PEER, located_peaks_timed, round_orders

#: backend: (scenario overrides, the bench method integrating the same, rtol)
BACKENDS = {
    "diffrax": (('solver.backend="diffrax"', "solver.rtol=1e-5", "solver.atol=1e-7"), "diffrax-Tsit5", 1e-5),
    "ida-compiled": (('solver.backend="ida-compiled"', 'solver.formulation="index1"', "solver.rtol=1e-7",
                      "solver.atol=1e-9"), "ida-compiled-index1", 1e-7),
    "ida": (('solver.backend="ida"', 'solver.formulation="index1"', "solver.rtol=1e-7", "solver.atol=1e-9"),
            "ida-index1", 1e-7),
    "default": (('solver.formulation="index1"', "solver.rtol=1e-7", "solver.atol=1e-9"), "ida-compiled-index1", 1e-7),
    "default idx2": ((), "ida-compiled-index2", 1e-8),
}


def main(rounds: int = 9, case: str = "A") -> None:
    base = CASES[case] + ("duration=5 s", "output_step=1 ms", "output.plots=false")
    problem = make_problem(BenchConfig(scenario="geneva-motor", duration=5.0, overrides=CASES[case]))
    calls = {}
    for name, (extra, method, rtol) in BACKENDS.items():
        sc = mechsim.load("geneva-motor", set=list(base + extra))
        calls[name] = lambda sc=sc: mechsim.run(sc)
        m = METHODS[method]
        with quiet_sundials():
            handle = m.setup(problem, rtol, rtol * 1e-2)[0]
        calls[f"{name} solve"] = lambda m=m, h=handle, rtol=rtol: m.run(h, problem, rtol, rtol * 1e-2)
    peer = METHODS[PEER]
    with quiet_sundials():
        handle = peer.setup(problem, 1e-6, 1e-8)[0]
    calls[PEER] = lambda: peer.run(handle, problem, 1e-6, 1e-8)
    names = list(calls)
    with quiet_sundials(), located_peaks_timed() as located:
        for name in names:                      # warm: compiled, derived, cached
            calls[name]()
            calls[name]()
        cpu: dict[str, list[float]] = {name: [] for name in names}
        peaks: dict[str, list[float]] = {name: [] for name in names}
        for order in round_orders(names, rounds):
            for name in order:
                located.clear()
                c = time.process_time()
                calls[name]()
                cpu[name].append(time.process_time() - c)
                peaks[name].append(sum(located))
    ms = {name: 1e3 * statistics.median(x) for name, x in cpu.items()}
    peak_ms = {name: 1e3 * statistics.median(peaks[name]) for name in BACKENDS}
    print(f"case {case}; {PEER} (rtol 1e-6): {ms[PEER]:.1f} ms CPU, median of {rounds}")
    for name in BACKENDS:
        run, solve = ms[name], ms[f"{name} solve"]
        print(f"{name:13s} warm run {run:5.1f} ms CPU = {run / ms[PEER]:.2f}x the peer; its integration alone "
              f"{solve:4.1f} ms, the rest (tables, checks, summary) {run - solve:4.1f} ms "
              f"({(run - solve) / solve:.2f}x the integration), of it the located peaks {peak_ms[name]:4.1f} ms; without them "
              f"{run - peak_ms[name]:5.1f} ms = {(run - peak_ms[name]) / ms[PEER]:.2f}x the peer")


if __name__ == "__main__":
    main(int(sys.argv[1]) if len(sys.argv) > 1 else 9, sys.argv[2] if len(sys.argv) > 2 else "A")
