"""`mechsim bench --peer`: mechsim against the strongest peer, side by side in one process, at equal error.

Cases (the seed Geneva, n = 4, r = 75 mm, driven by a linear motor, stall 40 N·m, no-load 6 rad/s, from
5.34 rad/s against 7 N·m on the wheel, 5 s, outputs every 1 ms; built-in `geneva-motor` with overrides):

- `A`: no friction (9 mode changes);
- `A-mu0.15`: friction 0.15 (slip reversals are real mode changes);
- `A-mu0.15-lumped`: friction 0.15 and the lumped thermal model (bulk pin/crank/wheel temperatures and the
  heat balance as 6 more states; without friction no heat flows, so the thermal case has friction).

Methods: mechsim's IDA (index-1 and index-2; the scenario's formulation is index-2), mechsim's diffrax Tsit5 (warm; its compile time
per tolerance is reported apart), the CasADi IDAS peer of `bench_casadi` (a Python event loop as a careful
CasADi user writes it, and CasADi's own event support), the diffsol peer of `bench_diffsol` (the crank angle
per mode in DiffSL, compiled by LLVM, Tsit45; the external Geneva without friction: case A only; skipped when
pydiffsol is not installed), and scipy's LSODA and DOP853 on the reduced 2-state ODE, a scipy user's first
choice (mechanics only: not in the thermal case).

Two times per mechsim row: the solve (`hybrid.simulate`, what the peers do) and, interleaved in the same
rounds, the warm `mechsim.run` of the same scenario and settings end to end (tables, located peaks, checks,
summary; `run_cpu_time_s`, its own error in `run_error_rad`), plus `mechsim-default`: the run with the
scenario's default backend and formulation at each tolerance (end to end only). Both are divided by each
peer's solve at equal error. Of each end-to-end run, its located peaks are timed from inside it
(`runner.PEAKS_OBSERVERS`; `run_peaks_cpu_time_s`) and the run without them (`run_less_peaks_cpu_time_s`, the
median of each round's difference) is divided by the peers' solves too: the peers locate nothing.

Error: max crank-angle difference (rad) at the output times from the reduced-coordinate reference
(`Mechanism.reference_solution`, DOP853 at rtol 1e-12; thermal states do not act on the mechanics).
Time: process CPU time of a warm run. The machine is shared and noisy, so every tolerance is timed in
`rounds` rounds; in each round every method runs once, in an order shuffled anew each round (a fixed seed):
interleaved, so that a burst of load hits every method alike, and with different neighbours each round, so that
no method always runs after the same one (what a run leaves in the caches changes the next one's time); the figure
is the median over the rounds. The ratios at equal
error interpolate each method's median-CPU work-precision curve (log-log, its Pareto front, no
extrapolation, `bench.time_at_error`) at 1e-6 and 1e-8 rad and divide by the peer's.
"""
from __future__ import annotations

import random
import time
from contextlib import contextmanager
from dataclasses import dataclass, field
from typing import Callable

import numpy as np
import pandas as pd

from mechsim.benchmarks.bench import BenchConfig, make_problem, reference, time_at_error
from mechsim.benchmarks.bench_methods import METHODS, NAN, quiet_sundials

CASE_A = ("drive.no_load_speed=6 rad/s", "contact.friction=0")
CASES: dict[str, tuple[str, ...]] = {
    "A": CASE_A,
    "A-mu0.15": ("drive.no_load_speed=6 rad/s", "contact.friction=0.15"),
    "A-mu0.15-lumped": ("drive.no_load_speed=6 rad/s", "contact.friction=0.15", 'thermal.model="lumped"'),
}
PEER = "casadi-idas"
#: the peers every ratio is reported against: the CasADi IDAS script and the compiled diffsol one (case A)
PEERS = ("casadi-idas", "diffsol-tsit45")
#: the default backend's end-to-end run at each tolerance (no solve of its own: it is one of the backends)
DEFAULT = "mechsim-default"
METHODS_FULL = ("ida-compiled-index1", "ida-compiled-index2", "ida-index1", "ida-index2", "diffrax-Tsit5", DEFAULT,
                "casadi-idas", "casadi-idas-events", "diffsol-tsit45", "scipy-LSODA", "scipy-DOP853")
