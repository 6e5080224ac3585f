"""How much of the test suite's time is compilation (not a test): a pytest plugin that adds up, per test, the seconds
JAX spends tracing, lowering and compiling (its own monitoring events) and numba compiling (its outermost
"numba:compile" events), and a summary of what the workers recorded (docs/benchmarks.md, "The suite on a clean
clone").

    MECHSIM_SUITE_COMPILE_DIR=/tmp/sc python -m pytest -q -n 2 --dist loadfile -p mechsim.benchmarks.suite_compile
    python -m mechsim.benchmarks.suite_compile /tmp/sc

Each worker writes its records to `<dir>/<worker>.json` at its end: (test id, what, function, seconds). A module's
or session's fixture counts toward the test that first asked for it. Programs loaded from JAX's persistent cache are
counted apart, with the compile time JAX says they saved.
"""
from __future__ import annotations

import collections
import json
import os
import sys
import time
from pathlib import Path

#: JAX's duration events counted, by the name they are reported under
JAX_EVENTS = {
    "/jax/core/compile/jaxpr_trace_duration": "jax trace",
    "/jax/core/compile/jaxpr_to_mlir_module_duration": "jax lower",
    "/jax/core/compile/backend_compile_duration": "xla compile",
    "/jax/compilation_cache/compile_time_saved_sec": "xla saved by the cache",
}

_current = ["(before any test)"]
_records: list[tuple[str, str, str, float]] = []


def _jax_listener(event: str, duration: float, **kwargs) -> None:
    what = JAX_EVENTS.get(event)
    if what is not None:
        _records.append((_current[0], what, str(kwargs.get("fun_name", "")), float(duration)))


def _numba_listener():
    """A numba event listener timing the outermost compilation (a compiled function's callees nest in it)."""
    from numba.core import event

    class Outermost(event.Listener):
        def __init__(self):
            self.depth, self.started = 0, 0.0

        def on_start(self, ev):
            if self.depth == 0:
                self.started = time.perf_counter()
            self.depth += 1

        def on_end(self, ev):
            self.depth -= 1
            if self.depth == 0:
                name = getattr(ev.data.get("dispatcher"), "__name__", "") if isinstance(ev.data, dict) else ""
                _records.append((_current[0], "numba compile", name, time.perf_counter() - self.started))

    event.register("numba:compile", Outermost())


def pytest_configure(config) -> None:
    if not os.environ.get("MECHSIM_SUITE_COMPILE_DIR"):
        raise SystemExit("suite_compile: set MECHSIM_SUITE_COMPILE_DIR to the folder the records go to")
    from jax import monitoring
    monitoring.register_event_duration_secs_listener(_jax_listener)
    try:
        _numba_listener()
    except ImportError:
        pass


def pytest_runtest_setup(item) -> None:
    _current[0] = item.nodeid


def pytest_unconfigure(config) -> None:
    folder = Path(os.environ["MECHSIM_SUITE_COMPILE_DIR"])
    folder.mkdir(parents=True, exist_ok=True)
    worker = os.environ.get("PYTEST_XDIST_WORKER", "main")
    (folder / f"{worker}.json").write_text(json.dumps(_records))


def summarise(folder: Path, top: int = 20) -> str:
    """Totals by kind, by test file and by compiled function, from every worker's records in `folder`."""
    records = [r for f in sorted(folder.glob("*.json")) for r in json.loads(f.read_text())]
    lines = []
    kinds, counts = collections.Counter(), collections.Counter()
    for _, what, _, seconds in records:
        kinds[what] += seconds
        counts[what] += 1
    lines.append("seconds over all workers, by kind:")
    lines += [f"  {what:24s} {kinds[what]:8.1f} s  ({counts[what]} events)" for what in kinds]
    spent = [r for r in records if r[1] != "xla saved by the cache"]
    by_file = collections.Counter()
    for test, _, _, seconds in spent:
        by_file[test.split("::")[0]] += seconds
    lines.append(f"by test file (compilation of every kind), the {top} largest:")
    lines += [f"  {seconds:7.1f} s  {name}" for name, seconds in by_file.most_common(top)]
    by_fn, n_fn = collections.Counter(), collections.Counter()
    for _, what, fn, seconds in spent:
        if what in ("xla compile", "numba compile"):
            by_fn[f"{what}: {fn}"] += seconds
            n_fn[f"{what}: {fn}"] += 1
    lines.append(f"by compiled function, the {top} largest:")
    lines += [f"  {seconds:7.1f} s  {n_fn[name]:4d}x  {name}" for name, seconds in by_fn.most_common(top)]
    return "\n".join(lines)


if __name__ == "__main__":
    if len(sys.argv) != 2:
        raise SystemExit(__doc__)
    print(summarise(Path(sys.argv[1])))
