"""mechsim's Python API (docs/api.md): load a scenario, run it, look at the result, save what the CLI saves.

    import mechsim
    sc = mechsim.load("geneva-motor", set=["duration=2 s"])
    r = mechsim.run(sc)
    r.timeseries, r.events, r.summary["peaks"]
    figs = r.plot()                 # {name: matplotlib Figure}, the CLI's figures
    fig = r.plot("contact_force_N") # chosen columns against time (x="angle": per drive cycle)
    r.save("results/motor")         # the CLI's output folder, written atomically
    r = mechsim.open("results/motor")   # and read back

`mechsim sweep`, `mechsim compare A B`, `mechsim compare --backends`, `mechsim sensitivity` and `mechsim size` are
`sweep(...)`, `compare(a, b)`, `compare_backends(...)`, `sensitivity(...)` and `size(...)`. The command line is a
thin layer over these functions (scenarios/cli.py), so both give the same numbers and files.
"""
from __future__ import annotations

import dataclasses
import tempfile
from pathlib import Path
from typing import Callable, Iterable, Mapping

from mechsim.dynamics.result import Result as RunResult
from mechsim.scenarios.loader import Scenario, builtin_names
from mechsim.scenarios.loader import load as _load_scenario
from mechsim.scenarios.loader import override_strings as _override_list
from mechsim.scenarios.schema import did_you_mean
from mechsim.scenarios.units import ScenarioError

__all__ = ["Result", "Scenario", "ScenarioError", "builtins", "compare", "compare_backends", "load", "open",
           "output_size", "run", "sensitivity", "size", "sweep"]

Overrides = Iterable[str] | Mapping[str, object] | None


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

    def __getitem__(self, column: str):
        """A column of the timeseries (a pandas Series, SI), e.g. r["contact_force_N"]."""
        self._check_columns([column])
        return self.timeseries[column]

    def _check_columns(self, columns: list[str]) -> None:
        unknown = [c for c in columns if c not in self.timeseries.columns]
        if unknown:
            raise KeyError(f"no column {', '.join(map(repr, unknown))} in this result"
                           f"{did_you_mean(unknown[0], self.timeseries.columns)}; its columns: "
                           f"{', '.join(self.timeseries.columns)}")

    def plot(self, which: str | Iterable[str] | None = None, x: str = "time"):
        """Figures of the run.

        which None: the figures the CLI writes, as matplotlib Figures keyed by name (the PNG's name without .png).
        which a column or a list of columns (e.g. "contact_force_N", ["crank_speed_rad_s", "wheel_speed_rad_s"]):
        one Figure of them against time, a panel per unit; x="angle" against the drive angle within its cycle, a
        line per cycle, as the CLI's *_vs_angle figures. which a figure name or names (e.g. "motion_vs_time"):
        those of the CLI's figures, keyed by name. Display a figure in a notebook by leaving it as a cell's value;
        save with fig.savefig(path). A name that is neither a column nor a figure raises KeyError listing both."""
        from mechsim.scenarios.output.figures import result_figures
        if which is None:
            return result_figures(self, self.mechanism)
        wanted = [which] if isinstance(which, str) else list(which)
        if x not in ("time", "angle"):
            raise ValueError(f"plot(x={x!r}): x is \"time\" or \"angle\"")
        if wanted and all(w in self.timeseries.columns for w in wanted):
            return self._columns_figure(wanted, x)
        if not any(w in self.timeseries.columns for w in wanted):
            figs = result_figures(self, self.mechanism)
            if wanted and all(w in figs for w in wanted):
                return {w: figs[w] for w in wanted}
            names = f"; or one of its figures: {', '.join(figs)}"
        else:
            names = ""
        unknown = [w for w in wanted if w not in self.timeseries.columns]
        names_known = [*self.timeseries.columns, *figs] if names else self.timeseries.columns
        hint = did_you_mean(unknown[0], names_known) if unknown else ""
        raise KeyError(f"no column {', '.join(map(repr, unknown)) or '(none given)'} in this result{hint}; its "
                       f"columns: {', '.join(self.timeseries.columns)}{names}")

    def _columns_figure(self, columns: list[str], x: str):
        import pandas as pd

        from mechsim.scenarios.output.plots import angle_figure, column_panels, poles_of, time_figure
        df = self.timeseries
        bad = [c for c in columns if not pd.api.types.is_numeric_dtype(df[c])]
        if bad:
            raise ValueError(f"column {', '.join(map(repr, bad))} is not numeric; plot takes numeric columns")
        title = f"{self.summary.get('scenario', '')}: {', '.join(columns)}"
        rows = column_panels(df, columns)
        poles = poles_of(self.summary)             # a column unbounded toward events: drawn clipped
        if x == "time":
            return time_figure(df, "", title, rows=rows, poles=poles)
        mechanism = self.mechanism
        if mechanism is None and self.scenario:
            from mechsim.scenarios.loader import build_mechanism
            mechanism = build_mechanism(self.scenario)
        cycle = mechanism.drive_cycle() if mechanism is not None else None
        if cycle is None or cycle.column not in df:
            raise ValueError("plot(x=\"angle\"): this run has no drive cycle to fold over; use x=\"time\"")
        return angle_figure(df, "", title, cycle, rows=rows, poles=poles)

    def output_size(self):
        """The size of this run's tables as `save` writes them, measured from the table (an OutputSize,
        scenarios/output/size.py `table_bytes`)."""
        from mechsim.scenarios.output.size import table_bytes
        return table_bytes(self.timeseries)

    def save(self, folder: str | Path, force: bool = False, plots: bool | None = None, progress=None) -> Path:
        """Write the CLI's output folder (timeseries.parquet/.csv, events.csv, summary.json, scenario.toml, extra
        tables and PNG figures) atomically: all or nothing. An existing folder raises FileExistsError unless
        force=True, and force replaces only a folder mechsim wrote. plots: None follows the scenario's output.plots.
        timeseries.csv follows output.csv ("auto": left out of a large output, `output_size`). progress(fraction,
        what): called as the tables are written (the share of their bytes, and the file being written)."""
        from mechsim.scenarios.output.atomic import check_replaceable
        from mechsim.scenarios.output.writer import write_result
        folder = Path(folder)
        if folder.exists() or folder.is_symlink():
            if not force:
                raise FileExistsError(f"{folder} exists; save(..., force=True) replaces it")
            try:
                check_replaceable(folder, force)
            except ScenarioError:
                raise FileExistsError(f"{folder} exists and was not written by mechsim (a file, a link, or a "
                                      "folder without its marker): force=True will not replace it") from None
        if plots is None:
            plots = bool(self.scenario.get("output", {}).get("plots", True))
        return write_result(self, folder, force=force, plots=plots, mechanism=self.mechanism, progress=progress)


