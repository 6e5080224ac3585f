"""Physical invariants of every output row: friction dissipates, heat is generated, energy balances.

A row that breaks one of them comes from a model that no longer holds (a friction force pointing along the
slip after a missed stall creates energy: docs/stability.md, 'Stalls'), so a run reports it as a failure at the
first such row instead of writing it. Checked once per run on the finished table (`first_violation`):

- friction power >= 0 (docs/theory.md §G1: mu |N| |u| >= 0). A sign error is only resolvable where the slip
  is larger than what the integrator resolves, so the bound is -|F_f| du with du = K (rtol max|u| + atol*1 m)
  (velocities carry atol in rad/s; the lever arm is taken as 1 m, above every mechanism's size);
- heat generated >= 0: the heat rate as friction power, the generated heat not below its start by more than
  K (rtol max|E_heat| + atol max(1, max|E_heat|)) (its integrator weight, dynamics/backends/ida.atol_vector);
- the energy balance closes on every row: work of drive, load, friction and damping (all signed into the
  system) = change of kinetic energy + energy lost in impacts up to that row. Integrated runs: within
  K (rtol S + atol max(1, S)), S = sum of the largest |work| of each kind + the largest kinetic energy (the
  work states are integrated with the motion under the same weights); closed-form runs: within
  QUADRATURE_FACTOR times the quadrature's own error estimate, since there the works are quadratures of exact
  powers (dynamics/quadrature.py's, given; for a table without it, the trapezoidal rule's on its rows,
  `trapezoid_error_estimate`).

K = 1000 (GLOBAL_FACTOR), or the run's accepted steps where it took more (`global_factor`): integrators control
the local error per step to rtol, and the global error of a run is their sum at most, where the motion does not
amplify them. Over the built-ins it is a modest multiple of the tolerance (docs/stability.md measures it over them
and the robustness grid); a long run's grows with its steps (a crank run up for 40 s: 0.4-0.9 % of its steps,
docs/stability.md "Long runs"). A violation is far outside it: a missed stall makes a power balance miss by
watts, not round-off.
"""
from __future__ import annotations

from dataclasses import dataclass

import numpy as np
import pandas as pd

from mechsim.dynamics.tables import TableColumns

#: global error of a run in units of the local tolerance, its least (see the module docstring)
GLOBAL_FACTOR = 1000.0
#: the closed form's energy bound in units of its quadrature's error estimate, with a margin: the trapezoidal
#: rule's error reaches 4 times its estimate at a jump of the power inside a panel (`trapezoid_error_estimate`)
QUADRATURE_FACTOR = 10.0
#: where a closed-form table carries its works' quadrature error estimate per row from its making to its check
#: (scenarios/runner.py `_closed_form_table`, `_finished`: an attrs entry, removed there)
QUADRATURE_ERROR = "work_quadrature_error_J"
#: lever arm (m) turning atol on angular speeds (rad/s) into a slip-speed resolution (m/s)
LEVER_M = 1.0


@dataclass(frozen=True)
class Violation:
    """The first row that breaks an invariant: when, which, by how much, and the bound it broke."""

    time: float
    mode: str
    invariant: str
    value: float
    bound: float

    def reason(self) -> str:
        return (f"physical invariant broken: {self.invariant} is {self.value:.6g}, beyond its bound "
                f"{self.bound:.3g} from the solver tolerances; the rows from here on are not written")


def global_factor(steps: int | None = None) -> float:
    """A run's global error in units of its local tolerance (K of the module docstring): GLOBAL_FACTOR, or the
    run's accepted steps where more (each step's local error is within the tolerance, and a run's global error is
    at most their sum where the motion does not amplify them). steps: None for a run without steps (a closed form)."""
    return max(GLOBAL_FACTOR, float(steps or 0))


def _columns(df) -> TableColumns:
    """The table's columns, each read once (dynamics/tables.py TableColumns); a TableColumns passes through."""
    return df if isinstance(df, TableColumns) else TableColumns(df)


