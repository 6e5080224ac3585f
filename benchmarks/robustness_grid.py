"""The robustness grid of issue 12: valid Geneva torque/motor scenarios over slots, drive, load, friction and
tolerance, each run on IDA index1, IDA index2 and diffrax, counted by outcome.

The cases are defined once here (`cases`) and shared with the CI tier (tests/test_robustness.py, a spread
subset at short durations). Factors: slots 3-12; a constant drive torque 2-20 N*m or a linear motor curve;
wheel load 0-20 N*m; friction 0, 0.15, 0.3; rtol 1e-4 ... 1e-10 with atol = rtol / 100. Case i takes level
(i * step_k) mod n_k of factor k, with steps coprime to the level counts, so consecutive cases differ in every
factor and any run of cases covers every level of every factor (a deterministic spread, not random).

Outcomes (`classify`): completed; a physical stop (stall = the crank came to rest, by kind); a numerical
failure (the integrator gave up, an invariant broke, a re-initialisation failed); max_steps. For each case
the first stop is compared with the independent one-coordinate model (`reference_stop`), and the
smallest friction power of every run is kept (negative = energy created).

    python -m mechsim.benchmarks.robustness_grid [--cases N] [--duration S] [--workers W] [--out DIR] [--resume]

writes DIR/stability_grid.csv (one row per case x backend) and prints the count table that the
robustness-grid section of the stability document shows. Rows are appended to
DIR/stability_grid.partial.csv as cases finish; `--resume` keeps that file and runs only the missing cases.
"""
from __future__ import annotations

import argparse
import time
from concurrent.futures import ProcessPoolExecutor
from dataclasses import dataclass, replace
from functools import lru_cache
from pathlib import Path

import numpy as np
import pandas as pd

SLOTS = (3, 4, 5, 6, 8, 10, 12)
#: ("torque", T) constant drive torque in N*m, or ("motor", stall torque N*m, no-load speed rad/s)
DRIVES = (("torque", 2.0), ("torque", 4.0), ("torque", 6.0), ("torque", 8.0), ("torque", 12.0), ("torque", 16.0),
          ("torque", 20.0), ("motor", 20.0, 4.0), ("motor", 30.0, 4.0), ("motor", 40.0, 8.0), ("motor", 60.0, 10.0))
LOADS = (0.0, 5.0, 10.0, 15.0, 20.0)
FRICTION = (0.0, 0.15, 0.3)
RTOLS = (1e-4, 1e-5, 1e-6, 1e-7, 1e-8, 1e-9, 1e-10)
#: (backend, formulation) every case runs on
BACKENDS = (("ida", "index1"), ("ida", "index2"), ("diffrax", "index1"))
_STEPS = (3, 5, 2, 2, 3)
#: cases in the grid (the benchmark's default; the CI tier takes every 7th)
N_CASES = 210        # coprime to (7, 11, 5, 3, 7): each factor cycles through all its levels


@dataclass(frozen=True)
class Case:
    """One valid Geneva scenario of the grid (backend and duration are chosen by the caller)."""

    index: int
    slots: int
    drive: tuple
    load: float
    friction: float
    rtol: float

    @property
    def name(self) -> str:
        d = (f"T{self.drive[1]:g}" if self.drive[0] == "torque" else f"M{self.drive[1]:g}-{self.drive[2]:g}")
        return f"g{self.index:03d}-n{self.slots}-{d}-L{self.load:g}-mu{self.friction:g}-rtol{self.rtol:.0e}"

    @property
    def scenario(self) -> str:
        return "geneva-torque" if self.drive[0] == "torque" else "geneva-motor"

    def overrides(self, backend: str, formulation: str, duration: float) -> list[str]:
        out = [f"mechanism.slots={self.slots}", f"load.wheel_torque={self.load:g} N*m",
               f"contact.friction={self.friction:g}", f"solver.rtol={self.rtol:g}",
               f"solver.atol={self.rtol / 100:g}", f"solver.formulation={formulation}",
               f"solver.backend={backend}", f"duration={duration:g} s"]
        if self.drive[0] == "torque":
            out.append(f"drive.torque={self.drive[1]:g} N*m")
        else:
            out += [f"drive.stall_torque={self.drive[1]:g} N*m", f"drive.no_load_speed={self.drive[2]:g} rad/s"]
        return out


def with_rtol(case: Case, rtol: float) -> Case:
    """The same case at another tolerance."""
    return replace(case, rtol=rtol)


