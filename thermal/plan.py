"""The thermal model alongside a run: plan it (states for the DAE, how long the mechanics must run), then finish
the result (bulk temperatures where no DAE ran, cycle averaging, flash columns, heat balance, summary).

Columns added (SI): heat_rate_W, heat_share_pin, hertz_half_width_m, hertz_pressure_max_Pa, peclet_pin,
peclet_wheel, temp_flash_rise_K, temp_contact_C; with bulk states temp_bulk_{pin,crank,wheel}_C, heat_share_pin_bulk,
heat_generated_J, heat_pin_J, heat_convected_J; with 1d also temp_wall_surface_C.

Contact temperature (Blok's postulate with unequal base temperatures, docs/theory.md §G4.6): equal surface temperatures
give T_c = gamma T_pin + (1 - gamma) T_wheel + dT_flash exactly, gamma = R_wheel/(R_pin + R_wheel) the pin's share
at equal base temperatures; T_pin/T_wheel are the bulk temperatures (lumped), the wall track's surface (1d) or
the ambient (flash). No contact (dwell): NaN.
"""
from __future__ import annotations

import dataclasses
import math
from dataclasses import dataclass, field
from typing import Callable, ClassVar

import numpy as np
import pandas as pd

import mechsim.thermal.cycle as cyc
from mechsim.thermal.conduction1d import VALID_PECLET_MIN, validity
from mechsim.thermal.exact import ModalNetwork, closed_form_columns, integrate_closed_form, states_between_rows
from mechsim.thermal.flash import flash_temperature
from mechsim.thermal.hertz import effective_modulus, half_width, peak_pressure
from mechsim.thermal.impact import ImpactHeat, impact_flash, impact_share_pin
from mechsim.thermal.models import MODELS
from mechsim.thermal.network import KELVIN, ContactSource, ThermalSetup, ThermalSetupError, prepare
from mechsim.thermal.model_validity import conditions as validity_conditions

__all__ = ["ThermalPlan", "ThermalSetupError", "plan"]

#: averaging = 'auto' picks the cycle-averaged bulk from this many nominal cycles on
AUTO_CYCLES = 50
#: nominal periods of the first mechanics window in cycle mode: closed form (periodic at once), DAE (settling first);
#: a DAE window grows until its crank turns are periodic (`ThermalPlan.extend`)
CYCLE_TURNS_CLOSED_FORM = 2
CYCLE_TURNS_DAE = 6
#: the turns are periodic when the last one's estimated distance from the periodic motion (thermal/cycle.py
#: `turn_periodicity`) is within this (relative: it bounds the error of the cycle-mean heat, and so of the rise after
#: the window, by as much)
PERIODICITY_TOLERANCE = 1e-3
#: the averaging error on a row relative to the rise (`ThermalPlan.averaging_error`) a window must promise: half of
#: the 1 % docs/thermal.md states, the estimate being first order
AVERAGING_TOLERANCE = 5e-3
#: turn-to-turn changes up to this share of the tolerance count as scatter, not as a trend (the rows' interpolation
#: and the solver's tolerance): even a trend as slow as 0.99 per turn adds no more than the tolerance after one
SCATTER = 1e-2
#: the mechanics window may grow to this share of the duration; a motion not periodic by then is resolved whole
WINDOW_SHARE = 0.5
#: windows tried at most before resolving the whole run
WINDOW_TRIES = 5
#: the periodic turn's heat input read between rows (`WindowReadings`) on this many pieces per turn, each piece within
#: one smooth stretch between the window's events, at INPUT_NODES Gauss-Legendre nodes per piece and polynomial
#: between them (`_period_input`)
INPUT_PIECES = 1024
INPUT_NODES = 4
#: Newton steps on the drive angle that put the periodic turn's ends where the drive passes its start angle
TURN_END_STEPS = 4


@dataclass
class WindowReadings:
    """The mechanics window's columns and the network's states at any instants of the window, on its continuous
    solution, not its rows: `read(times)` gives a table of the window's columns (the network's states under their
    extension names) at the instants (at an event: the limit from after it); `breaks`, the window's events (where
    the heat input may jump). With these the cycle averaging takes the periodic turn's ends, its states and energies
    there and its heat input from the solution itself, so that it does not depend on the output step
    (docs/thermal.md, "Reported temperatures")."""

    read: Callable[[np.ndarray], pd.DataFrame]
    breaks: list[float]
    #: what was read of the turn, by what it was read for (finish and the located peaks read the same turn)
    memo: dict = field(default_factory=dict)

def input_pieces(a: float, P: float, breaks) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """(edges, lo, hi) of the pieces the periodic turn [a, a + P) reads its heat input on (`ThermalPlan._read_input`):
    the turn cut at the breaks inside it (the window's events), each stretch [lo, hi] between cuts split evenly
    into ceil((hi - lo) INPUT_PIECES / P) pieces. edges: the pieces' ends in time; lo, hi: for each edge, the ends
    of its stretch, edge = lo + w (hi - lo) with w fixed by the split (the design sensitivities move the edges with
    the cuts so)."""
    cuts = np.unique(np.r_[a, [b for b in breaks if a < b < a + P], a + P])
    parts = [np.linspace(lo, hi, max(1, int(np.ceil((hi - lo) * INPUT_PIECES / P))) + 1)
             for lo, hi in zip(cuts[:-1], cuts[1:])]
    edges = np.concatenate([parts[0]] + [p[1:] for p in parts[1:]])
    lo = np.concatenate([[cuts[0]]] + [np.full(len(p) - 1, c) for p, c in zip(parts, cuts[:-1])])
    hi = np.concatenate([[cuts[1]]] + [np.full(len(p) - 1, c) for p, c in zip(parts, cuts[1:])])
    return edges, lo, hi


def input_nodes() -> np.ndarray:
    """The INPUT_NODES Gauss-Legendre nodes on [0, 1] at which each piece of the periodic turn reads its input."""
    x, _ = np.polynomial.legendre.leggauss(INPUT_NODES)
    return 0.5 * (x + 1.0)


def _with_columns(df: pd.DataFrame, new: dict[str, np.ndarray], drop: list[str]) -> pd.DataFrame:
    """df without `drop`, its columns named in `new` replaced in place and the others of `new` appended in order:
    as assigning them one at a time would, but in one step (each insertion into a frame has a cost of its own). The
    new columns are taken as they are (`copy=False`: not copied into one block, which costs as much as computing
    them on a long run's rows)."""
    dropped = set(drop)
    columns = {c: new[c] if c in new else df[c] for c in df.columns if c not in dropped}
    fresh = {k: v for k, v in new.items() if k not in columns}
    out = pd.DataFrame({**columns, **fresh}, index=df.index, copy=False)
    out.attrs = {} if fresh else dict(df.attrs)         # as joining a frame of the fresh columns left them
    return out


