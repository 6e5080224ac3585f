"""How large a run's tables are: estimated from the scenario before it runs, measured from the table before it is
written, so that a long run at a fine output_step is announced while there is still time to change it.

Before the run only the number of rows is known (duration / output_step, as the runner's output grid); the
columns and the bytes of a value are taken at the high end of what the mechanisms write (`ESTIMATED_COLUMNS`,
`CSV_BYTES_PER_VALUE`, `PARQUET_BYTES_PER_VALUE`; docs/api.md "Output size" has the measured spread), so the
estimate is an upper one. After the run, `table_bytes` formats an even sample of the rows as the writer does and
scales it: the CSV's size to within a few per cent. Above `LARGE_OUTPUT_BYTES` the console says so before the run and
suggests a coarser output_step or Parquet only; [output] csv = "auto" then leaves timeseries.csv out.
"""
from __future__ import annotations

import io
import math
from dataclasses import dataclass

#: columns a run's table has at most in practice (the measured counts: docs/api.md "Output size")
ESTIMATED_COLUMNS = 40
#: bytes of one value in timeseries.csv at the high end (shortest round-trip floats and a comma)
CSV_BYTES_PER_VALUE = 18
#: bytes of one value in timeseries.parquet at the high end
PARQUET_BYTES_PER_VALUE = 8
#: above this many bytes of tables (CSV and Parquet together) a run is announced as large; csv = "auto" then
#: writes Parquet only
LARGE_OUTPUT_BYTES = 512 * 2**20
#: rows sampled to measure a table's CSV size (`table_bytes`)
SAMPLE_ROWS = 500


@dataclass(frozen=True)
class OutputSize:
    """A run's tables: rows, columns, and the bytes of timeseries.csv and timeseries.parquet (`measured`: from
    the table itself, else estimated from the scenario)."""

    rows: int
    columns: int
    csv_bytes: float
    parquet_bytes: float
    measured: bool

    @property
    def total_bytes(self) -> float:
        return self.csv_bytes + self.parquet_bytes

    @property
    def large(self) -> bool:
        return self.total_bytes > LARGE_OUTPUT_BYTES


def output_rows(duration: float, step: float) -> int:
    """Rows of the output grid 0, step, 2 step, ... and the end (thermal/cycle.py `output_times`)."""
    n = int(math.floor(duration / step + 1e-9))
    return n + 1 + (0 if abs(n * step - duration) <= 1e-12 else 1)


def estimate(si: dict) -> OutputSize:
    """The tables of a validated scenario (SI) before it runs: at most this large (a cycle-averaged thermal run
    keeps only its mechanics window, fewer rows)."""
    rows = output_rows(si["duration"], si["output_step"])
    return OutputSize(rows, ESTIMATED_COLUMNS, rows * ESTIMATED_COLUMNS * CSV_BYTES_PER_VALUE,
                      rows * ESTIMATED_COLUMNS * PARQUET_BYTES_PER_VALUE, measured=False)


def table_bytes(table) -> OutputSize:
    """The tables of a finished run, measured: an even sample of `SAMPLE_ROWS` rows written as CSV (the writer's
    own format) and scaled to all rows; Parquet at `PARQUET_BYTES_PER_VALUE`."""
    from mechsim.scenarios.output.csv import write_csv
    rows, columns = table.shape
    if rows == 0:
        return OutputSize(0, columns, 0.0, 0.0, measured=True)
    sample = table.iloc[:: max(rows // SAMPLE_ROWS, 1)]
    buffer = io.BytesIO()
    write_csv(sample, buffer)
    header = len(",".join(f'"{c}"' for c in table.columns)) + 1
    per_row = (len(buffer.getvalue()) - header) / len(sample)
    return OutputSize(rows, columns, header + per_row * rows, rows * columns * PARQUET_BYTES_PER_VALUE, measured=True)


def csv_wanted(setting: str, size: OutputSize) -> bool:
    """Whether timeseries.csv is written: [output] csv = "always", "never", or "auto" (below LARGE_OUTPUT_BYTES)."""
    return setting == "always" or (setting == "auto" and not size.large)


def _bytes(n: float) -> str:
    for unit, scale in (("GB", 1e9), ("MB", 1e6), ("kB", 1e3)):
        if n >= scale:
            return f"{n / scale:.3g} {unit}"
    return f"{n:.0f} B"


def coarser_step(si: dict, size: OutputSize) -> float:
    """An output_step (1, 2 or 5 times a power of ten) at which the same run's tables fall below
    LARGE_OUTPUT_BYTES."""
    wanted = si["output_step"] * size.total_bytes / (0.5 * LARGE_OUTPUT_BYTES)
    decade = 10.0 ** math.floor(math.log10(wanted))
    return next(m * decade for m in (1, 2, 5, 10) if m * decade >= wanted)


def large_note(si: dict, size: OutputSize) -> str | None:
    """The console's note before a large run (None below LARGE_OUTPUT_BYTES): its size, and what writes less."""
    if not size.large:
        return None
    step = coarser_step(si, size)
    rows = output_rows(si["duration"], step)
    csv = si.get("output", {}).get("csv", "always")
    then = {"always": "; or Parquet only: [output] csv = \"auto\" (or \"never\")",
            "auto": f"; [output] csv = \"auto\" leaves timeseries.csv out if the tables, measured after the run, "
                    f"pass {_bytes(LARGE_OUTPUT_BYTES)}",
            "never": ""}[csv]
    return (f"note: a large output: {size.rows:,} rows x about {size.columns} columns, up to about "
            f"{_bytes(size.csv_bytes)} of timeseries.csv and {_bytes(size.parquet_bytes)} of timeseries.parquet "
            f"(at output_step = {si['output_step']:g} s); output_step = {step:g} s writes {rows:,} rows{then}")


def skipped_note(size: OutputSize) -> str:
    """The console's note where csv = "auto" left timeseries.csv out."""
    return (f"note: timeseries.csv not written ({_bytes(size.csv_bytes)} as CSV, [output] csv = \"auto\"); "
            "timeseries.parquet holds the same table (pandas.read_parquet, mechsim.open)")
