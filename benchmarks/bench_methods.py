"""The integrators `mechsim bench` compares, each behind one small interface (set up cold, run warm, count).

- mechsim's IDA backend in each formulation (`ida-index1`, `ida-index2`, `ida-index3`);
- mechsim's diffrax backend, explicit and implicit (`diffrax-Tsit5`, `diffrax-Dopri8`, `diffrax-Kvaerno5`),
  when `dynamics.backends.diffrax_backend` is importable;
- the peers a user would pick instead, on the same equations in the same process (for the Geneva only: they
  are written for its equations, `Method.mechanisms`; other mechanisms bench mechsim's methods alone): scipy `solve_ivp`
  (`scipy-Radau`, `scipy-BDF`, `scipy-LSODA`, `scipy-DOP853`) on the reduced-coordinate ODE of
  `mechanisms.geneva.reduced`, and CasADi's IDAS on the index-1 equations with the algebraic rows solved by
  CasADi, driven the way a careful CasADi user writes it (`casadi-idas`, see `bench_casadi`); diffsol (pydiffsol)
  on the crank angle per mode in minimal coordinates, DiffSL compiled by LLVM (`diffsol-tsit45`, `diffsol-bdf`,
  see `bench_diffsol`; the external Geneva without friction).

`setup` does the cold work once (derivation and code generation, compilation, integrator construction) and
says how often it is paid (`per process` or `per tolerance`); `run` is what is timed; `count` repeats a run
with counters attached (steps, rejected steps) that would disturb the timing.
"""
from __future__ import annotations

import importlib.util
import time
from contextlib import contextmanager
from dataclasses import dataclass, field

import numpy as np

from mechsim.dynamics.drives import Drive
from mechsim.dynamics.settings import SolverSettings
from mechsim.mechanisms.base import Mechanism

NAN = float("nan")


@dataclass
class Problem:
    """The benchmark problem: a torque/motor-driven mechanism from a scenario, on a fixed output grid."""

    scenario: str
    mech: Mechanism
    drive: Drive
    angle0: float
    speed0: float
    duration: float
    dt_out: float
    baumgarte: tuple[float, float] = (10.0, 10.0)
    ext: object = None            # thermal states in the same DAE (`thermal.coupling.ThermalExtension`)
    ext_initial: object = None

    @property
    def grid(self) -> np.ndarray:
        n = int(np.floor(self.duration / self.dt_out + 1e-9))
        return self.dt_out * np.arange(n + 1)


@dataclass
class Run:
    """Drive-coordinate angle at the output times a run reached, its statistics, and why it stopped early
    (or None)."""

    t: np.ndarray
    angle: np.ndarray
    stats: dict = field(default_factory=dict)
    failure: str | None = None


@dataclass
class Method:
    name: str
    family: str            # "mechsim IDA", "mechsim diffrax", "scipy", "CasADi"
    kind: str              # "explicit", "implicit", "DAE"
    equations: str         # what it integrates
    requires: str | None = None
    #: names (`Mechanism.name`) of the mechanisms whose equations this method is written for; () = any
    mechanisms: tuple[str, ...] = ()

    def available(self) -> bool:
        return self.requires is None or importlib.util.find_spec(self.requires) is not None

    def supports(self, mech: Mechanism) -> bool:
        return not self.mechanisms or mech.name in self.mechanisms

    def supports_problem(self, problem: "Problem") -> bool:
        """Whether this method integrates the whole problem (the mechanism, and its thermal states if any; the
        peers, written for the Geneva, a constant load)."""
        if self.mechanisms:
            from mechsim.benchmarks.bench_casadi import constant_load
            if not constant_load(problem.mech) or problem.drive.has_duty:
                return False
        return self.supports(problem.mech) and (problem.ext is None or self.thermal)

    #: integrates thermal states alongside (False: mechanics only)
    thermal = True

    def skip_reason(self, problem: "Problem") -> str:
        """Why the method does not run on `problem` (when `supports_problem` says so)."""
        if not self.supports(problem.mech):
            return f"written for {', '.join(self.mechanisms)} only (not {problem.mech.name})"
        from mechsim.benchmarks.bench_casadi import constant_load
        if not constant_load(problem.mech) or problem.drive.has_duty:
            return "written for a constant wheel torque and a drive always on (no station torques, profile or duty)"
        return "integrates no thermal states"

    def setup(self, problem: Problem, rtol: float, atol: float):
        """(handle, setup time in s, 'per process' | 'per tolerance')."""
        return None, 0.0, "none"

    def run(self, handle, problem: Problem, rtol: float, atol: float) -> Run:
        raise NotImplementedError

    def count(self, handle, problem: Problem, rtol: float, atol: float) -> dict:
        return {}


