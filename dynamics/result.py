"""What a run returns: tables, summary, the resolved scenario; failure as a value that keeps what ran."""
from __future__ import annotations

from dataclasses import dataclass, field

import pandas as pd


@dataclass
class Result:
    """timeseries: one row per output instant (SI, `<quantity>_<unit>` columns, a `mode` column);
    events: one row per transition; summary: peaks, statistics, model choices; scenario: resolved (SI)."""

    timeseries: pd.DataFrame
    events: pd.DataFrame
    summary: dict
    scenario: dict = field(default_factory=dict)
    failure: "Failure | None" = None
    extra_tables: dict[str, pd.DataFrame] = field(default_factory=dict)

    @property
    def success(self) -> bool:
        return self.failure is None


@dataclass(frozen=True)
class Failure:
    """Why a run stopped early: when (time), where (mode, crank angle), why, and a hint."""

    time: float
    mode: str
    reason: str
    hint: str = ""
    kind: str = "solver"   # "solver" (integrator failed) or "physics" (stall, reversal, ...)

    def message(self) -> str:
        text = f"stopped at t = {self.time:.6g} s in mode '{self.mode}': {self.reason}"
        return text + (f" (hint: {self.hint})" if self.hint else "")


class SolverFailure(RuntimeError):
    """Raised by callers that want an exception; carries the partial Result."""

    def __init__(self, result: Result):
        super().__init__(result.failure.message() if result.failure else "solver failure")
        self.result = result
