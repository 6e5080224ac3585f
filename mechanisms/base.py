"""The mechanism interface: a small symbolic description that `dynamics/` turns into DAEs.

A mechanism is written once, in sympy: generalized coordinates q, mass matrix M(q), and per mode the
holonomic constraints Phi(t, q) = 0, the applied generalized forces Q(t, q, v, lam) (linear in the
multipliers lam, which is how Coulomb friction on a constraint force enters), guard functions that end
the mode, and named read-outs (contact force, slip speed, ...). Everything the solvers need (constraint
Jacobian, acceleration right-hand side, residual Jacobians) is derived from this in `dynamics/`. What happens
when a guard fires is a table of `TransitionRule`s (`Mechanism.transitions`), functions of the state that
numpy and JAX both evaluate.

Physical and discrete (mode) parameters are sympy symbols too, so that one derivation serves every
scenario of a mechanism; their values travel in a dict keyed by symbol name.
"""
from __future__ import annotations

from abc import ABC, abstractmethod
from dataclasses import dataclass, field
from functools import cached_property
from importlib import import_module
from typing import TYPE_CHECKING, Callable, Mapping

import numpy as np

if TYPE_CHECKING:                      # sympy is imported where a model is derived, not to run a closed form
    import sympy as sp


@dataclass(frozen=True)
class Field:
    """One scenario key a mechanism reads, declared as data so `scenarios/` can validate it generically.

    kind: "quantity" (a string with a unit, converted to `unit`, the SI unit), "int", "float", "str",
        "bool", "points" (a list of [x, y] pairs with a length unit), "list" (a list of quantities in `unit`),
        "profile" (a piecewise-linear function of time, see `profile_key`).
    required: no default; default: the value (SI) when absent. positive/nonnegative/minimum/maximum: checks;
    why: the reason for the range, shown with a refusal (quantities also get their unit's physical range,
    scenarios/schema.py UNIT_RANGES; docs/limits.md).
    """

    kind: str
    unit: str = ""
    default: object = None
    required: bool = False
    positive: bool = False
    nonnegative: bool = False
    minimum: float | None = None
    choices: tuple = ()
    help: str = ""
    maximum: float | None = None
    why: str = ""
    #: (sibling key, value or tuple of values): the key means something only when that sibling has that value (a
    #: variant's key); a value other than the default under another variant is refused, since it would be ignored
    only_if: tuple[str, object] | None = None
    #: kind "profile" (a piecewise-linear function of time, a table {t = [times], <profile_key> = [values]}): the
    #: name of its value list; the values are in `unit`, the times in s, strictly increasing
    profile_key: str = "value"
    #: sibling keys this one is given in place of: an override (`--set`, `Scenario.set`) of this key drops the
    #: file's values of those siblings unless they are overridden too, so one way of giving a value replaces another
    replaces: tuple[str, ...] = ()

    def applies_with(self, sibling_value) -> bool:
        """Whether the key means something when its `only_if` sibling has this value (always without `only_if`)."""
        if not self.only_if:
            return True
        wanted = self.only_if[1]
        return sibling_value in wanted if isinstance(wanted, tuple) else sibling_value == wanted


@dataclass(frozen=True)
class Guard:
    """A scalar function of (t, q, v, lam, p) whose zero crossing ends the current mode.

    `direction` follows scipy's convention: +1 rising only, -1 falling only, 0 both.
    """

    name: str
    expr: sp.Expr
    direction: int = 0


@dataclass(frozen=True)
class Mode:
    """One smooth piece of the hybrid motion.

    constraints: Phi_i(t, q, p), all zero in this mode (any length, may be empty).
    force: the applied generalized force Q(t, q, v, lam, p), one entry per coordinate, linear in lam.
    powers: named power flows (W) whose time integrals are reported as work columns, e.g.
        {"load": -T_L*wheel_speed, "friction": -mu*|N|*|u|}. Positive = into the mechanism.
    readouts: named output columns `<quantity>_<unit>` as expressions of (t, q, v, a, lam, p).
    heat: the contact quantities the thermal model needs (see `CONTACT_KEYS`); empty if no sliding contact.
    """

    name: str
    constraints: tuple[sp.Expr, ...]
    force: tuple[sp.Expr, ...]
    guards: tuple[Guard, ...] = ()
    powers: Mapping[str, sp.Expr] = field(default_factory=dict)
    readouts: Mapping[str, sp.Expr] = field(default_factory=dict)
    heat: Mapping[str, sp.Expr] = field(default_factory=dict)


