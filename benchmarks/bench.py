"""`mechsim bench`: work-precision of mechsim's integrators against the peers a user would pick instead.

Every method integrates the same scenario (default `geneva-motor`: motor-driven Geneva, 5 s, 1 ms output; any
scenario with a torque or motor drive, `--scenario`) over a range of requested tolerances (atol = 1e-2 rtol).
The error of a run is the largest difference of the drive coordinate's angle (rad; the Geneva's crank) at the
output times from a reference the mechanism supplies (`Mechanism.reference_solution`): an independent
integration at rtol = atol = 1e-12, for the Geneva the reduced-coordinate equation of `mechanisms.geneva_reduced`
(docs/theory.md §G2) on DOP853, restarted at every engagement boundary and slip reversal; its own uncertainty is
estimated against rtol = atol = 1e-13. A mechanism without one (None) is measured against mechsim's own IDA
index-2 at rtol 1e-12, labelled a self-reference (not independent). Methods written for other mechanisms'
equations (the Geneva's scipy and CasADi peers, `Method.mechanisms`) are skipped with a note.
The wall time of a run is the best of `repeats` warm runs; the cold work (derivation and code generation,
compilation, integrator construction) is reported apart as the setup time.

The result: one row per (method, rtol) with error, wall time, setup time, steps, rejected steps, residual and
Jacobian evaluations, events; the cost per output point; the ratios at equal error (mechsim's IDA against
CasADi's IDAS, diffrax warm against IDAS) and how the achieved error tracks the requested tolerance.
"""
from __future__ import annotations

import math
import time
from dataclasses import dataclass, field, replace
from typing import Callable

import numpy as np
import pandas as pd

from mechsim.benchmarks.bench_methods import METHODS, NAN, Problem, quiet_sundials
from mechsim.scenarios.units import ScenarioError
from mechsim.scenarios.output.atomic import atomic_folder

FULL_RTOLS = (1e-3, 1e-4, 1e-5, 1e-6, 1e-7, 1e-8, 1e-9, 1e-10)
SMALL_RTOLS = (1e-4, 1e-7)
#: methods of the small (CI) run: no compilation-heavy diffrax, no index-3 (it fails slowly, see stability); the
#: compiled-callback IDA is the default backend once a model's callbacks are cached, so it stands beside the peer
SMALL_METHODS = ("ida-index1", "ida-index2", "ida-compiled-index1", "ida-compiled-index2", "scipy-Radau", "scipy-BDF",
                 "scipy-LSODA", "scipy-DOP853", "casadi-idas")
TARGET_ERRORS = (1e-4, 1e-6, 1e-8, 1e-9, 1e-10)
REFERENCE_RTOL = 1e-12
COLUMNS = ["method", "family", "kind", "equations", "rtol", "atol", "status", "error_rad", "wall_time_s",
           "cpu_time_s", "setup_time_s", "setup_scope", "steps", "rejected_steps", "residual_evaluations",
           "jacobian_evaluations", "events", "segments", "output_points", "t_reached_s", "failure",
           "error_column", "reference"]
SELF_REFERENCE = "self-reference (IDA index2, rtol 1e-12; not independent)"


@dataclass(frozen=True)
class BenchConfig:
    scenario: str = "geneva-motor"
    methods: tuple[str, ...] = SMALL_METHODS
    rtols: tuple[float, ...] = SMALL_RTOLS
    duration: float | None = 1.0          # None: the scenario's
    output_step: float | None = None      # None: the scenario's
    repeats: int = 1
    atol_factor: float = 1e-2
    output_cost: bool = True
    overrides: tuple[str, ...] = ()       # --set section.key=value

    @classmethod
    def small(cls, names=(), scenario: str = "geneva-motor", overrides=()) -> "BenchConfig":
        return cls(scenario=scenario, overrides=tuple(overrides),
                   methods=select(names, tuple(n for n in SMALL_METHODS if METHODS[n].available())))

    @classmethod
    def full(cls, names=(), scenario: str = "geneva-motor", overrides=()) -> "BenchConfig":
        every = tuple(n for n, m in METHODS.items() if m.available())
        return cls(scenario=scenario, overrides=tuple(overrides), methods=select(names, every), rtols=FULL_RTOLS,
                   duration=None, repeats=3)


@dataclass
class BenchResult:
    rows: pd.DataFrame
    output_cost: pd.DataFrame
    summary: dict
    reference: dict = field(default_factory=dict)


