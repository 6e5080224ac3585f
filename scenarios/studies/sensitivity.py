"""Design sensitivities of a run's headline results (`mechsim sensitivity`, `mechsim.sensitivity`).

The derivatives come from `dynamics/sensitivity.py` (forward sensitivities through the events, Hiskens & Pai
2000); scenario values reach the model's parameters through `sensitivity_map.py` (jax differentiates the same
formulas the mechanism evaluates, checked against the mechanism at the scenario's values), the thermal rows through
`sensitivity_rows.py` and `sensitivity_cycle.py`. This module defines the headline quantities on the run and builds
the table, the tornado chart and the summary entry (docs/sensitivity.md).

Quantities (the run's reported numbers, so that a finite difference of `mechsim run` checks them):
- peaks: the mechanical ones located in continuous time, summary.json's `peaks.<column>.abs_max` (signed value;
  `max_<column>`, `min_<column>` name its max or min, `startup_max_<column>`, `startup_min_<column>` the start-up's
  of a run that settles, `named_peak`):
  dF/dt = 0 at an interior extremum t*, so the derivative is dF/dp at the fixed instant t* (the envelope rule),
  plus F' dtau/dp at an event's one-sided limit (`_located_derivative`, docs/theory.md §K5); one that grows without
  bound has none (a warning). The thermal ones are located too, by the same rule (at a prescribed speed the closed
  form's located value with the DAE pass's derivative at its own t*, `_closed_form_thermal`; a cycle-averaged run's,
  the run's own located value, the derivative at its instant's phase in the window). A column the run does not
  locate: the largest |value| over the output rows, whose derivative is the arg-max row's (the envelope rule of a
  maximum over a fixed set). A warning
  names the change of a value at which another row becomes the maximum (a neighbouring row, or the same peak of
  another cycle, within PEAK_MARGIN), or at which an event next to the row or instant reaches it, where that change
  is smaller than the stated one: there the maximum has a kink.
- index_time_s: the last complete engagement (entry to exit); cycle_time_s: between the last two entries (one
  drive revolution); energy_per_cycle_J: the drive's work over that cycle; heat_per_index_J: the frictional heat
  of the last complete engagement (minus the friction work over it). Event times are differentiated by the
  implicit-function rule, the work at an event as W(tau) with the state's total derivative.
"""
from __future__ import annotations

import dataclasses
import time

import numpy as np
import pandas as pd

from mechsim.scenarios.studies.sensitivity_cycle import (CYCLE_COLUMNS, closed_form_turn, cycle_bulk_samples,
                                                         cycle_temperatures, cycle_window, dense_bulk_samples,
                                                         dense_jump, dense_turn, event_crosses_turn_row,
                                                         event_row_trend, switch_correction, period_gradient,
                                                         repetition_crosses_end, repetition_trend, row_repetition,
                                                         turn_peak)
from mechsim.scenarios.studies.sensitivity_map import (HEAT, PEAKS, THERMAL_PEAKS, ParameterMap, check_request,
                                                       extremum, make_seed, named_peak, scenario_value,
                                                       traced_quantities)
from mechsim.scenarios.studies.sensitivity_rows import row_state_columns, thermal_samples
from mechsim.scenarios.units import ScenarioError

#: a second peak within this relative distance of the first is reported (the maximum may switch between them)
PEAK_MARGIN = 1e-2


def _peak_rows(values: np.ndarray) -> list[int]:
    """Row of the largest |value|, then the rows that could take its place: the rows next to it (the output step
    samples the peak) and other local maxima of |value| (a repeating motion repeats its peaks) within PEAK_MARGIN.
    NaN rows (no contact; outside the periodic turn) are no candidates."""
    y = np.abs(values)
    i = int(np.nanargmax(y))
    rows = [i]
    if np.nanmax(y) - np.nanmin(y) <= 1e-12 * y[i]:
        return rows                       # a constant column (a constant drive torque): every row is the peak
    inner = np.zeros(len(y), bool)
    inner[1:-1] = (y[1:-1] > y[:-2]) & (y[1:-1] >= y[2:])       # the first row of a plateau counts once
    inner[[j for j in (i - 1, i + 1) if 0 <= j < len(y)]] = True
    inner[i] = False
    rows += [int(j) for j in np.flatnonzero(inner) if y[j] >= (1 - PEAK_MARGIN) * y[i]]
    return rows


#: a one-sided limit at an event is differentiated from samples this far and twice as far inside its interval
EVENT_OFFSET_S = 1e-6
#: a cycle-averaged closed-form run's derivatives are traced on window rows at most 1/CLOSED_CYCLE_ROWS of a nominal
#: turn apart (docs/sensitivity.md, "At a prescribed speed": the traced bulk takes the input linear between rows, an
#: O(h^2) error: an hour of geneva-seed-lc1-mu015, the contact temperature by the friction, 2e-4 of the derivative
#: at 0.05 s rows, 1.1e-6 at 1 ms)
CLOSED_CYCLE_ROWS = 720


