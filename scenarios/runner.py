"""Run a validated scenario in two steps: `plan` (build the mechanism, the drive, the solver settings and the
thermal model once, and choose the cheapest method that answers the scenario), then `execute` (integrate,
tabulate, summarise). `run` is both."""
from __future__ import annotations

import dataclasses
import math
import platform
import time
from collections import Counter
from collections.abc import Mapping
from dataclasses import dataclass
from functools import lru_cache
from importlib import metadata
from typing import Callable

import numpy as np
import pandas as pd

from mechsim.dynamics.drives import Drive
from mechsim.dynamics.invariants import QUADRATURE_ERROR, event_floats, first_violation
from mechsim.dynamics.quadrature import cumulative_integrals
from mechsim.dynamics.result import Failure, FailureCode, Result
from mechsim.dynamics.settings import SolverSettings
from mechsim.dynamics.stats import new_stats
from mechsim.dynamics.tables import TableColumns, coordinate_columns, events_table, timeseries
from mechsim.mechanisms.base import Mechanism

from mechsim.scenarios import validity
from mechsim.scenarios.console import group_warnings, warning_time
from mechsim.scenarios.loader import Scenario, build_mechanism
from mechsim.scenarios.peaks import CLOSED_READINGS, CLOSED_STEP_RAD, Source as PeakSource
from mechsim.scenarios.singular import singular_warnings
from mechsim.scenarios.units import ScenarioError

VERSION_PACKAGES = ("mechsim", "numpy", "scipy", "sympy", "scikit-sundae", "jax", "diffrax", "pandas")
#: callables `observer(cpu_seconds)` run after a run's located peaks (`peaks` in `execute`) with their process CPU
#: time: the documented way for a benchmark to time them from inside a run (`benchmarks/peer_bench.py`
#: `located_peaks_timed`), as `ida.SOLVE_OBSERVERS` is for IDA's counters
PEAKS_OBSERVERS: list = []


def solver_settings(si: dict) -> SolverSettings:
    s = si["solver"]
    return SolverSettings(backend=s["backend"], formulation=s["formulation"], method=s["method"],
                          rtol=s["rtol"], atol=s["atol"], multiplier_atol=s["multiplier_atol"],
                          baumgarte_alpha=s["baumgarte_alpha"], baumgarte_beta=s["baumgarte_beta"],
                          max_steps=s["max_steps"], events=s["events"], diffrax_solver=s["diffrax_solver"],
                          jacobian=s["jacobian"], diffrax_compiled_run=s["diffrax_compiled_run"])


def make_drive(si: dict) -> Drive:
    d = si["drive"]
    return Drive(d["type"], speed=d["speed"] or 0.0, torque=d["torque"] or 0.0,
                 stall_torque=d["stall_torque"] or 0.0, no_load_speed=d["no_load_speed"] or 0.0,
                 duty_on=d.get("duty_on") or 0.0, duty_off=d.get("duty_off") or 0.0)


@lru_cache(maxsize=1)
def versions() -> dict[str, str]:
    """Versions of Python and the packages a result depends on (read once per process: the metadata is slow to read)."""
    out = {"python": platform.python_version()}
    for pkg in VERSION_PACKAGES:
        try:
            out[pkg] = metadata.version(pkg)
        except metadata.PackageNotFoundError:
            out[pkg] = "not installed"
    return out


def choose_method(si: dict, mech: Mechanism, drive: Drive, settings: SolverSettings) -> tuple[str, str]:
    """('closed-form' | 'dae', why): the closed form where the drive is prescribed and the mechanism has one."""
    if settings.method == "dae":
        return "dae", "solver.method = 'dae' asks for the DAE"
    if drive.is_prescribed:
        probe = mech.closed_form(np.array([0.0]), 0.0, 1.0) is not None
        if probe and settings.method in ("auto", "closed-form"):
            return "closed-form", ("prescribed speed: the motion is known in closed form, no DAE needed, and the "
                                   "[solver] settings are unused; solver.method = 'dae' integrates it with them")
        if settings.method == "closed-form":
            raise ValueError("solver.method = 'closed-form' but this mechanism has no closed form")
        return "dae", "prescribed speed, but this mechanism has no closed form: the DAE with a speed constraint"
    if settings.method == "closed-form":
        raise ValueError("solver.method = 'closed-form' needs drive.type = 'speed'")
    return "dae", f"drive.type = '{drive.kind}': the speed follows from the dynamics, so the DAE is integrated"


