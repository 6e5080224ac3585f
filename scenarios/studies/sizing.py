"""Sizing (`mechsim size`, `mechsim.size`): the best design within bounds and limits, driven by exact gradients.

A bounded, constrained optimisation over scenario values (`--vary section.key=LOW:HIGH`), minimising one headline
quantity of the run or one of the varied values themselves, subject to limits on headline quantities
(`--subject-to "QUANTITY <= VALUE"`). Every evaluation is one run and its forward sensitivities
(`scenarios/studies/sensitivity.py`, docs/sensitivity.md), so the optimiser gets the objective and the constraints with
their exact gradients from one solve. The optimiser is scipy's SLSQP (docs/sensitivity.md, "Sizing", says why,
with the measurements against trust-constr).

The problem is solved in normalised values u = (x - low) / (high - low) in [0, 1], the objective divided by its
size at the start and each limit written as (limit - q) / |limit| >= 0, so that one tolerance serves every
value and quantity; the optimiser aims at FEASIBLE inside each limit, so that an active limit holds strictly. Peak quantities are limited and minimised by their magnitude (a contact force limit holds
for either flank). The multipliers at the optimum follow from the KKT conditions on the active set (non-negative
least squares on the gradients), reported as shadow prices: the change of the optimal objective per unit change
of each active limit or bound (Nocedal & Wright, "Numerical Optimization", 2nd ed., Theorem 12.1 and eq. 12.34).

The request is parsed in `sizing_spec.py`; the design's own run is read in `sizing_check.py`.
"""
from __future__ import annotations

import time
from dataclasses import dataclass, field
from typing import Callable

import numpy as np
import pandas as pd

from mechsim.mechanisms import MECHANISMS
from mechsim.scenarios.keys import lookup
from mechsim.scenarios.studies.sizing_check import design_run
from mechsim.scenarios.studies.sizing_spec import SLOTS, Bound, Limit, parse_bound, parse_limit, set_list_entries
from mechsim.scenarios.units import ScenarioError

#: the optimisers offered; SLSQP is the default (docs/sensitivity.md, "Sizing": measured against trust-constr)
METHODS = ("slsqp", "trust-constr")
#: a design's largest constraint violation, relative to the limit, that still counts as feasible
FEASIBLE = 1e-8
#: a constraint (scaled as (limit - q) / |limit|) or a normalised bound this close is active at the optimum
ACTIVE = 1e-6
#: SLSQP stops where this many consecutive iterations each changed the normalised objective by less than its
#: tolerance at a feasible design (`_settling`): the classic SLSQP test (Kraft 1988), which scipy's SLSQP since 1.16
#: no longer ends on where the runs' values carry integration noise (it cycled in its line search: 43 iterations and
#: 62 runs on docs/sensitivity.md's first sizing, where scipy 1.15 stopped after 7 iterations and 9 runs)
SETTLED = 2
#: the slot count is enumerated over at most this many whole values
MAX_SLOT_CHOICES = 12
#: a limit the design's own run breaks is tightened and the sizing solved again at most this many times
MAX_RESOLVES = 3
#: the part of the excess added to it when a limit is tightened (`tightening`)
EXCESS_MARGIN = 0.1
#: Newton steps onto the limits at most, where the optimiser ends just outside them (`_restore`)
RESTORE_STEPS = 3


class SizingFailed(RuntimeError):
    """The optimiser stopped without a feasible optimum; `.result` holds what ran (the convergence history)."""

    def __init__(self, message: str, result: "SizingResult | None" = None):
        super().__init__(message)
        self.result = result


@dataclass
class Evaluation:
    """One design: the quantities (peaks as magnitudes) and their gradients per SI unit of each varied value."""

    x: np.ndarray
    values: dict
    grads: dict
    warnings: list
    wall: float
    #: the quantities' own derivatives where `grads` holds a trend (a cycle-averaged peak's), else `grads`
    local_grads: dict | None = None


