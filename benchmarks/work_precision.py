"""Refresh the measured figures of docs/benchmarks.md: `mechsim bench --full`, then copy its chart and tables
into docs/ (the numbers in the text are edited by hand from the printed summary).

Run: python benchmarks/work_precision.py [--out results/bench]   (about 6 minutes on 2 cores)
"""
from __future__ import annotations

import argparse
import json
import shutil
from pathlib import Path

DOCS = Path(__file__).resolve().parents[1] / "docs"


def main() -> None:
    from mechsim.benchmarks.bench import BenchConfig, report_lines, run_bench, write

    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--out", type=Path, default=Path("results") / "bench")
    args = parser.parse_args()
    result = run_bench(BenchConfig.full(), progress=print)
    write(result, args.out, force=True)
    for name, target in (("work_precision.png", "benchmarks_work_precision.png"),
                         ("work_precision.csv", "benchmarks_work_precision.csv"),
                         ("output_cost.csv", "benchmarks_output_cost.csv")):
        shutil.copyfile(args.out / name, DOCS / target)
    print("\n".join(report_lines(result)))
    print(json.dumps({k: result.summary[k] for k in ("ratios_at_equal_error_cpu_time", "per_call_residual_cost")},
                     indent=1, default=str))


if __name__ == "__main__":
    main()
