"""Save a result's figures as PNG, in two processes where the platform forks cheaply.

Drawing the figures is most of what a `mechsim run` costs after the physics (docs/benchmarks.md, "Cold start"),
and matplotlib draws them one by one on one core. On Linux a forked process (it shares this one's memory: the
result, the imported modules, nothing to pickle) builds and saves every other figure while this one writes the
tables and saves the rest. A child that fails leaves its figures to this process, so the folder is complete
either way (a figure that cannot be drawn here either is skipped with a one-line warning); on other platforms, inside a daemonic worker (a sweep's process pool) or once JAX is loaded (its
threads make a fork unsafe), all are drawn here.
"""
from __future__ import annotations

import multiprocessing
import sys
from pathlib import Path


def save_figures(makers, folder: Path, skip: bool = True) -> None:
    """Build each figure (`makers`: functions returning {stem: Figure}) and save it as <stem>.png in folder. With
    `skip`, a figure that cannot be drawn is skipped with a one-line warning on stderr (the run's data is written
    all the same); without, the error propagates (a forked child: its parent draws the figure again and warns).
    An OSError (a refused or full folder) is no drawing problem and always propagates."""
    for make in makers:
        from mechsim.scenarios.output.plots import save      # matplotlib: only where a figure is drawn
        name = getattr(make, "stem", None)
        try:
            for name, fig in make().items():
                save(fig, Path(folder) / f"{name}.png")
        except OSError:
            raise
        except Exception as exc:
            if not skip:
                raise
            warn_skipped(f"figure {name + '.png' if name else 'of this run'}", exc)


def warn_skipped(what: str, exc: Exception) -> None:
    """The one-line warning on stderr for an output that could not be drawn and was skipped."""
    text = str(exc).strip().splitlines()
    print(f"warning: {what} skipped, it could not be drawn ({type(exc).__name__}: "
          f"{text[0] if text else 'no message'})", file=sys.stderr, flush=True)


def _child(makers, folder: Path) -> None:
    try:
        save_figures(makers, folder, skip=False)
    except BaseException:          # the parent draws them again: no traceback from here
        sys.exit(1)


def can_fork() -> bool:
    """Whether this process may fork a figure worker: Linux, not itself a daemonic pool worker, and JAX not loaded
    (a diffrax run: XLA's threads make a fork unsafe, and JAX warns about it)."""
    return (sys.platform.startswith("linux") and "fork" in multiprocessing.get_all_start_methods()
            and not multiprocessing.current_process().daemon and "jax" not in sys.modules)


class FigureWriter:
    """Saves `makers`' figures into `folder`: half in a forked process started here, the rest in `finish()`.

    Use as a context manager around the other writing: leaving it by an exception stops the child first."""

    def __init__(self, makers, folder: Path):
        self.folder = Path(folder)
        self.mine, self.theirs, self.child = list(makers), [], None
        if len(self.mine) > 1 and can_fork():
            self.mine, self.theirs = self.mine[0::2], self.mine[1::2]
            self.child = multiprocessing.get_context("fork").Process(target=_child, args=(self.theirs, self.folder),
                                                                     daemon=True)
            self.child.start()

    def finish(self) -> None:
        """Save this process's share, wait for the child's, and save the child's here if it failed."""
        save_figures(self.mine, self.folder)
        if self.child is not None:
            self.child.join()
            failed, self.child = self.child.exitcode != 0, None
            if failed:
                save_figures(self.theirs, self.folder)

    def __enter__(self) -> "FigureWriter":
        return self

    def __exit__(self, *exc) -> None:
        if self.child is not None:
            self.child.terminate()
            self.child.join()
            self.child = None
