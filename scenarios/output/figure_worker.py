"""A figure worker started before the run, so that importing matplotlib overlaps the run (docs/benchmarks.md,
"Cold start").

`mechsim run` with figures spent about as long importing matplotlib after the run, before the first figure, as
loading the scenario and running it (docs/benchmarks.md, "Cold start").
`FigureWorker.start()` forks a process once the run's stack
(numpy, pandas) is imported, so both share it; the worker imports the figure code while this process loads the
scenario and runs it, then waits for a job. `draw(result, mechanism, folder)` sends it the result (pickled, from a thread, so
this process goes on writing the tables); the worker forks once more and the two processes save every other
figure each (as render.FigureWriter does). `finish()` waits until no worker holds the report pipe any more, so
no worker is writing into the folder, and draws here (render.FigureWriter) whatever a worker did not report
saved: a worker that fails, dies or was never given the job costs time, never a figure.
"""
from __future__ import annotations

import copy
import os
import pickle
import signal
import sys
import threading
import time
from pathlib import Path


def plots_wanted(scenario: str, overrides: list[str]) -> bool:
    """Whether the scenario as given (file or built-in, with --set overrides) keeps output.plots on, read from the
    TOML before it is validated; False where it cannot tell (the load that follows reports the error)."""
    from mechsim.scenarios.loader import apply_overrides, read_raw
    from mechsim.scenarios.units import ScenarioError
    try:
        raw = apply_overrides(read_raw(scenario)[0], list(overrides))
    except (ScenarioError, OSError, ValueError):
        return False
    output = raw.get("output", {})
    return isinstance(output, dict) and output.get("plots", True) is True


#: this process's ends of every open worker's pipes: a child forked for any other purpose (another worker, the
#: forked figure writer, a process pool) closes them at once, so a worker's job pipe reaches EOF and its report
#: pipe closes when this process closes its own ends, whatever else has forked meanwhile
_PARENT_FDS: set[int] = set()


def _close_inherited() -> None:
    for fd in list(_PARENT_FDS):
        try:
            os.close(fd)
        except OSError:
            pass
    _PARENT_FDS.clear()


if hasattr(os, "register_at_fork"):
    os.register_at_fork(after_in_child=_close_inherited)


def _close(fd: int) -> None:
    """Close one of this process's pipe ends and forget it."""
    _PARENT_FDS.discard(fd)
    os.close(fd)


class FigureWorker:
    """A forked process waiting to draw a result's figures into a folder (`start`, `draw`, `finish`).

    Use as a context manager around everything between start and finish: leaving it without `finish` (an
    error, Ctrl-C, no figures wanted after all) stops the workers and waits for them."""

    def __init__(self, pid: int, job_fd: int, report_fd: int):
        self.pid, self.job_fd, self.report_fd = pid, job_fd, report_fd
        self.sender: threading.Thread | None = None
        self.job: tuple | None = None

    @classmethod
    def start(cls) -> "FigureWorker | None":
        """Fork the worker (None where render.can_fork says no: not Linux, a daemonic pool worker, JAX loaded)."""
        from mechsim.scenarios.output.render import can_fork
        if not can_fork():
            return None
        job_r, job_w = os.pipe()
        report_r, report_w = os.pipe()
        sys.stdout.flush(), sys.stderr.flush()
        pid = os.fork()
        if pid == 0:                                   # the worker: never returns into the caller's code
            code = 1
            try:
                os.close(job_w), os.close(report_r)
                code = _serve(job_r, report_w)
            except BaseException:                      # the parent draws what is not reported saved
                pass
            finally:
                os._exit(code)
        os.close(job_r), os.close(report_w)
        _PARENT_FDS.update((job_w, report_r))
        return cls(pid, job_w, report_r)

    def draw(self, result, mechanism, folder: Path) -> None:
        """Send the worker the job of saving `result`'s figures (scenarios/output/figures.py, drawn with
        `mechanism`) into folder; the pipe is fed from a thread while this process goes on."""
        self.job = (result, mechanism, Path(folder))
        sent = result
        if getattr(result, "mechanism", None) is not None:
            sent = copy.copy(result)
            sent.mechanism = _without_symbols(result.mechanism)
        try:
            data = pickle.dumps((sent, _without_symbols(mechanism), str(folder)), protocol=pickle.HIGHEST_PROTOCOL)
        except Exception:                              # not picklable: the worker gets nothing, finish() draws here
            return
        self.sender = threading.Thread(target=_send, args=(self.job_fd, data), daemon=True)
        self.job_fd = None                            # the thread closes it
        self.sender.start()

    def finish(self) -> None:
        """Wait for the workers' reports (every worker gone or done), then save here every figure no worker
        reported saved (all of them if the job never reached a worker)."""
        if self.job is None:
            raise RuntimeError("FigureWorker.finish before draw")
        reports = self._reports()
        self._reap(patience=5.0)       # at EOF the worker has exited: this returns at once (SIGKILL is a backstop)
        total = max((n for n, _ in reports), default=None)
        done = {i for _, saved in reports for i in saved}
        if total is not None and done >= set(range(total)):
            return
        from mechsim.scenarios.output.figures import result_figure_makers
        from mechsim.scenarios.output.render import FigureWriter
        result, mechanism, folder = self.job
        makers = result_figure_makers(result, mechanism)
        with FigureWriter([make for i, make in enumerate(makers) if i not in done], folder) as writer:
            writer.finish()

    def _reports(self) -> list[tuple[int, list[int]]]:
        """Read the report pipe to its end (EOF: no worker holds it any more): (figures in all, figures saved) of
        each worker's line."""
        if self.job_fd is not None:
            _close(self.job_fd)
            self.job_fd = None
        chunks = []
        _PARENT_FDS.discard(self.report_fd)
        with os.fdopen(self.report_fd, "rb") as pipe:
            self.report_fd = None
            while chunk := pipe.read(4096):
                chunks.append(chunk)
        self._join_sender()
        reports = []
        for line in b"".join(chunks).decode("ascii", "replace").splitlines():
            try:
                total, _, saved = line.partition(":")
                reports.append((int(total), [int(i) for i in saved.split()]))
            except ValueError:
                continue
        return reports

    def _reap(self, patience: float | None = None) -> None:
        """Wait for the worker; with `patience` (s), kill it outright if it has not exited by then."""
        if self.pid is None:
            return
        try:
            if patience is not None:
                deadline = time.monotonic() + patience
                while os.waitpid(self.pid, os.WNOHANG) == (0, 0):
                    if time.monotonic() > deadline:
                        os.kill(self.pid, signal.SIGKILL)
                        break
                    time.sleep(0.005)
                else:
                    return
            os.waitpid(self.pid, 0)
        except ChildProcessError:
            pass
        finally:
            self.pid = None

    def close(self) -> None:
        """Stop the worker (and with it its own child) if it still runs, and wait for it (SIGTERM, which the worker
        answers by stopping its child and exiting; SIGKILL if it has not exited within 5 s)."""
        if self.pid is not None:
            try:
                os.kill(self.pid, signal.SIGTERM)
            except ProcessLookupError:
                pass
            self._reap(patience=5.0)
        for name in ("job_fd", "report_fd"):
            fd = getattr(self, name)
            if fd is not None:
                _close(fd)
                setattr(self, name, None)
        self._join_sender()

    def _join_sender(self) -> None:
        """Wait for the thread feeding the job pipe, if it started: a Ctrl-C inside its `start` leaves one that never
        ran (nothing to wait for; the process is ending)."""
        if self.sender is None:
            return
        try:
            self.sender.join()
        except RuntimeError:            # "cannot join thread before it is started"
            pass

    def __enter__(self) -> "FigureWorker":
        return self

    def __exit__(self, *exc) -> None:
        self.close()