#: CI: index-1, whose error reaches 1e-8 on case A within the small tolerance range (index-2 stalls at ~2e-8)
METHODS_SMALL = ("ida-compiled-index1", "ida-index1", DEFAULT, "casadi-idas", "diffsol-tsit45")
RTOLS_FULL = (1e-4, 1e-5, 1e-6, 1e-7, 1e-8, 1e-9, 1e-10)
RTOLS_SMALL = (1e-5, 1e-6, 1e-7, 1e-8, 1e-9)
TARGETS = (1e-6, 1e-8)
#: the peer's error target on case A (issue: <= 1e-6 rad within 25 ms CPU on the 2-core machine)
PEER_TARGET_ERROR = 1e-6
COLUMNS = ["case", "method", "family", "rtol", "atol", "status", "error_rad", "cpu_time_s", "cpu_time_min_s",
           "wall_time_s", "run_error_rad", "run_cpu_time_s", "run_cpu_time_min_s", "run_peaks_cpu_time_s",
           "run_less_peaks_cpu_time_s", "rounds", "setup_time_s",
           "setup_scope", "steps", "rejected_steps",
           "residual_evaluations", "jacobian_evaluations", "events", "segments", "output_points", "failure"]


@dataclass(frozen=True)
class PeerConfig:
    cases: tuple[str, ...] = tuple(CASES)
    methods: tuple[str, ...] = METHODS_FULL
    rtols: tuple[float, ...] = RTOLS_FULL
    rounds: int = 7
    atol_factor: float = 1e-2
    #: the mechsim methods also run end to end (warm mechsim.run); None: all of them
    end_to_end: tuple[str, ...] | None = None

    @classmethod
    def small(cls) -> "PeerConfig":
        """The CI size: case A, mechsim IDA (solve and end to end), the default's end-to-end run and both peers
        (diffsol when installed), five tolerances (both target errors inside), two rounds."""
        return cls(cases=("A",), methods=METHODS_SMALL, rtols=RTOLS_SMALL, rounds=2,
                   end_to_end=("ida-compiled-index1", DEFAULT))


@dataclass
class PeerResult:
    rows: pd.DataFrame
    summary: dict = field(default_factory=dict)


def available(names) -> tuple[str, ...]:
    return tuple(n for n in names if n == DEFAULT or (n in METHODS and METHODS[n].available()))


def unavailable(names) -> list[str]:
    """One line per chosen method whose package is not installed."""
    return [f"{n}: skipped, {METHODS[n].requires} is not installed (the `peers` extra)"
            for n in names if n != DEFAULT and n in METHODS and not METHODS[n].available()]


def run_overrides(name: str, rtol: float, atol: float) -> tuple[str, ...] | None:
    """The scenario overrides under which `mechsim.run` integrates as bench method `name` does (None: not a
    mechsim method); DEFAULT sets the tolerances only."""
    from mechsim.benchmarks.bench_methods import DiffraxMethod, IdaMethod
    tol = (f"solver.rtol={rtol!r}", f"solver.atol={atol!r}")
    if name == DEFAULT:
        return tol
    m = METHODS.get(name)
    if isinstance(m, IdaMethod):
        return tol + (f'solver.backend="{m.backend}"', f'solver.formulation="{m.formulation}"')
    if isinstance(m, DiffraxMethod):
        return tol + ('solver.backend="diffrax"', 'solver.formulation="index1"', f'solver.diffrax_solver="{m.solver}"')
    return None


def default_backend() -> str:
    """The scenario's default backend and formulation, as `mechsim.run` resolves them on case A."""
    import mechsim
    s = mechsim.load("geneva-motor", set=list(CASE_A)).si["solver"]
    return f"{s['backend']} {s['formulation']}"


