"""diffrax's objects that mechsim's compiled programs are traced with: the solver a `DiffraxOptions` names (with
its stage root finder), the root finder of the segment solve's event, the adjoint, and diffrax's result codes.

Importing this module imports diffrax, equinox and optimistix (about 0.4 s): it is imported where a program is
traced or a result code is read, never by a process that loads its programs from the user's cache
(dynamics/traced.py) and runs them.
"""
from __future__ import annotations

from typing import Callable

from mechsim.dynamics.jax_model import jax_model  # noqa: F401  (switches on float64 before diffrax loads)
from mechsim.dynamics.backends.diffrax_common import DiffraxOptions

import diffrax  # noqa: E402
import equinox as eqx  # noqa: E402
import jax  # noqa: E402
import jax.numpy as jnp  # noqa: E402
import jax.tree_util as jtu  # noqa: E402
import optimistix as optx  # noqa: E402

#: plain lax while loops: no reverse-mode machinery in the compiled solve
ADJOINT = diffrax.ForwardMode()
#: diffrax's result codes that mechsim reads (a segment solve's `result`)
SUCCESSFUL = int(diffrax.RESULTS.successful._value)
EVENT_OCCURRED = int(diffrax.RESULTS.event_occurred._value)
MAX_STEPS_REACHED = int(diffrax.RESULTS.max_steps_reached._value)


class PatientVeryChord(diffrax.VeryChord):
    """diffrax's VeryChord with a corrected termination test (the cause of diffrax 0.7.2's rejected steps).

    In diffrax 0.7.2 `VeryChord.terminate` reports `nonlinear_divergence` whenever, from the second iteration on,
    the iteration has not yet converged, even while it is contracting; optimistix stops at the first
    non-successful result, so every stage that needs a third chord iteration fails, the step's error becomes
    inf and the step is rejected (about half the steps, docs/diffrax.md). Here divergence means divergence:
    the corrections grow (rate > 2) or are not finite. The iteration also stops when a correction is already
    below `floor` tolerance units, where the rate of two round-off-sized corrections is noise.
    """

    floor: float = 1e-3

    def terminate(self, fn, y, args, options, state, tags):
        at_least_two = state.step >= 2
        rate = state.diffsize / state.diffsize_prev
        factor = state.diffsize * rate / (1 - rate)
        tiny = (state.step >= 1) & (state.diffsize < self.floor)
        converged = tiny | (at_least_two & (factor > 0) & (factor < self.kappa))
        diverged = at_least_two & jnp.invert(tiny) & (jnp.invert(jnp.isfinite(rate)) | (rate > 2))
        linsolve_fail = state.result != optx.RESULTS.successful
        result = optx.RESULTS.where(diverged, optx.RESULTS.nonlinear_divergence, optx.RESULTS.successful)
        result = optx.RESULTS.where(linsolve_fail, state.result, result)
        return converged | diverged | linsolve_fail, result


def _stage_root_finder(o: DiffraxOptions):
    rtol, atol = o.newton_tol * o.rtol, o.newton_tol * o.atol
    if o.newton == "verychord":
        return diffrax.VeryChord(rtol=rtol, atol=atol, kappa=o.newton_kappa)
    if o.newton == "patient":
        return PatientVeryChord(rtol=rtol, atol=atol, kappa=o.newton_kappa, floor=o.newton_floor)
    if o.newton == "chord":
        return optx.Chord(rtol=rtol, atol=atol, kappa=o.newton_kappa, cauchy_termination=True)
    if o.newton == "newton":
        return optx.Newton(rtol=rtol, atol=atol, kappa=o.newton_kappa, cauchy_termination=True)
    raise ValueError(f"unknown implicit root finder {o.newton!r}")


def solver_for(o: DiffraxOptions):
    cls = getattr(diffrax, o.solver)
    return cls(root_finder=_stage_root_finder(o)) if o.implicit else cls()


class _State(eqx.Module):
    lower: jax.Array
    upper: jax.Array


class FirstCrossing(optx.AbstractRootFinder):
    """Bisection on [lower, upper] for the time where the segment's guard function first reaches zero.

    Terminates on the width of the bracket only (guards have mixed units, so no test on |f|), and returns the
    bracket's upper end: the first instant located *past* the crossing, as IDA does.
    """

    rtol: float
    atol: float
    norm: Callable = optx.max_norm

    def init(self, fn, y, args, options, f_struct, aux_struct, tags):
        dtype = jnp.result_type(y)
        return _State(jnp.asarray(options["lower"], dtype), jnp.asarray(options["upper"], dtype))

    def step(self, fn, y, args, options, state, tags):
        mid = state.lower + 0.5 * (state.upper - state.lower)
        f, aux = fn(mid, args)
        before = sum(jtu.tree_leaves(f)) > 0          # the guard function is positive before its crossing
        new = _State(jnp.where(before, mid, state.lower), jnp.where(before, state.upper, mid))
        return new.upper, new, aux

    def terminate(self, fn, y, args, options, state, tags):
        width = state.upper - state.lower
        return width <= self.atol + self.rtol * jnp.abs(state.upper), optx.RESULTS.successful

    def postprocess(self, fn, y, aux, args, options, state, tags, result):
        return y, aux, {}


def result_message(code: int) -> str:
    """diffrax's words for a solve's result code, first line (diffrax keeps its message table private: read
    in this one place)."""
    return diffrax.RESULTS._index_to_message[int(code)].splitlines()[0]