def _closed_form_table(mech: Mechanism, si: dict, drive: Drive) -> pd.DataFrame:
    from mechsim.thermal.cycle import output_times
    t = output_times(si["duration"], si["output_step"])      # as the DAE's rows: k step, and the end itself
    angle0 = si["initial"][mech.initial_keys[0]]
    cols = mech.closed_form(t, angle0, drive.speed)
    powers = cols.pop("powers")
    events = cols.pop("events", None)
    if events is None:   # a mechanism may list the closed form's transitions apart from its columns
        listing = getattr(mech, "closed_form_events", None)
        events = listing(t, angle0, drive.speed) if listing else []
    works, error = _closed_form_works(mech, t, angle0, drive.speed, [float(e["t_s"]) for e in events], powers)
    df = pd.DataFrame({"t_s": t, **cols, **{f"work_{name}_J": w for name, w in works.items()}})   # one constructor
    df.attrs["events"] = events
    df.attrs[QUADRATURE_ERROR] = error
    return df


def _closed_form_works(mech: Mechanism, t: np.ndarray, angle0: float, speed: float, breaks: list[float],
                       at_rows: dict | None = None) -> tuple[dict[str, np.ndarray], np.ndarray]:
    """({flow: its work at each row}, the quadrature's error estimate of their sum per row): the closed form's
    exact powers integrated between the rows (`dynamics.quadrature.cumulative_integrals`), cut where the run changes
    mode (a power jumps there: a Geneva's engagement, a chain's arc entry) and into panels of at most
    CLOSED_STEP_RAD of drive angle, the powers read at the instants in order from the run's start (a closed form
    counts its angles from its first instant). at_rows: the powers at the rows t, where read already."""
    def powers(at: np.ndarray) -> dict[str, np.ndarray]:
        order = np.argsort(at, kind="stable")
        got = mech.closed_form(np.concatenate([t[:1], at[order]]), angle0, speed)["powers"]
        out = {}
        for name, p in got.items():
            values = np.broadcast_to(np.asarray(p, dtype=float), (len(at) + 1,))[1:]
            out[name] = np.empty(len(at))
            out[name][order] = values
        return out
    pace = abs(float(speed))
    widest = CLOSED_STEP_RAD / pace if pace > 0.0 and np.isfinite(pace) else np.inf
    return cumulative_integrals(powers, t, np.asarray(breaks, dtype=float), widest, CLOSED_READINGS, at_rows)


def peaks(df: pd.DataFrame, angle_column: str, columns: tuple[str, ...], cols: TableColumns | None = None,
          events: pd.DataFrame | None = None, source=None, speed_column: str | None = None,
          event_cols: TableColumns | None = None) -> tuple[dict, dict | None]:
    """(peaks, periodic regime or None): maximum, minimum and largest magnitude of each of `columns` in the table
    (the mechanism's `peak_columns`, then the thermal model's) with their instants and drive angles, located in
    continuous time where `source` (scenarios/peaks.py Source) is given, else the output rows'; the periodic
    regime's, with the start-up's beside them, where the run reaches one (docs/theory.md §K5). cols: the table's
    TableColumns, if at hand (event_cols: the events')."""
    from mechsim.scenarios.peaks import located_peaks
    cols = TableColumns(df) if cols is None else cols
    return located_peaks(df, angle_column, columns, events, cols, source, speed_column,
                         None if events is None else _event_columns(events, event_cols))