class _EndToEnd:
    """A warm `mechsim.run` of the case under a bench method's settings, its crank angle compared as a Run."""

    def __init__(self, case: str, overrides: tuple[str, ...], problem):
        import mechsim
        from mechsim.benchmarks.bench import error_column
        base = CASES[case] + (f"duration={problem.duration!r} s", f"output_step={problem.dt_out!r} s",
                              "output.plots=false")
        self.scenario = mechsim.load("geneva-motor", set=list(base + overrides))
        self.column = error_column(problem)

    def __call__(self):
        import mechsim
        return mechsim.run(self.scenario)

    def angle(self, result):
        from mechsim.benchmarks.bench_methods import Run
        ts = result.timeseries
        failure = None if result.failure is None else result.failure.message()
        return Run(ts["t_s"].to_numpy(), ts[self.column].to_numpy(), {}, failure)


def _error(run, ref) -> float:
    if len(run.t) < 2:
        return NAN
    return float(np.max(np.abs(run.angle - np.interp(run.t, ref["t"], ref["angle"]))))


def round_orders(items: list, rounds: int):
    """`items` in a new order for each of `rounds` rounds, shuffled with a fixed seed (the module docstring: no
    method always runs after the same one)."""
    shuffle = random.Random(0).shuffle
    for _ in range(rounds):
        order = list(items)
        shuffle(order)
        yield order


def measure_case(case: str, config: PeerConfig, say: Callable[[str], None]) -> list[dict]:
    """Rows (method, rtol) of one case: set up every method, then `rounds` interleaved rounds of warm runs."""
    problem = make_problem(BenchConfig(scenario="geneva-motor", duration=5.0, overrides=CASES[case]))
    ref = reference(problem)
    names = [n for n in available(config.methods) if n == DEFAULT or METHODS[n].supports_problem(problem)]
    rows = []
    for rtol in config.rtols:
        atol = rtol * config.atol_factor
        handles, runs, cpu, wall = {}, {}, {n: [] for n in names}, {n: [] for n in names}
        e2e, e2e_runs, e2e_cpu = {}, {}, {n: [] for n in names}
        e2e_peaks = {n: [] for n in names}          # the located peaks' CPU inside each end-to-end run
        for n in names:
            try:
                with quiet_sundials():
                    if n != DEFAULT:
                        m = METHODS[n]
                        handles[n] = m.setup(problem, rtol, atol)
                        runs[n] = m.run(handles[n][0], problem, rtol, atol)      # warm-up, and the run judged
                    extra = run_overrides(n, rtol, atol)
                    if extra is not None and (config.end_to_end is None or n in config.end_to_end):
                        e2e[n] = _EndToEnd(case, extra, problem)
                        e2e[n]()                                                   # warm-up
                        e2e_runs[n] = e2e[n].angle(e2e[n]())
            except Exception as exc:  # noqa: BLE001 - a method that raises is a row with its reason
                runs[n] = exc
        live = [n for n in names if n != DEFAULT and not isinstance(runs[n], Exception) and not runs[n].failure]
        calls = [(n, False) for n in live] + [(n, True) for n in e2e if not isinstance(runs.get(n), Exception)
                                              and not e2e_runs[n].failure]
        with located_peaks_timed() as located:
            for order in round_orders(calls, config.rounds):
                for n, end_to_end in order:
                    located.clear()
                    w, c = time.perf_counter(), time.process_time()
                    with quiet_sundials():
                        if end_to_end:
                            e2e[n]()
                        else:
                            METHODS[n].run(handles[n][0], problem, rtol, atol)
                    if end_to_end:
                        e2e_cpu[n].append(time.process_time() - c)
                        e2e_peaks[n].append(sum(located))
                        continue
                    cpu[n].append(time.process_time() - c)
                    wall[n].append(time.perf_counter() - w)
        for n in names:
            r = runs.get(n, e2e_runs.get(n))
            row = dict(case=case, method=n, family=METHODS[n].family if n != DEFAULT else "mechsim default",
                       rtol=rtol, atol=atol)
            if isinstance(r, Exception):
                rows.append({**row, "status": "error", "failure": f"{type(r).__name__}: {r}"})
                continue
            if n in e2e_runs:
                row.update(run_error_rad=_error(e2e_runs[n], ref), **_times("run_cpu_time", e2e_cpu[n]),
                           run_peaks_cpu_time_s=_median(e2e_peaks[n]),
                           run_less_peaks_cpu_time_s=_median([r - p for r, p in zip(e2e_cpu[n], e2e_peaks[n])]))
            if n == DEFAULT:     # its error is the run's; no solve of its own
                row.update(status="failed" if r.failure else "ok", error_rad=row["run_error_rad"],
                           rounds=len(e2e_cpu[n]), output_points=len(r.t), failure=r.failure or "")
                rows.append(row)
                say(f"{case:<16} {n:<19} rtol {rtol:7.0e}: error {row['error_rad']:.2e} rad, run cpu median "
                    f"{1e3 * row['run_cpu_time_s']:.1f} ms")
                continue
            m = METHODS[n]
            with quiet_sundials():
                counts = m.count(handles[n][0], problem, rtol, atol)
            stats = {**r.stats, **counts}
            row.update(status="failed" if r.failure else "ok", error_rad=_error(r, ref),
                       **_times("cpu_time", cpu[n]),
                       wall_time_s=float(np.median(wall[n])) if wall[n] else NAN, rounds=len(cpu[n]),
                       setup_time_s=handles[n][1], setup_scope=handles[n][2], output_points=len(r.t),
                       failure=r.failure or "")
            for key in ("steps", "rejected_steps", "residual_evaluations", "jacobian_evaluations", "events",
                        "segments"):
                row[key] = stats.get(key, NAN)
            rows.append(row)
            run_part = (f"; run {1e3 * row['run_cpu_time_s']:.1f} ms ({row['run_error_rad']:.2e} rad)"
                        if n in e2e_runs else "")
            say(f"{case:<16} {n:<19} rtol {rtol:7.0e}: error {row['error_rad']:.2e} rad, cpu median "
                f"{1e3 * row['cpu_time_s']:.1f} ms (min {1e3 * row['cpu_time_min_s']:.1f}){run_part}")
    return rows


