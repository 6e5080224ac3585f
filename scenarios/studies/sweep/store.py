"""The sweep folder: one small file per finished case, the table assembled from them, resume by case key.

    DIR/sweep.toml            the sweep definition (valid `mechsim sweep` input)
    DIR/sweep.json            case keys in sweep order, the runs that worked on it
    DIR/cases/<key>.json      one finished case: its overrides, parameters, summary row, run id, build
    DIR/timeseries/<key>.parquet   its time series (--timeseries)
    DIR/sweep.parquet, sweep.csv   the table, a row per finished case
    DIR/sweep_summary.json    counts, runner, timing, batching note, failed cases

Every file is written to a temporary name in the same folder and renamed, so a reader (or a resumed sweep)
never sees half a file; a case counts as finished when its cases/<key>.json exists and verifies: it parses,
its SHA-256 checksum matches its content, it was computed by this build of mechsim (its code and its computing
libraries' versions: `results_fingerprint`), and its time series (when asked for) matches the checksum recorded
for it. A case that does not verify (a truncated or edited file, a disk fault, an upgrade) is removed and computed
again, so that a table never mixes rows of two builds.
"""
from __future__ import annotations

import functools
import hashlib
import json
import os
import re
import socket
import shutil
from pathlib import Path

import pandas as pd
import tomli_w

from mechsim.dynamics.user_cache import results_fingerprint
from mechsim.scenarios.output.atomic import MARKER, MARKER_TEXT, check_replaceable
from mechsim.scenarios.output.atomic import json_default as _json_default
from mechsim.scenarios.units import ScenarioError


@functools.lru_cache(maxsize=1)
def _host_tag() -> str:
    return hashlib.sha256(socket.gethostname().encode()).hexdigest()[:8]


#: .<name>.tmp-<pid>-<host tag>-<random>: a file being written by process pid on this host
_TEMP_FILE = re.compile(r"^\..+\.tmp-(\d+)-([0-9a-f]{8})-[A-Za-z0-9_]+$")


def remove_stale_files(folder: Path) -> int:
    """Remove temporary files left in `folder` by killed sweeps on this host (owning process gone)."""
    removed = 0
    try:
        entries = list(Path(folder).iterdir())
    except OSError:
        return 0
    for path in entries:
        m = _TEMP_FILE.match(path.name)
        if not m or m.group(2) != _host_tag() or not path.is_file() or path.is_symlink():
            continue
        try:
            os.kill(int(m.group(1)), 0)
        except ProcessLookupError:
            path.unlink(missing_ok=True)
            removed += 1
        except (OSError, OverflowError):
            pass
    return removed


def _temp_name(path: Path) -> Path:
    """The name of a new temporary file next to path (`_TEMP_FILE`), not made yet."""
    return path.parent / f".{path.name}.tmp-{os.getpid()}-{_host_tag()}-{os.urandom(6).hex()}"


def _create(tmp: Path) -> int:
    """A descriptor of tmp, made new (its folder made when missing: tried first, as a sweep writes its thousands
    of case files into folders that exist, and each file-system call costs here)."""
    flags = os.O_WRONLY | os.O_CREAT | os.O_EXCL
    try:
        return os.open(tmp, flags, 0o600)
    except FileNotFoundError:
        tmp.parent.mkdir(parents=True, exist_ok=True)
        return os.open(tmp, flags, 0o600)


def _written(path: Path, fill) -> None:
    """fill(fd, tmp) on a new temporary file tmp next to path (fd: its descriptor, fill's to close), then renamed
    to path. The temporary is named before it is
    made, inside the block that removes it: a Ctrl-C just after it was made leaves nothing behind."""
    tmp = _temp_name(path)
    try:
        try:
            fd = _create(tmp)
        except FileExistsError:       # another's (never in practice: a random name): not ours to remove
            tmp = None
            raise
        fill(fd, tmp)
        os.replace(tmp, path)
    except BaseException:
        if tmp is not None:
            tmp.unlink(missing_ok=True)
        raise