def _located(peaks: dict, column: str, side: str | None = None) -> dict | None:
    """The run's located extremum of `column` (summary.json peaks) with the sample times its derivative needs (t*,
    or at an event two instants inside the interval of the limit), or None where the column was not located (a
    column computed after the run: its output rows are differentiated) or has no such extremum. side: None, the one
    of largest magnitude (`abs_max`); 'max' or 'min'; 'startup_max' or 'startup_min', the start-up's (`startup`,
    held where the run settles)."""
    entry = peaks.get(column)
    if not entry or not entry.get("how", "").startswith("located"):
        return None
    if side is None:
        side = entry["abs_max"]["side"]
        other = entry["min" if side == "max" else "max"]["value"]
        e = dict(entry[side], other_magnitude=abs(other) if other is not None else None)
    else:
        found = extremum(entry, side)
        if found is None:
            return None
        e = dict(found, other_magnitude=None)
    # after a cycle-averaged window the instant of the periodic turn it repeats (scenarios/thermal_peaks.py): the
    # traced pass runs the window, and the periodic turn's instant is held fixed (the envelope rule on its phase)
    t = e["sample_t_s"] = e.get("window_t_s", e["t_s"])
    if e.get("unbounded"):
        e["samples"] = []
    elif e["at"].startswith(("start", "end")):                  # the run's fixed ends
        e["samples"] = [t]
    elif e.get("limit") is None:                                 # interior
        e["samples"] = [t]
        e["beside"] = [t - EVENT_OFFSET_S, t + EVENT_OFFSET_S]
    else:
        step = EVENT_OFFSET_S if e["limit"] == "after" else -EVENT_OFFSET_S
        e["samples"] = [t + step, t + 2 * step]
    return e


def _closed_form_thermal(run_plan, located: dict) -> dict:
    """The thermal peaks of `located` (the DAE pass's own, with the speed as a constraint) with the value and instant
    the closed-form run reports (scenarios/thermal_peaks.py `ClosedFormThermalReader`): the two solve the same
    motion and network, so their located extrema differ by the integrations' tolerances. The derivative is the DAE
    pass's at its own t* (the envelope rule, dT*/dp = dT/dp at t*); t* moves with that tolerance, which moves dT/dp
    only to second order (dT/dt = 0 there). A peak the closed-form run does not locate on the same side is left
    as it is (the DAE pass's value)."""
    from mechsim.scenarios import runner
    wanted = {q: e for q, e in located.items() if q in THERMAL_PEAKS}
    if not wanted:
        return {}
    own = runner.execute(run_plan)
    peaks = own.summary.get("peaks", {}) if own.failure is None else {}
    out = {}
    for q, e in wanted.items():
        mine = _located(peaks, THERMAL_PEAKS[q])
        if mine is None or mine.get("unbounded") or (mine["value"] >= 0) != (e["value"] >= 0):
            continue
        out[q] = {**e, "value": mine["value"], "t_s": mine["t_s"]}
    return out


def _located_derivative(e: dict, column: str, by_time: dict, events) -> tuple[float, np.ndarray, float]:
    """(value, gradient, the traced pass's value) of a located extremum F* = F(t*, p) (docs/sensitivity.md,
    "Peaks"). Interior: dF/dt = 0 at t*, so dF*/dp is the gradient of F at the fixed instant t* (the envelope rule),
    carried to the traced pass's own extremum (`_to_traced_extremum`). At an event tau (the one-sided limit there):
    dF*/dp = dF/dp + F'(tau) dtau/dp, with F' extrapolated from the exact rates at the two samples inside the
    interval and dtau/dp the event time's derivative (its implicit-function rule); dF/dp at tau is
    extrapolated from the two samples as the value is (dF/dp changes at the rate dF'/dp there, which a sample
    EVENT_OFFSET_S inside would otherwise add: 1e-5 of an elasticity after a Geneva entry)."""
    first = by_time[e["samples"][0]]
    g = np.asarray(first.grads[column], dtype=float)
    traced = first.values[column]
    if e.get("beside") and all(t in by_time for t in e["beside"]):
        g = g + _to_traced_extremum(first, *(by_time[t] for t in e["beside"]), column, events)
    if len(e["samples"]) == 2:
        second = by_time[e["samples"][1]]
        h = e["samples"][0] - e["samples"][1]
        slope = (first.values[column] - second.values[column]) / h
        t = e["sample_t_s"]
        traced = first.values[column] + slope * (t - e["samples"][0])
        g = g + (g - np.asarray(second.grads[column], dtype=float)) / h * (t - e["samples"][0])
        ev = min(events, key=lambda x: abs(x.t - t), default=None)
        if ev is None or abs(ev.t - t) > EVENT_OFFSET_S:
            raise ValueError(f"no traced event at t = {t:.9g} s for the limit of {column}")
        # F'(tau) extrapolated from the exact rates at the two samples where the traced pass has them (the
        # mechanical columns): the difference quotient's error, F'' times 1.5 EVENT_OFFSET_S, multiplies dtau/dp,
        # which grows with every cycle where the drive's speed moves with p
        rates = first.rates.get(column, np.nan), second.rates.get(column, np.nan)
        rate = rates[0] + (rates[0] - rates[1]) / h * (t - e["samples"][0]) if np.isfinite(rates).all() else slope
        g = g + rate * np.asarray(ev.dt, dtype=float)
    return float(e["value"]), g, float(traced)


