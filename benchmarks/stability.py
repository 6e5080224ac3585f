"""Where the methods fail: the stability study behind docs/stability.md.

Six cases, each run the way a user would (a built-in scenario plus `--set` overrides, through the runner),
each with the outcome mechsim must report (tests/test_stability.py checks them through the CLI):

- index-3 formulation on IDA                        -> exit 3, the message names the index-3 form
- Baumgarte gains raised on an explicit solver       -> exit 3, the message names stiffness from the gains
- events disabled, so a mode change is stepped over  -> exit 3, "mode change stepped over"
- a drive torque too weak to pass the load peak      -> exit 3, "crank stalled"
- a speed at which the pin crosses to the other flank -> exit 0, a warning and a "flank switch" event row
- an explicit solver on the coupled mechanics + refined 1-D thermal mesh -> exit 3, stiffness in the wall
  temperatures; and explicit against implicit solvers on the mesh alone (the conduction network of `thermal`,
  driven by the Geneva's friction-heat pulses) as it is refined

and three sweeps for the figure: Baumgarte gains against steps (explicit vs implicit), mesh refinement
against steps (explicit vs implicit, with a step budget), formulations against tolerance (from `bench`).
Run `python -m scenarios.stability [--out DIR]` to regenerate docs/stability.png and its CSV files.
"""
from __future__ import annotations

import time
from dataclasses import dataclass, replace

import numpy as np
import pandas as pd


@dataclass(frozen=True)
class Case:
    name: str
    scenario: str
    overrides: tuple[str, ...]
    expect: str            # "exit 3" or "warning"
    cause: str             # text the message must contain
    works: str             # what works there instead, and why (for the docs)


CASES = (
    Case("index-3 on IDA", "geneva-motor", ("solver.formulation=index3", "duration=1 s"), "exit 3",
         "index-3", "formulation index2 (GGL): position and velocity constraints, multipliers out of the error "
                    "test; or index1 + Baumgarte. Index 3 conditions IDA's Newton matrix like h^-3."),
    Case("Baumgarte gains on an explicit solver", "geneva-motor",
         ("solver.backend=diffrax", "solver.diffrax_solver=Tsit5", "solver.formulation=index1",
          "solver.baumgarte_alpha=1e6", "solver.baumgarte_beta=1e6", "solver.rtol=1e-6", "solver.atol=1e-8",
          "duration=1 s"), "exit 3", "stiff",
         "an implicit integrator (IDA/BDF, diffrax Kvaerno5) is not step-limited by the gains; IDA index2 needs "
         "no gains at all; gains ~10 are enough to damp the drift."),
    Case("explicit solver on a refined 1-D thermal mesh", "geneva-motor",
         ("thermal.model=1d", "solver.backend=diffrax", "solver.diffrax_solver=Tsit5", "duration=0.5 s",
          "thermal.mesh_first_cell=2.5e-6 m", "thermal.mesh_growth=4", "thermal.mesh_depth=2e-4 m"), "exit 3",
         "stiff", "IDA (BDF, implicit): its step follows the motion, not the mesh's fastest time constant "
                  "(about 1e-6 s here), so the same run succeeds; or diffrax Kvaerno5."),
    Case("events disabled", "geneva-motor", ("solver.events=false", "duration=1 s"), "exit 3",
         "mode change stepped over", "events on: IDA root-finds every guard and the loop restarts in the new "
                                     "mode."),
    Case("drive too weak (stall)", "geneva-torque", ("drive.torque=2 N*m",), "exit 3", "stalled",
         "none numerically - it is physics: a torque drive below the load peak cannot index the wheel; raise "
         "the torque or lower the load (or prescribe the speed)."),
    Case("pin crosses to the other flank", "geneva-lc1",
         ("drive.speed=40 rad/s", "solver.method=dae", "duration=0.3 s"), "warning", "flank",
         "the event restarts on the other flank; the closed form picks the flank from the sign of N. With slot "
         "clearance it would be an impact (not modelled)."),
)


def run_case(case: Case) -> dict:
    """Run one case through the runner; what a user would see (success, failure message, warnings, events)."""
    from mechsim.scenarios.loader import load
    from mechsim.scenarios.runner import run

    wall = time.perf_counter()
    result = run(load(case.scenario, list(case.overrides)))
    kinds = list(result.events["kind"]) if len(result.events) else []
    message = result.failure.message() if result.failure else ""
    text = message + " " + " ".join(result.summary["warnings"])
    return dict(case=case.name, scenario=case.scenario, overrides="; ".join(case.overrides),
                outcome="exit 3" if result.failure else ("warning" if result.summary["warnings"] else "ok"),
                detected=case.cause in text, message=message or " | ".join(result.summary["warnings"])[:400],
                events=", ".join(sorted(set(kinds))), wall_time_s=time.perf_counter() - wall, works=case.works)