def select(names, default: tuple[str, ...]) -> tuple[str, ...]:
    """Methods named (exactly, or a family prefix such as `ida`, `scipy`, `casadi`, `diffrax`), else default."""
    if not names:
        return default
    chosen: list[str] = []
    for name in names:
        hits = [n for n in METHODS if n == name or n.startswith(name.rstrip("-") + "-")]
        if not hits:
            raise ScenarioError("bench", f"unknown method {name!r} (known: {', '.join(METHODS)}; or a prefix: "
                                         "ida, diffrax, scipy, casadi)")
        missing = [n for n in hits if not METHODS[n].available()]
        if missing and len(missing) == len(hits):
            raise ScenarioError("bench", f"{', '.join(missing)} needs the '{METHODS[missing[0]].requires}' package "
                                         "(pip install 'mechsim[bench]')")
        chosen += [n for n in hits if n not in chosen and METHODS[n].available()]
    return tuple(chosen)


def make_problem(config: BenchConfig) -> Problem:
    """The scenario as a benchmark problem (any mechanism with a torque or motor drive: a prescribed speed
    leaves nothing to integrate in the drive coordinate)."""
    from mechsim.scenarios.loader import load
    from mechsim.scenarios.runner import plan

    sc = load(config.scenario, list(config.overrides))
    si = sc.si
    if si["drive"]["type"] not in ("torque", "motor"):
        raise ScenarioError("bench", "the benchmark needs a scenario with a torque or motor drive (a prescribed "
                                     f"speed fixes the drive coordinate); got {config.scenario!r}")
    s = si["solver"]
    planned = plan(sc)
    mech = planned.mechanism
    angle_key, speed_key = mech.initial_keys
    thermal = planned.thermal and planned.thermal.setup
    if thermal is not None and thermal.extension is None:
        raise ScenarioError("bench", f"thermal.model = {thermal.model!r} adds no states; the benchmark integrates "
                                     "'none', 'lumped' or '1d'")
    return Problem(sc.name, mech, planned.drive, si["initial"][angle_key],
                   si["initial"][speed_key], config.duration or si["duration"],
                   config.output_step or si["output_step"], (s["baumgarte_alpha"], s["baumgarte_beta"]),
                   thermal and thermal.extension, thermal and thermal.initial)


def error_column(problem: Problem) -> str:
    """The timeseries column the error is measured on (the drive coordinate's angle)."""
    from mechsim.dynamics.tables import coordinate_columns
    mech = problem.mech
    k = mech.drive_coordinate
    return coordinate_columns(mech.coordinates[k], k in mech.angle_coordinates)[0]


def reference(problem: Problem) -> dict:
    """The drive coordinate's angle on the output grid from the mechanism's independent reference
    (`Mechanism.reference_solution`), and its own uncertainty (against 10x tighter); without one, mechsim's
    IDA index-2 at rtol 1e-12, labelled a self-reference."""
    mech, grid = problem.mech, problem.grid
    args = (problem.drive, grid, problem.angle0, problem.speed0)
    wall = time.perf_counter()
    angle = mech.reference_solution(*args, rtol=REFERENCE_RTOL)
    if angle is not None:
        elapsed = time.perf_counter() - wall
        finer = mech.reference_solution(*args, rtol=REFERENCE_RTOL / 10)
        doc = " ".join((type(mech).reference_solution.__doc__ or "").split())
        return {"t": grid, "angle": np.asarray(angle, float), "rtol": REFERENCE_RTOL, "wall_time_s": elapsed,
                "uncertainty_rad": float(np.max(np.abs(np.asarray(angle) - np.asarray(finer)))),
                "method": f"{type(mech).__name__}.reference_solution: {doc}", "independent": True,
                "label": f"independent ({type(mech).__name__}.reference_solution, rtol {REFERENCE_RTOL:g})"}
    ida = METHODS["ida-index2"]
    with quiet_sundials():
        run = ida.run(None, problem, REFERENCE_RTOL, REFERENCE_RTOL * 1e-2)
        elapsed = time.perf_counter() - wall
        finer = ida.run(None, problem, REFERENCE_RTOL / 10, REFERENCE_RTOL * 1e-3)
    if run.failure or len(run.t) != len(grid):
        raise ScenarioError("bench", f"the self-reference (IDA index2, rtol 1e-12) did not finish: {run.failure}")
    n = min(len(finer.t), len(run.t))
    return {"t": run.t, "angle": run.angle, "rtol": REFERENCE_RTOL, "wall_time_s": elapsed,
            "uncertainty_rad": float(np.max(np.abs(run.angle[:n] - finer.angle[:n]))) if n else NAN,
            "method": SELF_REFERENCE, "independent": False, "label": SELF_REFERENCE}


