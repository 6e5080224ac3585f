"""Cold start (not a test): wall and CPU time of fresh `mechsim` processes, median of several runs.

    python benchmarks/cold_start.py                          # --help and `run geneva-lc1`, 7 runs each
    python benchmarks/cold_start.py --runs 9 --compare /path/to/other/root
    python benchmarks/cold_start.py --only "run geneva-motor no-plots"    # a DAE run (derived model cached)
    python benchmarks/cold_start.py --only "run geneva-motor diffrax,sensitivity geneva-motor"   # programs kept

Each command runs in a new Python process (`python -m mechsim.scenarios.cli ...`), the OS file cache warm (one
unrecorded warm-up run first, which also writes the bytecode caches an installed package has). CPU time is
user + sys of the child (what load distorts least on a shared machine); wall time is shown too. With
--compare, the same commands run with another package root (a folder holding a `mechsim` package, e.g. an
older checkout) interleaved run by run, so bursts of load hit both alike. The load average is printed: read
the figures against it. See docs/benchmarks.md, "Cold start".
"""
from __future__ import annotations

import argparse
import os
import statistics
import subprocess
import sys
import tempfile
import time
from pathlib import Path

import mechsim

ROOT = Path(mechsim.__file__).parent.parent      # the folder that holds this `mechsim` package

COMMANDS = {
    "--help": ["--help"],
    "run geneva-lc1": ["run", "geneva-lc1", "--out", "{out}"],
    "run geneva-lc1 no-plots": ["run", "geneva-lc1", "--quiet", "--set", "output.plots=false", "--out", "{out}"],
    # a DAE run (IDA): the derived model comes from the disk cache the warm-up run wrote
    "run geneva-motor no-plots": ["run", "geneva-motor", "--quiet", "--set", "output.plots=false", "--out", "{out}"],
    # diffrax and the sensitivity pass: their programs come traced and compiled from the cache the warm-up wrote
    "run geneva-motor diffrax": ["run", "geneva-motor", "--quiet", "--set", "output.plots=false", "--set",
                                 'solver.backend="diffrax"', "--out", "{out}"],
    "sensitivity geneva-motor": ["sensitivity", "geneva-motor", "--wrt", "contact.friction,mechanism.crank_radius",
                                 "--quiet", "--out", "{out}"],
}
#: the commands run without --only (the others take tens of seconds to warm up)
DEFAULT = ("--help", "run geneva-lc1", "run geneva-lc1 no-plots", "run geneva-motor no-plots")
#: what a command's warm-up run adds: the DAE run's warm-up compiles its callbacks in the foreground (`ida-compiled`
#: by name marks the model ready), so that the measured runs of the default load them rather than overlap a
#: background compilation
WARM_UP = {"run geneva-motor no-plots": ["--set", 'solver.backend="ida-compiled"']}


def once(root: Path, args: list[str], scratch: Path) -> tuple[float, float]:
    """(wall s, CPU s) of one fresh process."""
    out = Path(tempfile.mkdtemp(dir=scratch)) / "out"
    env = {k: v for k, v in os.environ.items() if k != "PYTHONDONTWRITEBYTECODE"}
    env.update(PYTHONPATH=str(root), MECHSIM_CACHE_DIR=str(scratch / "cache"))
    argv = [sys.executable, "-m", "mechsim.scenarios.cli", *(a.format(out=out) for a in args)]
    t0 = time.perf_counter()
    proc = subprocess.Popen(argv, env=env, stdout=subprocess.DEVNULL, stderr=subprocess.PIPE, cwd=scratch)
    _, status, usage = os.wait4(proc.pid, 0)
    wall = time.perf_counter() - t0
    proc.returncode = os.waitstatus_to_exitcode(status)
    if proc.returncode not in (0, 3):
        raise SystemExit(f"{' '.join(argv)} failed ({proc.returncode}): {proc.stderr.read().decode()[-2000:]}")
    proc.stderr.close()
    return wall, usage.ru_utime + usage.ru_stime


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--runs", type=int, default=7)
    ap.add_argument("--only", default=",".join(DEFAULT), help=f"comma list of: {', '.join(COMMANDS)}")
    ap.add_argument("--compare", type=Path, default=None, help="another package root, run interleaved")
    args = ap.parse_args()
    roots = {"this": ROOT} | ({"other": args.compare.resolve()} if args.compare else {})
    names = [n.strip() for n in args.only.split(",")]
    print(f"load average before: {os.getloadavg()[0]:.1f}; {os.cpu_count()} cores; {args.runs} runs each")
    with tempfile.TemporaryDirectory(prefix="mechsim-cold-") as tmp:
        scratch = Path(tmp)
        for name in names:
            times: dict[str, list[tuple[float, float]]] = {label: [] for label in roots}
            for label, root in roots.items():
                # warm-up: file cache, bytecode, disk cache
                once(root, COMMANDS[name] + WARM_UP.get(name, []), scratch)
            for _ in range(args.runs):
                for label, root in roots.items():
                    times[label].append(once(root, COMMANDS[name], scratch))
            for label, runs in times.items():
                wall = statistics.median(w for w, _ in runs)
                cpu = statistics.median(c for _, c in runs)
                spread = f"{min(w for w, _ in runs):.2f}-{max(w for w, _ in runs):.2f}"
                print(f"{name:<26} {label:<6} wall {wall:6.2f} s (range {spread})  CPU {cpu:6.2f} s", flush=True)
    print(f"load average after: {os.getloadavg()[0]:.1f}")


if __name__ == "__main__":
    main()