def _column(df: TableColumns, name: str, names=None) -> np.ndarray | None:
    return np.asarray(df[name], dtype=float) if name in (df if names is None else names) else None


def _works(df: TableColumns, names=None) -> list[str]:
    return [c for c in (df.names if names is None else names) if c.startswith("work_") and c.endswith("_J")]


def _matrix(df: TableColumns, names: list[str]) -> np.ndarray:
    """The columns as one (rows, len(names)) array (a column at a time: a list selection copies the frame),
    each column contiguous (column-major), so sums across a row and maxima down a column run over contiguous
    memory (ten times faster than on the row-major stack, the same values)."""
    return np.stack([np.asarray(df[c], dtype=float) for c in names], axis=0).T


def _friction(df, rtol, atol, power_col, label, names=None, factor=GLOBAL_FACTOR):
    power = _column(df, power_col, names)
    if power is None:
        return None
    force, slip = _column(df, "friction_force_N", names), _column(df, "slip_speed_m_s", names)
    if force is not None and slip is not None:
        du = factor * (rtol * float(np.nanmax(np.abs(slip), initial=0.0)) + atol * LEVER_M)
        bound = -np.abs(force) * du
    else:
        bound = np.full(len(power), -factor * (rtol * float(np.nanmax(np.abs(power), initial=0.0)) + atol))
    return label, power, bound


def _heat_generated(df, rtol, atol, names=None, factor=GLOBAL_FACTOR):
    heat = _column(df, "heat_generated_J", names)
    if heat is None:
        return None
    scale = float(np.nanmax(np.abs(heat), initial=0.0))
    gained = heat - heat[0]
    return "heat generated since the start (J)", gained, np.full(len(heat), -factor * (
        rtol * scale + atol * max(1.0, scale)))


def energy_closure(df: pd.DataFrame, events: pd.DataFrame | None = None, names=None,
                   works: np.ndarray | None = None) -> np.ndarray | None:
    """Per row: works (signed into the system) - change of kinetic energy - impact losses up to that row (J).
    names: the columns to look at (default: all); works: their work columns as one array, if already read.
    df: a frame or its TableColumns."""
    df = _columns(df)
    work_names = _works(df, names)
    if not work_names or "kinetic_energy_J" not in (df if names is None else names) or not len(df.frame):
        return None
    t = np.asarray(df["t_s"], dtype=float)
    w = _matrix(df, work_names) if works is None else works
    ke = np.asarray(df["kinetic_energy_J"], dtype=float)
    lost = impact_losses(t, events)
    return (w - w[0]).sum(axis=1) - (ke - ke[0]) - (0.0 if lost is None else lost)


def impact_losses(t: np.ndarray, events: pd.DataFrame | None) -> np.ndarray | None:
    """Per row at times t: the energy lost in the impacts at or before it, after the first row (J); None where the
    events hold no losses. events: a frame or its TableColumns."""
    ev = None if events is None else _columns(events)
    if ev is None or not len(ev.frame) or "energy_lost_J" not in ev or not len(t):
        return None
    te, el = event_floats(ev, "t_s"), event_floats(ev, "energy_lost_J")
    el = np.where(np.isnan(el), 0.0, el)                   # an event without a loss loses nothing
    order = np.argsort(te)
    te, cum = te[order], np.concatenate([[0.0], np.cumsum(el[order])])     # cum[k]: the first k impacts' loss
    k = np.searchsorted(te, t, side="right")               # impacts at or before each row, after the start
    return cum[k] - cum[k[0]]


def event_floats(events: TableColumns, name: str) -> np.ndarray:
    """events[name].to_numpy(float): the column's own array where it is float already (read once)."""
    values = events[name]
    return values if values.dtype == np.float64 else events.frame[name].to_numpy(float)


