"""mechsim's Python API (docs/api.md): load a scenario, run it, look at the result, save what the CLI saves.

    import mechsim
    sc = mechsim.load("geneva-motor", set=["duration=2 s"])
    r = mechsim.run(sc)
    r.timeseries, r.events, r.summary["peaks"]
    figs = r.plot()                 # {name: matplotlib Figure}, the CLI's figures
    r.save("results/motor")         # the CLI's output folder, written atomically

`mechsim sweep`, `mechsim compare`, `mechsim sensitivity` and `mechsim size` are `sweep(...)`, `compare(...)`,
`sensitivity(...)` and `size(...)`. The command line is a thin layer over
these functions (scenarios/cli.py), so both give the same numbers and files.
"""
from __future__ import annotations

import dataclasses
import tempfile
from pathlib import Path
from typing import Callable, Iterable, Mapping

from mechsim.dynamics.result import Result as RunResult
from mechsim.scenarios.loader import Scenario, builtin_names
from mechsim.scenarios.loader import load as _load_scenario
from mechsim.scenarios.units import ScenarioError

__all__ = ["Result", "Scenario", "ScenarioError", "builtins", "compare", "load", "run", "sensitivity", "size", "sweep"]

Overrides = Iterable[str] | Mapping[str, object] | None


def _override_list(overrides: Overrides) -> list[str]:
    """`set=` as the CLI's --set strings: a list of "section.key=value", or a dict {"section.key": value}
    whose values are written as TOML ("75 mm" stays a quantity string, 3 a number, True a boolean)."""
    if overrides is None:
        return []
    if isinstance(overrides, str):
        return [overrides]
    if isinstance(overrides, Mapping):
        from mechsim.scenarios.keys import toml_literal
        return [f"{key}={toml_literal(value)}" for key, value in overrides.items()]
    return [str(o) for o in overrides]


def builtins() -> list[str]:
    """Names of the built-in scenarios (`mechsim list`)."""
    return builtin_names()


def load(name_or_path: str | Path, set: Overrides = None) -> Scenario:  # noqa: A002 (the CLI's --set)
    """A validated scenario from a built-in name or a TOML file, with overrides applied.

    set: ["section.key=value", ...] like `mechsim run --set`, or {"section.key": value}.
    Raises ScenarioError (a ValueError whose message names the field) on any user error.
    """
    return _load_scenario(str(name_or_path), _override_list(set))


@dataclasses.dataclass(repr=False)
class Result(RunResult):
    """A finished run: `timeseries` (one row per output instant, SI columns `<quantity>_<unit>`), `events` (one
    row per transition), `summary` (peaks, energy balance, solver statistics, model choices, warnings),
    `scenario` (the resolved scenario in SI), `failure` (None, or when/where/why the run stopped; what ran is
    kept), `extra_tables` (mechanism- and thermal-specific tables, written as <name>.csv)."""

    mechanism: object = None

    def __repr__(self) -> str:
        state = "ok" if self.failure is None else f"failed: {self.failure.message()}"
        return (f"<mechsim.Result {self.summary.get('scenario', '?')}: {self.timeseries.shape[0]} rows x "
                f"{self.timeseries.shape[1]} columns, {len(self.events)} events, {state}>")

    def plot(self, which: str | Iterable[str] | None = None) -> dict:
        """The figures the CLI writes, as matplotlib Figures keyed by name (the PNG's name without .png).

        which: one name or several (e.g. "motion_vs_time"); None for all. Display one in a notebook by
        leaving it as a cell's value; save with fig.savefig(path)."""
        from mechsim.scenarios.output.figures import result_figures
        figs = result_figures(self, self.mechanism)
        if which is None:
            return figs
        wanted = [which] if isinstance(which, str) else list(which)
        unknown = [w for w in wanted if w not in figs]
        if unknown:
            raise KeyError(f"no figure named {', '.join(unknown)}; this result has: {', '.join(figs)}")
        return {w: figs[w] for w in wanted}

    def save(self, folder: str | Path, force: bool = False, plots: bool | None = None) -> Path:
        """Write the CLI's output folder (timeseries.parquet/.csv, events.csv, summary.json, scenario.toml, extra
        tables and PNG figures) atomically: all or nothing, an existing folder replaced only with force=True.
        plots: None follows the scenario's output.plots."""
        from mechsim.scenarios.output.writer import write_result
        if plots is None:
            plots = bool(self.scenario.get("output", {}).get("plots", True))
        return write_result(self, Path(folder), force=force, plots=plots, mechanism=self.mechanism)