@contextmanager
def located_peaks_timed():
    """Within it, each run's located peaks are timed from inside the run (`runner.PEAKS_OBSERVERS`): their process
    CPU is appended to the yielded list, which the caller clears before each run."""
    from mechsim.scenarios import runner
    located: list[float] = []
    runner.PEAKS_OBSERVERS.append(located.append)
    try:
        yield located
    finally:
        runner.PEAKS_OBSERVERS.remove(located.append)


def _median(samples: list[float]) -> float:
    return float(np.median(samples)) if samples else NAN


def _times(prefix: str, samples: list[float]) -> dict:
    return {f"{prefix}_s": float(np.median(samples)) if samples else NAN,
            f"{prefix}_min_s": float(np.min(samples)) if samples else NAN}


def ratios(rows: pd.DataFrame, peer: str = PEER, column: str = "cpu_time_s") -> dict:
    """Per case and target error: each method's time (interpolated on its measured curve) and its ratio to the
    peer's solve; NaN where a method's curve does not reach the target. column "run_cpu_time_s": the
    end-to-end runs, on their own errors (`run_error_rad`)."""
    out: dict = {}
    end_to_end = column.startswith("run_")
    for case, solves in rows.groupby("case", sort=False):
        d = solves.assign(error_rad=solves["run_error_rad"]) if end_to_end else solves
        entry = {}
        for target in TARGETS:
            t_peer = time_at_error(solves, peer, target, "cpu_time_s")
            measured = [m for m in dict.fromkeys(d.method) if np.isfinite(d.loc[d.method == m, column]).any()]
            times = {m: time_at_error(d, m, target, column) for m in measured}
            entry[f"{target:.0e}"] = {
                "time_s": {m: v for m, v in times.items()},
                "ratio_to_peer": {m: (v / t_peer if np.isfinite(v) and np.isfinite(t_peer) else NAN)
                                  for m, v in times.items() if m != peer}}
        out[case] = entry
    return out


