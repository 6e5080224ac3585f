"""How a mechanism's scenario values enter its model, for the design sensitivities and the sizing
(docs/sensitivity.md): the `ParameterMap` each mechanism gives in its own folder (`Mechanism.sensitivity_map`),
its parameters as jax-traceable formulas of the values. The studies (scenarios/studies/sensitivity_map.py) check
every map against the mechanism rebuilt with each value moved.
"""
from __future__ import annotations

from dataclasses import dataclass
from typing import Callable


@dataclass(frozen=True)
class ParameterMap:
    """How the scenario values of one mechanism type enter the model.

    keys: the supported scenario keys (SI). parameters(x, si, mech): the model parameters they set, as
    jax-traceable formulas of the dict x (key -> value); each is checked against the mechanism's own
    `parameter_values()`. speed_key: the initial-speed key (the initial velocities are linear in it). discrete:
    parameters that transitions may change, whose values do not depend on any of `keys` (integers, signs, or
    geometry that is not traced). list_keys, piece_parameters, pieces, refuse, hold_drive: below. engage/release:
    the event kinds that start and end an index (the cycle runs from one `engage` to the next; empty for a
    mechanism that does not index). peaks: its peak quantities (`peak_<column>` of its result columns).
    sliding: it has a sliding contact (the heat per index is a quantity). The contact fields trace its
    temperatures (below; None: thermal sensitivities are not traced for it).
    """

    keys: tuple[str, ...]
    parameters: Callable
    speed_key: str
    discrete: frozenset
    engage: str
    release: str
    peaks: tuple[str, ...] = ()
    sliding: bool = False
    #: (si) -> the keys of list entries traced in this scenario ('mechanism.sprocket_radii[0]', ...)
    list_keys: Callable | None = None
    #: (x, si, mech, values) -> the parameters a transition sets for the mode whose values are `values` (a piece of
    #: the chain's path), as jax formulas of x like `parameters`; None: transitions change only `discrete` ones
    piece_parameters: Callable | None = None
    #: (mech) -> every such set of values the mechanism's transitions can set (checked like `parameters`)
    pieces: Callable | None = None
    #: (plan, key) -> why the key cannot be traced on this plan (a tuned design's geometry), or None
    refuse: Callable | None = None
    #: the initial state assembles with the drive coordinate held (Mechanism.initial_state): its derivative too
    hold_drive: bool = False
    #: (mech, angle, speed) -> (dq, dv): the initial guess's derivative in the drive's initial angle, per radian
    #: (`initial_angle_seed`); None: the drive coordinate's unit vector and no velocity change, which is the whole
    #: derivative with `hold_drive` (the hold completes the other coordinates by the implicit-function rule)
    initial_angle: Callable | None = None
    #: (x, si) -> the sliding contact's geometry as jax formulas of x: a dict of `ContactGeometry`'s fields
    #: (mechanisms/base.py; `tracks` a whole number), as `Mechanism.contact_geometry` gives it
    contact_geometry: Callable | None = None
    #: the result columns a row's contact state is made of (`contact_row`'s `columns`)
    contact_columns: tuple[str, ...] = ()
    #: (columns, R, xp) -> the contact state of rows (normal_force, slip_speed, source_speed_driver,
    #: source_speed_driven, sliding_accel; `Mechanism.contact_state`) from the values of `contact_columns` (a
    #: sequence in that order, scalars or arrays) and the traced contact radius R, with array module xp
    contact_row: Callable | None = None
    #: the event kinds at which a contact begins (the heat source switched on at a new place)
    contact_starts: tuple[str, ...] = ()
