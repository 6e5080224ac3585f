"""The sweep folder: one small file per finished case, the table assembled from them, resume by case key.

    DIR/sweep.toml            the sweep definition (valid `mechsim sweep` input)
    DIR/sweep.json            case keys in sweep order, the runs that worked on it
    DIR/cases/<key>.json      one finished case: its overrides, parameters, summary row, run id
    DIR/timeseries/<key>.parquet   its time series (--timeseries)
    DIR/sweep.parquet, sweep.csv   the table, a row per finished case
    DIR/sweep_summary.json    counts, runner, timing, batching note, failed cases

Every file is written to a temporary name in the same folder and renamed, so a reader (or a resumed sweep)
never sees half a file; a case counts as finished when its cases/<key>.json exists.
"""
from __future__ import annotations

import json
import os
import shutil
import tempfile
from pathlib import Path

import pandas as pd
import tomli_w

from mechsim.scenarios.output.atomic import MARKER, MARKER_TEXT, check_replaceable
from mechsim.scenarios.output.atomic import json_default as _json_default
from mechsim.scenarios.units import ScenarioError


def atomic_write(path: Path, write) -> None:
    """Call write(tmp_path), then rename tmp_path to path."""
    path.parent.mkdir(parents=True, exist_ok=True)
    fd, tmp = tempfile.mkstemp(prefix=f".{path.name}.", dir=path.parent)
    os.close(fd)
    try:
        write(Path(tmp))
        os.replace(tmp, path)
    except BaseException:
        Path(tmp).unlink(missing_ok=True)
        raise


def atomic_write_text(path: Path, text: str) -> None:
    atomic_write(path, lambda p: p.write_text(text))


class SweepStore:
    """Per-case files of one sweep folder."""

    def __init__(self, root: Path):
        self.root = Path(root)
        self.cases = self.root / "cases"
        self.series = self.root / "timeseries"

    def case_path(self, key: str) -> Path:
        return self.cases / f"{key}.json"

    def series_path(self, key: str) -> Path:
        return self.series / f"{key}.parquet"

    def prepare(self, definition: dict, keys: list[str], run_id: str, force: bool) -> None:
        """Create the folder, or check that an existing one holds this same sweep (same cases), else refuse.

        force replaces whatever is there (finished cases included).
        """
        manifest = self.root / "sweep.json"
        runs: list[str] = []
        ours = (self.root / MARKER).is_file() or manifest.is_file()
        if self.root.exists() and force:
            if self.root.is_symlink() or not ours:
                check_replaceable(self.root, force)          # refuses a folder mechsim did not write
            shutil.rmtree(self.root)
        elif self.root.exists() and any(self.root.iterdir()):
            if not manifest.is_file():
                raise ScenarioError("--out", f"{self.root} exists and is not a sweep folder; pass --force to "
                                             "replace it")
            old = json.loads(manifest.read_text())
            if sorted(old.get("case_ids", [])) != sorted(set(keys)):
                common = len(set(old.get("case_ids", [])) & set(keys))
                raise ScenarioError("--out", f"{self.root} holds a different sweep ({len(old.get('case_ids', []))} "
                                             f"cases, {common} in common with this one); pass --force to replace "
                                             "it or choose another --out")
            runs = old.get("runs", [])
        self.cases.mkdir(parents=True, exist_ok=True)
        atomic_write_text(self.root / MARKER, MARKER_TEXT)
        runs.append(run_id)
        atomic_write_text(manifest, json.dumps({"case_ids": keys, "runs": runs}, indent=1))
        atomic_write_text(self.root / "sweep.toml",
                          "# The sweep definition (valid input to `mechsim sweep`).\n" + tomli_w.dumps(definition))

    def finished(self, keys: list[str], need_timeseries: bool) -> set[str]:
        """Keys whose case file exists (and time series, when asked for)."""
        return {k for k in set(keys) if self.case_path(k).is_file()
                and (not need_timeseries or self.series_path(k).is_file())}

    def write_case(self, record: dict, timeseries: pd.DataFrame | None = None) -> None:
        """The time series first, then the case file that marks the case finished."""
        key = record["case_id"]
        if timeseries is not None:
            atomic_write(self.series_path(key), lambda p: timeseries.to_parquet(p, index=False))
        atomic_write_text(self.case_path(key), json.dumps(record, default=_json_default))

    def read_case(self, key: str) -> dict:
        return json.loads(self.case_path(key).read_text())

    def table(self, cases: list[tuple[int, str, dict]]) -> pd.DataFrame:
        """Rows of the finished cases among (index, key, parameter columns), in sweep order."""
        rows = []
        for index, key, params in cases:
            path = self.case_path(key)
            if not path.is_file():
                continue
            rec = json.loads(path.read_text())
            rows.append({"case": index, "case_id": key, **params, **rec["row"], "run_id": rec["run_id"]})
        return pd.DataFrame(rows)

    def write_table(self, df: pd.DataFrame) -> None:
        atomic_write(self.root / "sweep.parquet", lambda p: df.to_parquet(p, index=False))
        atomic_write(self.root / "sweep.csv", lambda p: df.to_csv(p, index=False))

    def write_summary(self, summary: dict) -> None:
        atomic_write_text(self.root / "sweep_summary.json", json.dumps(summary, indent=2, default=_json_default))