def open(folder: str | Path) -> Result:  # noqa: A001 (mechsim.open reads a result folder)
    """The Result of a saved result folder (`mechsim run --out`, `Result.save`): timeseries, events, summary,
    scenario (resolved, SI), extra tables and failure, with its mechanism rebuilt from the scenario. The CSV
    tables come back with the numbers as written (whole numbers as integers). A folder that is not a mechsim
    result raises FileNotFoundError (absent) or ValueError saying what it lacks."""
    import json

    import pandas as pd

    from mechsim.dynamics.result import Failure, FailureCode
    from mechsim.scenarios.loader import build_mechanism, from_raw, parse_toml, read_text
    from mechsim.scenarios.output.atomic import MARKER
    from mechsim.scenarios.output.csv import read_csv
    folder = Path(folder)
    if not folder.is_dir():
        raise FileNotFoundError(f"{folder} is not a folder" if folder.exists() else f"{folder} does not exist")
    needed = ["summary.json", "scenario.toml", "events.csv"]
    missing = [n for n in needed if not (folder / n).is_file()]
    if not ((folder / "timeseries.parquet").is_file() or (folder / "timeseries.csv").is_file()):
        missing.insert(0, "timeseries.parquet")
    if missing or not (folder / MARKER).is_file():
        lacks = ", ".join(missing + ([] if (folder / MARKER).is_file() else [MARKER]))
        raise ValueError(f"{folder} is not a mechsim result folder (it has no {lacks}); "
                         "mechsim.open reads what `mechsim run --out` or Result.save wrote")
    parquet = folder / "timeseries.parquet"
    timeseries = pd.read_parquet(parquet) if parquet.is_file() else read_csv(folder / "timeseries.csv")
    events = read_csv(folder / "events.csv")
    summary = json.loads((folder / "summary.json").read_text())
    toml = folder / "scenario.toml"
    scenario = from_raw(parse_toml(read_text(toml), str(toml)), str(toml)).si
    extra = {p.stem: read_csv(p) for p in sorted(folder.glob("*.csv"))
             if p.stem not in ("timeseries", "events")}
    failure = None
    if summary.get("failure"):
        import re
        m = re.match(r"stopped at t = (\S+) s in mode '([^']*)': (.*?)(?: \(hint: (.*)\))?$", summary["failure"], re.S)
        code = FailureCode(summary["failure_code"]) if summary.get("failure_code") else FailureCode.INTEGRATOR_FAILED
        failure = (Failure(float(m.group(1)), m.group(2), m.group(3), m.group(4) or "", code.kind, code) if m else
                   Failure(float(timeseries["t_s"].iloc[-1]) if len(timeseries) else 0.0, "?", summary["failure"],
                           kind=code.kind, code=code))
    return Result(timeseries=timeseries, events=events, summary=summary, scenario=scenario, failure=failure,
                  extra_tables=extra, mechanism=build_mechanism(scenario))