def energy_balance(df: pd.DataFrame, events: pd.DataFrame | None = None, cols: TableColumns | None = None,
                   event_cols: TableColumns | None = None) -> dict:
    """Drive work = d(kinetic energy) - (load + friction + damping work) + energy lost in impacts (events table;
    all works signed into the system). closure_error_relative: the closure error over the largest energy any term
    of the balance reaches over the run (a work or the kinetic energy's change from the first row, the impact
    losses: largest_term_J), not over the net drive work: over whole periods of a prescribed motion against
    conservative forces the net works are round-off themselves (rolling-a-speed's 1.5e-14 J), though the run
    exchanges joules. cols,
    event_cols: the table's and the events' TableColumns, if at hand."""
    cols = TableColumns(df) if cols is None else cols
    if "work_drive_J" not in cols or len(df) < 2:
        return {}

    reach = 0.0                     # the largest |change from the first row| of any work or the kinetic energy

    def change(column: str) -> float:
        nonlocal reach
        values = np.asarray(cols[column], dtype=float)
        reach = float(np.fmax(reach, _largest_magnitude(values - values[0])))     # (NaN rows skipped)
        return float(values[-1] - values[0])

    works = {c[5:-2]: change(c) for c in cols.names if c.startswith("work_") and c.endswith("_J")}
    dke = change("kinetic_energy_J")
    lost = 0.0
    ev = None if events is None else _event_columns(events, event_cols)
    if ev is not None and "energy_lost_J" in ev and len(events):
        t = np.asarray(cols["t_s"], dtype=float)
        t0, t1 = float(t[0]), float(t[-1])
        te, el = event_floats(ev, "t_s"), ev["energy_lost_J"]
        inside = (te > t0) & (te <= t1)
        if el.dtype == np.float64:      # as pandas' fillna(0.0).sum() sums it (nanops.nansum: NaN -> 0, ndarray.sum)
            picked = el[inside]
            lost = float(np.where(np.isnan(picked), 0.0, picked).sum())
        else:
            lost = float(events["energy_lost_J"][inside].fillna(0.0).sum())
    closure = sum(works.values()) - dke - lost
    scale = max(reach, abs(lost), 1e-300)
    return {"work_J": works, "kinetic_energy_change_J": dke, "impact_losses_J": lost, "closure_error_J": closure,
            "closure_error_relative": closure / scale, "largest_term_J": scale}


def _largest_magnitude(values) -> float:
    """The largest |value| of a column with NaN skipped (NaN where every entry is NaN), as pandas'
    Series.abs().max() gives it, read from the column's array."""
    return float(np.fmax.reduce(np.abs(np.asarray(values, dtype=float))))


def _event_columns(events: pd.DataFrame, event_cols: TableColumns | None) -> TableColumns:
    """The events' TableColumns: event_cols where it reads this very frame, else read anew."""
    return event_cols if event_cols is not None and event_cols.frame is events else TableColumns(events)


def event_counts(events: pd.DataFrame, event_cols: TableColumns | None = None) -> dict[str, int]:
    """Events by kind, as {str(kind): count} of events["kind"].value_counts(): most frequent first, ties in the
    order of their first appearance (pandas orders the counts so: first appearance, then a stable sort), missing
    kinds left out; counted over the column's values (cheaper than building a value_counts Series), read by
    position (`TableColumns`: a read by name would build the column index's hash table first).
    event_cols: the events' TableColumns, if at hand."""
    if not len(events):
        return {}
    counts = Counter(k for k in _event_columns(events, event_cols)["kind"] if k is not None and k == k)
    return {str(k): int(n) for k, n in sorted(counts.items(), key=lambda kv: -kv[1])}


def _checked(df: pd.DataFrame, events: pd.DataFrame, failure: Failure | None, settings: SolverSettings,
             exact: bool = False, columns: list[str] | None = None, cols: TableColumns | None = None,
             event_cols: TableColumns | None = None, quadrature: np.ndarray | None = None, steps: int | None = None):
    """(table, events, failure) after the physical invariants of `dynamics.invariants`: a row that breaks one
    becomes the run's failure (when earlier than the one it has) and the rows from it on are not kept.
    cols, event_cols: df's and the events' TableColumns, if at hand; quadrature: a closed form's works' error
    estimate per row (`_closed_form_works`); steps: an integrated run's accepted steps (its global error's bound,
    `invariants.global_factor`)."""
    v = first_violation(df if cols is None else cols, events if event_cols is None else _event_columns(
        events, event_cols), settings.rtol, settings.atol, exact, columns, quadrature, steps)
    if v is None or (failure is not None and failure.time <= v.time):
        return df, events, failure
    failure = Failure(time=v.time, mode=v.mode, reason=v.reason(), kind="solver",
                      code=FailureCode.INVARIANT_VIOLATED, hint=(
                          "a model that no longer holds was integrated; tighten rtol, or try formulation = 'index2' "
                          "or solver.backend = 'diffrax', and please report the scenario"))
    keep = df["t_s"].to_numpy(float) < v.time
    df = df[keep].reset_index(drop=True)
    if len(events):
        events = events[events["t_s"].to_numpy(float) < v.time].reset_index(drop=True)
    return df, events, failure


