"""A mechanism's transition table (`Mechanism.symbolic_transitions`) as jax functions, for the compiled run.

Every (mode, guard) pair of a derived model gets one branch: the next mode number, the parameter vector after the
transition (each update lambdified from its sympy expression of (q, v, p), like `jax_model` does for the mode
functions) and a hand-back flag, true where the compiled loop must leave the transition to `on_guard` (a stop,
a pair without an entry, or where the entry's `handoff` expression is positive). Branches are laid out
k * ng_max + j over mode number k and guard j, so one `lax.switch` serves the whole table.
"""
from __future__ import annotations

from dataclasses import dataclass
from typing import Callable

import jax
import jax.numpy as jnp
import sympy as sp

from mechsim.dynamics.jax_model import JaxModel, lambdify_jax


@dataclass(frozen=True, eq=False)
class JaxTransitions:
    """apply(k, j, q, v, p) -> (next mode number, p after, hand back?) for mode number k and guard j."""

    branches: tuple[Callable, ...]
    ng_max: int
    #: (mode number, guard index) -> True where the loop never applies the transition itself (a stop)
    stops: tuple[tuple[bool, ...], ...]

    def apply(self, k, j, q, v, p):
        return jax.lax.switch(k * self.ng_max + j, self.branches, q, v, p)


def _hand_back(k: int):
    def branch(q, v, p):
        return jnp.int32(k), p, jnp.bool_(True)
    return branch


def _branch(k_next: int, index: list[int], updates: Callable | None, handoff: Callable | None):
    idx = jnp.asarray(index, dtype=jnp.int32)

    def branch(q, v, p):
        p = jnp.asarray(p)        # lax.switch over one branch calls it with the operands as given (numpy too)
        p_new = p
        if updates is not None:
            vals = jnp.stack([jnp.asarray(x, dtype=p.dtype) for x in updates(q, v, p)])
            p_new = p.at[idx].set(vals)
        back = jnp.bool_(False) if handoff is None else jnp.asarray(handoff(q, v, p)[0]) > 0
        return jnp.int32(k_next), p_new, back
    return branch


def jax_transitions(mech, model, jmod: JaxModel) -> JaxTransitions | None:
    """The table of `mech` for a derived model, or None if the mechanism has none."""
    table = mech.symbolic_transitions()
    if table is None:
        return None
    s = mech.symbols
    names = list(model.parameter_names)
    params = [sp.Symbol(n, real=True) for n in names]
    q, v = list(s.q), list(s.v)
    branches, stops = [], []
    for k, jm in enumerate(jmod.modes):
        row = []
        for j in range(jmod.ng_max):
            entry = table.get((jm.name, jm.guard_names[j])) if j < jm.ng else None
            if entry is None or entry.mode is None:
                branches.append(_hand_back(k))
                row.append(True)
                continue
            keys = list(entry.updates)
            updates = lambdify_jax([q, v, params], [entry.updates[n] for n in keys]) if keys else None
            handoff = lambdify_jax([q, v, params], [entry.handoff]) if entry.handoff is not None else None
            branches.append(_branch(jmod.index(entry.mode), [names.index(n) for n in keys], updates, handoff))
            row.append(False)
        stops.append(tuple(row))
    return JaxTransitions(tuple(branches), jmod.ng_max, tuple(stops))