# -- mechsim on IDA ------------------------------------------------------------------------------------------
def _trajectory_angle(traj, coordinate: int) -> tuple[np.ndarray, np.ndarray]:
    """Drive-coordinate angle at the output rows of a Trajectory (no table building: that is timed apart)."""
    t = np.concatenate([p.t for p in traj.pieces])
    ix = traj.model.modes[traj.pieces[0].mode].index["q"]
    a = np.concatenate([p.coordinates(ix)[:, coordinate] for p in traj.pieces])
    keep = np.r_[t[1:] != t[:-1], True]       # times are non-decreasing: the last row of each instant
    return t[keep], a[keep]


def _failure_text(f: dict | None) -> str | None:
    if not f:
        return None
    return f"t = {f['time']:.6g} s ({f['mode']}): {f['reason']}"


@dataclass
class IdaMethod(Method):
    formulation: str = "index2"
    backend: str = "ida"

    def settings(self, problem: Problem, rtol: float, atol: float) -> SolverSettings:
        a, b = problem.baumgarte
        return SolverSettings(backend=self.backend, formulation=self.formulation, rtol=rtol, atol=atol,
                              baumgarte_alpha=a, baumgarte_beta=b, method="dae")

    def setup(self, problem, rtol, atol):
        from mechsim.dynamics.model import derive
        wall = time.perf_counter()
        derive(problem.mech, self.formulation, False, problem.ext)     # the first call in a process derives
        if self.backend != "ida":          # and the compiled backend compiles (or loads) its callbacks
            self.run(None, problem, rtol, atol)
        return None, time.perf_counter() - wall, "per process (first call)"

    def run(self, handle, problem, rtol, atol):
        from mechsim.dynamics.hybrid import simulate
        traj = simulate(problem.mech, problem.drive, self.settings(problem, rtol, atol), problem.duration,
                        problem.dt_out, problem.angle0, problem.speed0, ext=problem.ext,
                        ext_initial=problem.ext_initial)
        t, a = _trajectory_angle(traj, problem.mech.drive_coordinate)
        s = traj.stats
        return Run(t, a, {"residual_evaluations": s["residual_evaluations"],
                          "jacobian_evaluations": s["jacobian_evaluations"], "events": s["events"],
                          "segments": s["segments"]}, _failure_text(traj.failure))

    def count(self, handle, problem, rtol, atol):
        if self.backend != "ida":          # IDA's own counters, read by the backend itself
            from mechsim.dynamics.hybrid import simulate
            s = simulate(problem.mech, problem.drive, self.settings(problem, rtol, atol), problem.duration,
                         problem.dt_out, problem.angle0, problem.speed0, ext=problem.ext,
                         ext_initial=problem.ext_initial).stats
            return {"steps": s["accepted_steps"], "rejected_steps": s["rejected_steps"]}
        from mechsim.benchmarks.ida_counters import counting
        with counting() as totals:
            self.run(handle, problem, rtol, atol)
        return {"steps": totals["steps"], "rejected_steps": totals["rejected_steps"],
                "convergence_failures": totals["convergence_failures"],
                "guard_evaluations": totals["guard_evaluations"]}