@dataclass
class Plan:
    """Everything decided before anything is integrated; the mechanism is built once, here."""

    scenario: Scenario
    mechanism: Mechanism
    drive: Drive
    settings: SolverSettings
    method: str              # "closed-form" | "dae"
    why: str
    thermal: object = None   # mechsim.thermal.ThermalPlan, or None without a thermal model
    seconds: float = 0.0     # wall time spent planning (counted in the run's wall_time_s)
    #: where the run is computed at a step `thin` times finer than the scenario's output step (`rows_every`): the
    #: scenario as asked, whose rows the run's table keeps (`execute`); `scenario` then holds the finer step
    asked: Scenario | None = None
    thin: int = 1

    @property
    def mechanics_duration(self) -> float:
        """How long the mechanics runs: the scenario's duration, or the cycle-averaging window."""
        return self.scenario.si["duration"] if self.thermal is None else self.thermal.mechanics_duration


#: a cycle-averaged run's rows are at most this fraction of a nominal crank turn apart while it runs: its window's
#: turns are compared for periodicity on them (thermal/plan.py `ThermalPlan.extend`), which rows a turn or more
#: apart cannot tell (docs/thermal.md, "Cycle averaging")
ROWS_PER_TURN = 16


def rows_every(si: dict, thermal, per_turn: int = ROWS_PER_TURN) -> int:
    """How many times finer than the output step a run is computed: 1, or for a cycle-averaged run whose output rows
    are more than 1/per_turn of a nominal turn apart the least integer that brings them within it (the output
    rows are then every `rows_every`-th row, `execute`)."""
    if thermal is None or thermal.averaging != "cycle":
        return 1
    return max(1, int(np.ceil(si["output_step"] * per_turn / thermal.setup.period - 1e-9)))


def plan(scenario: Scenario) -> Plan:
    """Build the mechanism, drive, settings and thermal model and choose the method (ValueError on bad input). A
    cycle-averaged run whose output rows are too coarse for its averaging is planned at a finer step
    (`rows_every`), its table thinned back to the output step by `execute`."""
    made = _plan(scenario)
    thin = rows_every(scenario.si, made.thermal)
    if thin == 1:
        return made
    return dataclasses.replace(_plan(finer(scenario, thin)), asked=scenario, thin=thin)


def finer(scenario: Scenario, every: int) -> Scenario:
    """The scenario with an output step `every` times finer, its rows bounded as the scenario's are before any
    work (scenarios/schema.py `rows_problem`: ScenarioError naming the output step)."""
    from mechsim.scenarios.schema import rows_problem
    si = {**scenario.si, "output_step": scenario.si["output_step"] / every}
    problem = rows_problem(si["duration"] / si["output_step"])
    if problem:
        raise ScenarioError("output_step", f"cycle averaging compares the crank turns on rows "
                                           f"{si['output_step']:.3g} s apart over {si['duration']:g} s, {problem}: "
                                           "shorten duration or set thermal.averaging = 'resolved'")
    return dataclasses.replace(scenario, si=si)


def _plan(scenario: Scenario) -> Plan:
    si = scenario.si
    wall0 = time.perf_counter()
    mech = build_mechanism(si)
    drive = make_drive(si)
    settings = solver_settings(si)
    method, why = choose_method(si, mech, drive, settings)
    refused = getattr(mech, "refused_formulations", {}).get(settings.formulation)
    if refused and method == "dae" and settings.backend != "diffrax":     # diffrax integrates the index-1 ODE
        raise ScenarioError("solver.formulation", f"{settings.formulation!r} {refused}")
    thermal = None
    if si.get("thermal", {}).get("model", "none") != "none":
        from mechsim.thermal.plan import ThermalSetupError, plan as thermal_plan   # local: optional per scenario
        try:
            thermal = thermal_plan(si, mech, drive, method)
        except ThermalSetupError as exc:
            raise ScenarioError(exc.field, exc.problem) from None
    return Plan(scenario, mech, drive, settings, method, why, thermal, time.perf_counter() - wall0)


def run(scenario: Scenario, progress: Callable[[float], None] | None = None,
        integrate: Callable | None = None) -> Result:
    """Plan and execute one scenario. Never raises for solver trouble: a failure comes back in Result.failure."""
    return execute(plan(scenario), progress, integrate)


