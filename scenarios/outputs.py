"""Write a Result to a folder atomically: everything goes to a temporary sibling folder, then one rename.

A reader never sees a half-written file; an existing folder is replaced only with `force`.
"""
from __future__ import annotations

import json
import shutil
import tempfile
from pathlib import Path

import numpy as np
import tomli_w

from dynamics.result import Result

from .units import ScenarioError


def _json_default(obj):
    if isinstance(obj, (np.floating, np.integer)):
        return obj.item()
    if isinstance(obj, np.ndarray):
        return obj.tolist()
    return str(obj)


def _toml_clean(d):
    """TOML has no null: drop None values (they mean 'default/not used')."""
    if isinstance(d, dict):
        return {k: _toml_clean(v) for k, v in d.items() if v is not None}
    if isinstance(d, list):
        return [_toml_clean(v) for v in d]
    return d


def resolved_scenario_toml(si: dict) -> str:
    """The scenario as run: every value in SI with its unit, defaults filled in; valid scenario input."""
    from .loader import resolved_raw
    header = "# Resolved scenario: every value in SI units, defaults filled in (valid input to `mechsim run`).\n"
    return header + tomli_w.dumps(_toml_clean(resolved_raw(si)))


def write_result(result: Result, out_dir: Path, force: bool = False, plots: bool = True, mechanism=None) -> Path:
    """Write timeseries.parquet/.csv, events.csv, summary.json, scenario.toml and PNG plots into out_dir."""
    out_dir = Path(out_dir)
    if out_dir.exists() and not force:
        raise ScenarioError("--out", f"{out_dir} exists; pass --force to replace it")
    out_dir.parent.mkdir(parents=True, exist_ok=True)
    tmp = Path(tempfile.mkdtemp(prefix=f".{out_dir.name}.", dir=out_dir.parent))
    try:
        result.timeseries.to_parquet(tmp / "timeseries.parquet", index=False)
        result.timeseries.to_csv(tmp / "timeseries.csv", index=False)
        result.events.to_csv(tmp / "events.csv", index=False)
        for name, table in result.extra_tables.items():
            table.to_csv(tmp / f"{name}.csv", index=False)
        (tmp / "summary.json").write_text(json.dumps(result.summary, indent=2, default=_json_default))
        (tmp / "scenario.toml").write_text(resolved_scenario_toml(result.scenario))
        if plots and len(result.timeseries):
            from .plots import write_plots
            write_plots(result, tmp, mechanism)
        if out_dir.exists():
            trash = out_dir.with_name(f".{out_dir.name}.old")
            if trash.exists():
                shutil.rmtree(trash)
            out_dir.rename(trash)
            tmp.rename(out_dir)
            shutil.rmtree(trash)
        else:
            tmp.rename(out_dir)
    except BaseException:
        shutil.rmtree(tmp, ignore_errors=True)
        raise
    return out_dir
