"""Solver settings: a policy object rather than flags scattered through the code."""
from __future__ import annotations

from dataclasses import dataclass, fields

from mechsim.dynamics.backend import REGISTRY
from mechsim.dynamics.formulation import FORMULATIONS

BACKENDS = tuple(REGISTRY)
METHODS = ("auto", "dae", "closed-form")


@dataclass(frozen=True)
class SolverSettings:
    """How to integrate.

    method: "auto" lets the runner skip the DAE where a closed form exists (prescribed speed);
        "dae" always integrates; "closed-form" insists on the closed form.
    multiplier_atol: IDA's absolute tolerance on multipliers. scikit-sundae cannot call IDASetSuppressAlg,
        so a large value keeps the algebraic variables out of the error test (docs/architecture.md, docs/theory.md §K4).
        None picks 1e6 for index2/index3 and 1e3 for index1.
    jacobian: "exact" (generated from the symbolic model, the default) or "fd" (IDA's internal finite
        differences, only when asked for).
    backend: "auto" (the default) runs `ida-compiled` where the model's compiled callbacks are ready and `ida`
        otherwise (dynamics/backends/ida_compiled.py AutoBackend); "ida", "ida-compiled" or "diffrax" insist.
    events: False disables root-finding of guards (only for the stability study: mode changes are then
        stepped over and detected afterwards as a failure).
    """

    backend: str = "auto"
    formulation: str = "index2"
    method: str = "auto"
    rtol: float = 1e-8
    atol: float = 1e-10
    multiplier_atol: float | None = None
    baumgarte_alpha: float = 10.0
    baumgarte_beta: float = 10.0
    max_steps: int = 20000
    events: bool = True
    diffrax_solver: str = "Tsit5"
    jacobian: str = "exact"
    #: diffrax: the whole run as one compiled call where possible (docs/diffrax.md 'The compiled run')
    diffrax_compiled_run: bool = True

    def __post_init__(self) -> None:
        if self.backend not in BACKENDS:
            raise ValueError(f"solver.backend must be one of {BACKENDS}, got {self.backend!r}")
        if self.formulation not in FORMULATIONS:
            raise ValueError(f"solver.formulation must be one of {FORMULATIONS}, got {self.formulation!r}")
        if self.method not in METHODS:
            raise ValueError(f"solver.method must be one of {METHODS}, got {self.method!r}")
        if self.jacobian not in ("exact", "fd"):
            raise ValueError(f"solver.jacobian must be 'exact' or 'fd', got {self.jacobian!r}")
        if not (0 < self.rtol < 1):
            raise ValueError(f"solver.rtol must be in (0, 1), got {self.rtol}")
        if not self.atol > 0:
            raise ValueError(f"solver.atol must be positive, got {self.atol}")

    def unused(self) -> list[tuple[str, str]]:
        """(key, why) of each setting given another value than its default that this backend and formulation do not
        read, so that it changes nothing in a DAE run (docs/limits.md, "Values"): diffrax's own keys on IDA, the
        Baumgarte gains on IDA's index-2 and index-3 forms, and on diffrax, which integrates the index-1 ODE with
        those gains, the formulation and IDA's own keys."""
        diffrax = self.backend == "diffrax"
        readers = {
            "diffrax_solver": (not diffrax, "it chooses the diffrax backend's solver"),
            "diffrax_compiled_run": (not diffrax, "it is the diffrax backend's"),
            "baumgarte_alpha": (not diffrax and self.formulation != "index1",
                                "the Baumgarte terms are the index-1 form's and diffrax's"),
            "baumgarte_beta": (not diffrax and self.formulation != "index1",
                               "the Baumgarte terms are the index-1 form's and diffrax's"),
            "formulation": (diffrax, "diffrax integrates the index-1 ODE with the Baumgarte terms"),
            "multiplier_atol": (diffrax, "it is IDA's tolerance on the constraint forces"),
            "jacobian": (diffrax, "it is IDA's Jacobian"),
        }
        defaults = {f.name: f.default for f in fields(self)}
        return [(key, why) for key, (ignored, why) in readers.items()
                if ignored and getattr(self, key) != defaults[key]]

    @property
    def lam_atol(self) -> float:
        if self.multiplier_atol is not None:
            return self.multiplier_atol
        return 1e3 if self.formulation == "index1" else 1e6
