"""The xdist schedule (`--dist loadfile`, as .ci/run), derived from what the suite itself records.

Every run records, per test file, the seconds its tests took and the compiled programs they looked up
(`mechsim.dynamics.programs`: the diffrax solves, the compiled whole run, the sensitivity pass's solve and tools).
A program is built once per process, so files that use the same program are cheaper in one worker than in two;
the scheduler therefore puts files that share a program into one work unit (joined while a unit stays under its
share of the suite's time, so no unit keeps one worker busy long after the other has finished) and starts the
units longest first (xdist would order them by their number of tests, which leaves a few-test file that takes
minutes for the end). Nothing else changes: every file still runs whole in one worker, in its own order, with its
own module fixtures.

The record is kept in pytest's cache (`.pytest_cache`, key "mechsim/schedule"), updated by every run for the files
it ran; `--record-schedule` also writes it to tests/xdist_schedule.json, which a checkout without a cache (a clean
clone) reads. Without either, or without pytest-xdist, or with another --dist, the schedule is xdist's own.
"""
from __future__ import annotations

import hashlib
import json
from collections import defaultdict
from pathlib import Path

import pytest

SEED = Path(__file__).with_name("xdist_schedule.json")
CACHE_KEY = "mechsim/schedule"
#: programs that are worth sharing a worker for: compiled JAX programs (numba's callbacks and the derived models are
#: on disk already; a mode's jax functions are built in a moment)
SHARED_KINDS = ("diffrax_segment_solve", "diffrax_whole_run", "diffrax_batch_solve", "sensitivity_segment_solve",
                "sensitivity_tools")
#: a unit of files joined by shared programs takes at most this share of the suite's time per worker
UNIT_SHARE = 0.5


def addoption(parser) -> None:
    parser.addoption("--record-schedule", action="store_true",
                     help=f"also write the recorded schedule to {SEED.relative_to(SEED.parents[1])}")


def _program_uses() -> dict:
    try:
        from mechsim.dynamics import programs
    except ImportError:
        return {}
    return programs.uses()


def _label(key: tuple) -> str:
    return f"{key[0]}:{hashlib.sha256(repr(key[1:]).encode()).hexdigest()[:12]}"


def recorded(config) -> dict:
    """The latest record: this checkout's pytest cache, else the committed seed."""
    cache = getattr(config, "cache", None)
    data = cache.get(CACHE_KEY, None) if cache is not None else None
    if not data and SEED.is_file():
        data = json.loads(SEED.read_text())
    return data or {}


class Schedule:
    """The plugin (registered by conftest.py): records in every process, schedules in the controller."""

    def __init__(self, config):
        self.config = config
        self.controller = not hasattr(config, "workerinput")
        self.before: dict = {}
        self.seconds: dict[str, float] = defaultdict(float)
        self.programs: dict[str, set] = defaultdict(set)

    # -- recording: the programs a test looked up travel with its teardown report -----------------------------
    @pytest.hookimpl(tryfirst=True)
    def pytest_runtest_setup(self, item):
        self.before = _program_uses()

    @pytest.hookimpl(hookwrapper=True)
    def pytest_runtest_makereport(self, item, call):
        outcome = yield
        if call.when == "teardown":
            after = _program_uses()
            used = sorted(_label(k) for k, n in after.items() if n != self.before.get(k) and k[0] in SHARED_KINDS)
            if used:
                outcome.get_result().user_properties.append(("programs", used))

    def pytest_runtest_logreport(self, report):
        if not self.controller:
            return
        scope = report.nodeid.split("::", 1)[0]
        self.seconds[scope] += report.duration
        for name, value in report.user_properties:
            if name == "programs":
                self.programs[scope].update(value)

    def pytest_sessionfinish(self, session):
        if not self.controller or not self.seconds:
            return
        files = dict(recorded(self.config).get("files", {}))
        for scope, seconds in self.seconds.items():
            files[scope] = {"seconds": round(seconds, 2), "programs": sorted(self.programs.get(scope, ()))}
        data = {"files": dict(sorted(files.items()))}
        if getattr(self.config, "cache", None) is not None:
            self.config.cache.set(CACHE_KEY, data)
        if self.config.getoption("--record-schedule"):
            SEED.write_text(json.dumps(data, indent=1) + "\n")

    # -- the schedule -------------------------------------------------------------------------------------
    @pytest.hookimpl(optionalhook=True)
    def pytest_xdist_make_scheduler(self, config, log):
        return make_scheduler(config, log)


# -- the schedule --------------------------------------------------------------------------------------------
def work_units(files: dict, workers: int) -> tuple[dict[str, str], dict[str, float]]:
    """(file -> the file naming its unit, unit -> its recorded seconds): files that share a program in one unit,
    longest files first, a unit growing only while it stays under UNIT_SHARE of one worker's part of the suite."""
    total = sum(f["seconds"] for f in files.values())
    cap = UNIT_SHARE * total / max(workers, 1)
    unit_of: dict[str, str] = {}
    seconds: dict[str, float] = {}
    owner: dict[str, str] = {}                        # program -> the unit holding it
    for scope in sorted(files, key=lambda s: -files[s]["seconds"]):
        mine, own = files[scope]["seconds"], set(files[scope]["programs"])
        join = sorted({owner[p] for p in own if p in owner}, key=lambda u: -seconds[u])
        unit = next((u for u in join if seconds[u] + mine <= cap), scope)
        unit_of[scope] = unit
        seconds[unit] = seconds.get(unit, 0.0) + mine
        for p in own:
            owner.setdefault(p, unit)
    return unit_of, seconds


def make_scheduler(config, log):
    """loadfile with the recorded work units, or None (xdist's own) where there is no record."""
    if config.getvalue("dist") != "loadfile":
        return None
    try:
        from xdist.scheduler import LoadFileScheduling
    except ImportError:          # an xdist without it: its own scheduler
        return None
    files = recorded(config).get("files", {})
    if not files:
        return None
    workers = config.getoption("numprocesses")
    unit_of, seconds = work_units(files, workers if isinstance(workers, int) else 2)

    class RecordedScheduling(LoadFileScheduling):
        """loadfile, with files that share a program in one work unit, the longest units first."""

        def _split_scope(self, nodeid: str) -> str:
            scope = super()._split_scope(nodeid)
            return unit_of.get(scope, scope)

        def _assign_work_unit(self, node) -> None:
            if not getattr(self, "_longest_first", False):     # once, before the first unit leaves the queue
                self._longest_first = True
                for scope in sorted((s for s in self.workqueue if s in seconds), key=seconds.get):
                    self.workqueue.move_to_end(scope, last=False)
            super()._assign_work_unit(node)

    return RecordedScheduling(config, log)
