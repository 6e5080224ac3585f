"""A sweep from definition to table: validate every case, skip finished ones, run the rest, assemble, plot.

Nothing runs until every case has been validated by the scenario loader (a bad key, unit or geometry in any
case is one ScenarioError naming the field and the case). Finished cases are written as they finish; an
interruption keeps them, and running the same sweep again computes only the rest.
"""
from __future__ import annotations

import time
import uuid
from dataclasses import dataclass
from pathlib import Path
from typing import Protocol

from mechsim.scenarios.loader import Scenario, from_raw, read_raw
from mechsim.scenarios.output.paths import default_folder
from mechsim.scenarios.studies.sweep.execute import CaseTask, Outcome, SweepInterrupted
from mechsim.scenarios.studies.sweep.rows import case_key, parameter_columns
from mechsim.scenarios.studies.sweep.spec import SweepSpec
from mechsim.scenarios.studies.sweep.store import SweepStore
from mechsim.scenarios.units import ScenarioError


@dataclass
class PlannedCase:
    index: int
    key: str
    overrides: list[str]
    params: dict
    scenario: Scenario


@dataclass
class Plan:
    spec: SweepSpec
    cases: list[PlannedCase]

    @property
    def keys(self) -> list[str]:
        return [c.key for c in self.cases]

    @property
    def param_columns(self) -> list[str]:
        return list(self.cases[0].params) if self.cases else []


def plan(spec: SweepSpec, extra: list[list[str]] | None = None) -> Plan:
    """Validate every case (base scenario + its overrides) with the loader; nothing runs yet.

    extra: per case, further overrides derived from its values (Python API only, e.g. a duration of three
    crank turns at each case's crank speed in benchmarks/sweep_bench.py).
    """
    base_raw, source = read_raw(spec.scenario)       # parsed once; each case is overridden and validated
    cases = []
    per_case = spec.case_overrides()
    if extra is not None:
        per_case = [o + list(e) for o, e in zip(per_case, extra, strict=True)]
    for i, overrides in enumerate(per_case):
        try:
            sc = from_raw(base_raw, source, overrides)
        except ScenarioError as exc:
            varied = ", ".join(overrides[len(spec.base):])
            raise ScenarioError(exc.field, f"{exc.problem} (sweep case {i + 1}: {varied})") from None
        cases.append(PlannedCase(i, case_key(sc, overrides, base_raw), overrides,
                                 parameter_columns(sc, spec.keys), sc))
    return Plan(spec, cases)


class Progress(Protocol):
    def start(self, total: int, done: int, failed: int) -> None: ...

    def advance(self, success: bool) -> None: ...


class NoProgress:
    def start(self, total, done, failed):
        pass

    def advance(self, success):
        pass


class RichProgress:
    """A rich progress bar: cases done of total, failed so far, elapsed and estimated time left."""

    def __init__(self, console, label: str, disable: bool = False):
        from rich.progress import (BarColumn, MofNCompleteColumn, Progress as RProgress, TextColumn,
                                   TimeElapsedColumn, TimeRemainingColumn)
        self.bar = RProgress(TextColumn("[bold]{task.description}"), BarColumn(), MofNCompleteColumn(),
                             TextColumn("cases, {task.fields[failed]} failed"), TimeElapsedColumn(),
                             TextColumn("ETA"), TimeRemainingColumn(), console=console, disable=disable,
                             transient=True)
        self.label = label
        self.task = None

    def __enter__(self):
        self.bar.__enter__()
        return self

    def __exit__(self, *exc):
        return self.bar.__exit__(*exc)

    def start(self, total, done, failed):
        self.failed = failed
        self.task = self.bar.add_task(self.label, total=total, completed=done, failed=failed)

    def advance(self, success):
        self.failed += 0 if success else 1
        self.bar.update(self.task, advance=1, failed=self.failed)


@dataclass
class Report:
    """What happened: counts, where, and why it stopped early (if it did)."""

    out: Path
    total: int
    computed: int = 0
    reused: int = 0
    failed: int = 0
    remaining: int = 0
    interrupted: str | None = None
    wall_time_s: float = 0.0
    runner: str = ""
    run_id: str = ""
    batching: str | None = None
    #: (case key, why) of stored cases that failed verification on resume and were computed again
    discarded: list = None

    def line(self) -> str:
        head = (f"sweep: {self.total} cases ({self.computed} computed, {self.reused} reused, {self.failed} failed) "
                f"in {self.wall_time_s:.1f} s on {self.runner} -> {self.out}")
        if self.interrupted:
            return (f"sweep {self.interrupted}: {self.total - self.remaining} of {self.total} cases finished and "
                    f"kept, {self.remaining} remain; run the same command again to finish them -> {self.out}")
        return head