def run_peer_bench(config: PeerConfig, progress: Callable[[str], None] | None = None) -> PeerResult:
    say = progress or (lambda _m: None)
    rows = []
    for case in config.cases:
        rows += measure_case(case, config, say)
    df = pd.DataFrame(rows).reindex(columns=COLUMNS)
    summary = {
        "cases": {c: list(CASES[c]) for c in config.cases}, "scenario": "geneva-motor, 5 s, 1 ms outputs",
        "error": "max |crank_angle_rad - reference| at the output times (rad)",
        "time": f"process CPU time of a warm run, median of {config.rounds} interleaved rounds",
        "rtols": list(config.rtols), "atol": f"{config.atol_factor:g} x rtol", "peer": PEER,
        "ratios_at_equal_error_cpu": ratios(df), "peer_target": _peer_target(df),
        "ratios_by_peer": {p: {"solve": ratios(df, p), "end_to_end": ratios(df, p, "run_cpu_time_s"),
                               "end_to_end_without_located_peaks": ratios(df, p, "run_less_peaks_cpu_time_s")}
                           for p in PEERS if p in set(df.method)},
        "end_to_end": "warm mechsim.run of the same scenario and settings (tables, located peaks, checks, "
                      "summary), process CPU, interleaved with the solves; its own error (run_error_rad); "
                      "end_to_end_without_located_peaks: the same runs less their located peaks (runner.peaks, "
                      "timed from inside each run), which the peers do not compute",
        "default_backend": default_backend(), "load_average": list(_load()),
        "versions": versions(),
    }
    return PeerResult(df, summary)


def versions() -> dict[str, str]:
    from importlib import metadata
    out = {}
    for pkg in ("mechsim", "scikit-sundae", "casadi", "pydiffsol", "diffrax", "jax", "scipy", "numpy"):
        try:
            out[pkg] = metadata.version(pkg)
        except metadata.PackageNotFoundError:
            out[pkg] = "not installed"
    return out


def _load() -> tuple[float, ...]:
    import os
    try:
        return tuple(round(x, 2) for x in os.getloadavg())
    except OSError:
        return ()


def _peer_target(rows: pd.DataFrame) -> dict:
    """On case A: the peer's cheapest run at or below the target error (error, CPU time)."""
    d = rows[(rows.case == "A") & (rows.method == PEER) & (rows.status == "ok") & (rows.error_rad <= PEER_TARGET_ERROR)]
    if d.empty:
        return {"target_error_rad": PEER_TARGET_ERROR, "reached": False}
    best = d.sort_values("cpu_time_s").iloc[0]
    return {"target_error_rad": PEER_TARGET_ERROR, "reached": True, "rtol": float(best.rtol),
            "error_rad": float(best.error_rad), "cpu_time_s": float(best.cpu_time_s)}


def report_lines(result: PeerResult) -> list[str]:
    lines = []
    for case, entry in result.summary["ratios_at_equal_error_cpu"].items():
        for target, e in entry.items():
            t_peer = e["time_s"].get(PEER, NAN)
            parts = [f"{m} {v:.2f}x" if np.isfinite(v) else f"{m} -" for m, v in e["ratio_to_peer"].items()]
            lines.append(f"{case}, error {target} rad: CPU time / {PEER} ({1e3 * t_peer:.1f} ms): " + ", ".join(parts))
    lines += comparison_lines(result.summary)
    pt = result.summary["peer_target"]
    if pt.get("reached"):
        lines.append(f"peer on case A: error {pt['error_rad']:.2e} rad (rtol {pt['rtol']:.0e}) in "
                     f"{1e3 * pt['cpu_time_s']:.1f} ms CPU")
    else:
        lines.append(f"peer on case A: did not reach {pt['target_error_rad']:.0e} rad")
    return lines