def _to_traced_extremum(at, before, after, column: str, events) -> np.ndarray:
    """The change of dF/dp (fixed time) from the run's extremum t* to the traced pass's own, t' = t* - F'/F''
    (docs/theory.md §K5): the envelope rule holds where the traced pass's F' = 0, and the two integrations'
    extrema differ by their tolerances, dt ~ rtol times the time scale. dF/dp at a fixed time carries the phase's
    sensitivity, -F' dtau/dp, which grows with every cycle where the period moves with p; so its change over dt,
    F'' (dtau/dp) dt, is not small where the extremum is sharp and late (a near-dwell's crank acceleration after
    many turns: 3e-4 of the derivative at the default tolerances). F'' and d(dF/dp)/dt from the samples
    EVENT_OFFSET_S either side, with their exact rates; zero where an event lies between them (the sides are in
    other modes) or the traced pass has no rates (the thermal columns)."""
    span = (before.t, after.t)
    rates = np.array([at.rates.get(column, np.nan), before.rates.get(column, np.nan),
                      after.rates.get(column, np.nan)])
    if not np.isfinite(rates).all() or any(span[0] <= ev.t <= span[1] for ev in events):
        return np.zeros_like(np.asarray(at.grads[column], dtype=float))
    curvature = (rates[2] - rates[1]) / (span[1] - span[0])
    if curvature == 0.0:
        return np.zeros_like(np.asarray(at.grads[column], dtype=float))
    drift = (np.asarray(after.grads[column], dtype=float) - np.asarray(before.grads[column], dtype=float)) / (
        span[1] - span[0])
    return -rates[0] / curvature * drift


def _near_peaks(q: str, wrt: list[str], relative: list[bool], df, rows: list[int], by_time: dict, column: str,
                change: float) -> str | None:
    """A warning where another candidate row (`_peak_rows`) becomes the maximum within the stated change of a value
    (relative, or absolute for a value at zero): there the maximum's derivative jumps (a non-smooth point), so
    the first-order change is not to be trusted that far. Gradients are per relative change (per unit for a value
    at zero), see `make_seed`."""
    first = by_time[float(df["t_s"].iloc[rows[0]])]
    y, g = first.values[column], first.grads[column]
    nearest = {}
    for j in rows[1:]:
        other = by_time[float(df["t_s"].iloc[j])]
        y2, g2 = other.values[column], other.grads[column]
        gap = abs(y) - abs(y2)
        rate = np.sign(y2) * g2 - np.sign(y) * g     # d(|y2| - |y|) per relative change of each value
        for key, r in zip(wrt, rate):
            if r != 0 and gap / abs(r) < nearest.get(key, (np.inf, 0, 0.0))[0]:
                nearest[key] = (gap / abs(r), np.sign(r), other.t)
    rel = dict(zip(wrt, relative))
    swap = [f"{key} {'+' if s > 0 else '-'}" + (f"{d * 100:.2g}%" if rel[key] else f"{d:.2g} (absolute)")
            + f" (to t = {t2:.6g} s)" for key, (d, s, t2) in nearest.items() if d < change]
    if not swap:
        return None
    return (f"{q}: the peak at t = {first.t:.6g} s is the largest of {len(rows)} nearly equal output rows (the rows "
            "next to it, or the same peak of another cycle); another one takes over, and the derivative jumps, "
            "within the stated change: " + ", ".join(swap))


def _event_crosses_row(q: str, wrt: list[str], relative: list[bool], t_row: float, events, change: float):
    """A warning where the events next to a peak's row (the last before it, the first after it) move past the row
    within the stated change of a value: the row then lies in another mode, where the quantity may jump (a
    non-smooth point; the derivative holds only for smaller changes). Event-time gradients are per relative change."""
    before = [e for e in events if e.t <= t_row]
    after = [e for e in events if e.t > t_row]
    near = ([before[-1]] if before else []) + ([after[0]] if after else [])
    rel = dict(zip(wrt, relative))
    found = []
    for e in near:
        for key, d in zip(wrt, e.dt):
            if d == 0:
                continue
            step = (t_row - e.t) / d              # the change of the value that brings the event to the row
            if abs(step) < change:
                amount = f"{step * 100:+.2g}%" if rel[key] else f"{step:+.2g} (absolute)"
                found.append(f"{key} {amount} ('{e.kind}' at t = {e.t:.6g} s)")
    if not found:
        return None
    return (f"{q}: its row t = {t_row:.6g} s is next to a mode change that reaches it within the stated change; "
            "beyond it the row lies in the other mode, where the quantity may jump (the derivative holds up to "
            "there): " + ", ".join(found))


