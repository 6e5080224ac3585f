"""What happens when a guard fires — shared by every backend's hybrid loop (IDA, diffrax).

Given the guard(s) that fired at time t, ask the mechanism for its transition, write the events-table rows
(kinetic energy before and after, impacts and absorbed rebounds as their own rows), and either stop (a
physics stop or a failed re-initialisation, reported as a failure value) or re-initialise consistently in
the next mode.
"""
from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np

from mechsim.mechanisms.base import Mechanism, Transition

from mechsim.dynamics.consistent import consistent_state, floats, matrix, project_positions, project_velocities
from mechsim.dynamics.model import DerivedModel

DEFAULT_STOP_HINT = "raise the drive torque or lower the load"
_TINY = np.finfo(float).tiny


@dataclass
class Outcome:
    """The result of one transition: new mode and consistent state, or a failure; rows for the events table."""

    mode: str
    values: dict
    p: tuple
    y: np.ndarray | None = None
    yp: np.ndarray | None = None
    failure: dict | None = None
    rows: list[dict] = field(default_factory=list)
    warnings: list[str] = field(default_factory=list)
    offset: np.ndarray | None = None    # the coordinates' re-based offset after the transition (see `rebased`)
    transition: Transition | None = None    # the mechanism's transition taken (its impact law: the sensitivity pass)


def _where(model: DerivedModel, q) -> dict:
    return {c: float(val) for c, val in zip(model.coordinates, q)}


def rebased(mech: Mechanism, model: DerivedModel, values: dict, t: float, q: np.ndarray, offset: np.ndarray
            ) -> tuple[dict, np.ndarray, np.ndarray]:
    """(values, q, offset) moved by the mechanism's symmetry (`Mechanism.rebase`) so that q stays small.

    The solvers integrate q while q + offset is the unwrapped coordinate reported: ulp(q), the round-off of
    every constraint and guard evaluated from q, then does not grow with the number of turns. A prescribed
    drive's reference (angle0 + speed (t - time0)) is moved to the shifted frame and to the current time.
    """
    r = mech.rebase(values)
    if r is None:
        return values, q, offset
    shift, updates = r
    shift = np.asarray(shift, dtype=float)
    values = {**values, **updates}
    if model.prescribed:
        k = mech.drive_coordinate
        values["drive_angle0"] = (values["drive_angle0"] - shift[k]
                                  + values["drive_speed"] * (t - values["drive_time0"]))
        values["drive_time0"] = t
    return values, np.asarray(q, dtype=float) - shift, offset + shift


def chattering(model: DerivedModel, mode: str, guard: str, t: float, q, last) -> dict | None:
    """A failure if `guard` fires again at the instant of its own transition (the state did not leave it)."""
    if last is not None and guard == last[0] and t - last[1] <= 1e-9 * max(1.0, abs(t)):
        return dict(time=t, mode=mode, reason=f"guard '{guard}' fires again immediately after its own "
                    "transition (chattering)", where=_where(model, q),
                    hint="the mechanism's guard for this transition should be directional")
    return None


def stepped_over_failure(model: DerivedModel, mode: str, crossed: dict) -> dict:
    """The failure for a guard that crossed zero while events were disabled (see hybrid.stepped_over)."""
    return dict(time=crossed["after"], mode=mode, reason=(
        f"mode change stepped over: guard '{crossed['guard']}' of mode '{mode}' crossed zero between "
        f"t = {crossed['before']:.6g} s and {crossed['after']:.6g} s, but events are disabled "
        "(solver.events = false), so the run went on in the wrong mode; rows after the crossing are "
        "dropped"), where=_where(model, crossed["q"]),
        hint="set solver.events = true (guards root-found by the integrator)")


