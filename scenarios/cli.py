"""The `mechsim` command line: list, show and run scenarios.

Exit codes: 0 success; 2 a user error (one line naming the field, no traceback); 3 a solver or physics
failure, or with output.on_invalid = "stop" the model leaving its validity (what ran is written, plus one line:
when, where, why, hint); 4 the operating system refused a read or
write (permission, read-only folder, full disk): one line, nothing half-written left (docs/limits.md).
"""
from __future__ import annotations

import sys
import time
from pathlib import Path
from typing import List, Optional

import typer

from mechsim.scenarios.units import ScenarioError

#: when this command started (the console reports the whole command's wall time, what the user waited)
STARTED = time.perf_counter()

# Cold start (docs/benchmarks.md, "Cold start"): this module imports only typer; rich, the scientific stack and
# the solvers load inside the commands that use them, and help is click's plain text (typer's rich help alone
# imports rich), so `mechsim --help` answers in a fraction of a second.
app = typer.Typer(add_completion=False, no_args_is_help=True, pretty_exceptions_enable=False,
                  rich_markup_mode=None,
                  help="Simulate intermittent-motion mechanisms and their contact temperatures.")


class LazyConsole:
    """A rich Console made on first use (importing rich is a cost `--help` need not pay)."""

    def __init__(self, stderr: bool = False):
        self._stderr = stderr
        self._console = None

    @property
    def console(self):
        if self._console is None:
            from rich.console import Console
            self._console = Console(stderr=self._stderr)
        return self._console

    def __getattr__(self, name):
        return getattr(self.console, name)


err = LazyConsole(stderr=True)
out = LazyConsole()

USER_ERROR, SOLVER_FAILURE, OS_REFUSED = 2, 3, 4
INTERRUPTED = 130           # 128 + SIGINT, as a shell reports a Ctrl-C

#: whether this process has seen a Ctrl-C (`_on_ctrl_c`); whether the command has said why it stopped (`_fail`, a
#: sweep's report): a Ctrl-C typer turned into exit 130 silently is then said by `main`
_ctrl_c_seen = _said = False


def _on_ctrl_c(signum, frame) -> None:
    """A command's Ctrl-C handler: Python's own (KeyboardInterrupt), with the interrupt noted. The exception can
    reach the command as another one: raised while C code runs (an import building its own ImportError, as
    `ssl` does while pyarrow.parquet loads), it is replaced by what that code raises next (a TypeError), and the
    command must still say it was interrupted (exit 130), not report an internal error (`_interrupted`)."""
    global _ctrl_c_seen
    _ctrl_c_seen = True
    raise KeyboardInterrupt


def _saying_why() -> None:
    """Note that the command says itself why it stops (`main` then adds nothing)."""
    global _said
    _said = True


def _interrupted(exc: BaseException) -> bool:
    """Whether `exc` is a Ctrl-C: the KeyboardInterrupt itself, or whatever replaced it (`_on_ctrl_c`)."""
    return isinstance(exc, KeyboardInterrupt) or _ctrl_c_seen


def _fail(message: str, code: int = USER_ERROR) -> None:
    if _ctrl_c_seen and code != INTERRUPTED:     # what a Ctrl-C raised in any command is the interrupt (`_on_ctrl_c`)
        message, code = "interrupted (Ctrl-C)", INTERRUPTED
    _saying_why()
    if code == USER_ERROR:              # a refused command leaves no trace: not even the unit conversions it read
        from mechsim.scenarios.units import forget_unsaved_conversions
        forget_unsaved_conversions()
    err.print(f"error: {message}", markup=False, highlight=False, soft_wrap=True)
    raise typer.Exit(code)


def _internal_error(exc: Exception) -> str:
    """`Type: first line of the message` of a fault we did not foresee (one line, never a traceback)."""
    text = str(exc).strip()
    return f"{type(exc).__name__}: {text.splitlines()[0] if text else 'no message'}"


def _save_or_fail(result, target: Path, force: bool, doing: str, worker=None, progress=None) -> None:
    """result.save(target): a refused folder is a user error naming --out (exit 2), also where another run wrote it
    while this one ran (the result's own FileExistsError, refused as the start refuses it: `check_replaceable`);
    an OSError one line with exit 4. worker: a figure worker started before the run
    (scenarios/output/figure_worker.py) to draw the figures; progress: as write_result's."""
    from mechsim.scenarios.output.atomic import check_replaceable
    try:
        if worker is None:
            result.save(target, force=force, progress=progress)
        else:
            from mechsim.scenarios.output.writer import write_result
            plots = bool(result.scenario.get("output", {}).get("plots", True))
            write_result(result, target, force=force, plots=plots, mechanism=result.mechanism, worker=worker,
                         progress=progress)
    except ScenarioError as exc:
        _fail(str(exc))
    except FileExistsError as exc:
        try:
            check_replaceable(target, force)
        except ScenarioError as refused:
            _fail(str(refused))
        _os_refused(exc, doing, target)
    except OSError as exc:
        _os_refused(exc, doing, target)


def _os_refused(exc: OSError, doing: str, target=None) -> None:
    """One line for an OSError (permission, read-only, full disk, ...), exit 4; `target`: the folder being written,
    named where the error does not name its file (a full disk while a writer flushes)."""
    where = exc.filename if exc.filename is not None else f"writing {target}" if target is not None else "a write"
    _fail(f"{doing}: the operating system refused {where}: {exc.strerror or exc} (nothing half-written is left)",
          OS_REFUSED)