#: Contact quantities a mode exposes for the thermal model (all SI): normal force (N, signed),
#: sliding speed at the contact (m/s, signed), speed of the contact over the driver body's and over the driven
#: body's surface (m/s; the heat source's speed over each body, docs/theory.md §G4.2).
CONTACT_KEYS = ("normal_force", "slip_speed", "source_speed_driver", "source_speed_driven")
#: Optional keys: the friction power mu |N| |u_slip| as a smooth in-mode expression (W; needed for thermal
#: states) and an integer index of the surface track in contact (e.g. the Geneva's slot counter).
CONTACT_OPTIONAL_KEYS = ("heat_rate", "track")
#: Keys of `Mechanism.contact_state`: CONTACT_KEYS and CONTACT_OPTIONAL_KEYS per output row, plus
#: `sliding_accel` (m/s^2, the rate of change of source_speed_driven, for the time a band needs to pass a
#: point) and `engaged` (bool, the bodies touch).
CONTACT_STATE_KEYS = CONTACT_KEYS + CONTACT_OPTIONAL_KEYS + ("sliding_accel", "engaged")


@dataclass(frozen=True)
class ContactGeometry:
    """A sliding line contact as the thermal model sees it (SI), in body-neutral terms: a cylinder carried by the
    driver body (radius `contact_radius`, touching along `contact_length`, at `driver_arm` from the driver's
    axis) slides along one of `tracks` flat tracks of the driven body (each swept over `track_length`); the
    driven body is about a disc of radius `driven_radius`; one contact lasts `contact_angle` of drive angle."""

    contact_radius: float
    contact_length: float
    driver_arm: float
    tracks: int
    track_length: float
    driven_radius: float
    contact_angle: float


@dataclass(frozen=True)
class ValidityCondition:
    """A condition the model's idealisation needs, evaluated on every output row (docs/theory.md, "Validity").

    `quantity(columns)` gives the monitored quantity per row from the table's columns (a mapping of name -> numpy
    array; NaN where the condition does not apply, e.g. no contact); the condition holds while quantity <= bound
    (`sense` "max") or quantity >= bound (`sense` "min"). `margin` is the signed distance to the bound, >= 0 where
    valid; the worst row is the one of least margin. `needs` names the columns `quantity` reads (the condition is
    not evaluated where the table lacks one); `unit` is the quantity's unit ("" if dimensionless); `source` where
    the condition comes from (paper and equation, or docs section). `signed(columns)`, where given, is a continuous
    signed quantity that passes zero exactly where `quantity` does (a magnitude's own sign: the traction of a friction
    demand |F_t|/|N|): where it changes sign between two rows of a smooth interval, the quantity reaches zero
    between them, however narrow that stretch (`scenarios/validity.py` `located` searches there)."""

    name: str
    description: str
    quantity: object            # Callable[[Mapping[str, np.ndarray]], np.ndarray]
    bound: float
    sense: str                  # "max": quantity <= bound; "min": quantity >= bound
    unit: str
    source: str
    needs: tuple[str, ...] = ()
    signed: object = None       # Callable[[Mapping[str, np.ndarray]], np.ndarray] | None

    def __post_init__(self) -> None:
        if self.sense not in ("max", "min"):
            raise ValueError(f"ValidityCondition {self.name}: sense must be 'max' or 'min', got {self.sense!r}")

    def margin(self, values: np.ndarray) -> np.ndarray:
        """bound - quantity ("max") or quantity - bound ("min"): >= 0 where the condition holds, NaN where it does
        not apply."""
        values = np.asarray(values, dtype=float)
        return self.bound - values if self.sense == "max" else values - self.bound