def _without_symbols(mechanism):
    """The mechanism without its sympy symbols (made again on first use): unpickling them would import sympy."""
    if mechanism is None or "symbols" not in getattr(mechanism, "__dict__", {}):
        return mechanism
    light = copy.copy(mechanism)
    del light.__dict__["symbols"]
    return light


def _send(fd: int, data: bytes) -> None:
    try:
        view = memoryview(data)
        while view:
            view = view[os.write(fd, view):]
    except OSError:                                   # the worker is gone: finish() draws its figures here
        pass
    finally:
        _close(fd)


_grandchild: int | None = None


def _stop(signum, frame) -> None:
    """SIGTERM in the worker: stop its own child too and wait for it, so nothing writes into the folder after."""
    if _grandchild is not None:
        try:
            os.kill(_grandchild, signal.SIGKILL)
            os.waitpid(_grandchild, 0)
        except OSError:
            pass
    os._exit(1)


def _serve(job_fd: int, report_fd: int) -> int:
    """The worker: import the figure code, wait for the job, fork once, save every other figure in each process,
    and write one report line per process: "<figures in all>: <indices saved>"."""
    global _grandchild
    signal.signal(signal.SIGINT, signal.SIG_DFL)     # Ctrl-C: the parent reports it; the workers just stop
    signal.signal(signal.SIGTERM, _stop)
    import mechsim.scenarios.api  # noqa: F401  (what unpickling the result needs: pandas, the Result)
    from mechsim.scenarios.output.figures import result_figure_makers
    from mechsim.scenarios.output.plots import save
    from mechsim.scenarios.output.render import can_fork
    with os.fdopen(job_fd, "rb") as pipe:
        try:
            result, mechanism, folder = pickle.load(pipe)
        except EOFError:                               # no figures after all
            return 0
    makers = result_figure_makers(result, mechanism)
    mine = list(range(len(makers)))
    if len(makers) > 1 and can_fork():                 # not if unpickling the result loaded JAX
        pid = os.fork()
        if pid == 0:
            signal.signal(signal.SIGTERM, signal.SIG_DFL)
            _grandchild = None
            mine = mine[1::2]
        else:
            _grandchild = pid
            mine = mine[0::2]
    saved = []
    try:
        for i in mine:
            for stem, fig in makers[i]().items():
                save(fig, Path(folder) / f"{stem}.png")
            saved.append(i)
    finally:
        line = f"{len(makers)}:{' '.join(map(str, saved))}\n".encode("ascii")
        os.write(report_fd, line)                       # one short write: atomic on a pipe
        if _grandchild is not None:
            os.waitpid(_grandchild, 0)
    return 0