# -- sweeps ---------------------------------------------------------------------------------------------------
def baumgarte_sweep(gains=(1e1, 1e2, 1e3, 1e4, 1e5, 1e6), methods=("ida-index1", "diffrax-Tsit5", "diffrax-Kvaerno5"),
                    duration: float = 1.0, rtol: float = 1e-6, max_steps: int = 20000) -> pd.DataFrame:
    """Steps and outcome of geneva-motor (index-1 + Baumgarte, alpha = beta = gain) per method and gain, with
    the scenario default step limit per segment (so an explicit solver fails where a user's run would)."""
    from mechsim.benchmarks.bench import BenchConfig, make_problem, reference, bench_one
    from mechsim.benchmarks.bench_methods import METHODS, quiet_sundials

    problem = make_problem(BenchConfig(duration=duration))
    ref = reference(problem)
    rows, cache = [], {}
    for name in methods:
        method = METHODS[name]
        if not method.available():
            continue
        if hasattr(method, "max_steps"):
            method = replace(method, max_steps=max_steps)
        for g in gains:
            if name.startswith("ida") and g > 1e5:      # IDA's Newton iteration degrades: minutes per run
                continue
            prob = replace(problem, baumgarte=(g, g))
            with quiet_sundials():
                row = bench_one(method, prob, rtol, rtol * 1e-2, ref, 1, cache)
            rows.append({**row, "gain": g})
    return pd.DataFrame(rows)


def heat_pulses(duration: float, period: float = 2 * np.pi / 5.34, engaged: float = 0.29415,
                peak_flux: float = 2.0e6):
    """Heat flux into a slot wall (W/m^2): one smooth pulse per engagement (sin^2 over the engaged time),
    the shape of the Geneva's friction heat; peak of the order of geneva-lc1's mean friction power over the
    Hertz band."""
    def q(t):
        tau = t % period
        return peak_flux * np.sin(np.pi * tau / engaged) ** 2 if tau < engaged else 0.0
    return q


def thermal_mesh_sweep(first_cells=(8e-5, 5e-5, 3.5e-5, 2.5e-5, 8e-6, 2.5e-6, 8e-7),
                       methods=("RK45", "DOP853", "BDF", "Radau"), duration: float = 2.4, rtol: float = 1e-6,
                       budget: int = 300_000) -> pd.DataFrame:
    """Explicit against implicit solvers on the 1-D conduction mesh (thermal.conduction_system) as the first
    cell shrinks: the fastest time constant falls like dz^2 and an explicit step with it. An explicit run is
    stopped once it has used `budget` right-hand-side evaluations ("step budget exceeded: stiff"), and not run
    on finer meshes after that."""
    from scipy.integrate import solve_ivp
    from mechsim.thermal.conduction1d import conduction_system, graded_mesh

    q = heat_pulses(duration)
    rows, exhausted = [], set()

    class Budget(Exception):
        pass

    for first in first_cells:
        cond = conduction_system(graded_mesh(first, 1.2, 0.012), "aisi1045", h=7.0, temp_ambient=293.15)
        system = cond.system
        tau = system.time_constants()
        fastest = float(tau[np.isfinite(tau)].min())
        T0 = np.full(system.size, 293.15)
        for method in methods:
            row = dict(first_cell_m=first, cells=system.size, fastest_time_constant_s=fastest, method=method,
                       kind="explicit" if method in ("RK45", "DOP853") else "implicit")
            if method in exhausted:
                rows.append({**row, "status": "skipped: a coarser mesh already exceeded the step budget"})
                continue
            count = {"n": 0}

            def rhs(t, T):
                count["n"] += 1
                if count["n"] > budget:
                    raise Budget
                return system.rhs(T, [q(t)])

            options = {"jac": system.jacobian()} if method in ("BDF", "Radau") else {}
            wall = time.perf_counter()
            try:
                sol = solve_ivp(rhs, (0.0, duration), T0, method=method, rtol=rtol, atol=1e-6, max_step=0.01,
                                **options)
                status = "ok" if sol.success else f"failed: {sol.message}"
                steps, surface = len(sol.t) - 1, float(cond.surface_temperature(sol.y[:, -1], 0.0))
            except Budget:
                exhausted.add(method)
                status = (f"step budget exceeded: stiff (fastest time constant {fastest:.2g} s; an explicit step "
                          f"must stay below ~3/|lambda|)")
                steps, surface = np.nan, np.nan
            rows.append({**row, "status": status, "rhs_evaluations": count["n"], "steps": steps,
                         "wall_time_s": time.perf_counter() - wall, "final_surface_temp_K": surface})
    return pd.DataFrame(rows)