def _error(run, ref: dict) -> float:
    if len(run.t) < 2:
        return NAN
    return float(np.max(np.abs(run.angle - np.interp(run.t, ref["t"], ref["angle"]))))


def bench_one(method, problem: Problem, rtol: float, atol: float, ref: dict, repeats: int, setup_cache: dict):
    """One row: set up (cold), run warm `repeats` times (best wall time), count, compare with the reference."""
    row = dict(method=method.name, family=method.family, kind=method.kind, equations=method.equations,
               rtol=rtol, atol=atol)
    scope_key = (method.name, rtol) if method.name.startswith(("diffrax", "casadi")) else method.name
    try:
        if scope_key not in setup_cache:
            setup_cache[scope_key] = method.setup(problem, rtol, atol)
        handle, setup_time, scope = setup_cache[scope_key]
        walls, cpus = [], []
        run = None
        for i in range(max(1, repeats) + 1):            # the first run warms up (caches, lazy initialisation)
            wall, cpu = time.perf_counter(), time.process_time()
            run = method.run(handle, problem, rtol, atol)
            walls.append(time.perf_counter() - wall)
            cpus.append(time.process_time() - cpu)
            if run.failure or walls[-1] > 20.0:          # failures and slow runs are not repeated
                break
        counts = method.count(handle, problem, rtol, atol)
    except Exception as exc:  # noqa: BLE001 - a method that raises is a row with its reason, not a crash
        return {**row, "status": "error", "failure": f"{type(exc).__name__}: {exc}", "error_rad": NAN,
                "wall_time_s": NAN, "cpu_time_s": NAN, "setup_time_s": NAN, "setup_scope": ""}
    stats = {**run.stats, **{k: v for k, v in counts.items() if k not in run.stats or run.stats[k] is None or
                             (isinstance(run.stats[k], float) and math.isnan(run.stats[k]))}}
    row.update(status="failed" if run.failure else "ok", error_rad=_error(run, ref),
               wall_time_s=min(walls[1:]) if len(walls) > 1 else walls[0],
               cpu_time_s=min(cpus[1:]) if len(cpus) > 1 else cpus[0], setup_time_s=setup_time,
               setup_scope=scope, output_points=len(run.t), t_reached_s=float(run.t[-1]) if len(run.t) else 0.0,
               failure=run.failure or "")
    for key in ("steps", "rejected_steps", "residual_evaluations", "jacobian_evaluations", "events", "segments"):
        row[key] = stats.get(key, NAN)
    return row


def output_cost(problem: Problem, names: tuple[str, ...], rtol: float = 1e-8) -> pd.DataFrame:
    """Cost per output point: the same run with 10x fewer output points, (wall difference) / (row difference);
    plus mechsim's table building (read-outs of every row) per row."""
    rows = []
    coarse = replace(problem, dt_out=problem.dt_out * 10)
    for name in names:
        method = METHODS[name]
        if not name.startswith(("ida-index1", "ida-index2", "casadi", "diffrax-Tsit5")):
            continue
        atol = rtol * 1e-2
        try:
            walls = {}
            for label, prob, meth in (("fine", problem, method), ("coarse", coarse, method)):
                handle, _, _ = meth.setup(prob, rtol, atol)
                meth.run(handle, prob, rtol, atol)
                best = math.inf
                for _ in range(3):
                    wall = time.perf_counter()
                    run = meth.run(handle, prob, rtol, atol)
                    best = min(best, time.perf_counter() - wall)
                walls[label] = (best, len(run.t))
        except Exception:  # noqa: BLE001
            continue
        (w1, n1), (w2, n2) = walls["fine"], walls["coarse"]
        row = dict(method=name, rtol=rtol, output_points=n1, wall_time_s=w1, output_points_coarse=n2,
                   wall_time_coarse_s=w2, cost_per_output_point_us=1e6 * (w1 - w2) / max(n1 - n2, 1),
                   table_building_per_row_us=NAN)
        if name.startswith("ida"):
            from mechsim.dynamics.hybrid import simulate
            from mechsim.dynamics.tables import timeseries
            traj = simulate(problem.mech, problem.drive, method.settings(problem, rtol, atol), problem.duration,
                            problem.dt_out, problem.angle0, problem.speed0)
            wall = time.perf_counter()
            df = timeseries(traj, problem.mech.angle_coordinates)
            row["table_building_per_row_us"] = 1e6 * (time.perf_counter() - wall) / len(df)
        rows.append(row)
    return pd.DataFrame(rows)