def _output_folder(out_dir: Optional[Path], label: str, force: bool, prefix: str = "") -> Path:
    """--out if given, else results/<prefix><slug of the label>; refuses an existing folder without --force and
    any folder mechsim did not write (ScenarioError naming --out)."""
    from mechsim.scenarios.output.atomic import check_replaceable
    from mechsim.scenarios.output.paths import default_folder
    target = out_dir if out_dir is not None else default_folder(label, prefix)
    check_replaceable(target, force)
    return target


@app.command("list")
def list_cmd() -> None:
    """List the built-in scenarios."""
    from mechsim.scenarios.loader import builtin_names, read_raw
    for name in builtin_names():
        raw, _ = read_raw(name)
        out.print(f"{name:<28} {raw.get('description', '')}", markup=False, highlight=False, soft_wrap=True)


@app.command()
def show(
    scenario: str = typer.Argument(..., help="built-in scenario name or path to a TOML file"),
    set_: List[str] = typer.Option([], "--set", help="override a value: section.key=value (repeatable)"),
) -> None:
    """Print a scenario as TOML, every key with its meaning and unit as a comment and every key it leaves out
    commented with its default: `mechsim show geneva-lc1 > mine.toml`, edit, `mechsim run mine.toml`."""
    from mechsim.scenarios.loader import load
    try:
        sys.stdout.write(load(scenario, list(set_)).to_toml(comments=True))
    except ScenarioError as exc:
        _fail(str(exc))


@app.command()
def docs(topic: Optional[str] = typer.Argument(None, help="a document: theory, limits, api, ... (docs/<topic>.md)")
         ) -> None:
    """Where the documentation is installed (it ships with the package): the docs folder and its documents, or
    the path of one, e.g. `mechsim docs theory` for the docs/theory.md that messages and summary.json cite."""
    folder = Path(__file__).resolve().parents[1] / "docs"
    names = sorted(p.stem for p in folder.glob("*.md"))
    if topic is None:
        print(folder)
        print("documents: " + ", ".join(names))
        return
    stem = Path(topic).name.removesuffix(".md")
    if stem not in names:
        _fail(f"docs: no document '{topic}'; there are: {', '.join(names)}")
    print(folder / f"{stem}.md")


@app.command()
def run(
    scenario: str = typer.Argument(..., help="built-in scenario name or path to a TOML file"),
    out_dir: Optional[Path] = typer.Option(None, "--out", help="output folder (default: results/<name>)"),
    set_: List[str] = typer.Option([], "--set", help="override a value: section.key=value (repeatable)"),
    force: bool = typer.Option(False, "--force", help="replace an existing output folder"),
    quiet: bool = typer.Option(False, "--quiet", help="print only errors"),
) -> None:
    """Run a scenario and write timeseries.parquet/.csv, events.csv, summary.json, scenario.toml and plots."""
    from contextlib import nullcontext

    from mechsim.scenarios import api
    from mechsim.scenarios.output.figure_worker import FigureWorker, plots_wanted
    # the figure worker forks now, sharing what is imported (numpy, pandas): it imports matplotlib while this
    # process loads the scenario and runs it (docs/benchmarks.md, "Cold start")
    with (FigureWorker.start() if plots_wanted(scenario, set_) else None) or nullcontext() as worker:
        _run(api, scenario, out_dir, set_, force, quiet, worker)


def _run(api, scenario: str, out_dir: Optional[Path], set_: List[str], force: bool, quiet: bool, worker) -> None:
    try:
        sc = api.load(scenario, set_)
        target = _output_folder(out_dir, sc.name, force)
    except ScenarioError as exc:
        _fail(str(exc))
    from mechsim.scenarios.console import RunProgress, native_output
    from mechsim.scenarios.output import size
    duration = sc.si["duration"]
    if not quiet and (note := size.large_note(sc.si, size.estimate(sc.si))):
        err.print(note, markup=False, highlight=False, soft_wrap=True)
    with RunProgress(None if quiet else err.console, sc.name, duration, disable=quiet) as bar:
        try:
            with native_output() as native:
                result = api.run(sc, progress=bar.simulated)
        except (KeyboardInterrupt, Exception) as exc:
            if _interrupted(exc):
                _fail(f"{sc.name}: interrupted (Ctrl-C) at t = {bar.time:.4g} s of {duration:g} s; "
                      "nothing was written", INTERRUPTED)
            if isinstance(exc, ScenarioError):
                _fail(str(exc))
            if isinstance(exc, ValueError):
                _fail(f"scenario: {exc}")
            # a backend fault we did not foresee: one line, exit 3, never a traceback
            _fail(f"the integration stopped on an internal error ({_internal_error(exc)}); "
                  "try solver.backend = 'ida' or another solver.formulation", SOLVER_FAILURE)
        result.summary["solver_messages"] = native
        bar.writing(0.0)
        try:
            _save_or_fail(result, target, force, f"{sc.name}: the results", worker, progress=bar.writing)
        except (KeyboardInterrupt, Exception) as exc:
            if not _interrupted(exc):
                raise
            _fail(f"{sc.name}: interrupted (Ctrl-C) while writing {target}; nothing half-written is left",
                  INTERRUPTED)
    if not quiet and result.scenario.get("output", {}).get("csv") == "auto":
        written = size.table_bytes(result.timeseries)
        if not size.csv_wanted("auto", written):
            err.print(size.skipped_note(written), markup=False, highlight=False, soft_wrap=True)
    _report_run(result, sc.name, target, quiet)