@dataclass
class SizingResult:
    """What `size` found: the design (a loaded Scenario that runs), its values, the quantities there, the
    convergence history (one row per optimiser iteration), the constraint activity and shadow prices."""

    design: object
    values: dict
    objective: str
    objective_value: float
    constraints: list
    bounds: list
    history: pd.DataFrame
    summary: dict
    success: bool = True
    message: str = ""
    choices: list = field(default_factory=list)
    problem: object = None

    def __repr__(self) -> str:
        state = "optimum" if self.success else f"not converged: {self.message}"
        lines = [f"<mechsim SizingResult {self.summary.get('scenario', '?')}: minimise {self.objective} = "
                 f"{self.objective_value:.6g} ({state}; {len(self.history)} iterations)"]
        units = {d["key"]: d.get("unit", "") for d in self.summary.get("design", [])}
        lines += [f"  {key} = {value:.6g} {units.get(key, '')}".rstrip() for key, value in self.values.items()]
        lines += [f"  {c['constraint']}: {c['value']:.6g}{' (active)' if c.get('active') else ''}"
                  for c in self.constraints]
        return "\n".join(lines) + ">"

    def design_toml(self) -> str:
        from mechsim.scenarios.output.writer import resolved_scenario_toml
        return resolved_scenario_toml(self.design.si)

    def save(self, folder, force: bool = False, progress=None):
        """design.toml (the chosen design, a scenario `mechsim run` accepts), convergence.csv, convergence.png and
        summary.json, atomically. Without a feasible optimum, everything but design.toml (what ran). progress: as a
        run's save takes it (the CLI passes one to every result); a sizing's files are few and not reported."""
        import json
        from pathlib import Path

        from mechsim.scenarios.output.atomic import atomic_folder, json_default
        from mechsim.scenarios.output.csv import write_csv
        from mechsim.scenarios.output.plots import save as save_figure
        folder = Path(folder)
        with atomic_folder(folder, force) as tmp:
            if self.success:
                (tmp / "design.toml").write_text(self.design_toml())
            write_csv(self.history, tmp / "convergence.csv")
            save_figure(convergence_figure(self), tmp / "convergence.png")
            (tmp / "summary.json").write_text(json.dumps({"sizing": self.summary}, indent=2, default=json_default))
        return folder