@dataclass(frozen=True)
class Symbols:
    """The symbols a mechanism's expressions are written in."""

    t: sp.Symbol
    q: tuple[sp.Symbol, ...]
    v: tuple[sp.Symbol, ...]
    a: tuple[sp.Symbol, ...]
    lam: tuple[sp.Symbol, ...]
    params: tuple[sp.Symbol, ...]

    @classmethod
    def make(cls, coordinates: tuple[str, ...], max_constraints: int, params: tuple[str, ...]) -> "Symbols":
        import sympy as sp
        real = dict(real=True)
        return cls(
            t=sp.Symbol("t", **real),
            q=tuple(sp.Symbol(f"q_{c}", **real) for c in coordinates),
            v=tuple(sp.Symbol(f"v_{c}", **real) for c in coordinates),
            a=tuple(sp.Symbol(f"a_{c}", **real) for c in coordinates),
            lam=tuple(sp.Symbol(f"lam_{i}", **real) for i in range(max_constraints)),
            params=tuple(sp.Symbol(p, **real) for p in params),
        )

    def p(self, name: str) -> sp.Symbol:
        """The parameter symbol called `name`."""
        for s in self.params:
            if s.name == name:
                return s
        raise KeyError(name)


@dataclass(frozen=True)
class Transition:
    """What happens when a guard fires.

    mode/updates: the next mode and the parameter values that change (e.g. the slot index).
    restitution: None = velocities stay (they must already satisfy the new constraints up to round-off;
        they are projected onto them, which removes only round-off); a number e in [0, 1] = an impact:
        the constraint-normal relative velocity is reversed and scaled by e (Newton's law), the energy loss
        is reported in the events table. The new mode keeps those constraints closed, so for e > 0 the rebound
        is then removed by a plastic projection, reported as a second row ("rebound absorbed").
    stop: a reason to stop the run here (stall, reversal, ...), reported to the user; None to go on.
    kind: a short label for the events table ("entry", "exit", "flank switch", "impact", ...).
    contact: with `restitution`, the mode whose constraints the impact acts on when it is not the new mode (an
        impact that rebounds into a mode free of them, e.g. a pin leaving the flank it struck); None: the new mode.
        With `contact` set the events row also carries the impulse on that mode's first constraint (`impulse_N_s`,
        signed as its multiplier; N s where that constraint is a length) and no rebound is absorbed.
    restitution_parameter: the parameter whose value `restitution` is (None: a fixed number, e.g. 0 for a plastic
        impact); the sensitivity pass differentiates the impact law by it (dynamics/sensitivity.py).
    """

    mode: str
    updates: Mapping[str, float] = field(default_factory=dict)
    restitution: float | None = None
    stop: str | None = None
    kind: str = "mode change"
    message: str | None = None
    #: with `stop`: what the user can do about it (shown after the reason)
    hint: str | None = None
    contact: str | None = None
    #: readings at the guard's root added to the events row (name -> number), with the work states there
    record: Mapping[str, float] | None = None
    restitution_parameter: str | None = None


