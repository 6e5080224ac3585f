"""The figure worker `mechsim run` forks before the run (scenarios/output/figure_worker.py): the folder it fills must
hold the same images as drawing them one by one with matplotlib's own `savefig` (decoded pixels, mode, size and PNG
metadata; tests/test_figure_writer.py), without this process drawing (or importing matplotlib at all) when the
workers succeed; whatever a worker fails to save is drawn here; a command that stops early leaves no worker
behind."""
import json
import os
import subprocess
import sys

import pytest

from mechsim.scenarios.output.figure_worker import plots_wanted

pytestmark = pytest.mark.skipif(not sys.platform.startswith("linux"), reason="the worker is forked on Linux only")

# Run apart, in a fresh process: the test session may have loaded JAX (no fork then) and has loaded matplotlib. One
# process for the three cases, the clean one first (its check is that this process has not imported matplotlib):
# one run, written three times by a worker forked for each case, and the result's figures drawn here once to compare
# the three folders with.
_SCRIPT = """
import json, os, sys, tempfile
from pathlib import Path
from mechsim.scenarios.output.figure_worker import FigureWorker
from mechsim.scenarios import api
from mechsim.scenarios.output.writer import write_result
parent = os.getpid()
tmp = Path(tempfile.mkdtemp())
folders, drew_here = {}, {}


def write(mode, result=None):
    worker = FigureWorker.start()          # forked before the (first) run, as `mechsim run` does
    assert worker is not None
    if result is None:
        result = api.run("geneva-lc1", set=["duration='1.5 s'", "output_step='5 ms'"])
    with worker:
        folders[mode] = write_result(result, tmp / mode, mechanism=result.mechanism, worker=worker)
    return result


result = write("clean")
drew_here["clean"] = "matplotlib" in sys.modules
from mechsim.scenarios.output import plots
save = plots.save
for mode in ("worker-fails", "grandchild-fails"):
    here = []

    def failing(fig, path, mode=mode, here=here):
        if os.getpid() == parent:
            here.append(path)              # drawn and saved by this process
        if mode == "worker-fails" and os.getpid() != parent:
            raise RuntimeError("no figures in any worker")
        if mode == "grandchild-fails" and os.getppid() != parent and os.getpid() != parent:
            raise RuntimeError("no figures in the worker's own child")
        return save(fig, path)
    plots.save = failing                    # before the fork: the worker inherits it
    write(mode, result)
    drew_here[mode] = bool(here)
plots.save = save
from figure_images import folders_show_the_drawn_figures
n, same = folders_show_the_drawn_figures(result, folders)
print(json.dumps({mode: [drew_here[mode], n, same[mode]] for mode in folders}))
"""


@pytest.fixture(scope="module")
def modes():
    """mode -> (whether the script's process drew a figure, number of figures, whether the folder shows them)."""
    env = {**os.environ, "PYTHONPATH": os.pathsep.join(p for p in sys.path if p)}
    out = subprocess.run([sys.executable, "-c", _SCRIPT], env=env, capture_output=True, text=True, timeout=300)
    assert out.returncode == 0, out.stderr[-2000:]
    return {mode: tuple(v) for mode, v in json.loads(out.stdout.strip().splitlines()[-1]).items()}


def test_the_workers_draw_every_figure_and_this_process_none(modes):
    drew_here, n, same = modes["clean"]
    assert n >= 7 and same
    assert not drew_here                 # this process never imported matplotlib: the workers drew all


@pytest.mark.parametrize("mode", ["worker-fails", "grandchild-fails"])
def test_what_a_worker_fails_to_save_is_drawn_here(modes, mode):
    drew_here, n, same = modes[mode]
    assert n >= 7 and same
    assert drew_here                     # this process saved what the worker (or its child) failed to


def test_plots_wanted_reads_the_scenario_and_overrides():
    assert plots_wanted("geneva-lc1", [])
    assert not plots_wanted("geneva-lc1", ["output.plots=false"])
    assert not plots_wanted("no-such-scenario", [])              # the load reports it, with no worker started
    assert not plots_wanted("geneva-lc1", ["not an override"])