class Problem:
    """The sizing problem in normalised values u in [0, 1]: objective, constraints and gradients, each design
    evaluated once (one run and its sensitivities), the history recorded per optimiser iteration."""

    def __init__(self, base, bounds: list[Bound], objective: str, limits: list[Limit], fixed: list[str]):
        self.base, self.bounds, self.objective, self.limits, self.fixed = base, bounds, objective, limits, fixed
        self.keys = [b.key for b in bounds]
        self.low = np.array([b.low for b in bounds])
        self.span = np.array([b.high - b.low for b in bounds])
        self.quantities = list(dict.fromkeys(([] if objective in self.keys else [objective])
                                             + [lim.quantity for lim in limits]))
        self.cache: dict[tuple, Evaluation] = {}
        self.rows: list[dict] = []
        self.f_scale = 1.0
        self.evaluations = 0

    def x_of(self, u) -> np.ndarray:
        return self.low + np.clip(np.asarray(u, float), 0.0, 1.0) * self.span

    def scenario_at(self, x):
        """The base scenario with the varied values set to x (SI), validated like any scenario."""
        from mechsim.scenarios.loader import Scenario, apply_overrides, build_mechanism, validate
        from mechsim.scenarios.keys import toml_literal
        overrides = list(self.fixed) + [f"{b.key}={toml_literal(f'{float(v)!r} {b.unit}' if b.unit else float(v))}"
                                        for b, v in zip(self.bounds, x) if "[" not in b.key]
        raw = apply_overrides(self.base.raw, overrides)
        raw = set_list_entries(raw, self.base.si, [(b.key, f"{float(v)!r} {b.unit}") for b, v in zip(self.bounds, x)
                                                   if "[" in b.key])
        si = validate(raw)
        build_mechanism(si)
        return Scenario(si["name"], raw, si, self.base.source)

    def evaluate(self, u) -> Evaluation:
        from mechsim.scenarios.studies.sensitivity import sensitivity
        x = self.x_of(u)
        key = tuple(x.tolist())
        if key in self.cache:
            return self.cache[key]
        wall = time.perf_counter()
        try:
            table = sensitivity(self.scenario_at(x), self.keys, self.quantities) if self.quantities else None
        except ScenarioError as exc:
            raise SizingFailed(f"the design {self.describe(x)} cannot be evaluated: {exc}") from None
        except ValueError as exc:       # SensitivityUnavailable: no derivative at this design
            raise SizingFailed(f"no derivatives at the design {self.describe(x)}: {exc}") from None
        values, grads, local = {}, {}, {}
        for q in self.quantities:
            part = table[table["quantity"] == q]
            if part.empty:
                why = [w for w in table.attrs["warnings"] if w.startswith(q)]
                raise SizingFailed(f"{q} does not exist at the design {self.describe(x)}"
                                   + (f": {why[0]}" if why else ""))
            y = float(part["value"].iloc[0])
            g = np.array([float(part[part["wrt"] == k]["derivative"].iloc[0]) for k in self.keys])
            # a cycle-averaged run's peak after the hour is a sawtooth in the period (`repetition_trend`) and in
            # the turn's events' places among the output rows (`event_row_trend`): its trend
            trend = table.attrs.get("trend", {}).get(q)
            sign = np.sign(y) if q.startswith("peak_") and y != 0 else 1.0   # peaks: magnitudes
            local[q] = sign * g
            if trend is not None:
                g = np.array([trend[k] for k in self.keys])
            values[q], grads[q] = sign * y, sign * g
        if self.objective in self.keys:
            j = self.keys.index(self.objective)
            values[self.objective], grads[self.objective] = float(x[j]), np.eye(len(x))[j]
            local[self.objective] = grads[self.objective]
        ev = Evaluation(x, values, grads, list(table.attrs["warnings"]) if table is not None else [],
                        time.perf_counter() - wall, local)
        self.cache[key] = ev
        self.evaluations += 1
        return ev

    def describe(self, x) -> str:
        return ", ".join(f"{b.key} = {v:.9g} {b.unit}".rstrip() for b, v in zip(self.bounds, x))

    # the scaled functions scipy sees
    def f(self, u) -> float:
        return self.evaluate(u).values[self.objective] / self.f_scale

    def f_grad(self, u) -> np.ndarray:
        return self.evaluate(u).grads[self.objective] * self.span / self.f_scale

    def c(self, u) -> np.ndarray:
        ev = self.evaluate(u)
        return np.array([lim.margin(ev.values[lim.quantity]) for lim in self.limits])

    def c_aimed(self, u) -> np.ndarray:
        """The constraints the optimiser is given: each limit moved inward by the feasibility tolerance FEASIBLE, so
        that an active limit ends inside the limit as given (its run then satisfies it strictly, not only within the
        tolerance; the cost, by the shadow price, is FEASIBLE |limit| of the limit)."""
        return self.c(u) - FEASIBLE

    def c_jac(self, u, local: bool = False) -> np.ndarray:
        """The limits' gradients (the trends where a quantity has one; with `local`, its own derivatives)."""
        ev = self.evaluate(u)
        grads = ev.local_grads if local and ev.local_grads is not None else ev.grads
        rows = [(-1.0 if lim.sense == "<=" else 1.0) * grads[lim.quantity] * self.span / lim.scale
                for lim in self.limits]
        return np.array(rows).reshape(len(self.limits), len(self.keys))

    def violation(self, u) -> float:
        return float(max([0.0] + [-v for v in self.c(u)]))

    def record(self, u) -> None:
        ev = self.evaluate(u)
        row = {"iteration": len(self.rows)}
        row.update({b.column: v for b, v in zip(self.bounds, ev.x)})
        row[f"objective_{self.objective}"] = ev.values[self.objective]
        for lim in self.limits:
            row[lim.quantity] = ev.values[lim.quantity]
        row["max_violation"] = self.violation(u)
        row["evaluations"] = self.evaluations
        self.rows.append(row)


def _kkt(problem: Problem, u) -> tuple[list[dict], list[dict], float]:
    """Constraint and bound activity at u with their multipliers: the non-negative least-squares solution of
    grad f = sum_i lambda_i grad c_i over the active set (the KKT stationarity condition, Nocedal & Wright
    Theorem 12.1), and the relative residual of that condition. Shadow prices are d f* / d limit (eq. 12.34),
    in the objective's unit per the limit's unit."""
    from scipy.optimize import nnls
    g = problem.f_grad(u)
    c, jac = problem.c(u), problem.c_jac(u)
    columns, owners = [], []
    for i, lim in enumerate(problem.limits):
        if c[i] <= ACTIVE:
            columns.append(jac[i])
            owners.append(("limit", i))
    for j in range(len(problem.keys)):
        if u[j] <= ACTIVE:
            columns.append(np.eye(len(u))[j])
            owners.append(("low", j))
        elif u[j] >= 1 - ACTIVE:
            columns.append(-np.eye(len(u))[j])
            owners.append(("high", j))
    lam = np.zeros(0)
    residual = float(np.linalg.norm(g))
    if columns:
        lam, residual = nnls(np.array(columns).T, g)
    size = max(float(np.linalg.norm(g)), 1e-300)
    multipliers = dict(zip(owners, lam))
    ev = problem.evaluate(u)
    limits = []
    for i, lim in enumerate(problem.limits):
        m = multipliers.get(("limit", i))
        price = None if m is None else float(m * problem.f_scale / lim.scale * (-1 if lim.sense == "<=" else 1)) + 0.0
        limits.append({"constraint": lim.text, "quantity": lim.quantity, "value": ev.values[lim.quantity],
                       "limit": lim.value, "margin_relative": float(c[i]), "active": m is not None,
                       "multiplier": None if m is None else float(m), "shadow_price": price})
    bounds = []
    for j, b in enumerate(problem.bounds):
        side = "low" if ("low", j) in multipliers else "high" if ("high", j) in multipliers else None
        m = multipliers.get((side, j)) if side else None
        price = None if m is None else float(m * problem.f_scale / problem.span[j] * (1 if side == "low" else -1)) + 0.0
        bounds.append({"key": b.key, "unit": b.unit, "value": float(ev.x[j]), "low": b.low, "high": b.high,
                       "active": side, "multiplier": None if m is None else float(m), "shadow_price": price})
    return limits, bounds, float(residual) / size