def sensitivity(scenario, wrt: list[str], of: list[str] | None = None, change: float = 0.01) -> pd.DataFrame:
    """The table of derivatives of the headline quantities `of` (default: all) with respect to the scenario values
    `wrt` (a loaded Scenario). One row per (quantity, value): value, t_s (the peak's output row, or the end of the
    cycle), derivative (SI), elasticity (p/y) dy/dp, and the first-order change of y for a change of p by `change`
    (relative). attrs: cost, warnings, scenario."""
    from mechsim.dynamics.hybrid import prepare
    from mechsim.scenarios import runner
    from mechsim.scenarios.keys import field_unit
    if not 0 < change < 1:
        raise ScenarioError("--change", f"must be a relative change in (0, 1), got {change}")
    plan = runner.plan(scenario)
    if plan.asked is not None:      # run at the finer step its cycle averaging needs: its rows are read there too
        scenario, plan = plan.scenario, dataclasses.replace(plan, asked=None, thin=1)
    every = runner.rows_every(scenario.si, plan.thermal, CLOSED_CYCLE_ROWS) if plan.method == "closed-form" else 1
    if every > 1:       # a closed form's cycle bulk is traced on its input linear between the window's rows
        scenario = runner.finer(scenario, every)
        plan = runner.plan(scenario)
    notes = []
    cycle = plan.thermal is not None and plan.thermal.averaging == "cycle"
    run_plan = plan            # the run's own plan: at a prescribed speed, its closed form reports the value
    if cycle:
        check_request(plan, list(wrt), list(of or []))
        run_plan = plan = runner.settled(plan)      # the window the run settles on, or the run resolved whole
        cycle = plan.thermal.averaging == "cycle"
    if cycle:
        plan = cycle_window(plan)
    if plan.method == "closed-form":
        # the closed form is not differentiated: the same motion as a DAE with the speed as a constraint (and the
        # thermal states in it)
        plan = dataclasses.replace(plan, method="dae", settings=dataclasses.replace(plan.settings, method="dae"),
                                   why="sensitivities follow the DAE path",
                                   thermal=plan.thermal and dataclasses.replace(plan.thermal, method="dae"))
        notes.append("prescribed speed: the run and its derivatives follow the DAE with the speed as a constraint "
                     "(solver.method = 'dae'); the closed form gives the same motion to the solver's tolerance")
    wrt = list(wrt)
    pmap = check_request(plan, wrt, list(of or []))
    of = list(of) if of else list(traced_quantities(plan, pmap))
    si, mech, drive, settings, thermal = scenario.si, plan.mechanism, plan.drive, plan.settings, plan.thermal
    wall = time.perf_counter()
    result = runner.execute(plan)
    run_wall = time.perf_counter() - wall
    if result.failure is not None:
        raise ScenarioError("scenario", f"the run failed ({result.failure.message()}): no derivatives of a run that "
                            "did not reach its end")
    df, events = result.timeseries, result.events
    warnings: list[str] = list(notes)
    angle_key, speed_key = mech.initial_keys
    angle0 = si["initial"][angle_key]
    speed0 = drive.speed if drive.is_prescribed else si["initial"][speed_key]
    ext, ext_initial = (thermal.extension, thermal.ext_initial) if thermal is not None else (None, None)
    t_end = plan.mechanics_duration
    model = prepare(mech, drive, settings, t_end, si["output_step"], angle0, speed0, ext, ext_initial).model
    seed, scales, flash = make_seed(plan, model, wrt, pmap)

    named = {q: side for q in of if (side := named_peak(q))}
    peak_columns = {**PEAKS, **THERMAL_PEAKS, **{q: column for q, (column, _) in named.items()}}
    # a DAE run reads its periodic turn on the window's solution, and so does the traced bulk (`dense_turn`); a
    # closed form's turn is traced on the window's rows (`cycle_temperatures`)
    dense = dense_turn(run_plan) if cycle and run_plan.method == "dae" and ext is not None else None
    turn = cycle_temperatures(plan, df) if cycle and dense is None else None
    if cycle and turn is None and dense is None:
        raise ScenarioError("thermal.averaging", "the mechanics window holds no full crank turn to average")
    if turn is not None and run_plan.method == "closed-form":
        turn = closed_form_turn(run_plan, turn)

    def peak_values(q):
        if turn is not None and q in THERMAL_PEAKS:       # the periodic turn's rows, at their last time in the run
            y = np.full(len(df), np.nan)
            y[turn["rows"]] = turn[THERMAL_PEAKS[q]]
            return y
        return df[peak_columns[q]].to_numpy(float)
    sides = {q: named[q][1] if q in named else None for q in of if q in PEAKS or q in named}
    located = {q: e for q, side in sides.items() if (e := _located(result.summary.get("peaks", {}), peak_columns[q],
                                                                   side))}
    # the thermal peaks located on the run's continuous solution: with cycle averaging the run itself (its hour
    # continues the window the derivatives trace; at a prescribed speed the closed form's); at a prescribed speed
    # (resolved) the DAE pass's own located peak, its value replaced by the closed-form run's (`_closed_form_thermal`)
    thermal_peaks = result.summary.get("peaks", {})
    if cycle and any(q in THERMAL_PEAKS for q in of):       # the run's, without its other columns over the hour
        thermal_peaks = runner.thermal_peaks(run_plan, [THERMAL_PEAKS[q] for q in of if q in THERMAL_PEAKS])
    located.update({q: e for q in of if q in THERMAL_PEAKS
                    and (e := _located(thermal_peaks, THERMAL_PEAKS[q])) and not e.get("unbounded")})
    if run_plan.method == "closed-form" and not cycle:
        located.update(_closed_form_thermal(run_plan, located))
    peak_rows = {q: _peak_rows(peak_values(q)) for q in of if q in peak_columns and peak_columns[q] in df
                 and q not in located and q not in named and np.nanmax(np.abs(peak_values(q)), initial=0.0) > 0}
    sample_times = sorted({float(df["t_s"].iloc[i]) for rows in peak_rows.values() for i in rows}
                          | {t for e in located.values() for t in e["samples"]}
                          | {t for q, e in located.items() if q not in THERMAL_PEAKS for t in e.get("beside", ())})
    thermal_times = sorted({float(df["t_s"].iloc[i]) for q, rows in peak_rows.items() if q in THERMAL_PEAKS
                            for i in rows} | {t for q, e in located.items() if q in THERMAL_PEAKS
                                              for t in e["samples"]})
    columns = {peak_columns[q] for q in [*peak_rows, *located] if q not in THERMAL_PEAKS} | {"work_drive_J"}
    if thermal_times:
        # with bulk states, the columns of the cycle bulk too (read only with cycle averaging), so that both
        # averagings share one compiled set of read-outs
        columns |= set(pmap.contact_columns) | row_state_columns(model.extension_names)
        columns |= set(CYCLE_COLUMNS) | set(ext.system.state_names) if ext is not None else set()
    if turn is not None and thermal_times and ext is not None:
        # the cycle-averaged bulk depends on every row of the turn (its input) and on the rows at its ends
        sample_times = sorted(set(sample_times) | {float(x) for x in df["t_s"].to_numpy(float)[turn["layout"].rows]})
    # the located peaks after the window: their instant in the periodic turn, and the whole periods after it
    repeats = {t: round((e["t_s"] - e["sample_t_s"]) / dense["period"]) for q, e in located.items()
               if q in THERMAL_PEAKS for t in e["samples"]} if dense is not None else {}
    repeats = {t: m for t, m in repeats.items() if m > 0}
    if repeats:       # the bulk there depends on the turn's ends and on its input at every node
        sample_times = sorted(set(sample_times) | set(dense["sample_times"]))
    wall = time.perf_counter()
    # JAX imported after the run: its threads would keep the default backend from compiling the model's callbacks
    # in the background (dynamics/backends/compiled_model.py), so a later process's run would stay on `ida`
    from mechsim.dynamics.sensitivity import path_sensitivities
    path = path_sensitivities(mech, drive, settings, events.to_dict("records"), seed, sample_times, sorted(columns),
                              t_end, si["output_step"], angle0, speed0, ext, ext_initial,
                              rates=bool(repeats) or any(len(e["samples"]) == 2 or e.get("beside")
                                                         for e in located.values()))
    by_time = {s.t: s for s in path.samples}
    if turn is not None and thermal_times and ext is not None:       # (the flash model's base is the ambient)
        cycle_bulk_samples(plan, df, turn, by_time, seed, model, [by_time[t] for t in thermal_times], path.stats)
    if repeats:
        dense_bulk_samples(plan, dense, by_time, seed, model, [by_time[t] for t in repeats], repeats, path.events,
                           path.stats)
    if thermal_times:
        thermal_samples(plan, df, events, path, [by_time[t] for t in thermal_times], flash)
    sens_wall = time.perf_counter() - wall

    results: dict[str, tuple[float, np.ndarray]] = {}
    traced_values: dict[str, float] = {}     # the traced pass's own value of each quantity
    # the slope of the peak's trend across repetitions and event-row crossings (`repetition_trend`, `event_row_trend`)
    trends: dict[str, np.ndarray] = {}
    relative = [scenario_value(plan, key) != 0.0 for key in wrt]
    for q in of:
        if q in located and located[q].get("unbounded"):
            warnings.append(f"{q}: {peak_columns[q]} grows without bound toward an event (t = "
                            f"{located[q]['t_s']:.6g} s; summary.json peaks): no peak, so no derivative")
        elif q in located:
            y, g, traced = _located_derivative(located[q], peak_columns[q], by_time, path.events)
            other = located[q]["other_magnitude"]
            if other is not None and abs(abs(y) - other) <= change * abs(y):
                warnings.append(f"{q}: the maximum and minimum of {peak_columns[q]} are equal in magnitude to "
                                f"{abs(abs(y) - other) / abs(y):.2g} (relative): the one of larger magnitude may "
                                f"change within the stated change; the derivative is the "
                                f"{'maximum' if y >= 0 else 'minimum'}'s")
            results[q] = (y, g, located[q]["t_s"])
            traced_values[q] = traced
            if located[q].get("limit") is None:
                note = _event_crosses_row(q, wrt, relative, located[q]["sample_t_s"], path.events, change)
                if note:
                    warnings.append(note)
            if turn is not None and q == "peak_temp_contact_C" and ext is not None:
                t_w = located[q]["sample_t_s"]
                dP = period_gradient(turn, by_time)
                rows_trend = 0.0
                if "traced_temp_contact_C" in turn:
                    # a closed-form run's input is exact, the traced turn's linear between rows: what the events'
                    # motion moves in the former (`switch_correction`, at the peak's instant and share); no row
                    # sawtooth (the exact input follows the events)
                    share = float(np.interp(t_w, turn["layout"].t[turn["rows"]], turn["share"]))
                    g = g + switch_correction(run_plan, turn, t_w, path.events, at=(located[q]["t_s"], share))
                    results[q] = (y, g, located[q]["t_s"])
                    warnings.append(f"{q}: the value is the closed-form run's located peak; the derivative is the "
                                    "traced pass's at its instant with the turn's heat input linear between output "
                                    f"rows (the DAE window, whose value differs by {traced - y:+.2g} K) plus what "
                                    "the events' motion moves in the run's exact input (docs/sensitivity.md, "
                                    "\"Cycle averaging\")")
                else:
                    rows_trend = event_row_trend(plan, turn, t_w, path.events)
                m, P, at, jump = row_repetition(turn, t_w)
                note = repetition_crosses_end(q, wrt, relative, m, P, at, jump, turn["duration"], dP, change)
                if note:
                    warnings.append(note)
                trends[q] = g + repetition_trend(m, P, jump, dP) + rows_trend
            if q == "peak_temp_contact_C" and located[q]["samples"][0] in repeats:
                e = located[q]
                m, P, dP = repeats[e["samples"][0]], dense["period"], dense["period_grad"]
                jump = dense_jump(dense, by_time[e["samples"][0]])
                note = repetition_crosses_end(q, wrt, relative, m, P, e["t_s"], jump, dense["duration"], dP, change)
                if note:
                    warnings.append(note)
                trends[q] = g + repetition_trend(m, P, jump, dP)
        elif q in named:
            column, side = named[q]
            entry = result.summary.get("peaks", {}).get(column)
            warnings.append(f"{q}: this run has no column {column}" if entry is None else
                            f"{q}: the run does not settle into a periodic regime after a start-up (summary.json "
                            "regime), so it has no start-up apart from its headline peaks" if side.startswith("startup")
                            else f"{q}: {column} is not located on this run (summary.json peaks.{column}.how)")
        elif q in peak_columns:
            column = peak_columns[q]
            if q not in peak_rows:
                warnings.append(f"{q}: this run has no column {column}" if column not in df else
                                f"{q}: zero on every row (no contact, or no frictional heat): no peak to differentiate")
                continue
            rows = peak_rows[q]
            first = by_time[float(df["t_s"].iloc[rows[0]])]
            # the value is the run's own (what `mechsim run` reports and `mechsim size` checks its design against);
            # the traced pass's value of the row differs from it by the two integrations' tolerances
            y, g = float(df[column].iloc[rows[0]]), first.grads[column]
            results[q] = (y, g, first.t)
            traced_values[q] = first.values[column]
            if turn is not None and q in THERMAL_PEAKS:
                value, at = turn_peak(turn, column, first.t)        # the run's reported peak, and its time
                results[q] = (value, g, at)
                if q == "peak_temp_contact_C" and "traced_temp_contact_C" in turn and ext is not None:
                    # the run's input jumps at the contact's switches, the traced one is linear between rows
                    results[q] = (value, g + switch_correction(run_plan, turn, first.t, path.events), at)
                    traced, _ = turn_peak(turn, "traced_temp_contact_C", first.t)
                    warnings.append(f"{q}: the value is the closed-form run's; the derivative is that of the same "
                                    "row with the turn's heat input linear between output rows (the DAE window, "
                                    f"whose value differs by {traced - value:+.2g} K) plus what the events' motion "
                                    "moves in the run's exact input (docs/sensitivity.md, \"Cycle averaging\")")
                note = event_crosses_turn_row(q, wrt, relative, turn, path.events, change)
                if note and q == "peak_temp_contact_C" and ext is not None and "traced_temp_contact_C" not in turn:
                    warnings.append(note)
                if q == "peak_temp_contact_C" and ext is not None:
                    m, P, at, jump = row_repetition(turn, first.t)
                    note = repetition_crosses_end(q, wrt, relative, m, P, at, jump, turn["duration"],
                                                  period_gradient(turn, by_time), change)
                    if note:
                        warnings.append(note)
            if len(rows) > 1:
                note = _near_peaks(q, wrt, relative, df, rows, by_time, column, change)
                if note:
                    warnings.append(note)
            note = _event_crosses_row(q, wrt, relative, first.t, path.events, change)
            if note:
                warnings.append(note)
        elif q == IMPULSE:
            got = _peak_impulse(q, path.events, wrt, relative, change, warnings)
            if got is None:
                warnings.append(f"{q}: the run has no impact")
                continue
            # the value is the run's own (summary.json impacts), the elasticity the traced pass's
            own = (result.summary.get("impacts") or {}).get(IMPULSE)
            results[q] = (got[0] if own is None else float(own),) + tuple(got[1:])
            traced_values[q] = got[0]
        else:
            got = _cycle_quantity(q, path.events, pmap, model)
            if got is None:
                index = q in ("index_time_s", HEAT)
                warnings.append(f"{q}: the run has no complete {'index' if index else 'cycle'} "
                                f"({pmap.engage} to {pmap.release if index else pmap.engage}); lengthen duration")
                continue
            own = run_event_quantities(events, pmap.engage, pmap.release).get(q)
            # event times: the run's own where its events table has them (the energy per cycle and the heat per
            # index need work states at the events, which the run's tables do not hold: the traced pass's)
            results[q] = got if own is None else (own,) + tuple(got[1:])
            traced_values[q] = got[0]
    warnings += _sequence_warnings(path.events, wrt, relative, change)
    rows = []
    for q, (y, g, at) in results.items():
        base = traced_values.get(q, y)       # the elasticity is the traced function's own, on its own value
        for j, key in enumerate(wrt):
            p = scenario_value(plan, key)
            deriv = float(g[j]) / scales[j]
            unit = field_unit(si, key)
            elasticity = p / base * deriv if base != 0 else float("nan")
            dp = change * abs(p) if p != 0 else float("nan")
            rows.append(dict(quantity=q, value=y, t_s=at, wrt=key, wrt_unit=unit, parameter=p, derivative=deriv,
                             elasticity=elasticity, parameter_change=dp, quantity_change=deriv * dp))
    table = pd.DataFrame(rows, columns=["quantity", "value", "t_s", "wrt", "wrt_unit", "parameter", "derivative",
                                        "elasticity", "parameter_change", "quantity_change"])
    table.attrs.update(
        scenario=scenario.name, change=change, warnings=warnings,
        trend={q: {key: float(g[j]) / scales[j] for j, key in enumerate(wrt)} for q, g in trends.items()},
        cost={"run_wall_time_s": run_wall, "run_backend": settings.backend,
              "sensitivity_wall_time_s": sens_wall, "sensitivity_compile_time_s": path.stats["compile_time_s"],
              # the pass without its one-off compilation, per run of the scenario's backend
              "sensitivity_per_run": (sens_wall - path.stats["compile_time_s"]) / run_wall if run_wall > 0 else None,
              "sensitivity_steps": path.stats["steps"], "values": len(wrt)})
    return table