def _angle_column(df: pd.DataFrame) -> str:
    """The drive angle's column (the first angle column: the runner tabulates the drive coordinate first)."""
    return next(c for c in df.columns if c.endswith("_angle_rad"))


def _window_record(duration: float, per, estimate: float) -> dict:
    """One tried mechanics window, its periodicity and the averaging error it would give, for the summary."""
    return {"mechanics_duration_s": float(duration), "turns": int(per.turns),
            "turn_to_turn_change": None if per.change is None else float(per.change),
            "decay_per_turn": None if per.rate is None else float(per.rate), "error_estimate": float(per.error),
            "averaging_error_estimate": float(estimate)}


def _thermal_why(model: str, method: str, n_states: int, backend: str) -> str:
    text = f"thermal.model = '{model}' (scenario): {MODELS[model].description}"
    if MODELS[model].build is None:
        return text
    if method == "dae":
        name = {"ida": "IDA"}.get(backend, backend)
        return text + f"; {n_states} thermal states integrated in the same {name} run as the mechanics"
    return text + ("; prescribed speed needs no DAE: closed-form kinematics + the thermal ODE (the network "
                   "integrated exactly in its modes, thermal/exact.py)")


@dataclass
class ThermalPlan:
    """What the runner needs before and after the mechanics for one scenario's thermal model."""

    #: the thermal columns whose peaks the summary reports (after the mechanism's `peak_columns`)
    PEAK_COLUMNS: ClassVar[tuple[str, ...]] = ("heat_rate_W", "temp_flash_rise_K", "temp_contact_C",
                                               "temp_bulk_pin_C", "temp_bulk_wheel_C")

    setup: ThermalSetup
    si: dict
    mech: ContactSource
    method: str
    speed: float
    averaging: str
    averaging_why: str
    mechanics_duration: float
    warnings: list[str] = field(default_factory=list)
    tried: tuple = ()          # the earlier mechanics windows of cycle mode, each with its periodicity (`extend`)
    fallback: str = ""         # why cycle averaging fell back to the resolved run (`extend`)
    #: a DAE window's `WindowReadings`, set by the runner once a cycle-averaged window has run (a closed form reads
    #: its own); without them (a window that could not be read, or before it ran: `extend`'s estimate) the turn is
    #: read linear between the window's rows
    dense: WindowReadings | None = None
    #: the last closed-form `_window_states` (its key, its result): the finish and the run's thermal reader ask for
    #: the same rows
    _closed_states: tuple | None = field(default=None, init=False, repr=False, compare=False)

    @property
    def extension(self):
        """The StateExtension for the DAE (None when no DAE runs or the model has no states)."""
        return self.setup.extension if self.method == "dae" else None

    @property
    def quadrature_piece(self) -> float:
        """The longest piece of the closed form's quadrature of the heat input (thermal/exact.py
        `ModalNetwork.integrate`): fixed by the cycle, so that the states do not depend on the output step."""
        return self.setup.period / INPUT_PIECES

    @property
    def ext_initial(self):
        return self.setup.initial if self.extension is not None else None

    # ---------------------------------------------------------------------------------------------- finish
    def finish(self, df: pd.DataFrame, events: pd.DataFrame, failed: bool = False, columns=None
               ) -> tuple[pd.DataFrame, pd.DataFrame, dict[str, pd.DataFrame], dict, list[str]]:
        """(timeseries with thermal columns, events, extra tables, summary['thermal'], warnings). With cycle
        averaging the timeseries and events cover the whole duration (thermal/cycle.py: the periodic turn
        continued after the simulated window). columns: df's columns as a mapping of the same arrays, each read
        from the frame once (the runner's dynamics.tables.TableColumns), if at hand: the contact and the closed
        form's switch search read them there instead of from the frame again."""
        setup, mech = self.setup, self.mech
        warnings = list(setup.warnings) + list(self.warnings)
        n_states = setup.system.size + 3 if setup.system else 0
        backend = self.si.get("solver", {}).get("backend", "ida")
        summary = {"model": setup.model, "why": _thermal_why(setup.model, self.method, n_states, backend),
                   "flash": setup.section["flash"], "distribution": setup.section["distribution"],
                   "averaging": self.averaging, "averaging_why": self.averaging_why}
        if self.fallback and self.averaging == "resolved":        # cycle averaging fell back (`extend`: its warning)
            summary["windows_tried"] = list(self.tried)
        extra: dict[str, pd.DataFrame] = {}
        if df.empty:
            return df, events, extra, summary, warnings
        table = df if columns is None else columns
        states, inputs, breaks = self._window_states(df, table)
        events, states, impacts = self._impacts(events, table, states, summary)
        window = None
        if self.averaging == "cycle" and not failed:
            window = self._cycle(df, events, states, inputs, breaks, summary, warnings, extra)
        if window is not None:
            df, events, states = window
            table = df
        elif self.averaging == "cycle":
            summary["averaging"] = "resolved"
            summary["averaging_why"] += ("; the run failed before a periodic cycle" if failed else
                                         "; no full crank turn to average") + ", so what ran is shown resolved"
        t_on_pin = self._time_since(np.asarray(table["t_s"], dtype=float), mech.contact_starts(table, events))
        contact = mech.contact_state(table)
        df = self._add_columns(df, contact, states, t_on_pin)
        if states is not None and window is None:
            summary["heat_balance"] = self._balance(states)
            if impacts is not None:
                summary["heat_balance"]["impacts_J"] = float(np.sum(impacts.energies))
                summary["heat_balance"]["sliding_J"] = summary["heat_balance"]["generated_J"] - float(
                    np.sum(impacts.energies))
        summary.update(setup.describe())
        summary["heat_share"] = ("flash columns: Blok partition of the exact band rises (fast table) with the "
                                 "transient floors of docs/theory.md §G4.7; bulk states: the same partition with the "
                                 "band fit and smooth floors (heat_share_pin_bulk; docs/thermal.md)")
        summary["notes"] = list(setup.notes)
        warnings += self._validity(df, contact, summary)
        return df, events, extra, summary, warnings

    def _impacts(self, events: pd.DataFrame, table, states, summary: dict):
        """(events with impact_flash_rise_K, states with the impacts' heat, the ImpactHeat or None): each impact's
        energy lost (events 'impact...' rows, energy_lost_J, or heat_J where given) enters the network at its
        instant, split between pin and wheel by effusivity, with its flash estimate (thermal/impact.py;
        docs/theory.md §G2.2)."""
        if events is None or not len(events) or "energy_lost_J" not in events:
            return events, states, None
        # a compliant contact's impact loses its energy over the episode (a work column, not the rows' energy_lost_J):
        # its heat_J, on the episode's onset row
        lost = events["heat_J" if "heat_J" in events else "energy_lost_J"].to_numpy(float)
        rows = np.array([str(k).startswith("impact") for k in events["kind"].tolist()], dtype=bool) & np.isfinite(lost)
        if not rows.any():
            return events, states, None
        setup, geo, mat = self.setup, self.setup.geometry, self.setup.material
        hit = events[rows]
        t_k, energy = hit["t_s"].to_numpy(float), np.maximum(lost[rows], 0.0)
        e = mat.conductivity / math.sqrt(mat.diffusivity)
        flash = impact_flash(energy, hit["approach_speed_m_s"].to_numpy(float), hit["impact_mass_kg"].to_numpy(float),
                             geo.contact_radius, geo.contact_length, effective_modulus(mat), 2 * e)
        column = np.full(len(events), np.nan)
        column[rows] = flash["rise_K"]
        events = events.assign(impact_flash_rise_K=column)
        share = impact_share_pin(mat.conductivity, mat.diffusivity, mat.conductivity, mat.diffusivity)
        t = np.asarray(table["t_s"], dtype=float)
        wheel = np.ones(len(t_k), dtype=int)
        if setup.mesh is not None:                    # the wheel's share into the surface of the track in contact
            track = np.asarray(self.mech.contact_state(table)["track"], dtype=float)
            at = np.clip(np.searchsorted(t, t_k, side="left"), 0, len(t) - 1)
            wheel = 1 + np.mod(np.rint(track[at]), geo.tracks).astype(int)
        heat = ImpactHeat(t_k, energy, wheel, share)
        peak = int(np.argmax(flash["rise_K"]))
        summary["impacts"] = {
            "count": int(len(t_k)), "heat_J": float(np.sum(energy)), "heat_share_pin": share,
            "flash_rise_max_K": float(flash["rise_K"][peak]), "flash_rise_max_t_s": float(t_k[peak]),
            "duration_at_max_s": float(flash["duration_s"][peak]), "force_at_max_N": float(flash["force_N"][peak]),
            "half_width_at_max_m": float(flash["half_width_m"][peak]),
            "source": "each impact's energy lost enters the network at its instant, split by effusivity (stationary "
                      "source, Carslaw & Jaeger §2.9); flash estimate: half-sine pulse of a linear contact spring "
                      "E* l under the impact's effective mass, its heat uniform over the Hertz band for the pulse "
                      "(docs/theory.md §G2.2)"}
        if states is None:
            return events, states, heat
        n = setup.system.size
        dT, generated, pin, convected = heat.response(ModalNetwork(setup.system), setup.system.capacity,
                                                      setup.system.input_matrix, setup.extension.loss, t)
        states = np.array(states, dtype=float, copy=True)
        states[:, :n] += dT
        states[:, n] += generated
        states[:, n + 1] += pin
        states[:, n + 2] += convected
        return events, states, heat

    def _window_states(self, df: pd.DataFrame, table=None):
        """(states, input function, its breaks) of the thermal network over the mechanics table `df`: the DAE's
        states (input function None), or with the closed form the network integrated exactly in its modes along
        the closed-form motion (thermal/exact.py `integrate_closed_form`); (None, None, None) without states.
        table: df's columns as a mapping (see `finish`), if at hand."""
        setup, mech, ext = self.setup, self.mech, self.setup.extension
        if ext is None:
            return None, None, None
        table = df if table is None else table
        if self.method == "dae":        # the states' columns side by side (as df[names].to_numpy(float) gives them)
            states = np.array([np.asarray(table[c], dtype=float) for c in ext.names])
            return states.reshape(len(ext.names), -1).T, None, None
        angle0, t = self.si["initial"][mech.initial_keys[0]], np.asarray(table["t_s"], dtype=float)
        key = (angle0, self.speed, self.quadrature_piece, np.asarray(setup.initial, dtype=float).tobytes(),
               t.tobytes())
        kept = self._closed_states
        if kept is None or kept[0] is not ext or kept[1] is not mech or kept[2] != key:
            self._closed_states = ext, mech, key, integrate_closed_form(
                ext, mech, angle0, self.speed, t, setup.initial, table=table, max_piece=self.quadrature_piece)
        states, inputs, breaks = self._closed_states[3]
        return states.copy(), inputs, list(breaks)

    def cycle_bulk(self, df: pd.DataFrame, t_rows, repetitions) -> tuple[np.ndarray, np.ndarray]:
        """(times, bulk states in K) of the run's cycle-averaged bulk at the window's rows t_rows repeated
        `repetitions` periods later (t_k + m P, P the run's period: the times `continue_periodically` writes),
        from its mechanics window `df` (as the runner hands it to `finish`; with the closed form also the
        window's finished table): the same turn, cycle means, period input and `bulk_response` as `_cycle`,
        evaluated at those times only. The design sensitivities read the run's own peak contact temperature this
        way at a prescribed speed (docs/sensitivity.md, "Cycle averaging") without continuing the whole duration."""
        states, inputs, breaks = self._window_states(df)
        readings = self._readings(df, states, inputs, breaks)
        means = self._cycle_means(df, states, readings)
        if states is None or means is None:
            raise ValueError("cycle_bulk needs bulk states and a full turn in the window")
        u_of_phase, phase_breaks = self._period_input(df, states, inputs, breaks, means, readings)
        times = np.asarray(t_rows, float) + np.asarray(repetitions) * means.period
        return times, cyc.bulk_response(self.setup.system, means, u_of_phase, phase_breaks, times)[1]

    def cycle_solution(self, df: pd.DataFrame) -> dict | None:
        """The cycle-averaged solution `finish` continues the mechanics window `df` with (`_cycle`): the periodic
        turn's start and period, and with bulk states its cycle means and period input, so that `cycle_states`
        gives the network's states at any instant after the window (the located peaks read them between rows).
        None without a full turn."""
        states, inputs, breaks = self._window_states(df)
        readings = self._readings(df, states, inputs, breaks)
        means = self._cycle_means(df, states, readings)
        if means is None:
            return None
        out = {"t_start": means.t_start, "period": means.period, "means": means}
        if states is not None:
            out["input"] = self._period_input(df, states, inputs, breaks, means, readings)
        return out

    def cycle_states(self, solution: dict, times) -> np.ndarray:
        """The network's states (K, one row per instant) of the cycle-averaged solution (`cycle_solution`) at
        `times` after the window: thermal/cycle.py `bulk_response`, as `_cycle` writes them on the later rows."""
        u_of_phase, phase_breaks = solution["input"]
        return cyc.bulk_response(self.setup.system, solution["means"], u_of_phase, phase_breaks,
                                 np.asarray(times, float), solution.setdefault("cache", {}))[1]

    def _readings(self, df: pd.DataFrame, states, inputs, breaks) -> WindowReadings | None:
        """The window's `WindowReadings`: a closed form's own (its columns at the instants, the network integrated
        exactly from the row before each, thermal/exact.py `states_between_rows`), a DAE window's as the runner
        set them (`dense`); None without bulk states or readings (the rows then stand for the solution)."""
        if states is None:
            return None
        if self.method != "closed-form":
            return self.dense
        ext = self.setup.extension
        columns = closed_form_columns(self.mech, self.si["initial"][self.mech.initial_keys[0]], self.speed)
        network = ModalNetwork(ext.system, ext.loss)
        t = df["t_s"].to_numpy(float)

        def read(times):
            times = np.asarray(times, dtype=float)
            got = states_between_rows(network, inputs, breaks, t, states, times, self.quadrature_piece)
            return pd.DataFrame({**columns(times), **{name: got[:, j] for j, name in enumerate(ext.names)}})
        return WindowReadings(read, list(breaks))

    def _turn_ends(self, df: pd.DataFrame, bounds: np.ndarray, readings: WindowReadings) -> np.ndarray:
        """The instants the drive passes its start angle + 2 pi m near `bounds` (the rows' linear estimates), on the
        continuous solution: Newton on the angle read there, its speed the slope."""
        key = ("ends", tuple(np.asarray(bounds, dtype=float).tolist()))
        if key in readings.memo:
            return readings.memo[key]
        column = _angle_column(df)
        speed = column[:-len("_angle_rad")] + "_speed_rad_s"
        angle = df[column].to_numpy(float)
        t = df["t_s"].to_numpy(float)
        targets = angle[0] + 2 * np.pi * np.round((np.interp(bounds, t, angle) - angle[0]) / (2 * np.pi))
        ends = np.asarray(bounds, dtype=float)
        for _ in range(TURN_END_STEPS):
            got = readings.read(ends)
            ends = ends - (got[column].to_numpy(float) - targets) / got[speed].to_numpy(float)
        readings.memo[key] = ends
        return ends

    def _cycle_means(self, df: pd.DataFrame, states, readings: WindowReadings | None = None):
        """The cycle means of the last full turn of the window (thermal/cycle.py `cycle_means_from_energies`) with
        the network's states at its start, or None with fewer than one full turn: with `readings` the turn's ends
        where the drive passes its start angle and the energies and states there read on the continuous solution,
        else the rows' (linear between them)."""
        t = df["t_s"].to_numpy(float)
        angle = df[_angle_column(df)].to_numpy(float)
        bounds = cyc.turn_boundaries(t, angle, angle[0])
        if len(bounds) < 2:
            return None
        if readings is not None and states is not None:
            n, names = self.setup.system.size, list(self.setup.extension.names)
            ends = self._turn_ends(df, bounds[-3:], readings)
            at = readings.read(ends)[names].to_numpy(float)
            means = cyc.cycle_means_from_energies(ends, ends, at[:, n], at[:, n + 1])
            means.start = at[-2, :n]
            return means
        if states is None:            # flash only: nothing to extrapolate, the last turn is the periodic state
            e_gen = self._heat_generated(df, t)
            return cyc.CycleMeans(float(bounds[-2]), float(bounds[-1] - bounds[-2]),
                                  float(np.diff(np.interp(bounds[-2:], t, e_gen))[0] / (bounds[-1] - bounds[-2])),
                                  float("nan"), None)
        n = self.setup.system.size
        means = cyc.cycle_means_from_energies(t, bounds, states[:, n], states[:, n + 1])
        means.start = np.array([np.interp(means.t_start, t, states[:, j]) for j in range(n)])
        return means

    def _heat_generated(self, df: pd.DataFrame, t: np.ndarray) -> np.ndarray:
        """The heat generated up to each row from the contact's heat rate (trapezoidal), where no state keeps it."""
        q = self.mech.contact_state(df)["heat_rate"]
        return np.concatenate([[0.0], np.cumsum(0.5 * (q[1:] + q[:-1]) * np.diff(t))])

    def periodicity(self, df: pd.DataFrame, states=None) -> cyc.Periodicity:
        """How periodic the crank turns of the mechanics window `df` are (thermal/cycle.py `turn_periodicity`)."""
        if states is None:
            states = self._window_states(df)[0]
        t = df["t_s"].to_numpy(float)
        column = _angle_column(df)
        angle = df[column].to_numpy(float)
        speed_column = column[:-len("_angle_rad")] + "_speed_rad_s"
        speed = df[speed_column].to_numpy(float) if speed_column in df else np.gradient(angle, t)
        energy = self._heat_generated(df, t) if states is None else states[:, self.setup.system.size]
        accel_column = column[:-len("_angle_rad")] + "_accel_rad_s2"
        accel = df[accel_column].to_numpy(float) if accel_column in df else None
        power = np.asarray(self.mech.contact_state(df)["heat_rate"], dtype=float)
        return cyc.turn_periodicity(t, angle, speed, energy, SCATTER * PERIODICITY_TOLERANCE, accel, power)

    def averaging_error(self, df: pd.DataFrame, states, per: cyc.Periodicity,
                        readings: WindowReadings | None = None) -> float:
        """The cycle averaging's estimated error on a row, relative to the bulk body's rise over the run (the largest
        over the bodies): the level, the continued turn's heat off by per.error, so per.error times the rise after
        the turn's start (the mean curve's), plus the phase drift of the in-cycle swing, the time continued times
        per.period_error, times the body's largest rate of change over the turn, plus how far the continuation
        misses the resolved states over the turn itself, twice (its input linear between rows where the resolved
        run's is not: that error repeats in the swing and stays in the mean curve's start, but does not grow).
        Without bulk states per.error. readings: the window's `WindowReadings`, where the run reads the turn with
        them."""
        if states is None or not math.isfinite(per.error):
            return per.error
        means = self._cycle_means(df, states, readings)
        if means is None:
            return math.inf
        _, inputs, breaks = self._window_states(df)
        u_of_phase, phase_breaks = self._period_input(df, states, inputs, breaks, means, readings)
        t = df["t_s"].to_numpy(float)
        own = (t > means.t_start) & (t <= means.t_start + means.period)
        if own.sum() < 2:       # rows a turn apart cannot say (scenarios/runner.py `rows_every` keeps a plan off them)
            return math.inf
        again = cyc.bulk_response(self.setup.system, means, u_of_phase, phase_breaks, t[own])[1]
        miss = np.max(np.abs(again - states[own, :again.shape[1]]), axis=0)
        system, n = self.setup.system, self.setup.system.size
        duration = float(self.si["duration"])
        u_bar = np.array([means.share_mean * means.heat_mean, (1.0 - means.share_mean) * means.heat_mean])
        T_end = ModalNetwork(system).constant(means.start, u_bar, [max(duration - means.t_start, 0.0)],
                                              energy=False)[0][0]
        turn = (t >= means.t_start) & (t <= means.t_start + means.period)
        slope = np.max(np.abs(np.gradient(states[:, :n], t, axis=0)[turn]), axis=0)
        drift = max(duration - means.t_start - means.period, 0.0) * per.period_error
        worst = 0.0
        for j, name in enumerate(system.state_names):
            rise = abs(T_end[j] - states[0, j])
            if name.startswith("temp_bulk_") and rise > 0:
                worst = max(worst, (per.error * abs(T_end[j] - means.start[j]) + drift * slope[j] + 2 * miss[j]) / rise)
        return float(worst)

    def extend(self, df: pd.DataFrame) -> "ThermalPlan | None":
        """None where the mechanics window `df` serves cycle averaging (its turns periodic to PERIODICITY_TOLERANCE,
        or not averaging); otherwise the plan of the next try: a longer window, as long as the measured decay of
        the turn-to-turn change says is needed (twice as long where it cannot say yet), or, where that is beyond
        WINDOW_SHARE of the duration (or WINDOW_TRIES windows were tried), the whole run resolved, saying why."""
        if self.averaging != "cycle":
            return None
        states = self._window_states(df)[0]
        per = self.periodicity(df, states)
        estimate = self.averaging_error(df, states, per)
        if per.error <= PERIODICITY_TOLERANCE and estimate <= AVERAGING_TOLERANCE:
            return None
        # the estimate scales with per.error (level and drift alike): the distance that brings it within tolerance
        tolerance = PERIODICITY_TOLERANCE
        if math.isfinite(estimate) and estimate > AVERAGING_TOLERANCE:
            tolerance = min(tolerance, per.error * AVERAGING_TOLERANCE / estimate)
        duration, step = float(self.si["duration"]), float(self.si["output_step"])
        period = float(per.ends[-1] - per.ends[-2]) if per.turns else self.setup.period
        needed = per.turns_needed(tolerance)
        if needed is None:
            window = 2.0 * self.mechanics_duration
        else:       # the turns still needed, one more for the partial turn at the window's end, 5 % margin
            window = float(per.ends[-1]) + 1.05 * (needed - per.turns + 1) * period + 2 * step
        window = max(window, self.mechanics_duration + 2 * period)
        tried = self.tried + (_window_record(self.mechanics_duration, per, estimate),)
        allotted = WINDOW_SHARE * duration
        if window <= allotted and len(tried) < WINDOW_TRIES:
            return dataclasses.replace(self, mechanics_duration=window, tried=tried)
        state = (f"after {per.turns} crank turns ({self.mechanics_duration:.4g} s) the turns still change by "
                 f"{per.change:.2g} from one to the next" if per.change is not None else
                 f"only {per.turns} full crank turn(s) in {self.mechanics_duration:.4g} s")
        if per.rate is not None and per.change is not None and per.change > SCATTER * tolerance:
            state += (f", decaying by {per.rate:.3g} per turn" if per.rate < 1 else
                      f", not decaying ({per.rate:.3g} per turn)")
        outlook = (f"about {needed} turns ({window:.4g} s) would be needed" if needed is not None else
                   "its trend does not yet tell when they will repeat")
        short = ([f"the averaging error {estimate:.2g} of the temperature rise exceeds the {AVERAGING_TOLERANCE:g} "
                  "allowed"] if not estimate <= AVERAGING_TOLERANCE else []) + (
                 [f"the last turn's distance {per.error:.2g} from the periodic motion exceeds the "
                  f"{PERIODICITY_TOLERANCE:g} allowed"] if not per.error <= PERIODICITY_TOLERANCE else [])
        why = (f"the crank turns do not repeat closely enough for averaging within the window allotted (up to "
               f"{WINDOW_SHARE:g} of the duration, {allotted:.4g} s): {' and '.join(short)}; {state}, {outlook}; so "
               "the whole run is resolved")
        return dataclasses.replace(self, averaging="resolved", averaging_why=self.averaging_why + "; but " + why,
                                   mechanics_duration=duration, tried=tried, fallback=why,
                                   warnings=self.warnings + ["thermal: cycle averaging fell back to the resolved run: "
                                                             + why])

    @staticmethod
    def _time_since(t: np.ndarray, starts: np.ndarray, before: np.ndarray | None = None) -> np.ndarray:
        """Time since the latest contact start (inf before the first); where `before`, the limit from before t: a
        contact starting at t has not begun (the time since the one before it)."""
        if not len(starts):
            return np.full(t.shape, np.inf)
        i = np.searchsorted(starts, t + 1e-12, side="right") - 1
        if before is not None and before.any():
            i = np.where(before, np.searchsorted(starts, t - 1e-12, side="left") - 1, i)
        out = np.where(i >= 0, t - starts[np.clip(i, 0, None)], np.inf)
        return np.clip(out, 0.0, None)

    # ---------------------------------------------------------------------------------------------- columns
    def _add_columns(self, df: pd.DataFrame, contact: dict, states, t_on_pin) -> pd.DataFrame:
        """The table with the thermal columns (module docstring) and without the DAE's temperature states."""
        return _with_columns(df, *self.thermal_columns(df, contact, states, t_on_pin))

    def thermal_columns(self, df, contact: dict, states, t_on_pin) -> tuple[dict[str, np.ndarray], list[str]]:
        """(the thermal columns of `_add_columns` by name, the DAE's temperature states to drop) of the table `df`
        (a frame or a mapping of its column arrays) and its contact state, states and times on the pin."""
        setup, geo, mat = self.setup, self.setup.geometry, self.setup.material
        th = setup.section
        N = contact["normal_force"]
        engaged = contact["engaged"] & (N != 0)
        U_wall = np.abs(contact["source_speed_driven"])
        U_pin = np.abs(contact["source_speed_driver"])
        E_star = effective_modulus(mat)
        b = half_width(N, geo.contact_radius, geo.contact_length, E_star)
        with np.errstate(divide="ignore", invalid="ignore"):
            t_cross = np.where(U_wall > 0, 2 * b / U_wall, np.inf)
            a_s = np.abs(contact["sliding_accel"])
            t_turn = np.where(a_s > 0, 2 * np.sqrt(2 * b / a_s), np.inf)
        t_on_wall = np.where(engaged, np.minimum(t_cross, t_turn), np.inf)
        t_on_pin = np.where(engaged, t_on_pin, np.inf)
        mu = float(self.si.get("contact", {}).get("friction", 0.0))
        res = flash_temperature(N, contact["slip_speed"], U_wall, U_pin, b, geo.contact_length, mu, mat, mat,
                                t_on_pin=t_on_pin, t_on_wall=t_on_wall, distribution=th["distribution"])
        rise = res["temp_flash_rise_K"]
        if th["flash"] == "seed-blok":
            seed_speed = geo.driver_arm * np.asarray(df["crank_speed_rad_s"], dtype=float)
            rise = flash_temperature(N, contact["slip_speed"], U_wall, seed_speed, b, geo.contact_length, mu, mat,
                                     mat, distribution=th["distribution"], method="seed-blok")["temp_flash_rise_K"]
        share = np.where(engaged, res["heat_share_pin"], np.nan)
        base_pin = base_wheel = np.full(len(N), setup.temp_ambient)
        new: dict[str, np.ndarray] = {}
        drop: list[str] = []
        if states is not None:
            names = setup.system.state_names
            base_pin = states[:, names.index("temp_bulk_pin_K")]
            base_wheel = states[:, names.index("temp_bulk_wheel_K")]
            for j, name in enumerate(setup.extension.names):
                if name.startswith("temp_bulk_"):
                    new[name[:-2] + "_C"] = states[:, j] - KELVIN
                elif not name.startswith("temp_wall_") and not np.all(np.isnan(states[:, j])):
                    new[name] = states[:, j]
            u, _, gamma_bulk = setup.extension.inputs_numeric(contact)
            new["heat_share_pin_bulk"] = np.where(engaged, gamma_bulk, np.nan)
            if setup.mesh is not None:
                surface = self._wall_surface(states, u, contact["track"])
                new["temp_wall_surface_C"] = surface - KELVIN
                base_wheel = surface
            drop = [c for c in setup.extension.names if c in df and c.startswith("temp_")]
        base = np.where(engaged, share * base_pin + (1.0 - share) * base_wheel, np.nan)
        new["heat_rate_W"] = res["heat_rate_W"]
        new["heat_share_pin"] = share
        new["hertz_half_width_m"] = b
        new["hertz_pressure_max_Pa"] = peak_pressure(N, geo.contact_radius, geo.contact_length, E_star)
        new["peclet_pin"] = res["peclet_pin"]
        new["peclet_wheel"] = res["peclet_wheel"]
        new["temp_flash_rise_K"] = rise
        new["temp_contact_C"] = base + rise - KELVIN
        return new, drop

    def _wall_surface(self, states, u, track) -> np.ndarray:
        """Surface temperature of the wall track under the contact: T_0 + q dz_0/(2k), q = heat into it / area."""
        setup = self.setup
        n = setup.geometry.tracks
        j = np.mod(np.rint(track), n).astype(int)
        dz0 = float(setup.mesh.widths[0])
        out = np.empty(len(track))
        for jj, idx in setup.mesh_states.items():
            rows = j == jj
            q = u[1 + jj][rows] / setup.track_area
            out[rows] = states[rows, idx[0]] + q * dz0 / (2 * setup.material.conductivity)
        return out

    def _balance(self, states) -> dict:
        sysm = self.setup.system
        n = sysm.size
        generated = float(states[-1, n] - states[0, n])
        stored = float(sysm.capacity @ (states[-1, :n] - states[0, :n]))
        convected = float(states[-1, n + 2] - states[0, n + 2])
        closure = generated - stored - convected
        return {"generated_J": generated, "stored_J": stored, "convected_J": convected,
                "into_pin_J": float(states[-1, n + 1] - states[0, n + 1]), "closure_error_J": closure,
                "closure_error_relative": closure / generated if generated > 0 else 0.0}

    # ---------------------------------------------------------------------------------------------- cycle mode
    def _cycle(self, df, events, states, inputs, breaks, summary, warnings, extra):
        """Cycle averaging: the window resolved up to its last row on the output grid, then the last full turn
        continued periodically on the output grid up to the duration, with the bulk states of the averaged
        solution (mean + periodic ripple) from the window's states at the turn's start. (table, events, states)
        or None when there is no full turn to average."""
        setup, mech = self.setup, self.mech
        readings = self._readings(df, states, inputs, breaks)
        means = self._cycle_means(df, states, readings)
        if means is None:
            warnings.append("thermal: fewer than one full crank turn in the mechanics window; shown resolved")
            return None
        per = self.periodicity(df, states)
        estimate = self.averaging_error(df, states, per, readings)
        n = None if states is None else setup.system.size
        duration, step = float(self.si["duration"]), float(self.si["output_step"])
        given = None
        if self.method == "closed-form":     # the closed form is exact at any time: its own values there
            given = closed_form_columns(mech, self.si["initial"][mech.initial_keys[0]], self.speed)
        full, full_events, t_sim, kept = cyc.continue_periodically(df, events, means.t_start, means.period, duration,
                                                                   step, given)
        times = full["t_s"].to_numpy(float)
        later = times > t_sim
        info = {"period_s": means.period, "mean_heat_rate_W": means.heat_mean,
                "mean_heat_share_pin": None if states is None else means.share_mean,
                "turns_simulated": int(per.turns), "mechanics_simulated_until_s": t_sim,
                "periodic_turn_s": [means.t_start, means.t_start + means.period],
                "rows_continued_periodically": int(later.sum()),
                "continuation": ("rows up to mechanics_simulated_until_s are the resolved run's; later rows are on "
                                 "the output grid, the last full turn (periodic_turn_s) at their phase "
                                 + ("given exactly by the closed form" if self.method == "closed-form" else
                                    "interpolated linearly between its rows")
                                 + ", with the bulk temperatures of the cycle-averaged solution continued from the "
                                 "resolved states at the turn's start"),
                "periodicity": {"turn_to_turn_change": per.change, "decay_per_turn": per.rate,
                                "turn_changes": [float(x) for x in per.changes],
                                "error_estimate": per.error, "period_error_estimate": per.period_error,
                                "tolerance": PERIODICITY_TOLERANCE},
                "averaging_error_estimate": estimate, "averaging_tolerance": AVERAGING_TOLERANCE,
                "windows_tried": list(self.tried) + [_window_record(self.mechanics_duration, per, estimate)],
                "periodicity_of_mean_heat": means.periodicity}
        summary["averaging_why"] += (f"; the mechanics ran {per.turns} crank turns until periodic (resolved up to "
                                     f"{t_sim:.6g} s; the last turn's change from the one before "
                                     + (f"{per.change:.2g}" if per.change is not None else "not measured (one turn)")
                                     + ")")
        summary["averaging_note"] = (f"thermal: cycle-averaged after {per.turns} crank turns resolved (0 to "
                                     f"{t_sim:.4g} s); estimated averaging error {estimate:.1g} of the temperature "
                                     "rise (the turns' distance from periodic, the phase drift it gives the in-cycle "
                                     "swing, the turn's own reproduction)")
        if per.error > PERIODICITY_TOLERANCE or estimate > AVERAGING_TOLERANCE:
            warnings.append(f"thermal: the mechanics is not yet periodic after {per.turns} crank turns (estimated "
                            f"distance of the last turn from the periodic motion {per.error:.2g}, averaging error "
                            f"{estimate:.2g} of the rise)")
        summary["cycle"] = info
        if states is None:
            return full, full_events, None
        u_of_phase, phase_breaks = self._period_input(df, states, inputs, breaks, means, readings)
        full_states = np.full((len(full), n + 3), np.nan)      # per-row energies after t_sim: see the history table
        full_states[:len(kept)] = states[kept]
        if later.any():
            full_states[later, :n] = cyc.bulk_response(setup.system, means, u_of_phase, phase_breaks,
                                                       times[later])[1]
        t_window = df["t_s"].to_numpy(float)
        extra["thermal_history"] = cyc.history_table(setup.system, means, u_of_phase, phase_breaks, duration,
                                                     KELVIN, (t_window, states), t_sim)
        summary["heat_balance"] = self._mean_balance(means, duration, t_window, states)
        full = full.drop(columns=[c for c in setup.extension.names if c in full])
        return full, full_events, full_states

    def _period_input(self, df, states, inputs, breaks, means, readings: WindowReadings | None = None):
        """u(phase) over the periodic turn (phase 0 = means.t_start) and the phases where it jumps: a closed form's
        own; a DAE window's read on its solution where `readings` are given (`_read_input`), else linear between
        its rows."""
        a, P = means.t_start, means.period
        if inputs is not None:                                    # closed form: exact at any time
            n_in = self.setup.system.input_matrix.shape[1]
            return (lambda s: inputs(a + s)[:n_in]), [b - a for b in breaks if a < b < a + P]
        if readings is not None:
            return self._read_input(readings, a, P)
        t = df["t_s"].to_numpy(float)
        u, _, _ = self.setup.extension.inputs_numeric(self.mech.contact_state(df))
        # the input is linear between output rows: every row inside the turn is a break, so that the quadratures
        # of the mean and of the ripple are exact for it (thermal/cycle_exact.py gives the same in closed form)
        rows = [float(x) - a for x in t[(t > a) & (t < a + P)]]
        return (lambda s: np.array([np.interp(a + s, t, ui) for ui in u])), rows

    def _read_input(self, readings: WindowReadings, a: float, P: float):
        """(u(phase), the phases of its pieces' ends) of the turn [a, a + P) read on the window's solution: each
        smooth stretch between the window's events split into pieces of at most P/INPUT_PIECES, the input read at
        INPUT_NODES Gauss-Legendre nodes of each (never at an event: a jump is met from its own side) and
        polynomial through them on the piece. The pieces are fixed by the turn and its events, not by the output
        rows; the quadratures of the mean and the ripple split at their ends (thermal/cycle.py `bulk_response`)."""
        if ("input", a, P) in readings.memo:
            return readings.memo[("input", a, P)]
        edges = input_pieces(a, P, readings.breaks)[0] - a
        h = np.diff(edges)
        x = input_nodes()
        frame = readings.memo[("frame", a, P)] = readings.read(a + (edges[:-1, None] + h[:, None] * x[None, :]).ravel())
        u, _, _ = self.setup.extension.inputs_numeric(self.mech.contact_state(frame))
        u = u.reshape(len(u), len(h), INPUT_NODES)
        # Lagrange basis through the nodes: weights[j] = 1 / prod_{m != j} (x_j - x_m)
        weights = np.array([1.0 / np.prod([x[j] - x[m] for m in range(INPUT_NODES) if m != j])
                            for j in range(INPUT_NODES)])

        def u_of_phase(s):
            s = np.asarray(s, dtype=float)
            k = np.clip(np.searchsorted(edges, s, side="right") - 1, 0, len(h) - 1)
            xi = (s - edges[k]) / h[k]
            basis = np.stack([weights[j] * np.prod([xi - x[m] for m in range(INPUT_NODES) if m != j], axis=0)
                              for j in range(INPUT_NODES)])
            return np.einsum("isj,js->is", u[:, k, :], basis)
        got = readings.memo[("input", a, P)] = (u_of_phase, [float(b) for b in edges[1:-1]])
        return got

    def _mean_balance(self, means, duration, t_window, states) -> dict:
        """Heat balance at the end of the run: the window's bookkeeping states up to the periodic turn's start a
        (linear between rows), then the cycle-mean heat from the states there (exact modal solution, convected
        integral)."""
        setup = self.setup
        n = setup.system.size
        a = means.t_start
        at_a = np.array([np.interp(a, t_window, states[:, j]) for j in range(n + 3)])
        u = np.array([means.share_mean * means.heat_mean, (1 - means.share_mean) * means.heat_mean])
        T0 = states[0, :n]
        T, convected = ModalNetwork(setup.system, setup.extension.loss).constant(at_a[:n], u, [duration - a])
        generated = at_a[n] - states[0, n] + means.heat_mean * (duration - a)
        stored = float(setup.system.capacity @ (T[0] - T0))
        convected = at_a[n + 2] - states[0, n + 2] + float(convected[0])
        closure = generated - stored - convected
        return {"generated_J": float(generated), "stored_J": stored, "convected_J": float(convected),
                "into_pin_J": float(at_a[n + 1] - states[0, n + 1] + means.share_mean * means.heat_mean
                                    * (duration - a)),
                "closure_error_J": float(closure),
                "closure_error_relative": float(closure / generated) if generated > 0 else 0.0,
                "basis": "the resolved window's bookkeeping up to the periodic turn's start, then the cycle-mean "
                         "heat from the states there (exact modal solution)"}

    # ---------------------------------------------------------------------------------------------- validity
    def validity_conditions(self) -> list[dict]:
        """The conditions this thermal model's formulas need on every row (thermal/model_validity.py), as data."""
        return validity_conditions(self.setup.section, self.setup.geometry, self.setup.material)

    def _validity(self, df, contact, summary) -> list[str]:
        """Warnings on the 1-D mesh and track (run-level checks; the per-row conditions are
        `validity_conditions`)."""
        setup, geo, mat = self.setup, self.setup.geometry, self.setup.material
        out = []
        if setup.mesh is None:
            return out
        engaged = contact["engaged"]
        U = np.abs(contact["source_speed_driven"][engaged])
        L_contact = df["peclet_wheel"].to_numpy(float)[engaged]
        if len(L_contact):
            L = float(np.max(L_contact))
            if not validity(L)[0]:
                out.append(f"thermal (1d): the wheel's Peclet number reaches only {L:.3g} (< {VALID_PECLET_MIN:g}), "
                           "where a 1-D mesh would neglect lateral conduction and over-predict the flash rise "
                           "(docs/theory.md §G6): here it carries only the track-scale heating (the wall's heat "
                           "spread over its swept track), and the flash rise on top comes from the exact moving-band "
                           "solution (§G4.3)")
        if len(U):
            L_track = float(np.mean(U)) * 0.5 * geo.track_length / (2 * mat.diffusivity)
            summary["track_peclet"] = L_track
            if not validity(L_track)[0]:
                out.append(f"thermal (1d): the contact sweeps the slot-wall track slowly (track Peclet number "
                           f"{L_track:.3g} < {VALID_PECLET_MIN:g}), so conduction along the track is not negligible "
                           "and the 1-D depth model of the track does not hold (docs/theory.md §G6)")
        penetration = math.sqrt(mat.diffusivity * setup.engagement_time)
        if setup.mesh.widths[0] > 0.25 * penetration:
            out.append(f"thermal (1d): first cell {setup.mesh.widths[0]:.3g} m is coarse against the depth heated "
                       f"during one engagement, {penetration:.3g} m; refine thermal.mesh_first_cell")
        periodic = math.sqrt(mat.diffusivity * geo.tracks * setup.period / math.pi)
        if setup.mesh.depth < periodic:
            out.append(f"thermal (1d): mesh depth {setup.mesh.depth:.3g} m is shallower than the periodic penetration "
                       f"depth {periodic:.3g} m; the far face ties the wall to the bulk too close to the surface")
        return out