class _Settled(Exception):
    """Raised by `_settling`'s callback to end SLSQP at its last iterate `u` (not StopIteration: scipy before 1.16
    passes that on out of its SLSQP, and after it ends SLSQP with a failure flag); feasible: whether a limit is
    still broken there."""

    def __init__(self, u: np.ndarray, feasible: bool = True):
        super().__init__("settled")
        self.u = u
        self.feasible = feasible


def _settling(problem: Problem, tolerance: float):
    """SLSQP's callback: each iterate recorded (`Problem.record`), and `_Settled` raised once SETTLED consecutive
    iterations each changed the normalised objective by at most `tolerance` at a feasible design, or, where a limit
    stays broken, changed neither the objective nor the largest violation by more than it: the least violation
    SLSQP reaches from this start (internal-geneva-motor's contact temperature held below what the bounds allow
    settled at iteration 15, and SLSQP went on to its iteration limit, 100 iterations and 484 runs, 3 minutes)."""
    seen: list[tuple[float, float]] = []

    def callback(u) -> None:
        problem.record(u)
        seen.append((problem.f(u), problem.violation(u)))
        last = seen[-(SETTLED + 1):]
        if len(last) < SETTLED + 1 or not all(abs(b - a) <= tolerance for (a, _), (b, _) in zip(last, last[1:])):
            return
        if all(v <= FEASIBLE for _, v in last[1:]):
            raise _Settled(np.array(u, dtype=float))
        if all(v > FEASIBLE for _, v in last[1:]) and all(abs(b - a) <= tolerance
                                                           for (_, a), (_, b) in zip(last, last[1:])):
            raise _Settled(np.array(u, dtype=float), feasible=False)
    return callback


def _optimise(problem: Problem, u0: np.ndarray, method: str, tolerance: float, max_iterations: int):
    """Run scipy's optimiser from u0; returns scipy's result (SLSQP's, or where its iterates settled first
    (`_settling`), one made at the last of them)."""
    from scipy import optimize
    problem.record(u0)
    if method == "slsqp":
        cons = [{"type": "ineq", "fun": problem.c_aimed, "jac": problem.c_jac}] if problem.limits else []
        try:
            return optimize.minimize(problem.f, u0, jac=problem.f_grad, method="SLSQP",
                                     bounds=[(0.0, 1.0)] * len(u0), constraints=cons,
                                     callback=_settling(problem, tolerance),
                                     options={"ftol": tolerance, "maxiter": max_iterations})
        except _Settled as done:
            if not done.feasible:
                return optimize.OptimizeResult(
                    x=done.u, success=False, status=4, nit=len(problem.rows) - 1,
                    message=(f"neither the objective nor the largest violation changed by more than the tolerance "
                             f"over {SETTLED} iterations: the least violation it reaches from this start"))
            return optimize.OptimizeResult(
                x=done.u, success=True, status=0, nit=len(problem.rows) - 1,
                message=(f"Optimization terminated successfully (the objective changed by at most the tolerance "
                         f"over {SETTLED} iterations at a feasible design)"))
    cons = [optimize.NonlinearConstraint(problem.c_aimed, 0.0, np.inf, jac=problem.c_jac)] if problem.limits else []
    return optimize.minimize(problem.f, u0, jac=problem.f_grad, method="trust-constr",
                             bounds=optimize.Bounds(np.zeros(len(u0)), np.ones(len(u0))), constraints=cons,
                             callback=lambda xk, state: problem.record(xk),
                             options={"gtol": tolerance, "xtol": tolerance, "maxiter": max_iterations})