#: the largest impulse of the run's impacts (a rigid contact with clearance: the events table's impulse_N_s)
IMPULSE = "peak_impulse_N_s"


def _amount(key: str, step: float, rel: bool) -> str:
    return f"{key} {step * 100:+.2g}%" if rel else f"{key} {step:+.2g} (absolute)"


def _peak_impulse(q: str, events, wrt: list[str], relative: list[bool], change: float, warnings: list[str]):
    """(value, gradient, time) of the largest |impulse| of the traced impacts (the impulse P = (1 + e) m_eff v_n of
    the struck flank, differentiated through the impact law, dynamics/sensitivity.py), or None without impacts.
    The maximum over the impacts is differentiated as the largest one's (the envelope rule of a maximum over a
    discrete set); a warning where another impact's impulse reaches it within the stated change."""
    hits = [e for e in events if e.impulse is not None]
    if not hits:
        return None
    top = max(hits, key=lambda e: abs(e.impulse))
    y, g = abs(top.impulse), np.sign(top.impulse) * np.asarray(top.dimpulse, float)
    rel = dict(zip(wrt, relative))
    swap = []
    for e in hits:
        if e is top:
            continue
        rate = np.sign(e.impulse) * np.asarray(e.dimpulse, float) - g
        for key, r in zip(wrt, rate):
            if r != 0 and (y - abs(e.impulse)) / abs(r) < change:
                swap.append(_amount(key, (y - abs(e.impulse)) / r, rel[key]) + f" (to t = {e.t:.6g} s)")
    if swap:
        warnings.append(f"{q}: the impact at t = {top.t:.6g} s is the largest; another takes over within the stated "
                        "change, and the derivative jumps: " + ", ".join(swap))
    return float(y), g, top.t