def plan(si: dict, mech: ContactSource, drive, method: str) -> ThermalPlan | None:
    """The thermal plan of a validated scenario (None for thermal.model = 'none'); ThermalSetupError names a
    [thermal] value that cannot work with this mechanism."""
    model = si.get("thermal", {}).get("model", "none")
    if model == "none":
        return None
    setup = prepare(si, mech, MODELS[model])
    th = setup.section
    duration = float(si["duration"])
    cycles = duration / setup.period
    turns = CYCLE_TURNS_CLOSED_FORM if method == "closed-form" else CYCLE_TURNS_DAE
    window = turns * setup.period + 2 * si["output_step"]
    varying = getattr(mech, "varying_load", False) or getattr(drive, "has_duty", False)
    if varying and th["averaging"] == "cycle":
        # the cycle average needs crank turns that repeat; a load or drive varying in time breaks that
        raise ThermalSetupError("averaging", "'cycle' needs a steady load and drive; with a time-varying load or "
                                             "a duty cycle use 'resolved' (docs/theory.md, 'Time-varying loads and "
                                             "drives')")
    impacts = getattr(mech, "impacts", False)
    if impacts and th["averaging"] == "cycle":
        # the cycle mean reads the sliding heat of the window's rows; the impacts' heat arrives at instants
        raise ThermalSetupError("averaging", "'cycle' does not carry the impacts' heat (mechanism.slot_clearance > "
                                             "0); use 'resolved' (docs/theory.md §G2.2)")
    if th["averaging"] == "cycle":
        averaging, why = "cycle", "thermal.averaging = 'cycle' (scenario)"
    elif th["averaging"] == "resolved":
        averaging, why = "resolved", "thermal.averaging = 'resolved' (scenario)"
    elif varying:
        averaging, why = "resolved", "auto: the load or drive varies in time, so every cycle is resolved"
    elif impacts:
        averaging, why = "resolved", "auto: the contact has impacts, whose heat arrives at their instants, so every " \
                                     "cycle is resolved"
    elif MODELS[model].every_cycle:
        averaging, why = "resolved", f"auto: model = '{model}' resolves every cycle (it follows each engagement)"
    elif cycles >= AUTO_CYCLES:
        head = f"auto: duration {duration:.6g} s = {cycles:.0f} cycles of {setup.period:.4g} s (>= {AUTO_CYCLES})"
        until = (f"the mechanics runs, resolved, until its crank turns repeat (to {PERIODICITY_TOLERANCE:g}, within "
                 f"{WINDOW_SHARE:g} of the duration; else the whole run is resolved)")
        if setup.system is None:
            tail = (f"; the flash model has no memory, so {until} and its last turn, continued to the end of the "
                    "run, stands for every later cycle")
        else:
            tail = (f"; the bulk time constants are >> one cycle (docs/theory.md §G5), so {until} and the cycle-mean "
                    "heat drives the bulk exactly from there (plus its periodic ripple)")
        averaging, why = "cycle", head + tail
    else:
        averaging, why = "resolved", f"auto: duration is {cycles:.3g} cycles (< {AUTO_CYCLES}), every cycle is resolved"
    if averaging == "cycle" and window >= duration:
        averaging, why = "resolved", why + (f"; but the duration is within the first mechanics window ({turns} nominal "
                                          "cycles), so resolved")
    speed = float(drive.speed) if drive.is_prescribed else setup.nominal_speed
    return ThermalPlan(setup=setup, si=si, mech=mech, method=method, speed=speed, averaging=averaging,
                       averaging_why=why, mechanics_duration=window if averaging == "cycle" else duration)