def apply_transition(mech: Mechanism, model: DerivedModel, parameter_tuple, mode: str, values: dict, t: float,
                     y_end: np.ndarray, fired: list[int], offset: np.ndarray | None = None, p: tuple | None = None
                     ) -> Outcome:
    """Handle guards `fired` (indices into the mode's guards, the first one the primary) at time t.

    y_end is in the re-based frame: the unwrapped coordinates are y_end's q + offset (zero when None); the
    outcome's state is re-based again for the new mode (`Outcome.offset`). p: parameter_tuple(model, values), where
    the caller has it."""
    mf = model.modes[mode]
    ix = mf.index
    q, v = y_end[ix["q"]], y_end[ix["v"]]
    offset = np.zeros(len(q)) if offset is None else np.asarray(offset, dtype=float)
    p = parameter_tuple(model, values) if p is None else p
    guard = mf.guard_names[fired[0]]
    tr = mech.on_guard(mode, guard, values, t, q, v)
    for other in fired[1:]:
        # guards that fire at the same instant (a stall and the slip reversal it causes): a stop wins
        if not tr.stop:
            alt = mech.on_guard(mode, mf.guard_names[other], values, t, q, v)
            if alt.stop:
                guard, tr = mf.guard_names[other], alt
    if tr.stop and tr.kind in mf.guard_names:
        guard = tr.kind     # the mechanism recognised its own stop guard at another guard's root (a stall)
    row = dict(t_s=t, from_mode=mode, to_mode=tr.mode, kind=tr.kind, guard=guard,
               **{f"{c}_q": float(val) for c, val in zip(model.coordinates, q + offset)})
    if tr.record is not None:
        row.update(tr.record, **{f"work_{n}_J": float(w) for n, w in zip(model.work_names, y_end[ix["work"]])})
    out = Outcome(mode, values, p, offset=offset, transition=tr)
    if tr.message:
        out.warnings.append(f"t = {t:.6g} s: {tr.message}")
    if tr.stop:
        M = matrix(mf.mass(floats(q), p))
        ke = 0.5 * float(v @ M @ v)
        out.rows.append(dict(row, kinetic_energy_before_J=ke, kinetic_energy_after_J=ke, message=tr.stop))
        out.failure = dict(time=t, mode=mode, reason=tr.stop, where=_where(model, q + offset),
                           hint=tr.hint or DEFAULT_STOP_HINT, kind="physics")
        return out
    values_before, p_before, q_before, offset_before, v_before = values, p, q, offset, v
    values = {**values, **tr.updates}
    values, q, offset = rebased(mech, model, values, t, q, offset)
    new_mode = tr.mode
    mf = model.modes[new_mode]
    p = parameter_tuple(model, values)
    out.mode, out.values, out.p, out.offset = new_mode, values, p, offset
    try:
        restitution, rebound, hit = tr.restitution, None, None
        if restitution is not None and tr.contact is not None and tr.contact != new_mode:
            # an impact on another mode's constraints (Newton's law there), the new mode free of them: the rebound
            # stands, nothing is absorbed
            contact = model.modes[tr.contact]
            q = project_positions(contact, t, q, p)
            v, hit = project_velocities(contact, t, q, v, p, restitution)
            restitution = None
        elif restitution:
            # Newton's law with e > 0 leaves G v = -e G v-, which the new mode's constraints forbid: its own
            # row, then the plastic projection of consistent_state removes the rebound (a second row)
            q = project_positions(mf, t, q, p)
            v, rebound = project_velocities(mf, t, q, v, p, restitution)
            restitution = None
        keep = not restitution and same_constraints(model, mode, new_mode, t, q_before, p_before, q, p)
        y, yp, impact = consistent_state(mf, t, q, v, y_end[ix["work"]], y_end[ix["ext"]], p, restitution,
                                         project=not keep)
    except (ValueError, np.linalg.LinAlgError) as exc:
        out.failure = dict(time=t, mode=new_mode, reason=f"re-initialisation after '{guard}' failed: {exc}",
                           where=_where(model, q + offset), hint="the new mode may be singular here")
        out.rows.append(row)
        return out
    if rebound is not None:
        out.rows.append(dict(row, kinetic_energy_before_J=rebound.energy_before,
                             kinetic_energy_after_J=rebound.energy_after, message=tr.message or ""))
        row = dict(row, kind="rebound absorbed", message=(
            f"the rebound of '{tr.kind}' (restitution {tr.restitution:g}) is not admissible in mode "
            f"'{new_mode}': removed by a plastic projection onto its constraints"))
    row.update(kinetic_energy_before_J=impact.energy_before, kinetic_energy_after_J=impact.energy_after)
    if tr.contact is not None:
        hit = hit if hit is not None else impact
        row.update(kinetic_energy_before_J=hit.energy_before,
                   impulse_N_s=float(hit.impulse[0]) if hit.impulse is not None and len(hit.impulse) else 0.0)
        if hit.impulse is not None and len(hit.impulse):
            v_after = y[ix_new(model, out.mode)["v"]]
            lost, driven = impact_split(model.modes[tr.contact], t, q, v_before, v_after, p, hit.impulse)
            row["energy_lost_J"] = lost
            row["approach_speed_m_s"], row["impact_mass_kg"] = impact_speed_mass(
                model.modes[tr.contact], t, q, v_before, v_after, p, hit.impulse)
            if driven != 0.0 and "drive" in model.work_names:
                # a rheonomic constraint (a prescribed drive) works impulsively: its work joins the drive's
                y[ix_new(model, out.mode)["work"].start + model.work_names.index("drive")] += driven
    row.setdefault("message", tr.message or "")
    carried = carried_stop(mech, model, mode, out.mode, values_before, p_before, p, t, y_end, y)
    if carried is not None:
        # the restart itself moved the state past a stop guard (a stall located a hair after the guard that
        # fired): that guard will never cross zero in the new mode, so it fires here and the stop wins
        name, stop = carried
        out.mode, out.values, out.p, out.offset, out.y, out.yp = mode, values_before, p_before, offset_before, None, None
        out.rows = [dict(row, to_mode=stop.mode, kind=stop.kind, guard=name, kinetic_energy_after_J=row[
            "kinetic_energy_before_J"], message=stop.stop)]
        out.failure = dict(time=t, mode=mode, reason=stop.stop, where=_where(model, q_before + offset_before),
                           hint=stop.hint or DEFAULT_STOP_HINT, kind="physics")
        return out
    out.rows.append(row)
    out.y, out.yp = y, yp
    return out