def _sequence_warnings(events, wrt: list[str], relative: list[bool], change: float) -> list[str]:
    """Warnings where the event sequence the derivatives follow changes within the stated change of a value
    (docs/sensitivity.md, "Impacts"): an event near grazing (its guard crossing zero almost tangentially, so that
    the event vanishes: `EventSensitivity.grazing`) or a transition whose rule changes (a rebound turning plastic
    at the bounce speed: `EventSensitivity.rule_change`). Beyond that change the derivative does not hold."""
    rel = dict(zip(wrt, relative))
    out = []
    for e in events:
        for what, steps in (("grazes (the event vanishes)", e.grazing), ("changes its rule", e.rule_change)):
            if steps is None:
                continue
            near = [_amount(key, d, rel[key]) for key, d in zip(wrt, map(float, steps)) if abs(d) < change]
            if near:
                out.append(f"'{e.kind}' at t = {e.t:.6g} s {what} within the stated change, where the event sequence "
                           f"changes and the derivatives hold only up to there: {', '.join(near)}")
    return out


def run_event_quantities(events, engage: str, release: str) -> dict:
    """The index time (the last release and the engage before it) and the cycle time (the last two engages) as a
    run's own events table gives them (the numbers `mechsim run` reports; None where it has no such events): the
    same selection as `_cycle_quantity` makes on the traced events."""
    kinds = events["kind"].to_numpy() if events is not None and len(events) else np.array([])
    t = events["t_s"].to_numpy(float) if len(kinds) else np.array([])
    engages, releases = t[kinds == engage], t[kinds == release]
    out = {"index_time_s": None, "cycle_time_s": None}
    if len(releases) and engage:
        before = engages[engages < releases[-1]]
        out["index_time_s"] = float(releases[-1] - before[-1]) if len(before) else None
    if len(engages) >= 2:
        out["cycle_time_s"] = float(engages[-1] - engages[-2])
    return out