# -- analysis -------------------------------------------------------------------------------------------------
def time_at_error(rows: pd.DataFrame, method: str, target: float, column: str = "wall_time_s") -> float:
    """Warm time (`column`) to reach `target` error: log-log interpolation on the method's Pareto front (the
    runs that are cheaper than every more accurate run). A target coarser than the whole front takes the
    cheapest run, which meets it; NaN for a target finer than every run (no extrapolation)."""
    d = rows[(rows.method == method) & (rows.status == "ok") & np.isfinite(rows.error_rad) & (rows.error_rad > 0)
             & np.isfinite(rows[column])]
    if d.empty:
        return NAN
    d = d.sort_values("error_rad")
    front, best = [], math.inf
    for err, wall in zip(d.error_rad, d[column]):           # from accurate to coarse: keep what gets cheaper
        if wall < best:
            front.append((err, wall))
            best = wall
    errs = np.log10([e for e, _ in front])
    walls = np.log10([w for _, w in front])
    x = math.log10(target)
    if x < errs[0] - 1e-9:
        return NAN
    if x > errs[-1]:
        return float(front[-1][1])
    if len(front) == 1:
        return float(front[0][1])
    return float(10 ** np.interp(x, errs, walls))


def tracking(rows: pd.DataFrame, method: str) -> dict:
    """Least-squares slope of log10(error) against log10(rtol) and the largest deviation from that line."""
    d = rows[(rows.method == method) & (rows.status == "ok") & (rows.error_rad > 0)]
    if len(d) < 2:
        return {"points": len(d)}
    x, y = np.log10(d.rtol.to_numpy(float)), np.log10(d.error_rad.to_numpy(float))
    slope, icpt = np.polyfit(x, y, 1)
    return {"points": int(len(d)), "slope": float(slope), "error_over_rtol_at_1": float(10 ** icpt),
            "max_deviation_decades": float(np.max(np.abs(y - (slope * x + icpt)))),
            "rtol_range": [float(d.rtol.min()), float(d.rtol.max())]}


def ratios(rows: pd.DataFrame, column: str = "wall_time_s") -> dict:
    """Time ratios at equal error: mechsim IDA / CasADi IDAS, diffrax warm / IDAS (lower is better); `column`
    is the wall time or the process CPU time (less disturbed by other load on the machine)."""
    methods = list(dict.fromkeys(rows.method))
    casadi = [m for m in methods if m.startswith("casadi")]
    out: dict = {}
    for target in TARGET_ERRORS:
        key = f"{target:.0e}"
        t_ids = {m: time_at_error(rows, m, target, column) for m in methods}
        finite = [t_ids[m] for m in casadi if np.isfinite(t_ids[m])]
        idas = min(finite) if finite else NAN
        entry = {"time_s": {m: v for m, v in t_ids.items() if np.isfinite(v)}, "casadi_idas_best_s": idas}
        for m in methods:
            if m.startswith(("ida-", "diffrax-")) and np.isfinite(t_ids[m]) and np.isfinite(idas):
                entry[f"{m}/casadi-idas"] = t_ids[m] / idas
        out[key] = entry
    return out


def run_bench(config: BenchConfig, progress: Callable[[str], None] | None = None) -> BenchResult:
    problem = make_problem(config)
    say = progress or (lambda _msg: None)
    skipped = {n: METHODS[n].skip_reason(problem) for n in config.methods if not METHODS[n].supports_problem(problem)}
    methods = tuple(n for n in config.methods if n not in skipped)
    for n, why in skipped.items():
        say(f"{n}: skipped, {why}")
    if not methods:
        raise ScenarioError("bench", f"none of the chosen methods applies to {problem.mech.name!r} "
                                     f"({'; '.join(f'{n}: {w}' for n, w in skipped.items())})")
    config = replace(config, methods=methods)
    wall0 = time.perf_counter()
    ref = reference(problem)
    column = error_column(problem)
    say(f"reference: {ref['method']} at rtol {ref['rtol']:g}, {ref['wall_time_s']:.2f} s, "
        f"uncertainty {ref['uncertainty_rad']:.1e} rad; error on {column}")
    rows, cache = [], {}
    # tolerance outside, methods inside: a change of load on a shared machine hits every method alike
    for rtol in config.rtols:
        for name in config.methods:
            with quiet_sundials():
                row = bench_one(METHODS[name], problem, rtol, rtol * config.atol_factor, ref, config.repeats, cache)
            row.update(error_column=column, reference=ref["label"])
            rows.append(row)
            say(f"{name:<18} rtol {rtol:7.0e}: {row['status']:<6} error {row['error_rad']:.2e} rad, "
                f"wall {row['wall_time_s']:.3f} s, cpu {row['cpu_time_s']:.3f} s")
    order = {name: i for i, name in enumerate(config.methods)}
    rows.sort(key=lambda r: (order[r["method"]], -r["rtol"]))
    with quiet_sundials():
        cost = output_cost(problem, config.methods) if config.output_cost else pd.DataFrame()
    df = pd.DataFrame(rows).reindex(columns=COLUMNS)
    summary = {
        "scenario": problem.scenario, "duration_s": problem.duration, "output_step_s": problem.dt_out,
        "output_points": len(problem.grid), "mechanism": problem.mech.name, "error_column": column,
        "error": f"max |{column} - reference| at the output times (rad)",
        "wall_time": f"best of {config.repeats} warm runs (setup apart)",
        "reference": {k: v for k, v in ref.items() if k not in ("t", "angle", "label")},
        "reference_label": ref["label"],
        "rtols": list(config.rtols), "atol": f"{config.atol_factor:g} x rtol", "methods": list(config.methods),
        "skipped_methods": skipped,
        "ratios_at_equal_error": ratios(df),
        "ratios_at_equal_error_cpu_time": ratios(df, "cpu_time_s"),
        "tolerance_tracking": {m: tracking(df, m) for m in config.methods},
        "per_call_residual_cost": residual_call_cost() if config.rtols == FULL_RTOLS else
        "run with --full (or python benchmarks/residual_cost.py)",
        "bench_wall_time_s": time.perf_counter() - wall0,
    }
    from mechsim.scenarios.runner import versions
    summary["versions"] = {**versions(), "casadi": _version("casadi")}
    return BenchResult(df, cost, summary, ref)