def _restore(problem: Problem, u: np.ndarray) -> np.ndarray:
    """u moved onto the limits where the optimiser ends just outside them (by more than FEASIBLE, at most ACTIVE):
    Newton steps, least-norm within the bounds, on the broken and active limits aimed at (`Problem.c_aimed`), with
    the quantities' own derivatives. A cycle-averaged peak is a sawtooth whose teeth have the derivative's slope
    while the optimiser follows its trend (`Problem.evaluate`), so its last step leaves about the slopes' relative
    difference of itself (a few percent) outside; a correction that small stays on its tooth. At most
    RESTORE_STEPS runs; the result is judged as the optimiser's own (`_solve`)."""
    for _ in range(RESTORE_STEPS):
        violation = problem.violation(u)
        if not FEASIBLE < violation <= ACTIVE:
            break
        c = problem.c_aimed(u)
        near = c <= ACTIVE
        du = np.linalg.lstsq(problem.c_jac(u, local=True)[near], -c[near], rcond=None)[0]
        u = np.clip(u + du, 0.0, 1.0)
        problem.record(u)
    return u


def size(scenario, vary: list[str], minimize: str, subject_to: list[str] | None = None, *,
         method: str = "slsqp", tolerance: float | None = None, max_iterations: int = 100,
         start: dict | None = None, progress: Callable[[str], None] | None = None,
         check: Callable | None = None, max_resolves: int = MAX_RESOLVES) -> SizingResult:
    """The design within `vary`'s bounds that minimises `minimize` (a headline quantity, or one of the varied
    keys) subject to `subject_to` limits, from a loaded Scenario. Raises ScenarioError on a bad request (before
    anything runs) and SizingFailed when the optimiser finds no feasible optimum, or when the design's own run
    breaks a limit after `max_resolves` tightened re-solves (`verify`), with what ran.

    check: design Scenario -> the run's quantities ({quantity: value or None}, `run_quantities`); default: the
    design's own run (`design_run`). Only a test passes another (to force a discrepancy).

    tolerance: the optimiser's (SLSQP's ftol on the normalised objective; trust-constr's gtol and xtol); default
    10x the scenario's solver.rtol, within [1e-12, 1e-4]: the quantities carry the run's error, and a tolerance
    below it makes the line search chase integration noise."""
    if tolerance is None:
        tolerance = min(max(10 * float(scenario.si["solver"]["rtol"]), 1e-12), 1e-4)
    from mechsim.scenarios import runner
    from mechsim.scenarios.studies.sensitivity import check_request
    if method not in METHODS:
        raise ScenarioError("--method", f"one of {', '.join(METHODS)}, got {method!r}")
    if not 0 < tolerance <= 1e-2:
        raise ScenarioError("--tolerance", f"must be in (0, 0.01), got {tolerance}")
    bounds = [parse_bound(v, scenario.si) for v in vary]
    if not bounds:
        raise ScenarioError("--vary", "name at least one scenario value to size: section.key=LOW:HIGH")
    if len({b.key for b in bounds}) != len(bounds):
        raise ScenarioError("--vary", "a key is named twice")
    limits = [parse_limit(s) for s in (subject_to or [])]
    slots = [b for b in bounds if b.key == SLOTS]
    continuous = [b for b in bounds if b.key != SLOTS]
    if minimize == SLOTS:
        raise ScenarioError("--minimize", "the slot count is enumerated, not minimised: name a quantity or a "
                            "continuous value")
    if minimize.startswith(("mechanism.", "load.", "drive.", "contact.", "initial.")) and minimize not in [
            b.key for b in continuous]:
        raise ScenarioError("--minimize", f"{minimize!r} is a scenario value but not one of the --vary keys")
    if slots:
        low, high = int(slots[0].low), int(slots[0].high)
        if high - low + 1 > MAX_SLOT_CHOICES:
            raise ScenarioError(f"--vary {SLOTS}", f"at most {MAX_SLOT_CHOICES} slot counts are enumerated, "
                                f"got {low}:{high}")
        mtype = scenario.si["mechanism"]["type"]
        if SLOTS not in MECHANISMS[mtype].enumerated_keys:
            raise ScenarioError("--vary", f"{SLOTS} is not enumerated for a '{mtype}' mechanism")
    if not continuous:
        raise ScenarioError("--vary", "name at least one continuous value besides the slot count")
    wall = time.perf_counter()
    choices = [int(n) for n in range(int(slots[0].low), int(slots[0].high) + 1)] if slots else [None]
    results, failures = [], []
    for n in choices:
        fixed = [f"{SLOTS}={n}"] if n is not None else []
        base = _with(scenario, fixed)
        plan = runner.plan(base)
        keys = [b.key for b in continuous]
        check_request(plan, keys, [])
        for q, where in [(minimize, "--minimize")] + [(lim.quantity, "--subject-to") for lim in limits]:
            if q in keys:
                continue
            try:
                check_request(plan, keys, [q])
            except ScenarioError as exc:
                raise ScenarioError(where, exc.problem) from None
        problem = Problem(base, continuous, minimize, limits, fixed)
        try:
            result = _solve(problem, method, tolerance, max_iterations, start, progress, n)
            result.problem = problem
            results.append(result)
        except SizingFailed as exc:
            if n is None:
                raise
            failures.append((n, str(exc)))
    feasible = [r for r in results if r.success]
    if not feasible:
        message = "; ".join(f"{SLOTS} = {n}: {why}" for n, why in failures) or results[0].message
        raise SizingFailed(message, results[0] if results else None)
    best = min(feasible, key=lambda r: r.objective_value)      # the fewest slots among equal objectives
    best = verify(best, method, tolerance, max_iterations, progress, check or design_run, max_resolves)
    best.summary["wall_time_s"] = time.perf_counter() - wall
    if slots:
        best.choices = [{"slots": r.summary["slots"], "objective": r.objective_value, "feasible": r.success}
                        for r in results] + [{"slots": n, "objective": None, "feasible": False, "why": why}
                                             for n, why in failures]
        best.summary["slot_choices"] = best.choices
    return best