def _report_run(result, name: str, target: Path, quiet: bool) -> None:
    """The run's console report: a summary line and one line per kind of warning (none with --quiet), the
    failure as an error line (exit 3)."""
    from mechsim.scenarios.console import group_line
    from mechsim.scenarios.validity import violation_lines
    s = result.summary
    if not quiet:
        for group in s.get("warning_groups", []):
            err.print(group_line(group), markup=False, highlight=False, soft_wrap=True)
        stopped = result.failure is not None and s.get("failure_code") == "model_invalid"
        for line in [] if stopped else violation_lines(s.get("validity")):   # stopped: the failure line says it
            err.print(line, markup=False, highlight=False, soft_wrap=True)
        if (s.get("thermal") or {}).get("averaging_note"):     # cycle averaging: its estimated error
            err.print(s["thermal"]["averaging_note"], markup=False, highlight=False, soft_wrap=True)
        if s.get("solver_messages"):
            err.print(f"note: {len(s['solver_messages'])} message(s) of the solver library captured, in "
                      "summary.json (solver_messages)", markup=False, highlight=False, soft_wrap=True)
    if result.failure:
        err.print(f"failed: {result.failure.message()}; results so far written to {target}",
                  markup=False, highlight=False, soft_wrap=True)
        raise typer.Exit(SOLVER_FAILURE)
    if not quiet:
        solver = s["solver"]
        out.print(f"{name}: {s['model']['method']} ({s['model']['why']}); {solver['output_rows']} rows, "
                  f"{len(result.events)} events -> {target}", markup=False, highlight=False, soft_wrap=True)
        from mechsim.scenarios.console import console_lines, impacts_line
        for line in [*console_lines(s), impacts_line(s)]:
            if line:
                out.print(line, markup=False, highlight=False, soft_wrap=True)
        plots = bool(result.scenario.get("output", {}).get("plots", True))
        thermal = s["model"].get("thermal", "none") != "none"
        out.print(time_line(solver, time.perf_counter() - STARTED, plots, thermal), markup=False, highlight=False,
                  soft_wrap=True)


def seconds_text(seconds: float) -> str:
    """A part of a command's time as a user reads it: milliseconds below a tenth of a second (a warm solve of a few
    ms is not "0.00 s"), else seconds to the hundredth."""
    return f"{1e3 * seconds:.1f} ms" if seconds < 0.1 else f"{seconds:.2f} s"


def time_line(solver: dict, total: float, plots: bool = True, thermal: bool = False) -> str:
    """Where the command's wall time went: within the run, the solve, compiling the model's code (or loading it
    from the cache of an earlier process), loading the model and the solver (the derived model, the solver's
    libraries), the tables, checks, thermal model (`thermal`: the run has one) and summary (`tables_time_s`); then the
    rest (start-up, files and figures), so a user sees what waiting on figures costs."""
    run, solve = solver["wall_time_s"], solver.get("solve_time_s") or 0.0
    compile_ = solver.get("compile_time_s") or 0.0
    tables = solver.get("tables_time_s")
    parts = [f"solve {seconds_text(solve)}"] + (
        [f"compile or load compiled code {seconds_text(compile_)}"] if compile_ else [])
    if tables is None:        # a summary written before the tables were timed on their own
        parts.append(f"tables and summary {seconds_text(max(run - solve - compile_, 0.0))}")
    else:
        setup = run - solve - compile_ - tables
        parts += ([f"loading the model and solver {seconds_text(setup)}"] if setup >= 0.0005 else []) + [
            f"tables{', thermal' if thermal else ''} and summary {seconds_text(tables)}"]
    parts.append(f"start-up, files and figures {seconds_text(max(total - run, 0.0))}")
    tip = "; `--set output.plots=false` skips the figures" if plots and total - run > run else ""
    return f"time: {total:.2f} s in all ({', '.join(parts)}){tip}"


@app.command()
def animate(
    scenario: str = typer.Argument(..., help="built-in scenario name or path to a TOML file"),
    out_dir: Optional[Path] = typer.Option(None, "--out", help="output folder (default: results/<name>)"),
    set_: List[str] = typer.Option([], "--set", help="override a value: section.key=value (repeatable)"),
    fmt: str = typer.Option("gif", "--format", help="gif (Pillow) or mp4 (needs ffmpeg)"),
    force: bool = typer.Option(False, "--force", help="replace an existing output folder"),
    quiet: bool = typer.Option(False, "--quiet", help="print only errors"),
) -> None:
    """Run a scenario and write everything `run` writes plus animation.gif (or .mp4): the mechanism moving, the
    contact force as an arrow, the contact temperature as colour, a time cursor on the force trace."""
    from mechsim.scenarios.output.animation import check_format
    try:
        check_format(fmt)
    except ScenarioError as exc:
        _fail(str(exc).replace("output.animation_format", "--format"))
    run(scenario, out_dir, list(set_) + ["output.animation=true", f"output.animation_format='{fmt}'"], force, quiet)


