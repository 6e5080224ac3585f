"""The contract between the hybrid loop and an integrator: integrate ONE mode, say how the segment ended.

The loop (`dynamics/hybrid.py`) owns everything hybrid: guards that fired, transitions, impacts, consistent
re-initialisation, recoveries, output assembly, statistics and failures. A backend only integrates one smooth
mode from a consistent state (a `Request`) to the first guard crossing, the end time, or a pause of its own
choosing, and returns a `Segment`. Every backend reports the same statistics keys (`dynamics/stats.py`); the
counters of one segment travel in `Segment.counts`.

A backend is a subclass of `Backend` (below): what it must provide, and the optional capabilities with their
defaults (a whole run in one call; naming a failure's cause). Adding a backend is one new module in
`dynamics/backends/` and its line in `REGISTRY`; the loop does not change.
"""
from __future__ import annotations

import importlib
from abc import ABC, abstractmethod
from dataclasses import dataclass, field
from enum import Enum
from typing import TYPE_CHECKING, Callable, ClassVar

import numpy as np

from mechsim.dynamics.result import FailureCode

if TYPE_CHECKING:      # the contract is imported by the settings: no sympy model behind it
    from mechsim.dynamics.model import DerivedModel, ModeFunctions
    from mechsim.dynamics.settings import SolverSettings

#: solver.backend value -> "module:class" of its backend (imported on first use: diffrax pulls in JAX)
REGISTRY = {
    "auto": "mechsim.dynamics.backends.ida_compiled:AutoBackend",
    "ida": "mechsim.dynamics.backends.ida:IdaBackend",
    "ida-compiled": "mechsim.dynamics.backends.ida_compiled:IdaCompiledBackend",
    "diffrax": "mechsim.dynamics.backends.diffrax_backend:DiffraxBackend",
}


class End(str, Enum):
    """How a segment ended."""

    END = "end"          # reached the request's end time
    GUARD = "guard"      # a guard crossed zero in its direction (Segment.fired says which)
    PAUSE = "pause"      # the backend stopped early in the same mode (output chunk, a guard re-armed);
    #                      the loop continues from (t_end, y_end, yp_end)
    FAILED = "failed"    # the integrator gave up (Segment.code, Segment.message)


@dataclass
class Request:
    """One mode to integrate: from the consistent state (t0, y0, yp0) through the output times t_out
    (all > t0, <= t_end; or all < t0, >= t_end, backward in time, where a backend can) to t_end or the first
    guard crossing. States are in the IDA layout of the mode
    (`ModeFunctions.index`: q, v, lam, mu, work, ext); p is the mode's parameter tuple."""

    model: DerivedModel
    mode: str
    mf: ModeFunctions
    p: tuple
    t0: float
    y0: np.ndarray
    yp0: np.ndarray
    t_out: np.ndarray
    t_end: float
    first_step: float = 0.0


#: a first step of this fraction of the time left, where a segment starts without a usable step estimate: a failed
#: segment's restart (`hybrid.recover`: the integrator's own estimate is what failed) and IDA's estimate where it
#: cannot move t (`backends.ida.resolving_first_step`)
FRESH_STEP_FRACTION = 1e-6


@dataclass
class Segment:
    """What a backend returns: rows at the requested output times (IDA layout), the end state, how it ended."""

    t: np.ndarray
    y: np.ndarray
    yp: np.ndarray
    end: End
    t_end: float
    y_end: np.ndarray
    yp_end: np.ndarray
    fired: tuple[int, ...] = ()          # End.GUARD: guards past zero at t_end, the one to handle first
    code: FailureCode | None = None      # End.FAILED: what went wrong
    message: str = ""                    # End.FAILED: the integrator's words, for people
    counts: dict = field(default_factory=dict)   # this segment's increments of the statistics counters
    next_step: float = 0.0               # a first step for the next segment (0: the integrator's estimate)


class Backend(ABC):
    """What the hybrid loop needs of an integrator.

    Required: `name` (the `solver.backend` value), `solver` (a label for the summary), `integrate(request) ->
    Segment`, `hint(code) -> str` (what a user can change after a failure with that code).
    Declared with defaults: `initial_step` (first trial step of a run, 0 = the integrator's own estimate),
    `recoverable` (failure codes after which the loop re-initialises and tries again), `unavailable`
    (statistics it cannot report, with the reason), `notes` (how a reported number is obtained when it is not
    a plain count).
    Optional capabilities:
    - `whole_run(mech, start, t0, t_end, progress) -> Trajectory | None`: the whole run in one call (a compiled
      loop of its own); None as an attribute when the backend has none, None as a result where it does not
      apply to this run. The loop then runs segment by segment.
    - `explain(traj, settings, t_end) -> dict | None`: the trajectory's failure with its cause named where the
      integrator reports only a symptom (a class method: called with the settings, no backend built).
    """

    name: ClassVar[str]
    solver: str
    initial_step: ClassVar[float] = 0.0
    recoverable: ClassVar[frozenset] = frozenset()
    unavailable: dict = {}
    notes: dict = {}
    whole_run: Callable | None = None

    @abstractmethod
    def integrate(self, request: Request) -> Segment:
        """One mode from the request's consistent state to the first guard crossing, its end time or a pause."""

    @abstractmethod
    def hint(self, code: FailureCode) -> str:
        """What a user can change after a failure with this code."""

    @classmethod
    def explain(cls, traj, settings: SolverSettings, t_end: float) -> dict | None:
        """The trajectory's failure dict, with its cause named where the backend can (default: as it is)."""
        return traj.failure


def backend_class(name: str) -> type[Backend]:
    """The backend class registered under `name` (its module imported on first use)."""
    try:
        module, cls = REGISTRY[name].split(":")
    except KeyError:
        raise ValueError(f"solver.backend must be one of {', '.join(REGISTRY)}; got {name!r}") from None
    return getattr(importlib.import_module(module), cls)


def backend_for(name: str, settings, **options) -> Backend:
    """The backend registered under `name`, built for these solver settings."""
    return backend_class(name)(settings, **options)