def ix_new(model: DerivedModel, mode: str) -> dict:
    """The state layout of `mode`."""
    return model.modes[mode].index


def impact_split(contact, t: float, q: np.ndarray, v_before: np.ndarray, v_after: np.ndarray, p: tuple,
                 impulse: np.ndarray) -> tuple[float, float]:
    """(energy dissipated, work of the rheonomic constraints) of an impulse on `contact`'s constraints.

    With v+ = v- - M^-1 G^T P and the constraint rates r = G v + Phi_t, the kinetic energy changes by
    -P.(G v+ + G v-)/2 = P.Phi_t - P.(r+ + r-)/2: the dissipation D = P.(r+ + r-)/2 (Newton's law: (1 - e^2)/2 of
    r-^2 over G M^-1 G^T, >= 0) and the work of a prescribed motion P.Phi_t, zero for a scleronomic system."""
    impulse = np.asarray(impulse, dtype=float)
    qs = floats(q)
    r_minus = np.asarray(contact.phi_dot(t, qs, floats(v_before), p), dtype=float).ravel()
    r_plus = np.asarray(contact.phi_dot(t, qs, floats(v_after), p), dtype=float).ravel()
    G = matrix(contact.G(t, qs, p))
    phi_t_minus = r_minus - G @ np.asarray(v_before, dtype=float)
    return float(0.5 * impulse @ (r_plus + r_minus)), float(impulse @ phi_t_minus)


def impact_speed_mass(contact, t: float, q: np.ndarray, v_before: np.ndarray, v_after: np.ndarray, p: tuple,
                      impulse: np.ndarray) -> tuple[float, float]:
    """(approach speed |r-|, effective mass |P|/|r+ - r-|) of an impulse P on `contact`'s first constraint, r = G v +
    Phi_t its rate: the normal speed the bodies close with and the mass 1/(G M^-1 G^T) the impulse sees (Newton's
    law in the mass metric, docs/theory.md §G2.1); what an impact's Hertz duration and flash estimate need (§G2.2)."""
    qs = floats(q)
    r_minus = float(np.asarray(contact.phi_dot(t, qs, floats(v_before), p), dtype=float).ravel()[0])
    r_plus = float(np.asarray(contact.phi_dot(t, qs, floats(v_after), p), dtype=float).ravel()[0])
    jump = abs(r_plus - r_minus)
    return abs(r_minus), (abs(float(np.asarray(impulse, dtype=float)[0])) / jump if jump > 0 else float("nan"))