def trapezoid_error_estimate(work: np.ndarray) -> np.ndarray:
    """Per row: the trapezoidal rule's error accumulated up to it, estimated from the cumulative work's panels.

    A panel's error is h^3 |p''| / 12 where the power p is smooth, which the second difference of the panel
    increments centred on it estimates. Where the power jumps or kinks inside a panel (an apex, a junction, an
    engagement: the closed form's events fall between the output rows) the difference centred on that panel
    vanishes by symmetry while its neighbours' do not, so each panel takes the largest of the three centred on
    it and on its neighbours: a jump J of the power then gets J h / 8 over the three panels against an error of
    at most J h / 2; a kink J' h^2 / 12 against J' h^2 / 8 (docs/stability.md, 'The closed form's energy
    bound')."""
    inc = np.diff(work)
    panel = np.zeros(len(inc))
    if len(inc) >= 3:
        panel[1:-1] = np.abs(inc[2:] - 2 * inc[1:-1] + inc[:-2]) / 12.0
        panel[0], panel[-1] = panel[1], panel[-2]
        padded = np.concatenate([panel[:1], panel, panel[-1:]])
        panel = np.maximum(np.maximum(padded[:-2], padded[1:-1]), padded[2:])
    return np.concatenate([[0.0], np.cumsum(panel)])


def _energy(df, events, rtol, atol, exact, names=None, quadrature=None, factor=GLOBAL_FACTOR):
    work_names = _works(df, names)
    w = _matrix(df, work_names) if work_names else None
    closure = energy_closure(df, events, names, w)
    if closure is None:
        return None
    if exact:   # closed form: its quadrature's own error estimate
        estimate = quadrature
        if estimate is None or len(estimate) != len(w):     # works by the trapezoidal rule on the rows
            estimate = trapezoid_error_estimate(w.sum(axis=1))
        bound = QUADRATURE_FACTOR * estimate + 1e-12 * np.max(np.abs(w), initial=1.0)
    else:
        scale = float(np.sum(np.max(np.abs(w - w[0]), axis=0)) + np.max(np.abs(df["kinetic_energy_J"])))
        bound = np.full(len(w), factor * (rtol * scale + atol * max(1.0, scale)))
    return "energy balance closure error (J)", np.abs(closure), bound


def first_violation(df: pd.DataFrame, events: pd.DataFrame | None, rtol: float, atol: float,
                    exact: bool = False, columns: list[str] | None = None, quadrature: np.ndarray | None = None,
                    steps: int | None = None) -> Violation | None:
    """The earliest row breaking an invariant, or None. exact: a closed-form table (works by quadrature, whose
    error estimate per row `quadrature` is, dynamics/quadrature.py; without it the trapezoidal rule's on the rows);
    columns: check only the invariants these columns carry (default: every column). df: a frame or its
    TableColumns; steps: the run's accepted steps (`global_factor`), None for a closed form."""
    if df is None or not len(df if not isinstance(df, TableColumns) else df.frame):
        return None
    df = _columns(df)
    frame = df.frame
    names = None if columns is None else [c for c in columns if c in df]
    k = global_factor(steps)
    checks = [_friction(df, rtol, atol, "friction_power_W", "friction power (W)", names, k),
              _friction(df, rtol, atol, "heat_rate_W", "frictional heat rate (W)", names, k),
              _heat_generated(df, rtol, atol, names, k), _energy(df, events, rtol, atol, exact, names, quadrature, k)]
    worst = None
    for check in checks:
        if check is None:
            continue
        label, value, bound = check
        # a one-sided invariant (>= 0) has a negative bound; the closure error's magnitude a positive one
        bad = np.flatnonzero(value > bound) if label.startswith("energy") else np.flatnonzero(value < bound)
        if len(bad) and (worst is None or bad[0] < worst[0]):
            i = int(bad[0])
            worst = (i, label, float(value[i]), float(bound[i]))
    if worst is None:
        return None
    i, label, value, bound = worst
    mode = str(frame["mode"].iloc[i]) if "mode" in (df if names is None else names) else ""
    return Violation(float(frame["t_s"].iloc[i]), mode, label, value, bound)