def formulation_sweep() -> pd.DataFrame:
    """IDA index1/2/3 on geneva-motor over rtol 1e-3..1e-10 (the bench rows)."""
    from mechsim.benchmarks.bench import FULL_RTOLS, BenchConfig, run_bench
    config = BenchConfig(methods=("ida-index1", "ida-index2", "ida-index3"), rtols=FULL_RTOLS, duration=None,
                         repeats=1, output_cost=False)
    return run_bench(config).rows


def figure(baum: pd.DataFrame, mesh: pd.DataFrame, forms: pd.DataFrame, path) -> None:
    import matplotlib
    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    fig, axes = plt.subplots(1, 3, figsize=(17, 5.2))
    ax = axes[0]
    for name, d in baum.groupby("method", sort=False):
        ok = d[d.status == "ok"]
        ax.plot(ok.gain, ok.steps, "o-", label=name)
        bad = d[d.status != "ok"]
        ax.plot(bad.gain, np.where(np.isfinite(bad.steps), bad.steps, 2e4), "x", ms=10, color=ax.lines[-1].get_color())
    ax.axhline(2e4, color="0.5", ls=":", lw=1)
    ax.text(12, 2.3e4, "solver.max_steps (per segment)", fontsize=7, color="0.4")
    ax.set(xscale="log", yscale="log", xlabel="Baumgarte gain alpha = beta (1/s)", ylabel="steps (geneva-motor, 1 s)",
           title="(a) Baumgarte gains: explicit steps grow like the gain\nx = failed (exit 3)")
    ax.legend(fontsize=8)
    ax = axes[1]
    for name, d in mesh[~mesh.status.str.startswith("skipped")].groupby("method", sort=False):
        ok = d[d.status == "ok"]
        ax.plot(ok.fastest_time_constant_s, ok.rhs_evaluations, "o-" if d.kind.iloc[0] == "implicit" else "s--",
                label=f"{name} ({d.kind.iloc[0]})")
        bad = d[d.status != "ok"]
        ax.plot(bad.fastest_time_constant_s, bad.rhs_evaluations, "x", ms=10, color=ax.lines[-1].get_color())
    ax.set(xscale="log", yscale="log", xlabel="fastest time constant of the 1-D mesh (s)",
           ylabel="right-hand-side evaluations (2.4 s)", title="(b) refining the 1-D thermal mesh\n"
                                                                "x = step budget exceeded (stiff)")
    ax.invert_xaxis()
    ax.legend(fontsize=8)
    ax = axes[2]
    for name, d in forms.groupby("method", sort=False):
        d = d.sort_values("rtol", ascending=False)
        ok = d[d.status == "ok"]
        ax.plot(ok.rtol, ok.error_rad, "o-", label=name)
        bad = d[d.status != "ok"]
        if len(bad):
            ax.plot(bad.rtol, bad.error_rad, "x", ms=10, color=ax.lines[-1].get_color())
            for r in bad.itertuples():
                ax.annotate(f"{r.t_reached_s:.2f} s", (r.rtol, r.error_rad), fontsize=6, xytext=(3, 3),
                            textcoords="offset points")
    ax.set(xscale="log", yscale="log", xlabel="requested rtol", ylabel="max crank-angle error (rad)",
           title="(c) formulations on IDA (geneva-motor, 5 s)\nx = failed, labelled with the time it reached")
    ax.invert_xaxis()
    ax.legend(fontsize=8)
    for ax in axes:
        ax.grid(True, which="both", alpha=0.3)
    fig.tight_layout()
    fig.savefig(path, dpi=110)
    plt.close(fig)


def main(argv=None) -> None:
    import argparse
    from pathlib import Path

    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--out", type=Path, default=Path(__file__).resolve().parents[1] / "docs")
    args = parser.parse_args(argv)
    out = args.out
    out.mkdir(parents=True, exist_ok=True)
    cases = pd.DataFrame([run_case(c) for c in CASES])
    cases.to_csv(out / "stability_cases.csv", index=False)
    print(cases[["case", "outcome", "detected", "message"]].to_string())
    mesh = thermal_mesh_sweep()
    mesh.to_csv(out / "stability_thermal_mesh.csv", index=False)
    print(mesh.to_string())
    baum = baumgarte_sweep()
    baum.to_csv(out / "stability_baumgarte.csv", index=False)
    print(baum[["method", "gain", "status", "steps", "rejected_steps", "wall_time_s", "error_rad"]].to_string())
    forms = formulation_sweep()
    forms.to_csv(out / "stability_formulations.csv", index=False)
    figure(baum, mesh, forms, out / "stability.png")


if __name__ == "__main__":
    main()