@dataclass(frozen=True)
class TransitionRule:
    """One row of a mechanism's transition table (`Mechanism.transitions`), written once: the Python hybrid loop
    evaluates it with numpy (`Mechanism.on_guard`), the compiled diffrax run traces the same functions in JAX
    (dynamics/backends/jax_transitions.py). Its functions take (q, v, p, xp): the state at the guard's root, the
    parameters before the transition (p["slot"]: a dict of numbers, or the traced parameter vector by name)
    and the array namespace (numpy or jax.numpy); of the mechanism they read its structure only (which formulas,
    e.g. a method reading the Geneva's geometry class), never its numbers, so one compiled run serves every
    scenario of a model structure, and they branch with xp.where, never with Python's `if`.

    mode: the next mode; None stays in the mode the guard fired in (the only choice with `stop`).
    updates: (q, v, p, xp) -> {parameter name: new value}; parameters not named keep their values.
    kind: the events-table label.
    when: (q, v, p, xp) -> a number; the rule applies where it is > 0 (None: everywhere). A guard's rules are
        tried in order and the first that applies is taken, so the last one has no `when`.
    restitution: None = velocities stay (projected onto the new mode's constraints, which removes only
        round-off); e in [0, 1] = an impact (`Transition`). Applied by the Python loop only: the compiled run
        hands such a rule back to it.
    contact: with `restitution`, the mode whose constraints the impact acts on (`Transition.contact`).
    restitution_parameter: the parameter whose value `restitution` is (`Transition.restitution_parameter`).
    stop, message, hint: templates (`str.format`) of the reason to stop here (the rule is then a stop: the run
        ends, handed back to the Python loop by the compiled run), of a note for the events table, and of what
        the user can do about a stop. Placeholders: `mode` (the mode the guard fired in) and the keys of
        `fields(q, v, p)` (numpy; numbers or words).
    """

    mode: str | None = None
    updates: Callable | None = None
    kind: str = "mode change"
    when: Callable | None = None
    restitution: float | None = None
    stop: str | None = None
    message: str | None = None
    hint: str | None = None
    fields: Callable | None = None
    contact: str | None = None
    restitution_parameter: str | None = None

    #: the rule reads the scenario's numbers (a per-station load, `Geneva.station_torque`), not only p: the
    #: compiled run hands it back to the Python loop, which evaluates it with numpy
    numeric: bool = False
    #: (q, v, p) -> {column: number} (numpy): readings at the guard's root written into the events row with the
    #: work states there (a contact episode's onset, force peak and end); evaluated by the Python loop only
    record: Callable | None = None

    @property
    def python_only(self) -> bool:
        """True for a rule the compiled run hands back to the Python loop: a stop, an impact, a numeric rule or one
        that records readings."""
        return self.stop is not None or self.restitution is not None or self.numeric or self.record is not None


def _filled(template: str | None, fields: Mapping | None) -> str | None:
    """A rule's template (`TransitionRule.stop`, `message`, `hint`) filled in with its fields; None stays None."""
    return None if template is None else template.format(**fields)


@dataclass(frozen=True)
class Breakpoint:
    """An instant where a time-varying input bends or jumps (a load profile's knot, a motor switched on or off):
    from `time` on, the parameters named in `updates` take these values. The integrators stop and restart there
    (docs/theory.md, 'Time-varying loads and drives'); `kind` labels its events-table row."""

    time: float
    updates: Mapping[str, float]
    kind: str


def piecewise_linear(times, values, names: tuple[str, str, str], kind: str
                     ) -> tuple[dict[str, float], list[Breakpoint]]:
    """A piecewise-linear function of time f(t) = value + rate (t - time0) as parameters `names` = (value, rate,
    time0) that hold on each piece: (the parameters before the first knot, the `Breakpoint`s). f is held at its
    first value before the first knot and at its last after the last (docs/theory.md, 'Time-varying loads and
    drives'). A knot where the slope does not change is no breakpoint (f is smooth there)."""
    times, values = [float(x) for x in times], [float(x) for x in values]
    value, rate, time0 = names
    first = {value: values[0], rate: 0.0, time0: 0.0}
    points = []
    slope = 0.0
    for k, t in enumerate(times):
        new = (values[k + 1] - values[k]) / (times[k + 1] - t) if k + 1 < len(times) else 0.0
        if new != slope:
            points.append(Breakpoint(t, {value: values[k], rate: new, time0: t}, kind))
        slope = new
    return first, points


@dataclass(frozen=True)
class InitialState:
    """Where a run starts: mode, parameter updates for that mode, and approximate q0, v0 (made consistent
    by `dynamics/`: q projected onto Phi = 0 keeping the drive coordinate, v onto the velocity constraints)."""

    mode: str
    updates: Mapping[str, float]
    q: np.ndarray
    v: np.ndarray


@dataclass(frozen=True)
class DriveCycle:
    """One cycle of the driven member (`Mechanism.drive_cycle`): its angle column, the angle of one cycle (None: the
    motion has no period), where a cycle starts, and the x label of the figures against it."""

    column: str
    period: float | None
    start: float
    label: str


def load(ref: str):
    """The object a "module:name" reference names, its module imported now (drawings and study hooks are named
    this way so that matplotlib and jax are imported only where they are used)."""
    module, name = ref.split(":")
    return getattr(import_module(module), name)