# -- mechsim on diffrax --------------------------------------------------------------------------------------
@dataclass
class DiffraxMethod(Method):
    solver: str = "Tsit5"
    max_steps: int = 200000

    def settings(self, problem, rtol, atol):
        a, b = problem.baumgarte
        return SolverSettings(backend="diffrax", formulation="index1", rtol=rtol, atol=atol, baumgarte_alpha=a,
                              baumgarte_beta=b, method="dae", diffrax_solver=self.solver, max_steps=self.max_steps)

    def _simulate(self, problem, rtol, atol):
        from mechsim.dynamics.hybrid import simulate
        return simulate(problem.mech, problem.drive, self.settings(problem, rtol, atol), problem.duration,
                        problem.dt_out, problem.angle0, problem.speed0, ext=problem.ext,
                        ext_initial=problem.ext_initial)

    def setup(self, problem, rtol, atol):
        wall = time.perf_counter()
        traj = self._simulate(problem, rtol, atol)        # compiles the per-mode solves at first use
        from mechsim.dynamics.backends.diffrax_common import IMPLICIT
        if self.solver in IMPLICIT:   # the stage root finder takes the tolerances as constants
            return traj, traj.stats.get("compile_time_s", 0.0) or (time.perf_counter() - wall), "per tolerance"
        # explicit solvers: the tolerances are traced arguments, one compilation per model structure
        return traj, traj.stats.get("compile_time_s", 0.0), "per process (first call)"

    def run(self, handle, problem, rtol, atol):
        traj = self._simulate(problem, rtol, atol)
        t, a = _trajectory_angle(traj, problem.mech.drive_coordinate)
        s = traj.stats
        return Run(t, a, {"steps": s.get("steps", NAN), "rejected_steps": s.get("rejected_steps", NAN),
                          "residual_evaluations": _num(s.get("residual_evaluations")),
                          "jacobian_evaluations": _num(s.get("jacobian_evaluations")),
                          "events": s["events"], "segments": s["segments"]}, _failure_text(traj.failure))


def _num(x) -> float:
    return NAN if x is None else float(x)


# -- scipy solve_ivp on the reduced-coordinate ODE -----------------------------------------------------------
def _counting_class(name: str, totals: dict):
    """The scipy OdeSolver `name` with accepted steps (and, for Runge-Kutta, attempts) counted."""
    import scipy.integrate as si
    from scipy.integrate._ivp.rk import RungeKutta

    base = getattr(si, name)

    class Counted(base):
        def _step_impl(self):
            ok, msg = super()._step_impl()
            totals["steps"] += int(ok)
            return ok, msg

    if issubclass(base, RungeKutta):          # explicit Runge-Kutta: one error estimate per attempt
        def _estimate_error_norm(self, *args):
            totals["attempts"] += 1
            return base._estimate_error_norm(self, *args)
        Counted._estimate_error_norm = _estimate_error_norm
    Counted.__name__ = name
    return Counted


@dataclass
class ScipyMethod(Method):
    solver: str = "DOP853"
    thermal = False        # the reduced ODE has no thermal states

    def _integrate(self, problem, rtol, atol, method, stats):
        import mechsim.mechanisms.geneva.reduced as red
        dv = problem.drive.parameter_values(problem.angle0)
        grid = problem.grid
        try:
            theta, _ = red.integrate(problem.mech, dv["drive_T0"], dv["drive_slope"], problem.angle0,
                                     problem.speed0, grid, rtol=rtol, atol=atol, method=method, stats=stats)
        except RuntimeError as exc:
            return Run(grid[:1], np.array([problem.angle0]), stats, f"solve_ivp {self.solver} failed: {exc}")
        ok = np.isfinite(theta)
        failure = None if ok.all() else f"solve_ivp {self.solver} stopped at t = {grid[ok][-1]:.6g} s"
        return Run(grid[ok], theta[ok], stats, failure)

    def run(self, handle, problem, rtol, atol):
        stats: dict = {}
        r = self._integrate(problem, rtol, atol, self.solver, stats)
        r.stats = {"residual_evaluations": stats.get("nfev", NAN), "jacobian_evaluations": stats.get("njev", NAN),
                   "events": stats.get("events", 0), "segments": stats.get("segments", 0)}
        return r

    def count(self, handle, problem, rtol, atol):
        totals = {"steps": 0, "attempts": 0}
        self._integrate(problem, rtol, atol, _counting_class(self.solver, totals), {})
        rejected = totals["attempts"] - totals["steps"] if totals["attempts"] else NAN
        return {"steps": totals["steps"], "rejected_steps": rejected}