@app.command()
def compare(
    a: str = typer.Argument(..., metavar="A", help="design A: built-in scenario name, TOML file or result folder"),
    b: Optional[str] = typer.Argument(None, metavar="B",
                                      help="design B: built-in scenario name, TOML file or result folder"),
    set_: List[str] = typer.Option([], "--set", help="override a value of each scenario: section.key=value "
                                   "(repeatable)"),
    set_a: List[str] = typer.Option([], "--set-a", help="override a value of A only (repeatable)"),
    set_b: List[str] = typer.Option([], "--set-b", help="override a value of B only (repeatable)"),
    out_dir: Optional[Path] = typer.Option(None, "--out", help="output folder (default: results/compare-<A>-vs-<B>)"),
    force: bool = typer.Option(False, "--force", help="replace an existing output folder"),
    plots: bool = typer.Option(True, "--plots/--no-plots", help="write the overlaid figures"),
    backends: bool = typer.Option(False, "--backends", help="instead: run the one scenario A on IDA and on diffrax "
                                  "and compare the columns; exit 1 if they disagree beyond tolerance"),
    rtol: Optional[float] = typer.Option(None, "--rtol", help="--backends: relative tolerance of both runs "
                                         "(default 1e-10)"),
    atol: Optional[float] = typer.Option(None, "--atol", help="--backends: absolute tolerance (default rtol / 100)"),
    solver: Optional[str] = typer.Option(None, "--solver", help="--backends: diffrax solver (default: the "
                                         "scenario's)"),
    fmt: str = typer.Option("table", "--format", help="table (plain full-precision text when piped), csv or json"),
) -> None:
    """Two designs side by side: the headline figures of A and B (located peaks, cycle means, temperatures,
    validity) with their differences, and the two runs' columns overlaid in figures, written to --out.
    With --backends: one scenario on IDA and on diffrax (docs/diffrax.md)."""
    if fmt not in ("table", "csv", "json"):
        _fail(f"--format must be table, csv or json, got {fmt!r}")
    if backends:
        if b is not None or set_a or set_b or out_dir is not None:
            _fail("compare --backends takes one scenario (and --set, --rtol, --atol, --solver); "
                  f"{'a second argument' if b is not None else '--set-a/--set-b/--out'} belongs to `compare A B`")
        _compare_backends(a, set_, 1e-10 if rtol is None else rtol, atol, solver, fmt)
        return
    if b is None:
        _fail("compare takes two designs, A and B (scenarios or result folders); --backends compares IDA with "
              "diffrax on one scenario")
    if rtol is not None or atol is not None or solver is not None:
        _fail("--rtol, --atol and --solver belong to `compare --backends`")
    from mechsim.scenarios import api
    from mechsim.scenarios.console import native_output
    try:
        if out_dir is not None:     # a refused --out is said before the runs
            _output_folder(out_dir, "", force)
        with native_output():       # the solver libraries' own prints stay off the table
            comparison = api.compare(a, b, set_, set_a, set_b)
        names = [r.summary.get("scenario", side) for r, side in ((comparison.a, "a"), (comparison.b, "b"))]
        target = _output_folder(out_dir, f"{names[0]}-vs-{names[1]}", force, "compare-")
    except ScenarioError as exc:
        _fail(str(exc))
    except ValueError as exc:
        _fail(f"scenario: {exc}")
    except Exception as exc:  # a backend fault we did not foresee: one line, exit 3, never a traceback
        _fail(f"compare: a run stopped on an internal error ({_internal_error(exc)})", SOLVER_FAILURE)
    try:
        comparison.save(target, force=force, plots=plots)
    except ScenarioError as exc:
        _fail(str(exc))
    except OSError as exc:
        _os_refused(exc, "compare", target)
    _print_designs(comparison, fmt, target)
    if any(r.failure is not None for r in (comparison.a, comparison.b)):
        raise typer.Exit(SOLVER_FAILURE)


def _print_designs(comparison, fmt: str, target: Path) -> None:
    """The headline table on stdout (rich on a terminal, a difference the runs do not resolve said so; full-precision
    plain text when piped, or csv/json); the notes and the folder on stderr, so stdout holds data only."""
    from mechsim.scenarios.studies.compare_designs import render
    title = f"A: {comparison.names[0]}   B: {comparison.names[1]}"
    if fmt == "table" and out.is_terminal:
        from rich.table import Table
        view = Table(title=title)
        for name in ("quantity", "A", "B", "B - A", "(B - A)/|A|"):
            view.add_column(name, justify="left" if name == "quantity" else "right", no_wrap=name == "quantity")
        for r in comparison.table.itertuples():
            rel = r.relative_difference
            shown = ("within accuracy" if r.difference and not r.resolved else
                     "" if rel != rel else f"{100 * rel:+.3g} %" if rel else "0")
            view.add_row(r.quantity, f"{r.a:.6g}", f"{r.b:.6g}", f"{r.difference:+.4g}" if r.difference else "0",
                         shown)
        out.print(view)
    elif fmt == "table":
        sys.stdout.write(f"{title}\n{render(comparison, 'text')}")
    else:
        sys.stdout.write(render(comparison, fmt))
    for note in comparison.notes + [f"-> {target}"]:
        err.print(note, markup=False, highlight=False, soft_wrap=True)


def _compare_backends(scenario: str, set_: List[str], rtol: float, atol: Optional[float], solver: Optional[str],
                      fmt: str) -> None:
    """`compare --backends`: IDA against diffrax on one scenario; exit 1 if they disagree beyond tolerance."""
    from mechsim.scenarios import api
    if not 0 < rtol < 1:
        _fail(f"--rtol must be in (0, 1), got {rtol}")
    from mechsim.scenarios.console import native_output
    try:
        with native_output():       # the solver libraries' own prints stay off the table
            table = api.compare_backends(scenario, set_, rtol=rtol, atol=atol, solver=solver)
    except ScenarioError as exc:
        _fail(str(exc))
    except ValueError as exc:
        _fail(f"scenario: {exc}")
    _print_compare(table, fmt)
    if not table.attrs["passed"]:
        raise typer.Exit(1)