class Mechanism(ABC):
    """A mechanism: the symbolic model (shared by all its scenarios) plus one scenario's numbers.

    Subclasses set `name`, `coordinates` (names of q), `max_constraints`, `parameter_names` and implement
    the abstract methods. `structure_key()` must change whenever the symbolic model changes (e.g. slot
    count if it entered the expressions structurally); derivations are cached on it.
    """

    name: str = "mechanism"
    coordinates: tuple[str, ...] = ()
    max_constraints: int = 0
    parameter_names: tuple[str, ...] = ()
    #: index of the coordinate the drive acts on (crank, driving sprocket, ...)
    drive_coordinate: int = 0
    #: coordinates whose values are angles (column unit rad) vs lengths (m)
    angle_coordinates: tuple[int, ...] = ()

    #: scenario keys, per section (e.g. {"mechanism": {...}, "load": {...}, "contact": {...}})
    schema: dict[str, dict[str, Field]] = {}
    #: names of the [initial] keys giving the drive coordinate's angle and speed
    initial_keys: tuple[str, str] = ("crank_angle", "crank_speed")
    #: default thermal model and whether the mechanism has a sliding contact at all
    has_sliding_contact: bool = False
    #: the result columns whose peaks (largest |value|, with time and drive angle) the run's summary reports
    peak_columns: tuple[str, ...] = ()
    #: "module:Class" of the mechanism's drawing (matplotlib artists, `mechanisms/drawing.py`), imported only when
    #: a figure or an animation is drawn; None: it has none
    drawing: str | None = None
    #: "module:NAME" of the mechanism's `ParameterMap` (mechanisms/parameter_map.py: its parameters as jax formulas
    #: of its scenario values, for the design sensitivities and the sizing), imported when asked for; None: none
    sensitivity_map: str | None = None
    #: whole-number scenario keys a sizing enumerates (each value one design to size) rather than varies
    #: continuously, e.g. the Geneva's slot count
    enumerated_keys: tuple[str, ...] = ()
    #: where functions a mechanism derives for itself are kept between processes: an object with
    #: `load_functions(key)` and `store_functions(key, functions, meta)` (dynamics/derivation_cache.py, which the
    #: scenario loader sets: mechanisms/ imports no dynamics/); None: derived in every process
    function_store = None

    def stored_functions(self, key: tuple, derive: Callable[[], tuple[dict, dict]]) -> tuple[dict, dict]:
        """(functions, meta) kept under `key` in `function_store`, else `derive()`d and kept there."""
        store = self.function_store
        got = store.load_functions(key) if store is not None else None
        if got is None:
            got = derive()
            if store is not None:
                store.store_functions(key, *got)
        return got

    @cached_property
    def symbols(self) -> Symbols:
        """The symbols of this model's expressions, made on first use (so that a closed-form run, which derives
        nothing, need not import sympy)."""
        return Symbols.make(self.coordinates, self.max_constraints, self.parameter_names)

    @classmethod
    def from_config(cls, config: dict[str, dict]) -> "Mechanism":
        """Build from validated scenario sections (SI values); raise ValueError naming a field on bad input."""
        raise NotImplementedError

    #: whether `closed_form`'s columns at an instant depend on that instant and the first one alone (its angle's
    #: origin), not on the instants between: its readings between rows then evaluate only the instants they ask for
    #: (scenarios/peaks.py `_closed_form_reader`); else each reading evaluates its interval's rows with them
    closed_form_pointwise: bool = False

    def closed_form(self, t: np.ndarray, angle0: float, speed: float) -> dict[str, np.ndarray] | None:
        """Time series at a prescribed constant drive speed without a DAE, or None if there is none.

        A dict of columns plus "powers" (name -> power array, integrated to work columns) and optionally "events"
        (a list of events-table rows: t_s, from_mode, to_mode, kind, kinetic_energy_before_J/after_J, ...)."""
        return None

    def reference_solution(self, drive, t_eval: np.ndarray, angle0: float, speed0: float,
                           rtol: float = 1e-12) -> np.ndarray | None:
        """The drive coordinate's angle (rad) at `t_eval` (t_eval[0] is the start, angle0/speed0 the state there)
        from an integration INDEPENDENT of `dynamics/` (e.g. a minimal-coordinate equation on scipy), at the
        relative and absolute tolerance `rtol`; or None when the mechanism has none for this drive
        (`dynamics.drives.Drive`). `mechsim bench` measures its methods against it; with None it falls back
        to a self-reference (mechsim's own IDA at a tight tolerance), labelled as not independent."""
        return None

    @abstractmethod
    def mass_matrix(self) -> sp.Matrix:
        """M(q, p), symmetric positive definite."""

    @abstractmethod
    def modes(self) -> dict[str, Mode]:
        """Every mode of the hybrid model, by name."""

    @abstractmethod
    def parameter_values(self) -> dict[str, float]:
        """Numeric values of every parameter symbol for this scenario (SI)."""

    @abstractmethod
    def initial_state(self, angle: float, speed: float) -> InitialState:
        """The mode and approximate state at the start, from the drive coordinate's angle and speed."""

    def transitions(self) -> dict[tuple[str, str], TransitionRule | tuple[TransitionRule, ...]] | None:
        """Every (mode, guard) pair's transition: one `TransitionRule`, or several tried in order (the first
        whose `when` holds is taken). The one description of the mechanism's transitions: `on_guard` evaluates
        it with numpy for the Python hybrid loop, and with it the diffrax backend runs a whole run as one
        compiled call (docs/diffrax.md, 'The compiled run'). None (the default): the mechanism writes `on_guard`
        itself instead, and runs on the segment loop."""
        return None

    def transition_rules(self) -> dict[tuple[str, str], tuple[TransitionRule, ...]] | None:
        """`transitions()` with every entry as a tuple of rules; built at the first call and kept (a mechanism's
        description is fixed once it is built, and the hybrid loop asks at every event). Read it, don't change it."""
        try:
            return self.__dict__["_transition_rules"]
        except KeyError:
            pass
        table = self.transitions()
        rules = None if table is None else {
            key: (entry,) if isinstance(entry, TransitionRule) else tuple(entry) for key, entry in table.items()}
        self.__dict__["_transition_rules"] = rules
        return rules

    def __getstate__(self) -> dict:
        """The mechanism to pickle or copy: without the kept `transition_rules` (functions that need not pickle;
        built again on first use)."""
        state = self.__dict__.copy()
        state.pop("_transition_rules", None)
        return state

    def on_guard(self, mode: str, guard: str, values: Mapping[str, float], t: float,
                 q: np.ndarray, v: np.ndarray) -> Transition:
        """The transition when `guard` of `mode` fires at state (q, v) with parameter values `values`: the first
        rule of the table (`transitions`) that applies there, evaluated with numpy, its templates filled in. A
        mechanism without a table overrides this."""
        rule, q, v, fields = self._fired_rule(mode, guard, values, q, v)
        updates = {} if rule.updates is None else {
            name: float(x) for name, x in rule.updates(q, v, values, np).items()}
        record = None if rule.record is None else {
            name: float(x) for name, x in rule.record(q, v, values).items()}
        return Transition(rule.mode or mode, updates, restitution=rule.restitution, stop=_filled(rule.stop, fields),
                          kind=rule.kind, message=_filled(rule.message, fields), hint=_filled(rule.hint, fields),
                          contact=rule.contact, record=record,
                          restitution_parameter=rule.restitution_parameter)

    def guard_outcome(self, mode: str, guard: str, values: Mapping[str, float], t: float,
                      q: np.ndarray, v: np.ndarray) -> tuple[str, str | None]:
        """(kind, message) of `on_guard`'s transition, for a caller that has its updates already (the compiled
        diffrax run, which applied the same table): the rule chosen and its message filled in as `on_guard` does,
        its updates and record not evaluated. A mechanism that overrides `on_guard` is asked through it."""
        if type(self).on_guard is not Mechanism.on_guard:
            tr = self.on_guard(mode, guard, values, t, q, v)
            return tr.kind, tr.message
        rule, _, _, fields = self._fired_rule(mode, guard, values, q, v)
        return rule.kind, _filled(rule.message, fields)

    def _fired_rule(self, mode: str, guard: str, values: Mapping[str, float], q, v):
        """(rule, q, v, fields) for `on_guard`: the first rule of (mode, guard) whose `when` holds at (q, v) as
        float arrays, and the placeholders of its templates (`_filled`; None where it has no template: its
        `fields` are not evaluated)."""
        table = self.transition_rules()
        if table is None:
            raise NotImplementedError(f"{self.name} has neither a transition table nor on_guard")
        rules = table.get((mode, guard))
        if rules is None:
            raise KeyError(f"unknown guard {guard!r} in mode {mode!r}")
        q, v = np.asarray(q, dtype=float), np.asarray(v, dtype=float)
        for rule in rules:
            if rule.when is not None and not float(rule.when(q, v, values, np)) > 0:
                continue
            if rule.stop is None and rule.message is None and rule.hint is None:
                return rule, q, v, None
            return rule, q, v, dict(rule.fields(q, v, values) if rule.fields is not None else {}, mode=mode)
        raise ValueError(f"no rule of guard {guard!r} in mode {mode!r} applies (the last one needs no 'when')")

    def schedule(self, t_end: float) -> list[Breakpoint]:
        """The breakpoints of the mechanism's time-varying inputs up to t_end, sorted by time (default: none; the
        parameters before the first are `parameter_values`'). The hybrid loop stops at each and takes its
        updates."""
        return []

    def rebase(self, values: Mapping[str, float]) -> tuple[np.ndarray, dict[str, float]] | None:
        """A symmetry that keeps the integrated coordinates small, or None (the default: there is none).

        (shift, updates): the state q with parameters `values` is the same physical state as q - shift with
        `values` updated by `updates` (e.g. slot k of a Geneva wheel is slot 0 one crank turn per slot back).
        Unwrapped angles grow with every turn, and so does their round-off, ulp(q); the solvers integrate
        q - shift and add the shift back to the output columns (docs/stability.md, 'Restarts')."""
        return None

    def structure_key(self) -> tuple:
        """Identifies the symbolic model; derivations are cached on (class, structure_key())."""
        return (type(self).__name__,)

    def describe(self) -> dict:
        """Derived geometry worth reporting in the summary (SI)."""
        return {}

    # -- the sliding contact (implemented by mechanisms with has_sliding_contact = True) ---------------------
    def contact_geometry(self) -> ContactGeometry:
        """The sliding contact's geometry (see ContactGeometry)."""
        raise NotImplementedError(f"{self.name} has no sliding contact")

    def contact_state(self, table) -> dict[str, np.ndarray]:
        """The contact quantities (CONTACT_STATE_KEYS) of each row of a result table (a DataFrame or a dict of
        columns, as `closed_form` returns), equal to the modes' `heat` expressions."""
        raise NotImplementedError(f"{self.name} has no sliding contact")

    def contact_starts(self, table, events) -> np.ndarray:
        """Sorted times at which a contact began (the heat source switched on at a new place), including one
        before the table's first row when the run starts in contact."""
        raise NotImplementedError(f"{self.name} has no sliding contact")

    def validity_conditions(self) -> tuple[ValidityCondition, ...]:
        """The conditions this model's idealisation needs on every output row (unilateral contacts in compression,
        friction demand within the friction available, distance from dead centres, ...); none by default."""
        return ()

    @classmethod
    def drawing_class(cls) -> type | None:
        """The class of the mechanism's drawing (`drawing`, imported now), or None."""
        return load(cls.drawing) if cls.drawing else None

    @classmethod
    def parameter_map(cls):
        """The mechanism's `ParameterMap` (`sensitivity_map`, imported now), or None: sensitivities not traced."""
        return load(cls.sensitivity_map) if cls.sensitivity_map else None

    def drive_cycle(self) -> DriveCycle | None:
        """One cycle of the driven member, for the figures against its angle; None (the default): none."""
        return None

    def extra_figures(self, timeseries, tables: dict) -> dict:
        """The mechanism's own figures of a run (file stem -> matplotlib Figure; default: none)."""
        return {}

    def completed_events(self, events, table):
        """The events table completed from its own rows and the result table (default: as it is), before anything
        reads it."""
        return events

    def extra_outputs(self, timeseries, events) -> dict:
        """Mechanism-specific tables derived from a run (name -> pandas DataFrame, written as <name>.csv)."""
        return {}