def _cycle_quantity(q: str, events, pmap: ParameterMap, model):
    """(value, gradient per scaled value, time of its end) of an event-based quantity, or None where the run has no
    such cycle."""
    entries = [e for e in events if e.kind == pmap.engage]
    if q in ("index_time_s", HEAT):
        pairs = []
        for i in range(len(events) - 1, -1, -1):
            if events[i].kind == pmap.release:
                start = [e for e in events[:i] if e.kind == pmap.engage]
                if start:
                    pairs = [(start[-1], events[i])]
                break
        if not pairs:
            return None
        a, b = pairs[0]
        if q == HEAT:       # the friction work is negative (dissipated): its drop over the index is the heat
            k = 2 * len(model.coordinates) + list(model.work_names).index("friction")
            return float(a.z[k] - b.z[k]), a.dz[k] - b.dz[k], b.t
        return b.t - a.t, b.dt - a.dt, b.t
    if len(entries) < 2:
        return None
    a, b = entries[-2], entries[-1]
    if q == "cycle_time_s":
        return b.t - a.t, b.dt - a.dt, b.t
    # the drive's work at each event (a work state: z = [q, v, work, ext]); dz holds S + f dtau
    k = 2 * len(model.coordinates) + list(model.work_names).index("drive")
    return float(b.z[k] - a.z[k]), b.dz[k] - a.dz[k], b.t