def _mechanics(the_plan: Plan, duration: float, progress, integrate):
    """(table, events, solver stats, warnings, failure) of the mechanics integrated over `duration`."""
    scenario, mech, drive, settings, thermal = (the_plan.scenario, the_plan.mechanism, the_plan.drive,
                                                the_plan.settings, the_plan.thermal)
    si = scenario.si
    run_si = {**si, "duration": duration}
    angle_key, speed_key = mech.initial_keys
    failure = None
    warnings: list[str] = []
    stats: dict = {}
    traj = None
    if the_plan.method == "closed-form":
        wall0 = time.perf_counter()
        df = _closed_form_table(mech, run_si, drive)
        rows = df.attrs.pop("events", [])
        events = pd.DataFrame(rows) if rows else pd.DataFrame(columns=["t_s", "from_mode", "to_mode", "kind"])
        # the statistics every path reports (dynamics/stats.py): nothing integrated, so no step was taken
        stats = new_stats("closed-form", "closed form", 0.0)
        stats.update(events=len(rows), solve_time_s=time.perf_counter() - wall0)
        stats["notes"]["backend"] = "a prescribed speed on the mechanism's closed form: no DAE was integrated"
        if progress:
            progress(si["duration"])
    else:
        speed0 = drive.speed if drive.is_prescribed else si["initial"][speed_key]
        if integrate is None:   # a caller (the batched sweep) may supply the backend call itself
            # imported here: a closed-form run derives no DAE and need not load sympy
            from mechsim.dynamics.hybrid import simulate as integrate
        traj = integrate(mech, drive, settings, run_si["duration"], si["output_step"], si["initial"][angle_key],
                         speed0, progress=progress, ext=thermal and thermal.extension,
                         ext_initial=thermal and thermal.ext_initial)
        tables0 = time.perf_counter()
        df = timeseries(traj, mech.angle_coordinates)
        events = mech.completed_events(events_table(traj), df)
        # the run's own time on its tables, checks and summary (`_finished` and `execute` add theirs): what the console
        # reports beside the solve, apart from loading the model and the solver
        stats = dict(traj.stats, tables_time_s=time.perf_counter() - tables0)
        warnings += traj.warnings
        warnings += [f"solver.{key} = {getattr(settings, key)!r} is unused on backend '{settings.backend}' "
                     f"(formulation '{settings.formulation}'): {why}" for key, why in settings.unused()]
        if traj.failure:
            from mechsim.dynamics.backend import backend_class
            # names the cause where the backend gives a symptom
            f = backend_class(settings.backend).explain(traj, settings, si["duration"])
            where = configuration_text(f.get("where", {}), mech)
            reason = f"{f['reason'].rstrip('. ')} at {where}" if where else f["reason"]
            failure = Failure(time=f["time"], mode=f["mode"], reason=reason,
                              hint=f.get("hint", ""), kind=f.get("kind", "solver"),
                              code=f.get("code", FailureCode.INTEGRATOR_FAILED))
    return df, events, stats, warnings, failure, traj


def configuration_text(where: dict, mech: Mechanism) -> str:
    """The configuration a run stopped at, as its failure message gives it: each coordinate with its unit, an angle
    also as its place in the turn in degrees (-180 to 180, the mechanisms' own convention: the Geneva's entry at
    -45 deg), where a designer finds it on the drawing: a run stopped after 57 turns reads 'crank = 361.023 rad
    (165.1 deg in its turn)', not a bare 361.023."""
    angles = {mech.coordinates[i] for i in mech.angle_coordinates}
    parts = []
    for name, value in where.items():
        if name in angles:
            turn = math.remainder(math.degrees(value), 360.0) if math.isfinite(value) else value
            parts.append(f"{name} = {value:.6g} rad ({turn:.1f} deg in its turn)")
        else:
            parts.append(f"{name} = {value:.6g} m")
    return ", ".join(parts)


def _settled(the_plan: Plan, progress, integrate):
    """(plan, mechanics) where the plan's thermal window is the one its cycle averaging settles on: the mechanics
    integrated over the thermal plan's window, and again over a longer one while its crank turns are not yet
    periodic (thermal/plan.py `ThermalPlan.extend`, which may also resolve the whole run)."""
    thermal = the_plan.thermal
    duration = the_plan.scenario.si["duration"] if thermal is None else thermal.mechanics_duration
    mechanics = _mechanics(the_plan, duration, progress, integrate)
    while thermal is not None and mechanics[4] is None:
        longer = thermal.extend(mechanics[0])
        if longer is None:
            break
        thermal = longer
        the_plan = dataclasses.replace(the_plan, thermal=thermal)
        mechanics = _mechanics(the_plan, thermal.mechanics_duration, progress, integrate)
    return the_plan, mechanics