def comparison_lines(summary: dict) -> list[str]:
    """Per case and error: each method's solve, warm end-to-end run and that run without its located peaks (CPU
    at equal error), each as ratios to every peer's solve."""
    by_peer = summary.get("ratios_by_peer", {})
    peers = list(by_peer)
    if not peers:
        return []
    lines = []
    head = "".join(f" {'/ ' + p:>17}" for p in peers)
    for case in by_peer[peers[0]]["solve"]:
        for target in TARGETS:
            key = f"{target:.0e}"
            solve = {p: by_peer[p]["solve"].get(case, {}).get(key, {}) for p in peers}
            run = {p: by_peer[p]["end_to_end"].get(case, {}).get(key, {}) for p in peers}
            bare = {p: by_peer[p].get("end_to_end_without_located_peaks", {}).get(case, {}).get(key, {})
                    for p in peers}
            t_peer = {p: solve[p].get("time_s", {}).get(p, NAN) for p in peers}
            if not any(np.isfinite(v) for v in t_peer.values()):
                continue
            lines.append(f"{case}, error {key} rad, CPU at equal error; peers: "
                         + ", ".join(f"{p} {1e3 * t_peer[p]:.2f} ms" for p in peers if np.isfinite(t_peer[p])))
            lines.append(f"  {'method':<20} {'solve':>9}{head}   {'end to end':>10}{head}   "
                         f"{'less peaks':>10}{head}")
            names = dict.fromkeys(m for p in peers for m in {**solve[p].get("time_s", {}),
                                                              **run[p].get("time_s", {})} if m not in peers)
            for m in names:
                ts = solve[peers[0]].get("time_s", {}).get(m, NAN)
                tr = run[peers[0]].get("time_s", {}).get(m, NAN)
                tb = bare[peers[0]].get("time_s", {}).get(m, NAN)
                if not (np.isfinite(ts) or np.isfinite(tr)):
                    continue
                line = f"  {m:<20}"
                for width, t in ((9, ts), (10, tr), (10, tb)):
                    line += (f" {_ms(t):>{width}}" if width == 9 else f"   {_ms(t):>{width}}")
                    line += "".join(f" {_x(t / t_peer[p]):>17}" for p in peers)
                lines.append(line)
    if "default_backend" in summary:
        lines.append(f"{DEFAULT}: the scenario's default ({summary['default_backend']}); end to end = a warm "
                     "mechsim.run, everything included; less peaks = the same run without its located peaks "
                     "(timed from inside it), which the peers do not compute")
    return lines


def _ms(t: float) -> str:
    return f"{1e3 * t:.2f} ms" if np.isfinite(t) else "-"


def _x(r: float) -> str:
    return f"{r:.2f}x" if np.isfinite(r) else "-"


def write(result: PeerResult, out_dir, force: bool = False):
    """peer.csv and peer_summary.json into out_dir, atomically."""
    import json
    from pathlib import Path

    from mechsim.scenarios.output.atomic import atomic_folder
    from mechsim.scenarios.output.atomic import json_default

    with atomic_folder(Path(out_dir), force) as tmp:
        result.rows.to_csv(tmp / "peer.csv", index=False)
        (tmp / "peer_summary.json").write_text(json.dumps(result.summary, indent=2, default=json_default))
    return out_dir


def main() -> None:
    import argparse
    import json
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--out", default="results/peer")
    ap.add_argument("--small", action="store_true")
    ap.add_argument("--rounds", type=int, default=None)
    ap.add_argument("--cases", default=None, help="comma list of " + ", ".join(CASES))
    ap.add_argument("--methods", default=None)
    ap.add_argument("--end-to-end", default=None, help="comma list of the methods also run end to end, or none")
    args = ap.parse_args()
    config = PeerConfig.small() if args.small else PeerConfig()
    from dataclasses import replace
    if args.rounds:
        config = replace(config, rounds=args.rounds)
    if args.cases:
        config = replace(config, cases=tuple(args.cases.split(",")))
    if args.methods:
        config = replace(config, methods=tuple(args.methods.split(",")))
    if args.end_to_end:
        config = replace(config, end_to_end=() if args.end_to_end == "none" else tuple(args.end_to_end.split(",")))
    for line in unavailable(config.methods):
        print(line, flush=True)
    result = run_peer_bench(config, progress=lambda m: print(m, flush=True))
    write(result, args.out, force=True)
    print("\n".join(report_lines(result)))
    print(json.dumps(result.summary["ratios_at_equal_error_cpu"], indent=1, default=str))


if __name__ == "__main__":
    main()
