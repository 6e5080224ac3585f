"""Write a Result to a folder atomically: everything goes to a temporary sibling folder, then one rename.

A reader never sees a half-written file; an existing folder is replaced only with `force`.
"""
from __future__ import annotations

import json
from pathlib import Path

import tomli_w

from mechsim.dynamics.result import Result

from mechsim.scenarios.output.atomic import atomic_folder, json_default
from mechsim.scenarios.output.csv import write_csv, write_parquet


def _toml_clean(d):
    """TOML has no null: drop None values (they mean 'default/not used')."""
    if isinstance(d, dict):
        return {k: _toml_clean(v) for k, v in d.items() if v is not None}
    if isinstance(d, list):
        return [_toml_clean(v) for v in d]
    return d


def resolved_scenario_toml(si: dict) -> str:
    """The scenario as run: every value in SI with its unit, defaults filled in; valid scenario input."""
    from mechsim.scenarios.loader import resolved_raw
    header = "# Resolved scenario: every value in SI units, defaults filled in (valid input to `mechsim run`).\n"
    return header + tomli_w.dumps(_toml_clean(resolved_raw(si)))


def write_result(result: Result, out_dir: Path, force: bool = False, plots: bool = True, mechanism=None,
                 worker=None, progress=None) -> Path:
    """Write timeseries.parquet/.csv, events.csv, summary.json, scenario.toml, the extra tables (<name>.csv),
    the PNG figures (scenarios/output/figures.py) and report.html (the figures embedded) into out_dir, atomically.
    timeseries.csv follows [output] csv (scenarios/output/size.py: "auto" leaves it out of a large output).
    worker: a figure worker started before the run (scenarios/output/figure_worker.py, as `mechsim run` does),
    which then draws the figures; it is stopped here if there are none to draw. progress(fraction, what): called
    as the tables are written (fraction of their bytes; what: the file being written, then "figures")."""
    from mechsim.scenarios.output.size import csv_wanted, table_bytes
    tell = progress or (lambda fraction, what: None)
    setting = result.scenario.get("output", {}).get("csv", "always")
    size = table_bytes(result.timeseries) if setting == "auto" or progress is not None else None   # a few ms
    csv = csv_wanted(setting, size) if size is not None else setting == "always"
    total = max(size.parquet_bytes + (size.csv_bytes if csv else 0.0), 1.0) if size is not None else 1.0
    with atomic_folder(out_dir, force) as tmp:
        want = plots and len(result.timeseries)
        if want and worker is not None:
            worker.draw(result, mechanism, tmp)           # every figure drawn meanwhile, in two other processes
            figures = worker
        else:
            if worker is not None:
                worker.close()
            makers = []
            if want:
                from mechsim.scenarios.output.figures import result_figure_makers
                makers = result_figure_makers(result, mechanism)
            from mechsim.scenarios.output.render import FigureWriter
            figures = FigureWriter(makers, tmp)           # half the figures drawn meanwhile, in another process
        with figures:
            done = size.parquet_bytes / total if size is not None else 0.0
            tell(0.0, "timeseries.parquet")
            write_parquet(result.timeseries, tmp / "timeseries.parquet",
                          progress=progress and (lambda f: tell(done * f, "timeseries.parquet")))
            if csv:
                tell(done, "timeseries.csv")
                write_csv(result.timeseries, tmp / "timeseries.csv",
                          progress=lambda f: tell(done + (1.0 - done) * f, "timeseries.csv"))
            write_csv(result.events, tmp / "events.csv")
            for name, table in result.extra_tables.items():
                write_csv(table, tmp / f"{name}.csv")
            (tmp / "summary.json").write_text(json.dumps(result.summary, indent=2, default=json_default))
            scenario_toml = resolved_scenario_toml(result.scenario)
            (tmp / "scenario.toml").write_text(scenario_toml)
            tell(1.0, "figures")
            figures.finish()
        output = result.scenario.get("output", {})
        if output.get("animation") and len(result.timeseries):
            from mechsim.scenarios.output.animation import write_animation
            from mechsim.scenarios.output.render import warn_skipped
            from mechsim.scenarios.units import ScenarioError
            try:
                write_animation(result, tmp, mechanism, output.get("animation_format", "gif"))
            except (OSError, ScenarioError):
                raise
            except Exception as exc:       # the data is written all the same
                warn_skipped("the animation", exc)
        from mechsim.scenarios.output.report_html import write_report
        write_report(result, tmp)
    return out_dir