def _version(pkg: str) -> str:
    from importlib import metadata
    try:
        return metadata.version(pkg)
    except metadata.PackageNotFoundError:
        return "not installed"


def residual_call_cost():
    """Per-call cost of the generated residual/Jacobian against jax.jit, from benchmarks/residual_cost.py
    (reused, not duplicated); available when running from a source checkout."""
    import importlib.util
    from pathlib import Path
    path = Path(__file__).resolve().parents[1] / "benchmarks" / "residual_cost.py"
    if not path.is_file():
        return "benchmarks/residual_cost.py not found (installed without the source tree)"
    spec = importlib.util.spec_from_file_location("mechsim_residual_cost", path)
    module = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(module)
    if not hasattr(module, "measure"):
        return "benchmarks/residual_cost.py has no measure()"
    try:
        return module.measure()
    except Exception as exc:  # noqa: BLE001 - a side measurement must not lose the benchmark
        return f"benchmarks/residual_cost.py failed: {type(exc).__name__}: {exc}"


# -- output ---------------------------------------------------------------------------------------------------
def write(result: BenchResult, out_dir, force: bool = False):
    """work_precision.csv, output_cost.csv, summary.json and work_precision.png into out_dir, atomically."""
    import json
    from pathlib import Path

    from mechsim.benchmarks.bench_plots import work_precision_figure
    from mechsim.scenarios.output.atomic import json_default as _json_default

    out_dir = Path(out_dir)
    with atomic_folder(out_dir, force) as tmp:
        result.rows.to_csv(tmp / "work_precision.csv", index=False)
        result.output_cost.to_csv(tmp / "output_cost.csv", index=False)
        (tmp / "summary.json").write_text(json.dumps(result.summary, indent=2, default=_json_default))
        work_precision_figure(result.rows, result.summary, tmp / "work_precision.png")
    return out_dir


def report_lines(result: BenchResult) -> list[str]:
    """A few lines for the console: ratios at equal error and how the error tracks the tolerance."""
    s = result.summary
    lines = []
    for target, entry in s["ratios_at_equal_error"].items():
        parts = [f"{k.split('/')[0]} {v:.2f}x" for k, v in entry.items() if k.endswith("/casadi-idas")]
        if parts:
            lines.append(f"at error {target} rad, wall time / CasADi IDAS ({entry['casadi_idas_best_s']:.3f} s): "
                         + ", ".join(parts))
    slopes = [f"{m} {v['slope']:.2f}" for m, v in s["tolerance_tracking"].items() if "slope" in v]
    if slopes:
        lines.append("error ~ rtol^slope: " + ", ".join(slopes))
    if not s["reference"].get("independent", True):
        lines.append(f"reference: {s['reference_label']}")
    for name, why in s.get("skipped_methods", {}).items():
        lines.append(f"{name} skipped: {why}")
    failed = result.rows[result.rows.status != "ok"]
    for r in failed.itertuples():
        lines.append(f"{r.method} rtol {r.rtol:.0e} {r.status}: {r.failure}")
    return lines