def settled(the_plan: Plan) -> Plan:
    """The plan with the thermal window its run settles on (`_settled`; integrates the mechanics windows)."""
    return _settled(the_plan, None, None)[0]


def read_window(the_plan: Plan):
    """(thermal plan with its `WindowReadings`, the mechanics window's table) of a settled cycle-averaged DAE plan
    (`settled`): the window integrated as `execute` integrates it and read on its solution as the cycle averaging
    reads it, for the design sensitivities' traced turn (scenarios/studies/sensitivity_cycle.py); None where the
    run fails or its window cannot be read."""
    from mechsim.scenarios.thermal_peaks import window_readings
    thermal = the_plan.thermal
    df, events, _, _, failure, traj = _mechanics(the_plan, thermal.mechanics_duration, None, None)
    if failure is not None or traj is None:
        return None
    dense = window_readings(thermal, traj, df, events, the_plan.mechanism, the_plan.settings)
    return None if dense is None else (dataclasses.replace(thermal, dense=dense), df)


class _Reads(Mapping):
    """A table's columns that note which of them are read or asked for (`_thermal_inputs`)."""

    def __init__(self, cols: TableColumns):
        self.cols, self.names = cols, set()

    def __getitem__(self, name):
        self.names.add(name)
        return self.cols[name]

    def __contains__(self, name) -> bool:
        self.names.add(name)
        return name in self.cols

    def __iter__(self):
        return iter(self.cols)

    def __len__(self) -> int:
        return len(self.cols)


def _thermal_inputs(df: pd.DataFrame, events: pd.DataFrame, cols: TableColumns, mech: Mechanism,
                    thermal) -> list[str]:
    """The columns of the mechanics table `df` the thermal finish reads, in the table's order: the contact's (what
    the mechanism's `contact_state` and `contact_starts` read), the angles, the drive's speed and acceleration, the
    network's states, and the columns the checks after the finish read."""
    reads = _Reads(cols)
    mech.contact_state(reads)
    mech.contact_starts(reads, events)
    drive = coordinate_columns(mech.coordinates[mech.drive_coordinate], mech.drive_coordinate in mech.angle_coordinates)
    wanted = reads.names | set(drive) | set(thermal.setup.extension.names if thermal.setup.extension else ()) | {
        "t_s", "mode", "friction_force_N", "slip_speed_m_s"}
    return [c for c in df.columns if c in wanted or c.endswith("_angle_rad")]


def thermal_peaks(the_plan: Plan, columns: list[str]) -> dict:
    """summary.json `peaks` of the thermal `columns` (of ThermalPlan.PEAK_COLUMNS) as `execute` reports them, from a
    table of only the mechanics columns the thermal finish reads (`_thermal_inputs`): every row of the thermal
    columns is computed from its own row's inputs and the network's states, and each column's extrema are located
    on their own, so those rows and extrema are the whole run's, without the run's other columns, peaks and checks
    (a long cycle-averaged run's table continued over the hour). The design sensitivities read the run's located
    thermal peaks so. {} where the run fails."""
    if the_plan.thermal is None or the_plan.scenario.si.get("output", {}).get("on_invalid", "warn") == "stop":
        result = execute(the_plan)        # the validity may cut the table: the whole run decides
        return {} if result.failure is not None else {c: e for c, e in result.summary.get("peaks", {}).items()
                                                       if c in columns}
    done = _finished(the_plan, None, None, _thermal_inputs)
    if done.failure is not None:
        return {}
    return peaks(done.df, done.angle_col, tuple(c for c in the_plan.thermal.PEAK_COLUMNS if c in columns), done.cols,
                 done.events, done.source, done.speed_col, done.event_cols)[0]


@dataclass
class _Finished:
    """A run's tables after the checks and the thermal finish, and what its summary reads of them."""
    plan: Plan
    df: pd.DataFrame
    events: pd.DataFrame
    failure: Failure | None
    cols: TableColumns                 # each column read once for the checks, the thermal finish, peaks and energy
    event_cols: TableColumns           # the same for the events' columns (the checks, energy, counts)
    source: PeakSource                 # where the located peaks read the continuous solution
    angle_col: str                     # the drive coordinate's angle and speed columns
    speed_col: str
    stats: dict                        # the solver's
    warnings: list[str]
    thermal_summary: dict | None
    thermal_tables: dict