def tightening(limit: "Limit", sized: float, run: float, tolerance: float) -> float:
    """How far a limit the design's own run breaks is moved inward before solving again: the excess of the run
    over the limit (or over the sizing's own value, if that was inside the limit) and a margin of
    2 FEASIBLE |limit| + EXCESS_MARGIN x excess. The re-solved design has its sizing quantity at the tightened limit
    to FEASIBLE |limit| (its feasibility tolerance; the run is judged by the same, hence twice it), and its run
    differs from that by the discrepancy of the first design, changed by the move between the designs; that move
    is about the excess over the quantity's gradient, so a discrepancy that is smooth in the design changes by a
    fraction of itself of the order excess/quantity (here < 1e-5): a tenth of the excess bounds it generously and
    costs, by the shadow price, a tenth more of the objective's change. At least 10 x the optimiser's `tolerance`
    (of the scaled constraint, |limit|): SLSQP counts a constraint violated by less than its tolerance as met, so
    a smaller move leaves the re-solve at its start, where the feasibility check then fails."""
    excess = max(run - limit.value, run - sized) if limit.sense == "<=" else max(limit.value - run, sized - run)
    return max(excess + 2 * FEASIBLE * limit.scale + EXCESS_MARGIN * max(excess, 0.0), 10 * tolerance * limit.scale)