def tornado_figure(table: pd.DataFrame):
    """One panel per quantity: horizontal bars of the elasticities (p/y) dy/dp, largest on top, on one scale for
    all panels, coloured by the sign of dy/dp (for a negative quantity, a minimum, the elasticity's sign is the
    other)."""
    from matplotlib.figure import Figure
    quantities = list(dict.fromkeys(table["quantity"]))
    rows = [max(1, int((table["quantity"] == q).sum())) for q in quantities]
    # each panel: its title and a bar per value (0.3 in each); one elasticity scale for all (they are all % per %,
    # so the panels compare: a quantity that barely moves shows a short bar, not a full one)
    fig = Figure(figsize=(8, 1.3 + sum(0.45 + 0.3 * n for n in rows)), constrained_layout=True)
    axes = fig.subplots(len(quantities), 1, sharex=True, gridspec_kw={"height_ratios": [n + 1.5 for n in rows]},
                        squeeze=False)[:, 0]
    e_all = table["elasticity"].to_numpy(float)
    lim = max(1e-12, float(np.nanmax(np.abs(e_all))) if np.isfinite(e_all).any() else 1.0) * 1.2
    for ax, q in zip(axes, quantities):
        part = table[table["quantity"] == q].copy()
        part = part.iloc[np.argsort(np.abs(part["elasticity"].fillna(0).to_numpy()))]
        e = part["elasticity"].to_numpy(float)
        bars = ax.barh(part["wrt"], e, color=["C3" if d > 0 else "C0" for d in part["derivative"].to_numpy(float)])
        ax.bar_label(bars, labels=[f"{v:.3g}" for v in e], fontsize=7, padding=2)
        ax.axvline(0.0, color="k", lw=0.8)
        ax.set_title(f"{q} = {part['value'].iloc[0]:.6g}", fontsize=9, loc="left")
        ax.tick_params(labelsize=8)
        ax.set_xlim(-lim, lim)
    axes[-1].set_xlabel("elasticity (p/y) dy/dp: % change of the quantity per % change of the value\n"
                        "(red: raising the value raises the quantity, blue: it lowers it)")
    fig.suptitle(f"{table.attrs.get('scenario', '')}: design sensitivities", fontsize=10)
    return fig


def write_sensitivity(table: pd.DataFrame, folder, force: bool = False):
    """sensitivity.csv, tornado.png and summary.json (entry `sensitivity`) into `folder`, atomically."""
    import json
    from pathlib import Path

    from mechsim.scenarios.output.atomic import atomic_folder, json_default
    from mechsim.scenarios.output.csv import write_csv
    from mechsim.scenarios.output.plots import save as save_figure
    folder = Path(folder)
    with atomic_folder(folder, force) as tmp:
        write_csv(table, tmp / "sensitivity.csv")
        save_figure(tornado_figure(table), tmp / "tornado.png")
        summary = {"scenario": table.attrs.get("scenario"), "sensitivity": {
            "rows": table.to_dict("records"), "change_relative": table.attrs.get("change"),
            "cost": table.attrs.get("cost"), "warnings": table.attrs.get("warnings", []),
            "method": "forward sensitivities through the events (docs/sensitivity.md)"}}
        (tmp / "summary.json").write_text(json.dumps(summary, indent=2, default=json_default))
    return folder