# -- CasADi IDAS ---------------------------------------------------------------------------------------------
@dataclass
class CasadiMethod(Method):
    """The CasADi peer (`bench_casadi`): `loop` = Python event loop on per-mode integrators, `events` = CasADi's
    own event support."""

    variant: str = "loop"

    def setup(self, problem, rtol, atol):
        from mechsim.benchmarks import bench_casadi as bc
        n_out = len(problem.grid) - 1
        build = bc.build if self.variant == "loop" else bc.build_events
        model = build(problem.mech, rtol, atol, n_out, problem.dt_out, problem.ext)
        return model, model.build_time_s, "per tolerance"

    def _simulate(self, handle, problem, count):
        from mechsim.benchmarks import bench_casadi as bc
        a, b = problem.baumgarte
        simulate = bc.simulate if self.variant == "loop" else bc.simulate_events
        return simulate(handle, problem.mech, problem.drive, problem.duration, problem.dt_out, problem.angle0,
                        problem.speed0, alpha=a, beta=b, ext=problem.ext, ext_initial=problem.ext_initial,
                        count=count)

    def run(self, handle, problem, rtol, atol):
        r = self._simulate(handle, problem, False)
        return Run(r.t, r.angle, {"events": r.stats["events"], "segments": r.stats["segments"]},
                   f"CasADi IDAS failed at {r.failure}" if r.failure else None)

    def count(self, handle, problem, rtol, atol):
        s = self._simulate(handle, problem, True).stats
        return {k: s[k] for k in ("steps", "rejected_steps", "residual_evaluations", "jacobian_evaluations")
                if k in s}


@dataclass
class DiffsolMethod(Method):
    """The diffsol peer (`bench_diffsol`): the Geneva's crank angle per mode in DiffSL, a Python loop restarting
    at each located boundary. The external Geneva without friction or thermal states only."""

    solver: str = "tsit45"
    coordinates: str = "minimal"      # "index1": two coordinates and the constraint (`bench_diffsol.CODE_INDEX1`)
    thermal = False

    def supports_problem(self, problem):
        from mechsim.benchmarks import bench_diffsol as bd
        return super().supports_problem(problem) and bd.supports(problem)

    def skip_reason(self, problem):
        if not super().supports_problem(problem):
            return super().skip_reason(problem)
        return ("written for the external Geneva without friction, a constant load, torque or motor drive, "
                "mechanics only")

    def setup(self, problem, rtol, atol):
        from mechsim.benchmarks import bench_diffsol as bd
        model = bd.build(problem, rtol, atol, self.solver, self.coordinates)
        return model, model.build_time_s, "per process (JIT), tolerances set per run"

    def run(self, handle, problem, rtol, atol):
        from mechsim.benchmarks import bench_diffsol as bd
        r = bd.simulate(handle, problem.grid, problem.angle0, problem.speed0)
        return Run(r.t, r.angle, r.stats, r.failure)