def _print_compare(table, fmt: str) -> None:
    """The comparison on stdout: a rich table on a terminal, full-precision plain text when piped, or csv/json
    (data only on stdout; notes and failures on stderr)."""
    from rich.table import Table

    from mechsim.scenarios.studies.compare import render
    a = table.attrs
    sv = a["solver"]
    notes = [f"rows {a['rows']}, events {a['events']}, max event-time difference {a['event_time_max_diff_s']:.3g} s; "
             f"wall IDA {sv['ida'].get('wall_time_s', float('nan')):.3f} s, diffrax "
             f"{sv['diffrax'].get('wall_time_s', float('nan')):.3f} s (compile "
             f"{sv['diffrax'].get('compile_time_s', 0.0):.3f} s)"]
    notes += [f"{backend} failed: {message}" for backend, message in a["failures"].items()]
    notes += [] if a["passed"] else ["the backends disagree beyond tolerance"]
    title = f"{a['scenario']}: IDA vs diffrax {a['diffrax_solver']} (rtol {a['rtol']:g})"
    if fmt == "table" and out.is_terminal:
        view = Table(title=title)
        for name in ("column", "max |diff|", "max rel", "t (s)", "drive angle (rad)", "tolerance", "ok"):
            view.add_column(name, justify="left" if name in ("column", "tolerance") else "right",
                            no_wrap=name == "column")
        for r in table.itertuples():
            ok = "" if r.passed is None else ("yes" if r.passed else "NO")
            view.add_row(r.column, f"{r.max_abs_diff:.3g}", f"{r.max_rel_diff:.3g}", f"{r.t_s:.6g}",
                         f"{r.drive_angle_rad:.6g}", r.tolerance, ok)
        out.print(view)
        out.print(notes[0], markup=False, highlight=False, soft_wrap=True)
        notes = notes[1:]
    elif fmt == "table":
        sys.stdout.write(f"{title}\n{render(table, 'text')}{notes[0]}\n")
        notes = notes[1:]
    else:
        sys.stdout.write(render(table, fmt))
    for note in notes:
        err.print(note, markup=False, highlight=False, soft_wrap=True)


@app.command()
def sweep(
    target: str = typer.Argument(..., help="scenario name or file, or a sweep TOML file with a [sweep] table"),
    vary: List[str] = typer.Option([], "--vary", help="section.key=SPEC: 5,7,14 N*m | 0.1:0.4:7 | log:1e-3:1e-1:5"),
    set_: List[str] = typer.Option([], "--set", help="override shared by every case: section.key=value"),
    zip_: bool = typer.Option(False, "--zip", help="zip the axes (equal lengths) instead of a full grid"),
    out_dir: Optional[Path] = typer.Option(None, "--out", help="output folder (default: results/sweep-<name>)"),
    workers: Optional[int] = typer.Option(None, "--workers", help="local processes (default: all cores; 0: here)"),
    dask_local: Optional[int] = typer.Option(None, "--dask-local", help="run on a Dask LocalCluster of N workers"),
    scheduler: Optional[str] = typer.Option(None, "--scheduler", help="run on the Dask scheduler at ADDRESS"),
    timeseries: bool = typer.Option(False, "--timeseries", help="also write each case's time series"),
    plots: bool = typer.Option(True, "--plots/--no-plots", help="write PNG plots of the table"),
    force: bool = typer.Option(False, "--force", help="replace an existing output folder, finished cases too"),
    quiet: bool = typer.Option(False, "--quiet", help="no progress bar"),
    batch: bool = typer.Option(False, "--batch", help="diffrax DAE cases of one model structure: one vmapped "
                               "solve (the rest on the pool; on the CPU the pool is faster: docs/sweeps.md, "
                               "'Batching')"),
    heatmap_aggregate: str = typer.Option("auto", "--heatmap-aggregate", help="how a heat map's cell reduces the "
                                          "cases sharing it: auto (max of maxima, min of minima, else mean), "
                                          "max, min or mean"),
) -> None:
    """Run a parameter sweep: sweep.parquet/.csv (a row per case) and plots; re-running resumes (docs/sweeps.md)."""
    from mechsim.scenarios.api import sweep as run_sweep
    from mechsim.scenarios.studies.sweep.run import RichProgress
    try:
        with RichProgress(err.console, f"sweep {Path(target).stem}", disable=quiet) as bar:
            table = run_sweep(target, vary, set_, zip_, out_dir, workers, timeseries, plots, force, batch,
                              dask_local=dask_local, scheduler=scheduler, default_folder=True, progress=bar,
                              heatmap_aggregate=heatmap_aggregate)
    except ScenarioError as exc:
        _fail(str(exc))
    except OSError as exc:
        _os_refused(exc, "sweep", out_dir)
    reasons: dict[str, list[str]] = {}
    for key, why in table.attrs["recomputed"]:
        reasons.setdefault(why, []).append(key)
    for why, keys in reasons.items():           # a line per reason: an upgrade discards every case at once
        err.print(f"sweep: stored case {keys[0]} did not verify ({why}); it was computed again" if len(keys) == 1
                  else f"sweep: {len(keys)} stored cases did not verify ({why}); they were computed again",
                  markup=False, highlight=False, soft_wrap=True)
    (err if table.attrs["interrupted"] else out).print(table.attrs["report"], markup=False, highlight=False,
                                                       soft_wrap=True)
    _saying_why()
    if not quiet:                # what the user waited for: the cases, and the rest (start-up, tables and figures)
        total, cases = time.perf_counter() - STARTED, table.attrs["cases_wall_time_s"]
        out.print(f"time: {total:.2f} s in all (cases {seconds_text(cases)}, start-up, tables and figures "
                  f"{seconds_text(max(total - cases, 0.0))})", markup=False, highlight=False, soft_wrap=True)
    raise typer.Exit(table.attrs["exit_code"])


@app.command()
def curves(
    name: str = typer.Argument(..., help="rolling-pair set (A, B, C, D, ...), built-in scenario or TOML file"),
    out_dir: Optional[Path] = typer.Option(None, "--out", help="output folder (default: results/curves-<name>)"),
    force: bool = typer.Option(False, "--force", help="replace an existing output folder"),
) -> None:
    """Coupler-curve atlas of a rolling-pair 4-bar: components, closure, cusps, crunodes (CSV) and atlas.png."""
    from mechsim.scenarios.curves import write_curves
    try:
        target, s = write_curves(name, out_dir, force)
    except ScenarioError as exc:
        _fail(str(exc))
    out.print(f"{s['mechanism']}: {s['components']} components ({s['monochromatic']} monochromatic, "
              f"{s['dichromatic']} dichromatic), {s['cusps']} cusp rows, {s['crunodes']} crunodes -> {target}",
              markup=False, highlight=False, soft_wrap=True)