def run_sweep(spec_or_plan, out: Path, runner, timeseries: bool = False, force: bool = False,
              progress: Progress | None = None, plots: bool = True, heatmap_aggregate: str = "auto") -> Report:
    """Validate, prepare the folder, run what is not finished, write the table, plots and sweep summary."""
    wall0 = time.perf_counter()
    pl = spec_or_plan if isinstance(spec_or_plan, Plan) else plan(spec_or_plan)
    progress = progress or NoProgress()
    store = SweepStore(out)
    run_id = uuid.uuid4().hex[:12]
    store.prepare(pl.spec.describe(), pl.keys, run_id, force)
    done = store.finished(pl.keys, timeseries)
    by_key = {}
    for c in pl.cases:
        by_key.setdefault(c.key, c)
    todo = [c for k, c in by_key.items() if k not in done]
    report = Report(out=Path(out), total=len(pl.cases), run_id=run_id, runner=runner.describe(),
                    discarded=list(store.discarded))
    report.reused = sum(1 for c in pl.cases if c.key in done)
    failed_before = sum(1 for k in done if not store.read_case(k)["row"].get("success", False))
    report.failed = failed_before
    progress.start(len(by_key), len(by_key) - len(todo), failed_before)
    tasks = [CaseTask(c.key, c.scenario, timeseries) for c in todo]

    def on_result(outcome: Outcome) -> None:
        case = by_key[outcome.key]
        record = {"case_id": outcome.key, "run_id": run_id, "finished_at": time.time(),
                  "overrides": case.overrides, "params": case.params, "row": outcome.row}
        store.write_case(record, outcome.timeseries)
        ok = bool(outcome.row.get("success"))
        report.computed += 1
        report.failed += 0 if ok else 1
        progress.advance(ok)

    try:
        runner.run(tasks, on_result)
    except SweepInterrupted as exc:
        report.interrupted = str(exc)
    finally:
        finished = store.finished(pl.keys, timeseries)
        report.remaining = sum(1 for c in pl.cases if c.key not in finished)
        report.batching = getattr(runner, "batching_note", None)
        report.wall_time_s = time.perf_counter() - wall0
        _finish(store, pl, report, plots, heatmap_aggregate)
    return report


def _finish(store: SweepStore, pl: Plan, report: Report, plots: bool, aggregate: str = "auto") -> None:
    df = store.table([(c.index, c.key, c.params) for c in pl.cases])
    if len(df):
        store.write_table(df)
    if plots and len(df):
        from mechsim.scenarios.studies.sweep.plots import write_plots
        write_plots(df, pl, store.root / "plots", aggregate)
    failed = df.loc[~df["success"].astype(bool), ["case", "failure"]].to_dict("records") if len(df) else []
    store.write_summary({
        "scenario": pl.spec.scenario, "mode": pl.spec.mode, "parameters": pl.param_columns,
        "cases": report.total, "finished": report.total - report.remaining, "remaining": report.remaining,
        "computed_this_run": report.computed, "reused": report.reused, "failed": report.failed,
        "complete": report.remaining == 0, "interrupted": report.interrupted, "runner": report.runner,
        "run_id": report.run_id, "wall_time_s": report.wall_time_s,
        "batching": report.batching or batching_note(pl), "failed_cases": failed,
    })


def batching_note(pl: Plan) -> str:
    """Why the cases ran one by one (docs/sweeps.md, 'Batching')."""
    diffrax = sum(1 for c in pl.cases if c.scenario.si["solver"]["backend"] == "diffrax")
    if not diffrax:
        return ("not applicable: no case uses solver.backend = 'diffrax'; closed-form and IDA cases run one per "
                "worker process")
    return (f"not batched: {diffrax} of {len(pl.cases)} cases use the diffrax backend and each ran its own hybrid "
            "integration; run with --batch to integrate the diffrax DAE cases that share a model structure "
            "as one vmapped solve (docs/sweeps.md, 'Batching')")


INTERRUPTED_EXIT, INCOMPLETE_EXIT = 130, 3


def check_runner_options(workers: int | None, dask_local: int | None, scheduler: str | None) -> None:
    """ScenarioError (named as the CLI option) when the runner options contradict each other or are out of range;
    workers = 0 (run here) or None (all cores) are the defaults and give way to Dask."""
    if dask_local is not None and scheduler:
        raise ScenarioError("--dask-local", "give either --dask-local N or --scheduler ADDRESS, not both")
    if workers not in (None, 0) and (dask_local is not None or scheduler):
        raise ScenarioError("--workers", "sets the local process pool; with Dask the cluster has the workers")
    if workers is not None and workers < 0 or dask_local is not None and dask_local < 1:
        raise ScenarioError("--workers" if dask_local is None else "--dask-local", "must be a positive number")


def exit_code(report: Report) -> int:
    """`mechsim sweep`'s exit code: 0 every case has a record; 130 Ctrl-C; 3 workers lost."""
    if not report.interrupted:
        return 0
    return INTERRUPTED_EXIT if "Ctrl-C" in report.interrupted else INCOMPLETE_EXIT