def atomic_write(path: Path, write) -> None:
    """Call write(tmp_path), then rename tmp_path to path."""
    def fill(fd: int, tmp: Path) -> None:
        os.close(fd)
        write(tmp)
    _written(path, fill)


def atomic_write_text(path: Path, text: str) -> None:
    """atomic_write of a text file, written through the temporary file's own descriptor (one open fewer; the same
    bytes as Path.write_text: default encoding, no newline translation on POSIX)."""
    def fill(fd: int, tmp: Path) -> None:
        with os.fdopen(fd, "w") as f:
            f.write(text)
    _written(path, fill)


def _checksum(record: dict) -> str:
    """SHA-256 of a case record's canonical JSON (sorted keys), the `checksum` field itself left out."""
    return hashlib.sha256(json.dumps(record, sort_keys=True).encode()).hexdigest()


def _with_keys(text: str, tail: dict[str, str]) -> str:
    """json.dumps of the object `text` encodes (a non-empty JSON object as json.dumps writes it) with the string
    entries `tail` appended, without encoding the object again: json.dumps of what json.loads reads back from its
    own output is that output (the same key order, floats by their shortest repr, NaN as NaN), so this equals
    json.dumps({**json.loads(text), **tail}) (tests/test_sweep_store.py checks it on case records)."""
    return text[:-1] + "".join(f", {json.dumps(k)}: {json.dumps(v)}" for k, v in tail.items()) + "}"


def _file_sha256(path: Path) -> str:
    return hashlib.sha256(Path(path).read_bytes()).hexdigest()