@app.command()
def bench(
    names: Optional[List[str]] = typer.Argument(None, help="methods or families (ida, diffrax, scipy, casadi); "
                                                          "default: all of the chosen size"),
    out_dir: Path = typer.Option(Path("results") / "bench", "--out", help="output folder"),
    full: bool = typer.Option(False, "--full", help="every tolerance 1e-3..1e-10, the whole scenario, diffrax"),
    scenario: str = typer.Option("geneva-motor", "--scenario",
                                 help="built-in scenario name or TOML file (torque or motor drive)"),
    set_: List[str] = typer.Option([], "--set", help="override a value: section.key=value (repeatable)"),
    force: bool = typer.Option(False, "--force", help="replace an existing output folder"),
    quiet: bool = typer.Option(False, "--quiet", help="no progress lines"),
    peer: bool = typer.Option(False, "--peer", help="mechsim against the CasADi IDAS and diffsol peers side by side "
                                                    "on case A and its friction and thermal variants: solve and "
                                                    "warm end-to-end run, CPU-time ratios at equal error (small: "
                                                    "case A, IDA and the peers; --full: all)"),
) -> None:
    """Work-precision diagrams (CSV + PNG): mechsim's IDA and diffrax against scipy and CasADi IDAS (the Geneva's
    peers) on any scenario, the error against the mechanism's reference solution."""
    if peer:
        _bench_peer(out_dir, full, force, quiet)
        return
    from mechsim.benchmarks.bench import BenchConfig, report_lines, run_bench, write
    try:
        config = (BenchConfig.full if full else BenchConfig.small)(names, scenario, set_)
        _output_folder(out_dir, "bench", force)
        say = None if quiet else (lambda m: err.print(m, markup=False, highlight=False, soft_wrap=True))
        result = run_bench(config, say)
        write(result, out_dir, force)
    except ScenarioError as exc:
        _fail(str(exc))
    for line in report_lines(result) + [f"-> {out_dir}"]:
        out.print(line, markup=False, highlight=False, soft_wrap=True)


def _bench_peer(out_dir: Path, full: bool, force: bool, quiet: bool) -> None:
    from mechsim.benchmarks.peer_bench import PeerConfig, report_lines, run_peer_bench, unavailable, write
    try:
        _output_folder(out_dir, "bench", force)
    except ScenarioError as exc:
        _fail(str(exc))
    say = None if quiet else (lambda m: err.print(m, markup=False, highlight=False, soft_wrap=True))
    config = PeerConfig() if full else PeerConfig.small()
    for line in unavailable(config.methods):
        err.print(line, markup=False, highlight=False, soft_wrap=True)
    result = run_peer_bench(config, say)
    write(result, out_dir, force)
    for line in report_lines(result) + [f"-> {out_dir}"]:
        out.print(line, markup=False, highlight=False, soft_wrap=True)


@app.command()
def report(
    kind: str = typer.Argument(..., help="which report: seed (the seed paper's six load cases, three models)"),
    out_dir: Optional[Path] = typer.Option(None, "--out", help="output folder (default: results/report-seed)"),
    small: bool = typer.Option(False, "--small", help="a short run: one index, coarse output step (CI)"),
    force: bool = typer.Option(False, "--force", help="replace an existing output folder"),
) -> None:
    """Reports (CSV tables, PNG figures, report.md): `seed` compares the seed as printed, corrected, and mechsim."""
    if kind != "seed":
        _fail(f"report: unknown report {kind!r}; available: seed")
    from mechsim.benchmarks.seed_report import cli_main as seed_report
    try:
        target, lines = seed_report(out_dir, small, force,
                                    lambda m: err.print(m, markup=False, highlight=False, soft_wrap=True))
    except ScenarioError as exc:
        _fail(str(exc))
    except RuntimeError as exc:
        _fail(f"report: {exc}", SOLVER_FAILURE)
    except ValueError as exc:
        _fail(f"report: {exc}")
    for line in lines:
        out.print(line, markup=False, highlight=False, soft_wrap=True)