def run(scenario: Scenario | str | Path, set: Overrides = None,  # noqa: A002
        progress: Callable[[float], None] | None = None) -> Result:
    """Run a scenario (a loaded Scenario, or a name/path loaded with `set` overrides).

    The mechanism and the thermal model are built once (runner.plan), then integrated (runner.execute). A solver
    or physics failure does not raise: it comes back in `Result.failure` with what ran. progress(t) is called
    with the simulated time as the run advances."""
    from mechsim.scenarios import runner
    if not isinstance(scenario, Scenario):
        scenario = load(scenario, set)
    elif set:
        raise ValueError("run(scenario, set=...): pass the overrides to load(); this scenario is already loaded")
    plan = runner.plan(scenario)
    base = runner.execute(plan, progress)
    fields = {f.name: getattr(base, f.name) for f in dataclasses.fields(base)}
    return Result(**fields, mechanism=plan.mechanism)


def compare(scenario: Scenario | str | Path, set: Overrides = None, rtol: float = 1e-10,  # noqa: A002
            atol: float | None = None, solver: str | None = None):
    """Run on IDA and on diffrax at rtol (atol = rtol/100 by default) and compare every column (`mechsim
    compare`): a DataFrame, one row per column (max |diff|, max relative, where, tolerance, passed);
    `.attrs["passed"]` says whether the backends agree, `.attrs` also holds row and event counts, the event-time
    difference, failures and each run's solver statistics."""
    from mechsim.scenarios.studies.compare import compare as compare_backends
    if not 0 < rtol < 1:
        raise ValueError(f"rtol must be in (0, 1), got {rtol}")
    target = scenario if isinstance(scenario, Scenario) else str(scenario)
    return compare_backends(target, _override_list(set), rtol=rtol, atol=atol, diffrax_solver=solver)


def sweep(scenario: str | Path, vary: Overrides, set: Overrides = None, zip: bool = False,  # noqa: A002
          out: str | Path | None = None, workers: int | None = 0, timeseries: bool = False, plots: bool = False,
          force: bool = False, batch: bool = False, *, dask_local: int | None = None, scheduler: str | None = None,
          default_folder: bool = False, progress=None):
    """A parameter sweep (`mechsim sweep` is this function): the table with one row per case (parameters, peaks,
    cycle figures, success and failure reason), as a DataFrame.

    vary: ["section.key=SPEC", ...] or {"section.key": "SPEC"}, SPEC as on the command line ("5,7,14 N*m",
    "0.1:0.4:7", "log:1e-3:1e-1:5"); zip=True pairs the axes instead of a full grid. out: the sweep folder
    (resumable, as the CLI writes it); None runs in a temporary folder and keeps only the table, or with
    default_folder=True writes results/sweep-<name> as the CLI does. workers: local processes (0 runs here,
    None all cores); dask_local / scheduler: a Dask LocalCluster of N workers / the scheduler at an address.
    batch: one vmapped diffrax solve per model structure. progress: an object with start(total, done, failed)
    and advance(ok) (the CLI's progress bar). The table's attrs: "report" (the one-line account), "exit_code"
    (the CLI's), "interrupted" (why, or None), "recomputed" ([(case, why)]: stored cases that did not verify).
    User errors raise ScenarioError before any case runs."""
    import pandas as pd

    from mechsim.scenarios.output.paths import default_folder as results_folder
    from mechsim.scenarios.studies.sweep.execute import make_runner
    from mechsim.scenarios.studies.sweep.run import check_runner_options, exit_code, plan, run_sweep
    from mechsim.scenarios.studies.sweep.spec import build_spec
    check_runner_options(workers, dask_local, scheduler)
    if isinstance(vary, Mapping):
        vary = [f"{key}={spec}" for key, spec in vary.items()]
    spec = build_spec(str(scenario), [str(v) for v in (vary or [])], _override_list(set), zip)
    runner = make_runner(workers, dask_local, scheduler, batch)   # first: a pool's workers start while cases validate
    pl = plan(spec)
    with tempfile.TemporaryDirectory(prefix="mechsim-sweep-") as scratch:
        if out is not None:
            folder = Path(out)
        else:
            folder = results_folder(pl.cases[0].scenario.name, "sweep-") if default_folder else Path(scratch) / "s"
        report = run_sweep(pl, folder, runner, timeseries=timeseries, force=force, progress=progress, plots=plots)
        stored = folder / "sweep.parquet"
        table = pd.read_parquet(stored) if stored.exists() else pd.DataFrame()
    table.attrs.update(report=report.line(), exit_code=exit_code(report), interrupted=report.interrupted,
                       recomputed=list(report.discarded or []))
    return table