def same_constraints(model: DerivedModel, mode: str, new_mode: str, t: float, q_old: np.ndarray, p_old: tuple,
                     q_new: np.ndarray, p_new: tuple) -> bool:
    """True for an index-1 restart into the same mode whose constraints are the same functions here (the same
    Phi and G to round-off in the old and the re-based frame): a Geneva flank switch or slip reversal.

    Such a restart is taken from the integrator's state without projection (`consistent_state(project=False)`):
    the index-1 rows hold off Phi = 0 and their Baumgarte terms keep damping the drift in the mass metric,
    while a minimum-norm projection here moved the Geneva's crank by about the drift (-2.4e-10 rad at rtol
    1e-10), an error each engagement added (docs/benchmarks.md, 'Work-precision on geneva-motor'). The index-2
    and index-3 forms have Phi = 0 as a row and are always projected.
    """
    mf = model.modes[new_mode]
    if model.formulation != "index1" or new_mode != mode or mf.m == 0:
        return False
    old, new = floats(q_old), floats(q_new)
    phi_old = np.asarray(mf.phi(t, old, p_old), dtype=float).ravel()
    phi_new = np.asarray(mf.phi(t, new, p_new), dtype=float).ravel()
    G_old, G_new = matrix(mf.G(t, old, p_old)), matrix(mf.G(t, new, p_new))
    G_abs = np.abs(G_old)
    scale = float((G_abs @ np.maximum(np.abs(q_old), np.abs(q_new))).max()) + float(G_abs.max())
    tol = 1e-12 * max(scale, _TINY)
    return bool((np.abs(phi_new - phi_old) <= tol).all() and (np.abs(G_new - G_old) <= tol).all())


def guard_values(mf, t: float, y: np.ndarray, p: tuple) -> np.ndarray:
    """The mode's guard values at state y (guards are functions of t and y; y' is not read)."""
    g = np.zeros(len(mf.guard_names))
    if len(g):
        mf.events(t, y, np.zeros(y.shape), g, p)
    return g


def carried_stop(mech: Mechanism, model: DerivedModel, mode: str, new_mode: str, values: dict, p: tuple,
                 new_p: tuple, t: float, y_end: np.ndarray, y_new: np.ndarray):
    """(guard, stop transition) for a stop guard that the restart carried across zero in its direction.

    A guard present in both modes (same name) that was on its before-side at the end of the old segment and is
    past zero at the restart state would never be root-found: the new segment starts beyond it. This happens
    when two guards vanish at the same instant (the Geneva crank coming to rest makes the slip vanish too) and
    the one that is not a stop was located first; the velocity projection of the restart then moves the
    other's value by round-off across zero. Only stops are looked at: they end the run, so nothing is skipped.
    """
    old, new = model.modes[mode], model.modes[new_mode]
    after = guard_values(new, t, y_new, new_p).tolist()
    past = [j for j, (name, d, a) in enumerate(zip(new.guard_names, new.guard_directions, after))
            if name in old.guard_names and ((d < 0 and 0 > a) or (d > 0 and 0 < a))]
    if not past:              # no guard past zero at the restart: none was carried across (the old side not needed)
        return None
    before = guard_values(old, t, y_end, p)
    ix = old.index
    q, v = y_end[ix["q"]], y_end[ix["v"]]
    for j in past:
        name = new.guard_names[j]
        d, b, a = new.guard_directions[j], before[old.guard_names.index(name)], after[j]
        if (d < 0 and b >= 0 > a) or (d > 0 and b <= 0 < a):
            tr = mech.on_guard(mode, name, values, t, q, v)
            if tr.stop and tr.kind == name:   # the guard's own stop (not one the mechanism infers from q, v)
                return name, tr
    return None