GENEVA = ("geneva",)    # the peers' equations (reduced ODE, the CasADi translation) are checked on the Geneva
METHODS: dict[str, Method] = {m.name: m for m in [
    IdaMethod("ida-index1", "mechsim IDA", "DAE", "index-1 DAE + Baumgarte (9 states)", formulation="index1"),
    IdaMethod("ida-index2", "mechsim IDA", "DAE", "stabilized index-2 DAE, GGL (10 states)", formulation="index2"),
    IdaMethod("ida-index3", "mechsim IDA", "DAE", "index-3 DAE (9 states)", formulation="index3"),
    IdaMethod("ida-compiled-index1", "mechsim IDA", "DAE", "index-1 DAE + Baumgarte (9 states), compiled callbacks",
              formulation="index1", backend="ida-compiled"),
    IdaMethod("ida-compiled-index2", "mechsim IDA", "DAE", "stabilized index-2 DAE (10 states), compiled callbacks",
              formulation="index2", backend="ida-compiled"),
    DiffraxMethod("diffrax-Tsit5", "mechsim diffrax", "explicit", "KKT ODE + Baumgarte", "diffrax", solver="Tsit5"),
    DiffraxMethod("diffrax-Dopri8", "mechsim diffrax", "explicit", "KKT ODE + Baumgarte", "diffrax",
                  solver="Dopri8"),
    DiffraxMethod("diffrax-Kvaerno5", "mechsim diffrax", "implicit", "KKT ODE + Baumgarte", "diffrax",
                  solver="Kvaerno5"),
    ScipyMethod("scipy-Radau", "scipy", "implicit", "reduced ODE (2 states)", mechanisms=GENEVA, solver="Radau"),
    ScipyMethod("scipy-BDF", "scipy", "implicit", "reduced ODE (2 states)", mechanisms=GENEVA, solver="BDF"),
    ScipyMethod("scipy-LSODA", "scipy", "implicit", "reduced ODE (2 states)", mechanisms=GENEVA, solver="LSODA"),
    ScipyMethod("scipy-DOP853", "scipy", "explicit", "reduced ODE (2 states)", mechanisms=GENEVA, solver="DOP853"),
    CasadiMethod("casadi-idas", "CasADi", "implicit", "index-1 + Baumgarte, KKT solved by CasADi (4 states)",
                 "casadi", GENEVA, variant="loop"),
    CasadiMethod("casadi-idas-events", "CasADi", "implicit", "the same, CasADi's event support (4 + 5 states)",
                 "casadi", GENEVA, variant="events"),
    DiffsolMethod("diffsol-tsit45", "diffsol", "explicit", "crank angle per mode, DiffSL JIT (2 states)",
                  "pydiffsol", GENEVA, solver="tsit45"),
    DiffsolMethod("diffsol-bdf", "diffsol", "implicit", "crank angle per mode, DiffSL JIT (2 states)",
                  "pydiffsol", GENEVA, solver="bdf"),
    DiffsolMethod("diffsol-tsit45-index1", "diffsol", "explicit",
                  "crank and wheel, index-1 + Baumgarte, DiffSL JIT (4 states)", "pydiffsol", GENEVA,
                  solver="tsit45", coordinates="index1"),
]}


@contextmanager
def quiet_sundials():
    """SUNDIALS prints its failures on the C stdout; keep them out of the benchmark's console (the rows have
    them). The file descriptors are restored on exit; without real descriptors (captured streams) nothing is
    redirected."""
    import os
    import sys
    try:
        fds = [sys.stdout.fileno(), sys.stderr.fileno()]
    except (AttributeError, OSError, ValueError):
        yield
        return
    saved = [os.dup(fd) for fd in fds]
    devnull = os.open(os.devnull, os.O_WRONLY)
    try:
        for stream in (sys.stdout, sys.stderr):
            stream.flush()
        for fd in fds:
            os.dup2(devnull, fd)
        yield
    finally:
        for stream in (sys.stdout, sys.stderr):
            stream.flush()
        for fd, copy in zip(fds, saved):
            os.dup2(copy, fd)
            os.close(copy)
        os.close(devnull)