def sensitivity(scenario: Scenario | str | Path, wrt: str | Iterable[str], of: str | Iterable[str] | None = None,
                set: Overrides = None, change: float = 0.01):  # noqa: A002
    """Exact derivatives of the run's headline results with respect to scenario values (`mechsim sensitivity`,
    docs/sensitivity.md): a DataFrame with one row per (quantity, value): `value`, `derivative` (SI, quantity unit
    per the value's unit), `elasticity` (p/y) dy/dp, and `quantity_change` for a change of the value by `change`
    (relative, first order). `.attrs` holds `warnings` (peaks that nearly tie, ...) and `cost` (the run's and the
    sensitivities' wall time).

    wrt: "section.key" names (a list or one comma-separated string), e.g. ["load.wheel_torque", "contact.friction"];
    of: quantities (default: all), e.g. "peak_contact_force_N,index_time_s". Raises ScenarioError on a key or
    quantity that is not traced, and `SensitivityUnavailable` (a ValueError) where the derivative does not exist on
    this run (a grazing event, a transition that recomputes a traced value)."""
    from mechsim.scenarios.studies.sensitivity import sensitivity as sensitivity_table
    if not isinstance(scenario, Scenario):
        scenario = load(scenario, set)
    elif set:
        raise ValueError("sensitivity(scenario, set=...): pass the overrides to load(); the scenario is loaded")

    def names(x):
        if x is None:
            return None
        items = x.split(",") if isinstance(x, str) else list(x)
        return [s.strip() for s in items if s.strip()]
    return sensitivity_table(scenario, names(wrt), names(of), change)


def size(scenario: Scenario | str | Path, vary: str | Iterable[str] | Mapping[str, str], minimize: str,
         subject_to: str | Iterable[str] | None = None, set: Overrides = None,  # noqa: A002
         method: str = "slsqp", tolerance: float | None = None, max_iterations: int = 100):
    """The best design within bounds (`mechsim size`, docs/sensitivity.md "Sizing"): minimise a headline quantity
    (or one of the varied values) over scenario values, subject to limits on headline quantities, with the exact
    gradients of `sensitivity`. Returns a SizingResult: `.design` (the chosen scenario, a Scenario that runs),
    `.values` (key -> SI value), `.objective_value`, `.constraints` (value, activity, multiplier, shadow price
    d objective / d limit), `.bounds`, `.history` (the convergence table), `.summary`, `.save(folder)`.

    vary: ["section.key=LOW:HIGH unit", ...] or {"section.key": "LOW:HIGH unit"}; `mechanism.slots=3:6` enumerates
    the slot counts. subject_to: ["peak_contact_force_N <= 500", ...]. Raises ScenarioError on a bad request and
    `mechsim.scenarios.studies.sizing.SizingFailed` (a RuntimeError, `.result` holding what ran) without a feasible
    optimum."""
    from mechsim.scenarios.studies.sizing import size as size_design
    if not isinstance(scenario, Scenario):
        scenario = load(scenario, set)
    elif set:
        raise ValueError("size(scenario, set=...): pass the overrides to load(); the scenario is loaded")
    if isinstance(vary, Mapping):
        vary = [f"{key}={spec}" for key, spec in vary.items()]
    elif isinstance(vary, str):
        vary = [vary]
    if isinstance(subject_to, str):
        subject_to = [subject_to]
    return size_design(scenario, list(vary), minimize, list(subject_to or []), method=method, tolerance=tolerance,
                       max_iterations=max_iterations)