def _finished(the_plan: Plan, progress, integrate, keep=None):
    """The run's tables after the checks and the thermal finish (`_Finished`). keep(df, events, cols, mech,
    thermal): the mechanics columns to keep for the thermal finish (`thermal_peaks`), else all."""
    the_plan, (df, events, stats, warnings, failure, traj) = _settled(the_plan, progress, integrate)
    post0 = time.perf_counter()
    scenario, mech, drive, settings = the_plan.scenario, the_plan.mechanism, the_plan.drive, the_plan.settings
    method, thermal = the_plan.method, the_plan.thermal
    if thermal is not None and thermal.averaging == "cycle" and traj is not None \
            and failure is None:       # the cycle averaging reads the periodic turn on the window's solution
        from mechsim.scenarios.thermal_peaks import window_readings
        thermal = dataclasses.replace(thermal, dense=window_readings(thermal, traj, df, events, mech, settings))
    si = scenario.si
    angle_col, speed_col, _ = coordinate_columns(mech.coordinates[mech.drive_coordinate],
                                                 mech.drive_coordinate in mech.angle_coordinates)
    cols = TableColumns(df)
    source = PeakSource(method, traj, mech, drive, settings, si, frozenset(cols.names), thermal, df)
    event_cols = TableColumns(events)
    # (the closed form's quadrature error travels with its table to here, not beyond: no writer keeps an array)
    quadrature = df.attrs.pop(QUADRATURE_ERROR, None)
    # (scikit-sundae's IDA counts no steps: its residual evaluations, at least one a step, bound them)
    steps = None if method == "closed-form" else stats.get("accepted_steps") or stats.get("residual_evaluations")
    checked, events, failure = _checked(df, events, failure, settings, exact=method == "closed-form", cols=cols,
                                        event_cols=event_cols, quadrature=quadrature, steps=steps)
    if checked is not df:
        df, cols = checked, TableColumns(checked)
    if keep is not None and thermal is not None:
        df = df[keep(df, events, cols, mech, thermal)]
        cols = TableColumns(df)
    thermal_summary, thermal_tables = None, {}
    if thermal is not None:
        df, events, thermal_tables, thermal_summary, thermal_warnings = thermal.finish(
            df, events, failed=failure is not None, columns=cols)
        warnings += thermal_warnings
        heat = [c for c in ("t_s", "mode", "heat_rate_W", "heat_generated_J", "friction_force_N", "slip_speed_m_s")
                if c in df]
        cols = TableColumns(df)
        checked, events, failure = _checked(df, events, failure, settings, columns=heat, cols=cols,
                                            event_cols=event_cols, steps=steps)
        if checked is not df:
            df, cols = checked, TableColumns(checked)
    stats = dict(stats, tables_time_s=stats.get("tables_time_s", 0.0) + time.perf_counter() - post0)
    return _Finished(the_plan, df, events, failure, cols, event_cols, source, angle_col, speed_col, stats, warnings,
                     thermal_summary, thermal_tables)


