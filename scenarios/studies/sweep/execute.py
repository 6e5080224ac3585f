"""Run sweep cases: in this process, on a local process pool, or on a Dask cluster.

Every runner takes the validated cases (`CaseTask`) and calls `on_result(outcome)` in the main process as each
case finishes, so the caller can write it at once. A case's solver failure or exception is an outcome (recorded
with its reason), never an interruption. Ctrl-C or a lost worker stops the runner: it first delivers every case
that had already finished, then raises `SweepInterrupted` so the caller can say how many remain.

Each worker process derives the symbolic model once (dynamics.model caches the derivation per process) and
reuses it for every case of the same mechanism structure it is given.
"""
from __future__ import annotations

import logging
import os
import signal
import socket
import sys
import threading
import time
from collections import deque
from concurrent.futures import FIRST_COMPLETED, ProcessPoolExecutor, wait
from concurrent.futures.process import BrokenProcessPool
from contextlib import contextmanager
from dataclasses import dataclass
from multiprocessing.context import ForkServerContext, ForkServerProcess
from typing import Callable, Iterable

import pandas as pd

from mechsim.scenarios.loader import Scenario


class SweepInterrupted(Exception):
    """The sweep stopped before every case ran (finished cases have been delivered)."""


@dataclass(frozen=True)
class CaseTask:
    """One case to run: its key (hash of the resolved scenario) and the validated scenario."""

    key: str
    scenario: Scenario
    timeseries: bool = False


@dataclass
class Outcome:
    """What a worker sends back: the flat summary row, and the time series when asked for."""

    key: str
    row: dict
    timeseries: pd.DataFrame | None = None


def _drive_columns(si: dict) -> tuple[str | None, str | None]:
    """The drive angle's and speed's columns, or (None, None) where the drive coordinate is not an angle."""
    from mechsim.dynamics.tables import coordinate_columns
    from mechsim.scenarios.loader import build_mechanism
    mech = build_mechanism(si)
    k = mech.drive_coordinate
    if k not in mech.angle_coordinates:
        return None, None
    names = coordinate_columns(mech.coordinates[k], True)
    return names[0], names[1]


def run_case(task: CaseTask, integrate=None) -> Outcome:
    """Run one case; any failure (solver, physics, exception) becomes a row with success = False and its reason."""
    from mechsim.scenarios.runner import run
    from mechsim.scenarios.studies.sweep.rows import cycle_figures, summary_row
    wall0, cpu0 = time.perf_counter(), time.process_time()
    worker = f"{socket.gethostname()}:{os.getpid()}"
    ts = None
    try:
        result = run(task.scenario, integrate=integrate)
        row = summary_row(result.summary)
        if result.failure is not None:
            row["failure_kind"] = result.failure.kind
            row["failure_code"] = result.failure.code.value
        df = result.timeseries
        angle, speed = _drive_columns(task.scenario.si)
        row.update(cycle_figures(df, angle, result.summary.get("regime"), speed))
        row["simulated_time_s"] = float(df["t_s"].iloc[-1]) if len(df) else 0.0
        if task.timeseries:
            ts = df
    except Exception as exc:  # a case's own error must not stop the others
        row = {"success": False, "failure": f"{type(exc).__name__}: {exc}".splitlines()[0], "failure_kind": "error"}
    row["case_wall_time_s"] = time.perf_counter() - wall0
    row["case_cpu_time_s"] = time.process_time() - cpu0
    row["worker"] = worker
    return Outcome(task.key, row, ts)


def run_chunk(tasks: list[CaseTask]) -> list[Outcome]:
    """Several cases in one pool call, one after another (each timed and recorded as run_case records it)."""
    return [run_case(task) for task in tasks]


#: a pool call should hold about this much work: each call costs the main process CPU (pickling, futures, the
#: executor's thread), a noticeable share for a short closed-form case sent alone
#: (docs/benchmarks.md, "Costs behind the code")
CHUNK_SECONDS = 0.15
#: at most this many cases a call, and this many calls a worker queued or running (so no worker waits for the next
#: call to be sent, and an interruption drops at most this many calls' unfinished cases per worker)
CHUNK_MAX = 32
IN_FLIGHT_PER_WORKER = 2
#: how often a pool worker checks that the sweep that started it is still alive (s)
PARENT_POLL_S = 0.5