def output_size(scenario: Scenario | str | Path, set: Overrides = None):  # noqa: A002
    """How large the run's tables will be, before it runs (scenarios/output/size.py): an OutputSize with `rows`,
    `columns` (estimated), `csv_bytes`, `parquet_bytes` (upper estimates), `total_bytes` and `large` (the size at
    which `mechsim run` says so and output.csv = "auto" leaves timeseries.csv out). `Result.output_size()` measures
    a finished run's."""
    from mechsim.scenarios.output.size import estimate
    if not isinstance(scenario, Scenario):
        scenario = load(scenario, set)
    elif set:
        raise ValueError("output_size(scenario, set=...): pass the overrides to load(); the scenario is loaded")
    return estimate(scenario.si)


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


def compare(a: Scenario | str | Path | Result, b: Scenario | str | Path | Result, set: Overrides = None,  # noqa: A002
            set_a: Overrides = None, set_b: Overrides = None):
    """Two designs side by side (`mechsim compare A B`): a and b each a scenario (a loaded Scenario, a built-in
    name or a TOML file: run here) or a finished run (a Result, or a folder `mechsim run` or `Result.save` wrote).
    `set` applies to each scenario, `set_a` / `set_b` to one (named in the comparison's labels).

    Returns a Comparison: `.table` (one row per headline quantity both runs have: located peaks, start-up peaks,
    cycle means and figures, heat, validity; columns quantity (its name ending in its unit), a, b, difference
    b - a, relative_difference (b - a)/|a|), `.only_a` / `.only_b` (what one run has and the other lacks),
    `.notes`, `.plot(which=None, x="time")` (the two runs overlaid, A solid, B dashed) and `.save(folder)`.
    Raises ScenarioError for a user error (a folder mechsim did not write, nothing in common)."""
    from mechsim.scenarios.studies.compare_designs import compare_runs, is_finished_run
    shared = _override_list(set)
    if shared and is_finished_run(a) and is_finished_run(b):
        raise ScenarioError("--set", "both sides are finished runs; --set applies to scenarios only")
    sides = []
    for side, arg, own in (("A", a, _override_list(set_a)), ("B", b, _override_list(set_b))):
        result, name = _design(arg, ([] if is_finished_run(arg) else shared) + own, side)
        sides.append((result, f"{name} with {', '.join(own)}" if own else name))   # the side's own changes named
    (ra, name_a), (rb, name_b) = sides
    return compare_runs(ra, rb, name_a, name_b)


def _design(arg, overrides: list[str], side: str) -> tuple[Result, str]:
    """(Result, label) of one side of `compare`: a Result as it is, a result folder read back (`open`), a Scenario
    or a scenario name/file run with the overrides. ScenarioError naming the side for a folder mechsim did not
    write and for overrides given to a finished run."""
    from mechsim.scenarios.studies.compare_designs import is_finished_run
    if is_finished_run(arg):
        if overrides:
            raise ScenarioError(side, f"{arg if isinstance(arg, (str, Path)) else 'the Result'} is a finished run; "
                                      "--set applies to scenarios only")
        if not isinstance(arg, (str, Path)):
            return arg, str(arg.summary.get("scenario", side))
        try:
            result = open(arg)
        except (ValueError, FileNotFoundError) as exc:
            raise ScenarioError(side, str(exc).replace("; mechsim.open reads", "; compare reads")) from None
        return result, str(result.summary.get("scenario", Path(arg).name))
    sc = (arg.set(overrides) if overrides else arg) if isinstance(arg, Scenario) else load(arg, overrides)
    return run(sc), sc.name