class SweepStore:
    """Per-case files of one sweep folder."""

    def __init__(self, root: Path):
        self.root = Path(root)
        self.cases = self.root / "cases"
        self.series = self.root / "timeseries"
        #: (key, why) of stored cases that failed verification and were removed, to be computed again
        self.discarded: list[tuple[str, str]] = []
        #: key -> record of the cases this store wrote or verified (as read back from their files): checked
        #: once, so the run's end counts and tabulates them without reading and checksumming each file again
        self._sound: dict[str, dict] = {}

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
        if self.root.exists() and force:
            check_replaceable(self.root, force)        # only a folder with mechsim's marker is ever removed
            shutil.rmtree(self.root)
        elif self.root.exists() and any(self.root.iterdir()):
            if not manifest.is_file() or not (self.root / MARKER).is_file():
                raise ScenarioError("--out", f"{self.root} exists and is not a sweep folder mechsim wrote; choose "
                                             "another --out")
            old = self._read_manifest(manifest)
            if set(old["case_ids"]) != set(keys):
                common = len(set(old["case_ids"]) & set(keys))
                raise ScenarioError("--out", f"{self.root} holds a different sweep ({len(set(old['case_ids']))} "
                                             f"cases, {common} in common with this one); pass --force to replace "
                                             "it or choose another --out")
            runs = old["runs"]
        self.cases.mkdir(parents=True, exist_ok=True)
        for folder in (self.root, self.cases, self.series):
            remove_stale_files(folder)
        atomic_write_text(self.root / MARKER, MARKER_TEXT)
        runs.append(run_id)
        atomic_write_text(manifest, json.dumps({"case_ids": keys, "runs": runs}, indent=1))
        atomic_write_text(self.root / "sweep.toml",
                          "# The sweep definition (valid input to `mechsim sweep`).\n" + tomli_w.dumps(definition))

    @staticmethod
    def _read_manifest(manifest: Path) -> dict:
        """sweep.json as {"case_ids": [str], "runs": [str]}, or one line saying it is damaged and how to recover."""
        try:
            old = json.loads(manifest.read_bytes().decode("utf-8"))
            if not (isinstance(old, dict) and all(isinstance(old.get(k, []), list) and
                                                  all(isinstance(x, str) for x in old.get(k, []))
                                                  for k in ("case_ids", "runs"))):
                raise ValueError("not a sweep manifest")
        except (OSError, UnicodeDecodeError, ValueError, RecursionError) as exc:
            raise ScenarioError("--out", f"{manifest} is damaged ({type(exc).__name__}: {str(exc)[:80]}); pass --force "
                                         "to start the sweep again in this folder (its finished cases are lost) or "
                                         "choose another --out") from None
        return {"case_ids": old.get("case_ids", []), "runs": old.get("runs", [])}

    def finished(self, keys: list[str], need_timeseries: bool) -> set[str]:
        """Keys whose case file exists and verifies (and time series, when asked for); a stored case that does
        not verify is removed and listed in `discarded` (it counts as not finished, so it is computed again)."""
        done = set()
        for k in sorted(set(keys)):
            if not self.case_path(k).is_file():
                continue
            known = self._sound.get(k)
            if known is not None and (not need_timeseries or "timeseries_sha256" in known):
                done.add(k)
                continue
            why = self.verify(k, need_timeseries)
            if why is None:
                done.add(k)
            elif why != "no time series":
                self.discarded.append((k, why))
                self.case_path(k).unlink(missing_ok=True)
                self.series_path(k).unlink(missing_ok=True)
        return done

    def verify(self, key: str, need_timeseries: bool) -> str | None:
        """None if the stored case is sound, else why not (parse, checksum, time-series checksum)."""
        try:
            record = json.loads(self.case_path(key).read_bytes().decode("utf-8"))
        except (OSError, UnicodeDecodeError, ValueError, RecursionError) as exc:
            return f"unreadable: {type(exc).__name__}"
        if not isinstance(record, dict) or "checksum" not in record:
            return "no checksum (written by an older mechsim, or edited)"
        stored = record.pop("checksum")
        if stored != _checksum(record) or record.get("case_id") != key or not isinstance(record.get("row"), dict):
            return "checksum mismatch"
        if record.get("computed_by") != results_fingerprint():
            return "computed by another mechsim build: its code or a computing library's version differs"
        if need_timeseries or "timeseries_sha256" in record:
            path = self.series_path(key)
            if not path.is_file():
                return "no time series" if "timeseries_sha256" not in record else "time series missing"
            if _file_sha256(path) != record.get("timeseries_sha256"):
                return "time series checksum mismatch"
        self._sound[key] = record
        return None

    def write_case(self, record: dict, timeseries: pd.DataFrame | None = None) -> None:
        """The time series first, then the case file (with checksums of both, and the build that computed it:
        `results_fingerprint`) that marks the case finished."""
        key = record["case_id"]
        record = {**record, "computed_by": results_fingerprint()}
        text = json.dumps(record, default=_json_default)
        record = json.loads(text)                                          # exactly what will be read back
        tail = {}
        if timeseries is not None:
            atomic_write(self.series_path(key), lambda p: timeseries.to_parquet(p, index=False))
            record["timeseries_sha256"] = tail["timeseries_sha256"] = _file_sha256(self.series_path(key))
        tail["checksum"] = _checksum(record)
        atomic_write_text(self.case_path(key), _with_keys(text, tail))
        self._sound[key] = record

    def read_case(self, key: str) -> dict:
        """The stored record (checksum left out for a case this store wrote or verified)."""
        known = self._sound.get(key)
        return known if known is not None else json.loads(self.case_path(key).read_text())

    def table(self, cases: list[tuple[int, str, dict]]) -> pd.DataFrame:
        """Rows of the finished cases among (index, key, parameter columns), in sweep order."""
        rows = []
        for index, key, params in cases:
            path = self.case_path(key)
            if not path.is_file():
                continue
            rec = self.read_case(key)
            rows.append({"case": index, "case_id": key, **params, **rec["row"], "run_id": rec["run_id"]})
        return pd.DataFrame(rows)

    def write_table(self, df: pd.DataFrame) -> None:
        atomic_write(self.root / "sweep.parquet", lambda p: df.to_parquet(p, index=False))
        atomic_write(self.root / "sweep.csv", lambda p: df.to_csv(p, index=False))

    def write_summary(self, summary: dict) -> None:
        atomic_write_text(self.root / "sweep_summary.json", json.dumps(summary, indent=2, default=_json_default))