def execute(the_plan: Plan, progress: Callable[[float], None] | None = None,
            integrate: Callable | None = None) -> Result:
    """Integrate a planned scenario, tabulate and summarise (solver trouble comes back in Result.failure)."""
    wall0 = time.perf_counter()
    done = _finished(the_plan, progress, integrate)
    post0 = time.perf_counter()
    the_plan, df, events, failure, cols, event_cols = (done.plan, done.df, done.events, done.failure, done.cols,
                                                       done.event_cols)
    warnings = done.warnings
    scenario, mech, drive, settings = the_plan.scenario, the_plan.mechanism, the_plan.drive, the_plan.settings
    method, why, thermal, si = the_plan.method, the_plan.why, the_plan.thermal, the_plan.scenario.si
    conditions = validity.conditions(mech, thermal)       # the model's validity on every row (scenarios/validity.py)
    valid = validity.evaluate(conditions, cols)
    if si.get("output", {}).get("on_invalid", "warn") == "stop":
        checked, events, failure = validity.stop(valid, df, events, failure)
        if checked is not df:
            df, cols = checked, TableColumns(checked)
            valid = validity.evaluate(conditions, cols)
            warnings = [w for w in warnings if (tw := warning_time(w)) is None or tw <= failure.time]
    peaks0 = time.process_time()
    peak_summary, regime = peaks(df, done.angle_col, mech.peak_columns + (thermal.PEAK_COLUMNS if thermal else ()),
                                 cols, events, done.source if failure is None else None, done.speed_col, event_cols)
    for observe in PEAKS_OBSERVERS:
        observe(time.process_time() - peaks0)
    if failure is None and any(validity.locatable(valid, conditions, done.source.columns)):
        from mechsim.scenarios.peaks import point_reader       # the validity's numbers on the continuous solution
        reader = point_reader(done.source, cols, events, event_cols)
        if reader is not None:
            validity.located(valid, conditions, cols, reader[:2], done.source.columns,
                             lambda: reader[3](done.angle_col, done.speed_col))
    if failure is None and thermal is not None and any(validity.locatable(valid, conditions, cols.names)):
        from mechsim.scenarios.peaks import thermal_point_reader     # those on the thermal columns
        reader = thermal_point_reader(done.source, cols, events, event_cols)
        if reader is not None:
            validity.located(valid, conditions, cols, reader[:2], reader[2],
                             lambda: reader[3](done.angle_col, done.speed_col))
    warnings += singular_warnings(peak_summary)
    wall = time.perf_counter() - wall0 + the_plan.seconds
    tables = done.stats.get("tables_time_s", 0.0) + time.perf_counter() - post0
    summary = {
        "scenario": scenario.name,
        "mechanism": si["mechanism"]["type"],
        "model": {
            "drive": drive.kind, "method": method, "why": why,
            "formulation": settings.formulation if method == "dae" else None,
            "backend": settings.backend if method == "dae" else None,
            "thermal": si.get("thermal", {}).get("model", "none"),
            "rtol": settings.rtol, "atol": settings.atol,
        },
        "geometry": mech.describe(),
        "peaks": peak_summary,
        "regime": regime,
        "energy": energy_balance(df, events, cols, event_cols),
        "events": event_counts(events, event_cols),
        "validity": valid,
        "solver": {**done.stats, "tables_time_s": tables, "wall_time_s": wall, "output_rows": len(df)},
        "max_constraint_residual_m": _largest_magnitude(cols["constraint_residual_m"]) if len(df) else 0.0,
        "warnings": warnings,
        "warning_groups": group_warnings(warnings),
        "success": failure is None,
        "failure": failure.message() if failure else None,
        "failure_code": failure.code.value if failure else None,
        "versions": dict(versions()),
    }
    if done.thermal_summary is not None:
        summary["thermal"] = done.thermal_summary
    elif not mech.has_sliding_contact:
        summary["thermal"] = {"model": "none", "why": f"{mech.name} has no sliding contact in the model (pure "
                              "rolling or pin joints): no frictional heat, so no thermal model was built"}
    extra_tables = {**mech.extra_outputs(df, events), **done.thermal_tables}
    if hasattr(mech, "extra_summary"):              # the mechanism's own figures of its tables (impacts)
        summary.update(mech.extra_summary(extra_tables))
    if the_plan.asked is not None:
        df, si = _thinned(df, the_plan.thin, the_plan.asked.si), the_plan.asked.si
        summary["solver"]["output_rows"] = len(df)
    return Result(df, events, summary, si, failure, extra_tables=extra_tables)


def _thinned(df: pd.DataFrame, every: int, si: dict) -> pd.DataFrame:
    """The rows of the output step `si` asks for, of a table computed at a step `every` times finer (`rows_every`):
    every `every`-th row and the last (the end itself, or where a failure stopped the run), their times those of
    the output grid (k step: k (step / every) every differs from it by round-off)."""
    keep = np.zeros(len(df), dtype=bool)
    keep[::every] = True
    keep[-1:] = True
    out = df.loc[keep].reset_index(drop=True)
    from mechsim.thermal.cycle import output_times
    grid = output_times(float(si["duration"]), float(si["output_step"]))[:len(out)]
    t = out["t_s"].to_numpy(float)
    on_grid = np.abs(t[:len(grid)] - grid) <= 1e-9 * np.maximum(np.abs(grid), si["output_step"])
    if on_grid.any():
        t = t.copy()
        t[:len(grid)][on_grid] = grid[on_grid]
        out["t_s"] = t
    return out