def verify(result: SizingResult, method: str, tolerance: float, max_iterations: int, progress, check,
           max_resolves: int) -> SizingResult:
    """Check the design on its own run: each limited quantity the run reports (`run_quantities`) against its
    limit, within the feasibility tolerance FEASIBLE. A limit the run breaks is tightened (`tightening`) and the
    sizing solved again from the design, at most `max_resolves` times; the checks go into summary.json
    `verification`, the history (`solve`, `<quantity>_run`, `<quantity>_limit`) and the printed result. Raises
    SizingFailed (no design.toml) when the run still breaks a limit, or fails."""
    problem = result.problem
    original = list(problem.limits)
    stages, histories = [], []
    for solve in range(max_resolves + 1):
        got = check(result.design)
        checks = []
        for lim, orig in zip(problem.limits, original):
            sized = result.summary["quantities_at_optimum"][lim.quantity]
            run = got.get(lim.quantity)
            entry = {"constraint": orig.text, "quantity": lim.quantity, "limit": orig.value,
                     "limit_solved": lim.value, "sizing_value": sized, "run_value": run}
            if run is None:
                entry.update(checked=False, holds=None,
                             why=got.get("_failure") or "the run does not report this quantity itself")
            else:
                margin = orig.margin(run)
                entry.update(checked=True, margin_relative=margin, holds=margin >= -FEASIBLE,
                             run_minus_sizing=run - sized)
            checks.append(entry)
        h = result.history.copy()
        h.insert(1, "solve", solve)
        for e in checks:
            h[f"{e['quantity']}_limit"] = e["limit_solved"]
            h[f"{e['quantity']}_run"] = np.nan
            h.loc[h.index[-1], f"{e['quantity']}_run"] = np.nan if e["run_value"] is None else e["run_value"]
        histories.append(h)
        broken = [e for e in checks if e["holds"] is False]
        failed_run = got.get("_failure")
        stages.append({"solve": solve, "design": dict(result.values),
                       "run_wall_time_s": got.get("_wall_time_s"), "limits": checks, "run_failure": failed_run})
        if progress:
            progress("checked on its own run: " + ("; ".join(
                f"{e['quantity']} {e['run_value']:.10g}" + (" breaks" if e["holds"] is False else " holds")
                for e in checks if e["checked"]) or "nothing it reports"))
        if not broken and failed_run is None:
            break
        if solve == max_resolves or failed_run is not None:
            what = (f"the design's own run failed ({failed_run})" if failed_run is not None else "; ".join(
                f"the design's own run breaks {e['constraint']}: {e['quantity']} = {e['run_value']:.10g}, "
                f"{abs(e['run_value'] - e['limit']):.3g} beyond it ({-e['margin_relative']:.3g} of the limit)"
                for e in broken))
            result.success = False
            result.message = what + (f" (after {solve} tightened re-solves)" if solve else "")
            _attach(result, stages, histories, original)
            raise SizingFailed(result.message, result)
        limits = []
        for lim, e in zip(problem.limits, checks):
            if e["holds"] is False:
                by = tightening(lim, e["sizing_value"], e["run_value"], tolerance)
                lim = Limit(lim.quantity, lim.sense, lim.value - by if lim.sense == "<=" else lim.value + by)
                e["tightened_to"] = lim.value
            limits.append(lim)
        problem = Problem(problem.base, problem.bounds, problem.objective, limits, problem.fixed)
        start = dict(result.values)
        slots = result.summary["slots"]
        result = _solve(problem, method, tolerance, max_iterations, start, progress, slots)
        result.problem = problem
        if not result.success:
            _attach(result, stages, histories + [result.history.assign(solve=solve + 1)], original)
            raise SizingFailed(f"re-solved with the limits tightened to what the run breaks: {result.message}",
                               result)
    _attach(result, stages, histories, original)
    return result


def _attach(result: SizingResult, stages: list, histories: list, original: list) -> None:
    """The verification stages into the summary and the history (all solves, one table)."""
    last = stages[-1]
    result.summary["verification"] = {
        "on": "the design's own run (mechsim run design.toml): summary.json peaks, the events' index and cycle times",
        "holds": all(e["holds"] is not False for e in last["limits"]) and last["run_failure"] is None,
        "resolves": len(stages) - 1, "limits": last["limits"], "stages": stages,
        "limits_as_given": [lim.text for lim in original]}
    history = pd.concat(histories, ignore_index=True)
    cols = ["iteration", "solve"] + [c for c in history.columns if c not in ("iteration", "solve")]
    result.history = history[cols]


def _with(scenario, overrides: list[str]):
    from mechsim.scenarios.loader import from_raw
    if not overrides:
        return scenario
    return from_raw(scenario.raw, scenario.source, overrides)


def _solve(problem: Problem, method: str, tolerance: float, max_iterations: int, start, progress, slots):
    """One continuous optimisation: start at the scenario's values (clipped into the bounds) or `start`."""
    wall = time.perf_counter()
    x0 = []
    for b in problem.bounds:
        v = (start or {}).get(b.key, lookup(problem.base.si, b.key))
        x0.append(min(max(float(v if v is not None else (b.low + b.high) / 2), b.low), b.high))
    u0 = (np.array(x0) - problem.low) / problem.span
    first = problem.evaluate(u0)
    problem.f_scale = abs(first.values[problem.objective]) or 1.0
    res = _optimise(problem, u0, method, tolerance, max_iterations)
    u = _restore(problem, np.clip(res.x, 0.0, 1.0))
    ev = problem.evaluate(u)
    if problem.rows and not np.allclose([problem.rows[-1][b.column] for b in problem.bounds], ev.x, rtol=0,
                                        atol=0):
        problem.record(u)
    violation = problem.violation(u)
    limits, bounds, kkt = _kkt(problem, u)
    history = pd.DataFrame(problem.rows)
    success = violation <= FEASIBLE and (res.success or kkt <= 1e-6)
    message = str(res.message)
    if violation > FEASIBLE:
        message = (f"no feasible design found: the largest limit violation is {violation:.3g} of its limit "
                   f"({method}: {res.message})")
    elif not success:
        message = f"{method} stopped without convergence: {res.message}"
    design = problem.scenario_at(ev.x)
    design.si["name"] = f"{problem.base.name}-sized"
    design.si["description"] = (f"Sized by mechsim size: minimise {problem.objective} over "
                                f"{', '.join(problem.keys)}" + (f" subject to {'; '.join(l.text for l in problem.limits)}"
                                                                 if problem.limits else ""))
    summary = {
        "scenario": problem.base.name, "method": method, "success": success, "message": message,
        "objective": {"name": problem.objective, "value": ev.values[problem.objective],
                      "start": first.values[problem.objective]},
        "design": [{"key": b.key, "unit": b.unit, "value": float(v), "low": b.low, "high": b.high,
                    "start": float(s)} for b, v, s in zip(problem.bounds, ev.x, x0)],
        "constraints": limits, "bounds": bounds, "kkt_residual_relative": kkt,
        "max_violation_relative": violation, "iterations": int(getattr(res, "nit", len(problem.rows) - 1)),
        "evaluations": problem.evaluations, "tolerance": tolerance, "slots": slots,
        "evaluation_wall_time_s": sum(e.wall for e in problem.cache.values()),
        "solve_wall_time_s": time.perf_counter() - wall,
        "warnings_at_optimum": ev.warnings,
        "quantities_at_optimum": dict(ev.values),
    }
    if method == "trust-constr" and problem.limits:
        summary["trust_constr_multipliers"] = [float(v) for v in np.atleast_1d(res.v[0])]
    if progress:
        progress(f"{method}: {summary['iterations']} iterations, {problem.evaluations} runs, {message}")
    return SizingResult(design=design, values=dict(zip(problem.keys, ev.x.tolist())), objective=problem.objective,
                        objective_value=ev.values[problem.objective], constraints=limits, bounds=bounds,
                        history=history, summary=summary, success=success, message=message)


