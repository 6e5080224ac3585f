"""Solver statistics with the same keys for every backend, so runs compare field by field.

A backend that cannot give a number reports None for it and says why in `notes` (never a made-up zero).
"""
from __future__ import annotations

#: every backend's statistics have exactly these keys (counts summed over all segments of a run; times in s)
STAT_KEYS = ("backend", "solver", "segments", "steps", "accepted_steps", "rejected_steps", "residual_evaluations",
             "jacobian_evaluations", "events", "restarts", "recoveries", "compilations", "derive_time_s",
             "compile_time_s", "compile_cpu_time_s", "solve_time_s", "notes")


def new_stats(backend: str, solver: str, derive_time_s: float, unavailable: dict[str, str] | None = None) -> dict:
    """Zeroed statistics for one run; `unavailable` maps counters the backend cannot report to the reason."""
    stats = {key: 0 for key in STAT_KEYS}
    stats.update(backend=backend, solver=solver, derive_time_s=derive_time_s, compile_time_s=0.0,
                 compile_cpu_time_s=0.0, solve_time_s=0.0, notes={})
    for key, why in (unavailable or {}).items():
        stats[key] = None
        stats["notes"][key] = why
    return stats
