"""What a run returns: tables, summary, the resolved scenario; failure as a value that keeps what ran."""
from __future__ import annotations

from dataclasses import dataclass, field
from enum import Enum
from typing import TYPE_CHECKING

if TYPE_CHECKING:          # (the tables' type only: a scenario's loading and checking import no pandas)
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


class FailureCode(str, Enum):
    """What stopped a run, as a value to switch on (the reason text is for people, not for code).

    Every backend and the hybrid loop report one of these; `kind` says whether it is the solver's trouble or
    the physics' answer (a physical stop is a result, not an error, though the run still exits 3).
    """

    INTEGRATOR_FAILED = "integrator_failed"        # the integrator gave up (error or Newton test, min step)
    MAX_STEPS = "max_steps"                        # the step limit (solver.max_steps) was reached
    NON_FINITE = "non_finite"                      # the state became NaN or infinite
    STEPPED_OVER = "stepped_over"                  # with events off, a guard crossed between samples
    CHATTERING = "chattering"                      # a guard keeps firing without time advancing
    REINITIALISATION_FAILED = "reinitialisation_failed"   # no consistent state after a transition
    INVARIANT_VIOLATED = "invariant_violated"      # a physical invariant broke on an output row
    PHYSICAL_STOP = "physical_stop"                # stall, reversal, dead centre: the mechanism cannot go on
    MODEL_INVALID = "model_invalid"                # a validity condition of the model failed (output.on_invalid)

    @property
    def kind(self) -> str:
        return "physics" if self in (FailureCode.PHYSICAL_STOP, FailureCode.MODEL_INVALID) else "solver"


@dataclass(frozen=True)
class Failure:
    """Why a run stopped early: when (time), where (mode, crank angle), why, and a hint; `code` to switch on."""

    time: float
    mode: str
    reason: str
    hint: str = ""
    kind: str = "solver"   # "solver" (integrator failed) or "physics" (stall, reversal, ...)
    code: FailureCode = FailureCode.INTEGRATOR_FAILED

    def message(self) -> str:
        text = f"stopped at t = {self.time:.6g} s in mode '{self.mode}': {self.reason}"
        return text + (f" (hint: {self.hint})" if self.hint else "")


class SolverFailure(RuntimeError):
    """Raised by callers that want an exception; carries the partial Result."""

    def __init__(self, result: Result):
        super().__init__(result.failure.message() if result.failure else "solver failure")
        self.result = result