def test_a_command_that_stops_early_leaves_no_worker(tmp_path):
    """An output folder that exists without --force: exit 2 after the worker was forked. capture_output reads the
    pipes to their end, which only comes when every process holding them (the workers too) has exited."""
    (tmp_path / "out").mkdir()
    (tmp_path / "out" / "x").write_text("not mechsim's")
    env = {**os.environ, "PYTHONPATH": os.pathsep.join(p for p in sys.path if p)}
    out = subprocess.run([sys.executable, "-m", "mechsim.scenarios.cli", "run", "geneva-lc1", "--out",
                          str(tmp_path / "out")], env=env, capture_output=True, text=True, timeout=120)
    assert out.returncode == 2 and out.stderr.startswith("error: ") and "Traceback" not in out.stderr
    assert sorted(p.name for p in tmp_path.iterdir()) == ["out"]          # no temporary folder left



_INHERIT_SCRIPT = """
import os, signal
from mechsim.scenarios.output.figure_worker import FigureWorker
worker = FigureWorker.start()
assert worker is not None
other = os.fork()                  # any other fork while the worker's job pipe is open (a second worker, a pool)
if other == 0:
    signal.pause()                 # holds whatever it inherited until it is killed
    os._exit(0)
try:
    os.close(worker.job_fd)        # no job after all: the worker must read EOF although `other` lives on
    _, status = os.waitpid(worker.pid, 0)
    print("worker exit status:", status)
    print("other alive:", os.waitpid(other, os.WNOHANG) == (0, 0))
finally:
    os.kill(other, signal.SIGKILL)
    os.waitpid(other, 0)
"""


def test_another_fork_does_not_hold_the_workers_pipes():
    """A child forked for any other purpose closes this process's ends of the worker's pipes (os.register_at_fork):
    when this process closes the job pipe unused, the worker reads EOF and exits by itself (status 0) while that
    other child still lives. Had the child kept the pipe's write end, the worker would block on its read for as
    long as the child lives (here: until the subprocess is timed out, a failure)."""
    out = subprocess.run([sys.executable, "-c", _INHERIT_SCRIPT], capture_output=True, text=True, timeout=60)
    assert out.returncode == 0, out.stderr
    assert "worker exit status: 0" in out.stdout
    assert "other alive: True" in out.stdout


_INTERRUPTED_SCRIPT = """
import threading
from mechsim.scenarios import api
from mechsim.scenarios.output.figure_worker import FigureWorker
worker = FigureWorker.start()
assert worker is not None
result = api.run("geneva-lc1", set=["duration='0.3 s'", "output_step='5 ms'", "output.plots=false"])
start = threading.Thread.start


def interrupted(self):
    raise KeyboardInterrupt         # a Ctrl-C as the thread feeding the job pipe starts
threading.Thread.start = interrupted
try:
    with worker:
        worker.draw(result, result.mechanism, "/nonexistent")
except KeyboardInterrupt:
    print("interrupted, closed")
"""


def test_a_ctrl_c_as_the_job_is_handed_over_leaves_no_traceback():
    """`mechsim run` interrupted while it hands the figures' job to the worker (the sender thread not started yet):
    closing the worker waits for no thread, stops the worker and lets the KeyboardInterrupt through (the CLI then
    says so in one line, exit 130); it raised "cannot join thread before it is started" (a traceback, exit 1)."""
    env = {**os.environ, "PYTHONPATH": os.pathsep.join(p for p in sys.path if p)}
    out = subprocess.run([sys.executable, "-c", _INTERRUPTED_SCRIPT], env=env, capture_output=True, text=True,
                         timeout=120)
    assert out.returncode == 0 and "Traceback" not in out.stderr, out.stderr[-2000:]
    assert "interrupted, closed" in out.stdout