def cases(n: int = N_CASES) -> list[Case]:
    """The first n cases of the grid (deterministic; see the module docstring)."""
    levels = (SLOTS, DRIVES, LOADS, FRICTION, RTOLS)
    out = []
    for i in range(n):
        pick = [lv[(i * s + i // len(lv)) % len(lv)] for lv, s in zip(levels, _STEPS)]
        out.append(Case(i, *pick))
    return out


def classify(result) -> tuple[str, str]:
    """(outcome, detail): 'completed', 'stop:<event kind>' (a physical stop), 'max_steps', or 'numerical'
    (any other failure code: the integrator gave up, an invariant broke, a re-initialisation failed, ...)."""
    from mechsim.dynamics.result import FailureCode

    f = result.failure
    if f is None:
        return "completed", ""
    if f.code is FailureCode.PHYSICAL_STOP:
        ev = result.events
        kind = str(ev["kind"].iloc[-1]) if len(ev) else "stop"
        return f"stop:{kind}", f.reason[:200]
    if f.code is FailureCode.MAX_STEPS:
        return "max_steps", f.reason[:200]
    return "numerical", f"{f.code.value}: {f.reason}"[:200]


def reference_stop(mech, drive, angle0: float, speed0: float, t_end: float):
    """The first stop (stall, creeping rest, or none: 'running') of the same Geneva in the independent
    one-coordinate model of benchmarks/stall_reference.py (own kinematics and events, DOP853 at rtol 1e-12)."""
    from mechsim.benchmarks.stall_reference import GenevaCase, first_stop

    g, dv = mech.geometry, drive.parameter_values(angle0)
    case = GenevaCase(g.slots, g.crank_radius, g.pin_radius, mech.crank_inertia, mech.wheel_inertia,
                      dv["drive_T0"], dv["drive_slope"], mech.wheel_torque, mech.friction, mech.crank_damping,
                      mech.wheel_damping)
    return first_stop(case, angle0, speed0, t_end)


def run_case(case: Case, backend: str, formulation: str, duration: float, reference: bool = True) -> dict:
    """Run one case on one backend; the row of the grid table."""
    import mechsim
    from mechsim.scenarios.runner import plan, execute

    sc = mechsim.load(case.scenario, set=case.overrides(backend, formulation, duration))
    wall = time.perf_counter()
    the_plan = plan(sc)
    r = execute(the_plan)
    wall = time.perf_counter() - wall
    outcome, detail = classify(r)
    df = r.timeseries
    row = dict(case=case.name, index=case.index, slots=case.slots, drive=case.drive[0],
               drive_torque_N_m=case.drive[1], no_load_speed_rad_s=case.drive[2] if len(case.drive) > 2 else np.nan,
               load_N_m=case.load, friction=case.friction, rtol=case.rtol, atol=case.rtol / 100, backend=backend,
               formulation=formulation, duration_s=duration, outcome=outcome, detail=detail,
               stop_time_s=r.failure.time if r.failure else np.nan,
               min_friction_power_W=float(df["friction_power_W"].min()) if "friction_power_W" in df and len(df)
               else np.nan, steps=r.summary["solver"].get("steps", np.nan), wall_s=wall)
    row["reduced_outcome"], row["reduced_stop_time_s"] = "", np.nan
    if reference:
        ref = case_reference(case, duration)
        row["reduced_outcome"] = ref.kind
        row["reduced_stop_time_s"] = ref.time if ref.kind != "running" else np.nan
    return row


@lru_cache(maxsize=None)
def case_reference(case: Case, duration: float):
    """The reference's first stop for a case (independent of the backend; computed once per process)."""
    import mechsim
    from mechsim.scenarios.runner import plan

    sc = mechsim.load(case.scenario, set=case.overrides("ida", "index1", duration))
    the_plan = plan(sc)
    return reference_stop(the_plan.mechanism, the_plan.drive, sc.si["initial"]["crank_angle"],
                          sc.si["initial"]["crank_speed"], duration)


def _run(args):
    case, backend, formulation, duration = args
    try:
        return run_case(case, backend, formulation, duration)
    except Exception as exc:   # a crash is a numerical failure of the grid, not of the script
        return dict(case=case.name, index=case.index, backend=backend, formulation=formulation,
                    outcome="numerical", detail=f"exception: {exc!r}"[:200])


def _run_case_all(args):
    """One case on every backend (one process: the reference is computed once, diffrax compiles per rtol)."""
    case, duration, backends = args
    rows = [_run((case, b, f, duration)) for b, f in backends]
    return rows


def run_grid(n: int, duration: float, workers: int = 1, partial: Path | None = None,
             backends: tuple[tuple[str, str], ...] = BACKENDS) -> pd.DataFrame:
    """Every case on every (backend, formulation); cases sorted by tolerance so that a worker reuses diffrax's
    compiled solve. partial: a CSV appended as cases finish (a long run can be inspected, or cut short)."""
    jobs = [(c, duration, backends) for c in sorted(cases(n), key=lambda c: (c.rtol, c.index))]
    rows: list[dict] = []
    if partial is not None and partial.exists():
        rows = pd.read_csv(partial).to_dict("records")
        finished = {r["index"] for r in rows}
        jobs = [j for j in jobs if j[0].index not in finished]

    def done(rs):
        rows.extend(rs)
        if partial is not None:
            pd.DataFrame(rs).to_csv(partial, mode="a", header=not partial.exists(), index=False)
        print(f"{len(rows) // len(backends)}/{n} cases", flush=True)

    if workers <= 1:
        for j in jobs:
            done(_run_case_all(j))
    else:
        with ProcessPoolExecutor(workers) as pool:
            for rs in pool.map(_run_case_all, jobs, chunksize=1):
                done(rs)
    return pd.DataFrame(rows).sort_values(["index", "backend", "formulation"]).reset_index(drop=True)


def counts(table: pd.DataFrame) -> pd.DataFrame:
    """Counts per solver (backend + formulation) x rtol: completed, stops by kind, numerical failures,
    max_steps; the largest |stop time - reference| and stops where the reference has none (or the reverse);
    the smallest friction power of any row."""
    t = table.assign(solver=table["backend"] + " " + table["formulation"])
    out = pd.crosstab([t["solver"], t["rtol"]], t["outcome"])
    for col in ("completed", "stop:stall", "stop:rest", "numerical", "max_steps"):
        if col not in out:
            out[col] = 0
    out = out[["completed", "stop:stall", "stop:rest", "numerical", "max_steps"]]
    keys = [t["solver"], t["rtol"]]
    stopped = t["outcome"].str.startswith("stop")
    ref_stopped = t["reduced_outcome"].isin(["stall", "rest"])
    out["stop_differs_from_reference"] = (stopped != ref_stopped).groupby(keys).sum()
    out["max_abs_stop_minus_reference_s"] = (t["stop_time_s"] - t["reduced_stop_time_s"]).abs().groupby(keys).max()
    out["min_friction_power_W"] = t.groupby(["solver", "rtol"])["min_friction_power_W"].min()
    return out


def markdown(summary: pd.DataFrame) -> str:
    """The count table as GitHub markdown (for docs/stability.md)."""
    head = ["solver", "rtol", *summary.columns]
    lines = ["| " + " | ".join(h.replace("_", " ") for h in head) + " |", "|" + "---|" * len(head)]
    for (solver, rtol), row in summary.iterrows():
        cells = [solver, f"{rtol:.0e}"]
        for v in row:
            cells.append("-" if pd.isna(v) else (f"{v:.2g}" if isinstance(v, float) and not float(v).is_integer()
                                                 else f"{v:g}"))
        lines.append("| " + " | ".join(cells) + " |")
    return "\n".join(lines)


def main(argv=None) -> None:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--cases", type=int, default=N_CASES)
    ap.add_argument("--duration", type=float, default=5.0)
    ap.add_argument("--workers", type=int, default=1)
    ap.add_argument("--out", type=Path, default=Path(__file__).resolve().parents[1] / "docs")
    ap.add_argument("--resume", action="store_true", help="keep the partial table and run only missing cases")
    ap.add_argument("--backends", default=",".join(f"{b}:{f}" for b, f in BACKENDS),
                    help="comma list of backend:formulation (default: %(default)s)")
    a = ap.parse_args(argv)
    backends = tuple(tuple(item.split(":")) for item in a.backends.split(","))
    wall = time.perf_counter()
    partial = a.out / "stability_grid.partial.csv"
    if not a.resume:
        partial.unlink(missing_ok=True)
    table = run_grid(a.cases, a.duration, a.workers, partial, backends)
    partial.unlink(missing_ok=True)
    table.to_csv(a.out / "stability_grid.csv", index=False)
    summary = counts(table)
    print(markdown(summary))
    print(f"{len(table)} runs in {time.perf_counter() - wall:.0f} s")


if __name__ == "__main__":
    main()
