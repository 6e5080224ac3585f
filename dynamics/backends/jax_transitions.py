"""A mechanism's transition table (`Mechanism.transitions`) traced in JAX, for the compiled run.

Every (mode, guard) pair of a derived model gets one branch: the next mode number, the parameter vector after the
transition and a hand-back flag, true where the compiled loop must leave the transition to the Python loop (the
rule that applies is a stop or an impact, `TransitionRule.python_only`, or the pair has no rule). The branch calls
the same rule functions `Mechanism.on_guard` calls with numpy, here with jax.numpy and the parameter vector read
by name; a guard's rules are tried in order, the first whose `when` is positive taken. Branches are laid out
k * ng_max + j over mode number k and guard j, so one `lax.switch` serves the whole table.
"""
from __future__ import annotations

from dataclasses import dataclass
from typing import Callable

import jax
import jax.numpy as jnp

from mechsim.dynamics.jax_model import JaxModel


@dataclass(frozen=True, eq=False)
class JaxTransitions:
    """apply(k, j, q, v, p) -> (next mode number, p after, hand back?) for mode number k and guard j."""

    branches: tuple[Callable, ...]
    ng_max: int
    #: (mode number, guard index) -> True where the loop never applies the transition itself (a stop)
    stops: tuple[tuple[bool, ...], ...]

    def apply(self, k, j, q, v, p):
        return jax.lax.switch(k * self.ng_max + j, self.branches, q, v, p)


class ByName:
    """The parameter vector read by name, p["slot"], as the rules read a dict of values in the Python loop."""

    def __init__(self, p, index: dict[str, int]):
        self.p, self.index = p, index

    def __getitem__(self, name: str):
        return self.p[self.index[name]]


def _branch(k: int, rules: tuple, k_next: list[int | None], index: dict[str, int]):
    """The branch of a guard of mode number k with `rules`, whose next modes are numbers `k_next` (None: hand
    back)."""
    def branch(q, v, p):
        p = jnp.asarray(p)        # lax.switch over one branch calls it with the operands as given (numpy too)
        named = ByName(p, index)
        k_out, p_out, back = jnp.int32(k), p, jnp.bool_(True)      # no rule applies: hand back
        for rule, kn in reversed(list(zip(rules, k_next))):        # the first rule that applies wins
            k_r, p_r, back_r = jnp.int32(k), p, jnp.bool_(True)
            if kn is not None:
                k_r, back_r = jnp.int32(kn), jnp.bool_(False)
                updates = rule.updates(q, v, named, jnp) if rule.updates is not None else {}
                for name, x in updates.items():
                    p_r = p_r.at[index[name]].set(jnp.asarray(x, dtype=p.dtype))
            if rule.when is None:
                k_out, p_out, back = k_r, p_r, back_r
            else:
                take = jnp.asarray(rule.when(q, v, named, jnp)) > 0
                k_out, p_out, back = (jnp.where(take, k_r, k_out), jnp.where(take, p_r, p_out),
                                      jnp.where(take, back_r, back))
        return k_out, p_out, back
    return branch


def jax_transitions(mech, model, jmod: JaxModel) -> JaxTransitions | None:
    """The table of `mech` for a derived model, or None if the mechanism has none."""
    table = mech.transition_rules()
    if table is None:
        return None
    index = {n: i for i, n in enumerate(model.parameter_names)}
    branches, stops = [], []
    for k, jm in enumerate(jmod.modes):
        row = []
        for j in range(jmod.ng_max):
            rules = table.get((jm.name, jm.guard_names[j]), ()) if j < jm.ng else ()
            k_next = [None if r.python_only else jmod.index(r.mode or jm.name) for r in rules]
            branches.append(_branch(k, rules, k_next, index))
            row.append(all(kn is None for kn in k_next))
        stops.append(tuple(row))
    return JaxTransitions(tuple(branches), jmod.ng_max, tuple(stops))