class ChunkSizer:
    """How many cases the next pool call carries: about CHUNK_SECONDS of work at the cases' recent wall time
    (one case a call until a case has been timed, so slow cases -- DAE runs -- always go one by one), and never
    more than the remaining cases shared by twice the workers, so the calls shrink towards the end and the
    workers finish together."""

    def __init__(self, workers: int):
        self.workers = max(workers, 1)
        self.estimate: float | None = None

    def observe(self, case_wall_s: float) -> None:
        """An exponential average of the recent cases' wall time."""
        self.estimate = case_wall_s if self.estimate is None else 0.8 * self.estimate + 0.2 * case_wall_s

    def next(self, remaining: int) -> int:
        if self.estimate is None:
            return 1
        by_time = int(CHUNK_SECONDS / max(self.estimate, 1e-6))
        share = -(-remaining // (2 * self.workers))
        return max(1, min(CHUNK_MAX, by_time, share))


def _worker_start(parent: int) -> None:
    """A pool worker leaves Ctrl-C to the main process (which stops the pool and keeps what finished), and dies
    with it: a watcher thread ends the worker once the process `parent` is gone (a kill -9 of the sweep runs no
    clean-up, and the workers' own parent is the fork server, not the sweep)."""
    signal.signal(signal.SIGINT, signal.SIG_IGN)

    def watch() -> None:
        while True:
            time.sleep(PARENT_POLL_S)
            try:
                os.kill(parent, 0)
            except ProcessLookupError:
                os._exit(1)
            except OSError:
                pass                    # alive, another user's: keep going

    threading.Thread(target=watch, name="mechsim-parent-watch", daemon=True).start()


class SerialRunner:
    """Every case in this process, one after another (debugging; tiny sweeps)."""

    name = "serial"
    workers = 1

    def describe(self) -> str:
        return "serial (this process)"

    def run(self, tasks: list[CaseTask], on_result: Callable[[Outcome], None]) -> None:
        try:
            for task in tasks:
                on_result(run_case(task))
        except KeyboardInterrupt:
            raise SweepInterrupted("interrupted (Ctrl-C)") from None


#: imported once by the pool's fork server, before it forks the workers: each worker then starts with them
#: loaded (pandas the most, instead of once per worker; DAE-only modules load on first use)
WORKER_PRELOAD = ("mechsim.scenarios.studies.sweep.execute", "mechsim.scenarios.studies.sweep.rows",
                  "mechsim.scenarios.runner", "mechsim.thermal.plan")


def _start_fork_server():
    """The forkserver context, its server started now with WORKER_PRELOAD: the server imports them in its own
    process while this one goes on (validating the cases), instead of the workers waiting for them later."""
    import multiprocessing as mp
    from multiprocessing import forkserver
    context = mp.get_context("forkserver")
    context.set_forkserver_preload(list(WORKER_PRELOAD))     # used when the server starts (once a process)
    forkserver.ensure_running()                              # returns at once; the server imports on its own
    return context


def _inside_main_guard(path: str, line: int) -> bool:
    """Whether `line` of the script at `path` lies in a top-level `if __name__ == "__main__":` block."""
    import ast
    try:
        with open(path, "rb") as fh:
            tree = ast.parse(fh.read())
    except (OSError, SyntaxError, ValueError):
        return False
    for node in tree.body:
        test = node.test if isinstance(node, ast.If) else None
        if isinstance(test, ast.Compare) and len(test.ops) == 1 and isinstance(test.ops[0], ast.Eq):
            sides = (test.left, test.comparators[0])
            named = any(isinstance(side, ast.Name) and side.id == "__name__" for side in sides)
            main = any(isinstance(side, ast.Constant) and side.value == "__main__" for side in sides)
            if named and main and node.lineno <= line <= (node.body[-1].end_lineno or node.lineno):  # not its else
                return True
    return False


def main_reimport_unsafe() -> bool:
    """Whether a pool worker that imports the main script again (what forkserver and spawn workers do, to find
    what the script defines) would run this sweep again: the call comes from the script's top level (directly or
    through functions) outside an `if __name__ == "__main__":` block. In a notebook or an interactive session, or
    after the script's top level has run, nothing is re-run."""
    main = sys.modules.get("__main__")
    path = getattr(main, "__file__", None)
    if main is None or path is None:
        return False
    frame = sys._getframe()
    while frame is not None:
        if frame.f_globals is vars(main) and frame.f_code.co_name == "<module>":
            return not _inside_main_guard(path, frame.f_lineno)
        frame = frame.f_back
    return False


@contextmanager
def _main_not_reimported():
    """While a worker is started: the main module named "__main__" in its spec, which multiprocessing's child
    preparation takes as "nothing to import" (a sweep's worker needs only mechsim's modules)."""
    from importlib.machinery import ModuleSpec
    main = sys.modules["__main__"]
    saved = vars(main).get("__spec__")
    main.__spec__ = ModuleSpec("__main__", None)
    try:
        yield
    finally:
        main.__spec__ = saved


class ScriptFreeProcess(ForkServerProcess):
    """A forkserver process that does not import the main script (`_main_not_reimported`)."""

    def start(self) -> None:
        with _main_not_reimported():
            super().start()


class ScriptFreeContext(ForkServerContext):
    """The forkserver context whose workers skip the main script: a sweep called at a script's top level without
    an `if __name__ == "__main__":` guard runs once, not again in every worker (which would stop the pool)."""

    Process = ScriptFreeProcess


class PoolRunner:
    """A local concurrent.futures.ProcessPoolExecutor (forkserver processes, so no fork of a threaded parent;
    the fork server starts with the runner and imports WORKER_PRELOAD first)."""

    name = "pool"

    def __init__(self, workers: int | None = None):
        self.workers = workers or len(os.sched_getaffinity(0))
        self.context = _start_fork_server()

    def describe(self) -> str:
        return f"local process pool, {self.workers} workers"

    def run(self, tasks: list[CaseTask], on_result: Callable[[Outcome], None]) -> None:
        if not tasks:
            return
        context = ScriptFreeContext() if main_reimport_unsafe() else self.context
        ex = ProcessPoolExecutor(max_workers=min(self.workers, max(len(tasks), 1)), mp_context=context,
                                 initializer=_worker_start, initargs=(os.getpid(),))
        queue = deque(tasks)
        sizer = ChunkSizer(self.workers)
        pending: dict = {}              # future -> its chunk, at most IN_FLIGHT_PER_WORKER chunks a worker
        delivered: set = set()          # keys handed to on_result

        def submit() -> None:
            while queue and len(pending) < IN_FLIGHT_PER_WORKER * self.workers:
                chunk = [queue.popleft() for _ in range(sizer.next(len(queue)))]
                pending[ex.submit(run_chunk, chunk)] = chunk

        try:
            submit()
            while pending:
                done, _ = wait(pending, return_when=FIRST_COMPLETED)
                for f in done:
                    for outcome in f.result():
                        sizer.observe(outcome.row["case_wall_time_s"])
                        on_result(outcome)
                        delivered.add(outcome.key)
                    del pending[f]          # after its last outcome: an interruption delivers the rest of it
                submit()
        except KeyboardInterrupt:
            self._stop(ex)
            self._deliver_finished(pending, delivered, on_result)
            raise SweepInterrupted("interrupted (Ctrl-C)") from None
        except BrokenProcessPool:
            self._stop(ex)
            self._deliver_finished(pending, delivered, on_result)
            raise SweepInterrupted("a worker process died (killed or out of memory); the pool stopped") from None
        except BaseException:
            self._stop(ex)
            raise
        ex.shutdown(wait=True)

    @staticmethod
    def _deliver_finished(futures: Iterable, delivered: set, on_result) -> None:
        """Every outcome of a finished chunk not yet handed over (also the rest of a chunk whose delivery the
        interruption cut short); a chunk still running is dropped with its cases."""
        for f in list(futures):
            if f.done() and not f.cancelled() and f.exception() is None:
                for outcome in f.result():
                    if outcome.key not in delivered:
                        on_result(outcome)
                        delivered.add(outcome.key)

    @staticmethod
    def _stop(ex: ProcessPoolExecutor) -> None:
        """Cancel what has not started and end the pool's own worker processes (running cases are dropped)."""
        processes = list(getattr(ex, "_processes", {}).values())   # the executor keeps no public handle
        ex.shutdown(wait=False, cancel_futures=True)
        for p in processes:
            if p.is_alive():
                p.terminate()
        for p in processes:
            p.join(timeout=5)


class DaskRunner:
    """A Dask distributed cluster: an existing scheduler (`address`) or a LocalCluster of `local_workers`.

    Cases are Dask futures (client.submit, distributed.as_completed); Dask does the scheduling, retries a task
    whose worker died on another worker (up to its `allowed-failures`), and reports a case that keeps killing
    workers as KilledWorker: such a case is not recorded (it remains to run), the others go on.
    """

    name = "dask"

    def __init__(self, address: str | None = None, local_workers: int | None = None):
        self.address = address
        self.workers = local_workers
        self.dashboard: str | None = None

    def describe(self) -> str:
        return f"Dask scheduler {self.address}" if self.address else f"Dask LocalCluster, {self.workers} workers"

    def run(self, tasks: list[CaseTask], on_result: Callable[[Outcome], None]) -> None:
        from mechsim.scenarios.units import ScenarioError
        if not tasks:
            return
        try:
            from distributed import Client, LocalCluster, as_completed as dask_completed
        except ImportError:
            raise ScenarioError("--dask-local/--scheduler", "needs dask[distributed]: pip install "
                                "\"mechsim[dask]\"") from None
        cluster = None
        if self.address:
            try:
                client = Client(self.address, timeout="20s")
            except (OSError, TimeoutError, ValueError) as exc:
                raise ScenarioError("--scheduler", f"cannot connect to {self.address}: {exc}") from None
        else:
            cluster = LocalCluster(n_workers=self.workers, threads_per_worker=1, processes=True,
                                   dashboard_address=":0", silence_logs=logging.CRITICAL)
            client = Client(cluster)
        self.dashboard = getattr(client, "dashboard_link", None)
        lost, first_error = 0, ""
        delivered: set = set()
        try:
            futures = [client.submit(run_case, t, key=f"mechsim-case-{t.key}-{os.urandom(4).hex()}", pure=False)
                       for t in tasks]
            try:
                for f in dask_completed(futures):
                    try:
                        outcome = f.result()
                    except Exception as exc:   # KilledWorker, or a worker that cannot run mechsim: not finished
                        delivered.add(f.key)
                        lost += 1
                        first_error = first_error or f"{type(exc).__name__}: {exc}".splitlines()[0]
                        continue
                    on_result(outcome)
                    delivered.add(f.key)
            except KeyboardInterrupt:
                client.cancel([f for f in futures if f.status == "pending"])
                for f in futures:
                    if f.key not in delivered and f.status == "finished":
                        on_result(f.result())
                        delivered.add(f.key)
                raise SweepInterrupted("interrupted (Ctrl-C)") from None
            if lost:
                raise SweepInterrupted(f"{lost} case(s) did not finish on Dask ({first_error})")
        finally:
            client.close()
            if cluster is not None:
                cluster.close()


def make_runner(workers: int | None = None, dask_local: int | None = None,
                scheduler: str | None = None, batch: bool = False):
    """The runner the options ask for: Dask if a scheduler or a local Dask cluster is given, else a pool;
    with batch, diffrax DAE cases of one structure run batched first (BatchRunner) and the rest on that runner."""
    if batch:
        return BatchRunner(make_runner(workers, dask_local, scheduler))
    if scheduler:
        return DaskRunner(address=scheduler)
    if dask_local:
        return DaskRunner(local_workers=dask_local)
    if workers == 0:
        return SerialRunner()
    return PoolRunner(workers)


class _Captured(BaseException):
    """Raised by the capturing `integrate` passed to the runner: it carries the arguments the runner would give the
    backend (not an Exception, so nothing on the way catches it)."""

    def __init__(self, args, kwargs):
        self.args_, self.kwargs = args, kwargs


def _batch_reason(task: CaseTask) -> str | None:
    """Why a case cannot join a batch (None if it can): closed-form cases and the IDA backend."""
    from mechsim.scenarios.loader import build_mechanism
    from mechsim.scenarios.runner import choose_method, make_drive, solver_settings
    si = task.scenario.si
    if si["solver"]["backend"] != "diffrax":
        return "IDA backend (solver.backend = 'ida')"
    try:
        mech, drive, settings = build_mechanism(si), make_drive(si), solver_settings(si)
        if choose_method(si, mech, drive, settings)[0] != "dae":
            return "closed-form method (no integration to batch)"
    except Exception as exc:  # the case's own error: it runs (and is recorded) on the fallback runner
        return f"could not prepare ({type(exc).__name__})"
    return None


class BatchRunner:
    """diffrax DAE cases grouped by derived model structure (the `derive` key), diffrax options and output step;
    each group of two or more runs as one vmapped hybrid integration (dynamics.backends.diffrax_batch) in this process,
    then each case's tables and summary are built as `run_case` builds them. Everything else (closed-form cases,
    the IDA backend, a structure with a single case, a group whose batch raised, every case in a process where a
    batched solve can hang: `xla_options.batching_hazard`) goes to the fallback runner; `batching_note` says what
    ran how and why.

    The runner's call into the backend is captured once per case (the arguments it would pass: duration after
    the thermal plan, initial state, state extension), then answered from the batch's trajectories.
    """

    name = "batch"

    def __init__(self, fallback):
        self.fallback = fallback
        self.workers = getattr(fallback, "workers", 1)
        self.batching_note: str | None = None

    def describe(self) -> str:
        return f"batched diffrax (vmap, this process), rest on {self.fallback.describe()}"

    def run(self, tasks: list[CaseTask], on_result: Callable[[Outcome], None]) -> None:
        from collections import Counter
        rest: list[CaseTask] = []
        reasons: Counter = Counter()
        candidates = []
        for task in tasks:
            why = _batch_reason(task)
            if why:
                rest.append(task)
                reasons[why] += 1
            else:
                candidates.append(task)
        hazard = None
        if candidates:
            from mechsim.dynamics.backends.xla_options import batching_hazard
            hazard = batching_hazard()
        if hazard:                      # never a hang: these cases run one by one, and the note says why
            rest += candidates
            reasons[hazard] += len(candidates)
            candidates = []
        groups: dict = {}
        for task in candidates:
            call = self._capture(task)
            if call is None:
                rest.append(task)
                reasons["could not prepare"] += 1
                continue
            groups.setdefault(call[0], []).append((task, call[1]))
        batched, sizes = 0, []
        try:
            for key, members in groups.items():
                if len(members) < 2:
                    rest += [t for t, _ in members]
                    reasons["a model structure with a single case"] += 1
                    continue
                try:
                    self._run_group(members, on_result)
                except (KeyboardInterrupt, SweepInterrupted):
                    raise
                except Exception as exc:
                    rest += [t for t, _ in members]
                    reasons[f"batch raised {type(exc).__name__}: {str(exc).splitlines()[0][:120]}"] += len(members)
                    continue
                batched += len(members)
                sizes.append(len(members))
        except KeyboardInterrupt:
            raise SweepInterrupted("interrupted (Ctrl-C)") from None
        finally:
            self.batching_note = self._note(batched, sizes, len(rest), reasons)
        if rest:
            self.fallback.run(rest, on_result)

    def _note(self, batched: int, sizes: list[int], rest: int, reasons) -> str:
        head = (f"batched: {batched} case(s) in {len(sizes)} vmapped diffrax group(s) of {sizes}" if batched
                else "batched: none")
        if not rest:
            return head
        why = "; ".join(f"{r} ({n})" for r, n in reasons.items())
        return f"{head}; {rest} case(s) ran one by one on {self.fallback.describe()}: {why}"

    @staticmethod
    def _capture(task: CaseTask):
        """((group key), call) for a case: the arguments scenarios.runner passes to the diffrax backend."""
        from mechsim.dynamics.backends.diffrax_backend import default_options
        from mechsim.dynamics.model import derive

        def capture(*args, **kwargs):
            raise _Captured(args, kwargs)

        try:
            from mechsim.scenarios.runner import run
            run(task.scenario, integrate=capture)
        except _Captured as c:
            mech, drive, settings, t_end, dt_out, angle0, speed0 = c.args_
            ext = c.kwargs.get("ext")
            from mechsim.dynamics.programs import structure   # cases of one model structure share a batch
            model = derive(mech, settings.formulation, drive.is_prescribed, ext or None)
            call = dict(mech=mech, drive=drive, settings=settings, t_end=t_end, dt_out=dt_out, angle0=angle0,
                        speed0=speed0, ext=ext or None, ext_initial=c.kwargs.get("ext_initial"))
            return (structure(model), default_options(settings), float(dt_out), settings), call
        except Exception:
            return None
        return None

    @staticmethod
    def _run_group(members, on_result) -> None:
        from mechsim.dynamics.backends.diffrax_batch import simulate_batch
        calls = [c for _, c in members]
        wall0, cpu0 = time.perf_counter(), time.process_time()
        trajs = simulate_batch([c["mech"] for c in calls], [c["drive"] for c in calls], calls[0]["settings"],
                               [c["t_end"] for c in calls], calls[0]["dt_out"], [c["angle0"] for c in calls],
                               [c["speed0"] for c in calls], [c["ext"] for c in calls],
                               [c["ext_initial"] for c in calls])
        share_wall = (time.perf_counter() - wall0) / len(members)
        share_cpu = (time.process_time() - cpu0) / len(members)
        for (task, _), traj in zip(members, trajs):
            outcome = run_case(task, integrate=lambda *a, _traj=traj, **k: _traj)
            outcome.row["case_wall_time_s"] += share_wall
            outcome.row["case_cpu_time_s"] += share_cpu
            on_result(outcome)