@app.command()
def sensitivity(
    scenario: str = typer.Argument(..., help="built-in scenario name or path to a TOML file"),
    wrt: str = typer.Option(..., "--wrt", help="scenario values to differentiate by: section.key[,section.key...]"),
    of: Optional[str] = typer.Option(None, "--of", help="quantities (default all peak_*, cycle ones): peak_<col> "
                                "(largest magnitude), max_<col>, min_<col>, startup_max_<col>, startup_min_<col>, "
                                "index_time_s, ..."),
    set_: List[str] = typer.Option([], "--set", help="override a value: section.key=value (repeatable)"),
    change: float = typer.Option(0.01, "--change", help="relative change of each value for the quantity_change column"),
    out_dir: Optional[Path] = typer.Option(None, "--out", help="output folder (default: results/sensitivity-<name>)"),
    force: bool = typer.Option(False, "--force", help="replace an existing output folder"),
    quiet: bool = typer.Option(False, "--quiet", help="print only errors"),
) -> None:
    """Exact derivatives of the run's headline results by scenario values (docs/sensitivity.md); writes
    sensitivity.csv, tornado.png (elasticities) and summary.json."""
    from mechsim.scenarios import api
    from mechsim.scenarios.console import native_output
    try:
        sc = api.load(scenario, set_)
        target = _output_folder(out_dir, sc.name, force, prefix="sensitivity-")
        with native_output():
            table = api.sensitivity(sc, wrt, of, change=change)
    except ScenarioError as exc:
        _fail(str(exc))
    except ValueError as exc:       # SensitivityUnavailable: the derivative does not exist on this run
        _fail(f"sensitivity: {exc}", SOLVER_FAILURE)
    except Exception as exc:  # a fault we did not foresee: one line, exit 3, never a traceback
        _fail(f"sensitivity: stopped on an internal error ({_internal_error(exc)})", SOLVER_FAILURE)
    if table.empty:     # every quantity asked for is undefined on this run (its warnings say why): nothing to write
        _fail("--of: no quantity asked for has a value on this run: " + "; ".join(table.attrs["warnings"]))
    from mechsim.scenarios.studies.sensitivity import write_sensitivity
    try:
        write_sensitivity(table, target, force=force)
    except ScenarioError as exc:
        _fail(str(exc))
    except OSError as exc:
        _os_refused(exc, f"{sc.name}: the sensitivities", target)
    if quiet:
        return
    _print_sensitivity(table)
    for w in table.attrs["warnings"]:
        err.print(f"warning: {w}", markup=False, highlight=False, soft_wrap=True)
    c = table.attrs["cost"]
    ratio = c["sensitivity_per_run"]
    out.print(f"{sc.name}: {len(table)} derivatives; run ({c['run_backend']}) {c['run_wall_time_s']:.3f} s, "
              f"sensitivities {c['sensitivity_wall_time_s']:.3f} s (compilation "
              f"{c['sensitivity_compile_time_s']:.3f} s" + (f"; without it {ratio:.2g}x the run" if ratio else "")
              + f") -> {target}", markup=False, highlight=False, soft_wrap=True)
    total = time.perf_counter() - STARTED
    rest = max(total - c["run_wall_time_s"] - c["sensitivity_wall_time_s"], 0.0)
    out.print(f"time: {total:.2f} s in all (run {seconds_text(c['run_wall_time_s'])}, sensitivities "
              f"{seconds_text(c['sensitivity_wall_time_s'])}, start-up, files and figure {seconds_text(rest)})",
              markup=False, highlight=False, soft_wrap=True)


def _print_sensitivity(table) -> None:
    """The table on stdout: rich on a terminal, plain full-precision text when piped."""
    head = ("quantity", "value", "wrt", "parameter", "derivative", "elasticity", "quantity_change")
    if out.is_terminal:
        from rich.table import Table
        view = Table(title=f"{table.attrs['scenario']}: sensitivities (change of y for a "
                           f"{table.attrs['change']:.3g} relative change of p)")
        for name in head:
            view.add_column(name, justify="left" if name in ("quantity", "wrt") else "right")
        for r in table.itertuples():
            view.add_row(r.quantity, f"{r.value:.6g}", r.wrt, f"{r.parameter:.6g} {r.wrt_unit}".strip(),
                         f"{r.derivative:.6g}", f"{r.elasticity:.4g}", f"{r.quantity_change:.4g}")
        out.print(view)
        return
    sys.stdout.write(table[list(head)].to_string(index=False, float_format=lambda v: f"{v:.10g}") + "\n")


@app.command()
def size(
    scenario: str = typer.Argument(..., help="built-in scenario name or path to a TOML file"),
    vary: List[str] = typer.Option(..., "--vary", help="a value to size and its bounds: section.key=LOW:HIGH "
                                   "[unit], e.g. mechanism.crank_radius=40:120 mm (repeatable)"),
    minimize: str = typer.Option(..., "--minimize", help="a quantity (peak_contact_force_N: largest magnitude; "
                                 "max_contact_force_N, min_<col>, startup_max_<col>, index_time_s, ...) or one of the "
                                 "--vary keys"),
    subject_to: List[str] = typer.Option([], "--subject-to", help="a limit: \"QUANTITY <= VALUE\" or >=, VALUE in "
                                         "the quantity's unit (repeatable)"),
    set_: List[str] = typer.Option([], "--set", help="override a value: section.key=value (repeatable)"),
    method: str = typer.Option("slsqp", "--method", help="slsqp or trust-constr"),
    tolerance: Optional[float] = typer.Option(None, "--tolerance", help="optimiser tolerance (default 10x "
                                              "solver.rtol)"),
    out_dir: Optional[Path] = typer.Option(None, "--out", help="output folder (default: results/size-<name>)"),
    force: bool = typer.Option(False, "--force", help="replace an existing output folder"),
    quiet: bool = typer.Option(False, "--quiet", help="print only errors"),
) -> None:
    """The best design within bounds and limits, by exact gradients (docs/sensitivity.md, "Sizing"); writes
    design.toml (a scenario that runs), convergence.csv, convergence.png and summary.json."""
    from mechsim.scenarios import api
    from mechsim.scenarios.console import native_output
    from mechsim.scenarios.studies.sizing import SizingFailed
    failed = None
    try:
        sc = api.load(scenario, set_)
        target = _output_folder(out_dir, sc.name, force, prefix="size-")
        with native_output():
            result = api.size(sc, vary, minimize, subject_to, method=method, tolerance=tolerance)
    except ScenarioError as exc:
        _fail(str(exc))
    except SizingFailed as exc:
        failed, result = exc, exc.result
    except Exception as exc:  # a fault we did not foresee: one line, exit 3, never a traceback
        _fail(f"size: stopped on an internal error ({_internal_error(exc)})", SOLVER_FAILURE)
    if result is not None:
        _save_or_fail(result, target, force, f"{sc.name}: the sizing")
    if failed is not None:
        _fail(f"size: {failed}" + (f"; the convergence history is in {target}" if result is not None else ""),
              SOLVER_FAILURE)
    if not quiet:
        _print_size(result, target)