def convergence_figure(result: SizingResult):
    """Objective, normalised design values and constraint ratios q / limit per iteration."""
    from matplotlib.figure import Figure
    h = result.history
    s = result.summary
    fig = Figure(figsize=(8, 10), constrained_layout=True)
    ax1, ax2, ax3, ax4 = fig.subplots(4, 1, sharex=True, gridspec_kw={"height_ratios": [1, 1, 1, 0.8]})
    it = np.arange(len(h))              # the iterations of every solve in order (a re-solve restarts its count)
    starts = np.flatnonzero(np.diff(h["solve"].to_numpy()) > 0) + 1 if "solve" in h else []
    obj = f"objective_{result.objective}"
    ax1.plot(it, h[obj], "o-", color="k")
    unit = next((d["unit"] for d in s["design"] if d["key"] == result.objective), "")
    ax1.set_ylabel(result.objective + (f" ({unit})" if unit else ""))
    ax1.set_title(f"{s['scenario']}: minimise {result.objective} ({s['method']}; "
                  f"{'converged' if result.success else 'NOT converged'})", fontsize=10, loc="left")
    for d in s["design"]:
        col = f"{d['key']}_{d['unit'].replace('*', '_').replace('/', '_').replace('^', '')}" if d["unit"] else d["key"]
        ax2.plot(it, (h[col] - d["low"]) / (d["high"] - d["low"]), "o-",
                 label=f"{d['key']} [{d['low']:.4g}, {d['high']:.4g}] {d['unit']}")
    ax2.set_ylabel("design value\n(0 = LOW, 1 = HIGH)")
    ax2.set_ylim(-0.05, 1.05)
    ax2.legend(fontsize=8)
    for c in s["constraints"]:
        limit = c["limit"] if c["limit"] != 0 else 1.0
        ax3.plot(it, h[c["quantity"]] / limit, "o-", label=c["constraint"] + (" (active)" if c["active"] else ""))
    ax3.axhline(1.0, color="k", lw=0.8, ls="--")
    ax3.set_ylabel("quantity / limit")
    if s["constraints"]:
        ax3.legend(fontsize=8)
    ax4.semilogy(it, np.maximum(h["max_violation"].to_numpy(float), 1e-16), "o-", color="C3")
    ax4.axhline(FEASIBLE, color="k", lw=0.8, ls="--")
    ax4.set_ylabel("largest violation\n(relative to its limit)")
    for ax in (ax1, ax2, ax3, ax4):
        for k in starts:
            ax.axvline(k - 0.5, color="0.5", lw=0.8, ls=":")
    ax4.set_xlabel("iteration (values below 1e-16 drawn at 1e-16; dashed: feasible"
                   + ("; dotted: re-solve, tightened)" if len(starts) else ")"))
    from matplotlib.ticker import MaxNLocator
    ax4.xaxis.set_major_locator(MaxNLocator(integer=True))     # iterations are counted, not 2.5
    return fig