def compare_backends(scenario: Scenario | str | Path, set: Overrides = None, rtol: float = 1e-10,  # noqa: A002
                     atol: float | None = None, solver: str | None = None):
    """Run on IDA and on diffrax at rtol (atol = rtol/100 by default) and compare every column (`mechsim
    compare --backends`): a DataFrame, one row per column (max |diff|, max relative, where, tolerance, passed);
    `.attrs["passed"]` says whether the backends agree, `.attrs` also holds row and event counts, the event-time
    difference, failures and each run's solver statistics."""
    from mechsim.scenarios.studies.compare import compare as compare_backends_table
    if not 0 < rtol < 1:
        raise ValueError(f"rtol must be in (0, 1), got {rtol}")
    target = scenario if isinstance(scenario, Scenario) else str(scenario)
    return compare_backends_table(target, _override_list(set), rtol=rtol, atol=atol, diffrax_solver=solver)


def sweep(scenario: str | Path, vary: Overrides, set: Overrides = None, zip: bool = False,  # noqa: A002
          out: str | Path | None = None, workers: int | None = 0, timeseries: bool = False, plots: bool = False,
          force: bool = False, batch: bool = False, *, dask_local: int | None = None, scheduler: str | None = None,
          default_folder: bool = False, progress=None, heatmap_aggregate: str = "auto"):
    """A parameter sweep (`mechsim sweep` is this function): the table with one row per case (parameters, peaks,
    cycle figures, success and failure reason), as a DataFrame.

    vary: ["section.key=SPEC", ...] or {"section.key": "SPEC"}, SPEC as on the command line ("5,7,14 N*m",
    "0.1:0.4:7", "log:1e-3:1e-1:5"); zip=True pairs the axes instead of a full grid. out: the sweep folder
    (resumable, as the CLI writes it); None runs in a temporary folder and keeps only the table, or with
    default_folder=True writes results/sweep-<name> as the CLI does. workers: local processes (0 runs here,
    None all cores); dask_local / scheduler: a Dask LocalCluster of N workers / the scheduler at an address.
    batch: one vmapped diffrax solve per model structure. progress: an object with start(total, done, failed)
    and advance(ok) (the CLI's progress bar). heatmap_aggregate: how a heat map reduces the cases that share a cell
    (those differing only in parameters beyond the third): "auto" (max of a peak_max_*, min of a peak_min_*, else
    mean), "max", "min" or "mean"; the figure's title names it. The table's attrs: "report" (the one-line account), "exit_code"
    (the CLI's), "interrupted" (why, or None), "recomputed" ([(case, why)]: stored cases that did not verify),
    "cases_wall_time_s" (the cases' wall time, the one the account gives).
    User errors raise ScenarioError before any case runs."""
    import pandas as pd

    from mechsim.scenarios.output.paths import default_folder as results_folder
    from mechsim.scenarios.studies.sweep.execute import make_runner
    from mechsim.scenarios.studies.sweep.plots import check_aggregate
    from mechsim.scenarios.studies.sweep.run import check_runner_options, exit_code, plan, run_sweep
    from mechsim.scenarios.studies.sweep.spec import build_spec
    check_runner_options(workers, dask_local, scheduler)
    check_aggregate(heatmap_aggregate)
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
        report = run_sweep(pl, folder, runner, timeseries=timeseries, force=force, progress=progress, plots=plots,
                           heatmap_aggregate=heatmap_aggregate)
        stored = folder / "sweep.parquet"
        table = pd.read_parquet(stored) if stored.exists() else pd.DataFrame()
    table.attrs.update(report=report.line(), exit_code=exit_code(report), interrupted=report.interrupted,
                       cases_wall_time_s=report.wall_time_s,
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
    of: quantities (default: all), e.g. "peak_contact_force_N,index_time_s"; by name also "max_<column>",
    "min_<column>" (the located max / min) and "startup_max_<column>", "startup_min_<column>" (the start-up's, where
    the run settles), `peak_<column>` being the one of larger magnitude (docs/sensitivity.md, "Quantities").
    Raises ScenarioError on a key or quantity that is not traced (naming the valid ones), and
    `SensitivityUnavailable` (a ValueError) where the derivative does not exist on this run (a grazing event, a
    transition that recomputes a traced value)."""
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
    the slot counts. subject_to: ["peak_contact_force_N <= 500", "min_drive_torque_N_m >= 0", ...]. Raises
    ScenarioError on a bad request and `mechsim.scenarios.studies.sizing.SizingFailed` (a RuntimeError, `.result`
    holding what ran) without a feasible optimum."""
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