def _print_size(result, target: Path) -> None:
    """The design, the objective and the limits with their activity, as plain lines."""
    s = result.summary
    lines = [f"{s['scenario']}: minimise {s['objective']['name']} ({s['method']}, {s['iterations']} iterations, "
             f"{s['evaluations']} runs, {s['wall_time_s']:.1f} s): {s['message']}"]
    lines += [f"  slots = {c['slots']}: " + (f"optimum {c['objective']:.10g}" if c["feasible"] else
                                             f"no feasible design ({c.get('why', '')})") for c in s.get("slot_choices", [])]
    lines += [f"  {d['key']} = {d['value']:.10g} {d['unit']}".rstrip() + f"   (bounds {d['low']:.6g}..{d['high']:.6g}"
              + (f", at its {b['active']} bound" if b["active"] else "") + ")" for d, b in zip(s["design"], s["bounds"])]
    lines.append(f"  {s['objective']['name']} = {s['objective']['value']:.10g} (start {s['objective']['start']:.6g})")
    for c in s["constraints"]:
        state = (f"active, d objective / d limit = {c['shadow_price']:.6g}" if c["active"] else "inactive")
        lines.append(f"  {c['constraint']}: {c['value']:.10g} ({state})")
    v = s.get("verification")
    if v:
        lines.append("  checked on its own run" + (f" after {v['resolves']} re-solves with tightened limits"
                                                   if v["resolves"] else "") + ": " + "; ".join(
            f"{e['constraint']}: {e['run_value']:.10g} ({'holds' if e['holds'] else 'BREAKS'})" if e["checked"]
            else f"{e['constraint']}: not checked ({e['why']})" for e in v["limits"]))
    lines.append(f"-> {target}")
    for line in lines:
        out.print(line, markup=False, highlight=False, soft_wrap=True)
    for w in s["warnings_at_optimum"]:
        err.print(f"warning (at the design): {w}", markup=False, highlight=False, soft_wrap=True)


#: the young generation's collection threshold of a command's process (CPython's default: 700 allocations)
GC_YOUNG_THRESHOLD = 10_000


def main() -> None:
    """Console entry point; any user error that escaped becomes one line and exit code 2.

    A command's process collects its young generation every GC_YOUNG_THRESHOLD allocations instead of 700: a
    `mechsim run` imports a few hundred thousand long-lived objects (pandas, numba, matplotlib), which the default
    threshold sweeps from the young generation hundreds of times and from the whole heap several times
    (docs/benchmarks.md, "Cold start"). The older generations keep their thresholds, so cyclic garbage is still
    freed within a run.

    OpenBLAS (numpy's and scipy's each) starts a thread per core when it loads, and an idle one spins before it
    sleeps: with OPENBLAS_THREAD_TIMEOUT at its least (2^4 cycles, unless the user set it) they sleep at once.
    Each BLAS call keeps its threads and its split of the work, so every number is the same; a command's
    matrices are small, and for the large ones waking a thread is nothing beside the call."""
    import gc
    import os
    gc.set_threshold(GC_YOUNG_THRESHOLD, *gc.get_threshold()[1:])
    os.environ.setdefault("OPENBLAS_THREAD_TIMEOUT", "4")     # read when numpy loads OpenBLAS, after this
    from mechsim.dynamics.backends.xla_options import checks_without_callbacks
    checks_without_callbacks()      # compiled solves kept across processes (before equinox is imported)
    import signal
    if signal.getsignal(signal.SIGINT) is signal.default_int_handler:     # (an ignored Ctrl-C stays ignored)
        signal.signal(signal.SIGINT, _on_ctrl_c)
    code = 0
    try:
        app()
    except SystemExit as exc:
        code = exc.code
        if code == INTERRUPTED and not _said:       # typer's own exit on a Ctrl-C, which it does not say
            err.print("error: interrupted (Ctrl-C)", markup=False, highlight=False)
    except ScenarioError as exc:
        err.print(f"error: {exc}", markup=False, highlight=False)
        code = USER_ERROR
    except OSError as exc:
        err.print(f"error: the operating system refused {exc.filename}: {exc.strerror or exc}", markup=False,
                  highlight=False)
        code = OS_REFUSED
    _leave(code)


def _leave(code) -> None:
    """Exit with `code` (as sys.exit reads it) without tearing the interpreter down: freeing pandas, pyarrow and
    the rest module by module is a noticeable cost at the end of every `mechsim run` (docs/benchmarks.md, "Cold
    start"). The exit handlers still run (atexit: the unit cache's flush, logging, temporary folders) and the
    standard streams are flushed (exit status 120 if that fails, as Python does), then os._exit. Where another
    Python thread is still alive (it would be cut off) or atexit has no way to run its handlers, sys.exit."""
    if code == USER_ERROR:              # a refused command leaves no trace: not even the unit conversions it read
        from mechsim.scenarios.units import forget_unsaved_conversions
        forget_unsaved_conversions()
    import atexit
    import os
    import threading
    run_handlers = getattr(atexit, "_run_exitfuncs", None)
    if run_handlers is None or threading.active_count() > 1:
        sys.exit(code)
    if code is None:
        status = 0
    elif isinstance(code, int):
        status = code
    else:
        print(code, file=sys.stderr)
        status = 1
    run_handlers()
    for stream in (sys.stdout, sys.stderr):
        try:
            if stream is not None:
                stream.flush()
        except Exception:
            status = status or 120
    os._exit(status)


if __name__ == "__main__":
    main()
