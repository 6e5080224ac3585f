"""The whole hybrid run as ONE compiled call on diffrax's stepping pieces (docs/diffrax.md, 'The compiled run').

One while loop (`_loop`: equinox's, the step buffer written in place) takes steps with diffrax's explicit solver
(`solver.step`, its error estimate judged by `PIDController.adapt_step_size`) in the active mode (a `lax.switch` on
the mode number, `jax_model`). After each accepted step the mode's guards are evaluated at its end; a sign change in
the direction of heading is located by bisection on the step's dense interpolant (to `event_rtol`/`event_atol`, the
upper end of the bracket, as the segment backend's `FirstCrossing`). The guard that fired picks a branch of the
transition table (`jax_transitions`): next mode and parameters, then the consistent re-initialisation of
`dynamics/consistent.py` in jax (positions by Gauss-Newton onto Phi = 0, velocities by the kinetic-energy-metric
projection; an index-1 restart into the same mode with the same constraints keeps q and v,
`transitions.same_constraints`). Every accepted step's dense output goes into a preallocated buffer (one row per
step: its interval, its segment and its interpolant's coefficients, written with one update), events into another; a
second, small compiled function (`make_rows`) interpolates the output rows' states on the requested grid from the
step buffer afterwards. Accelerations and multipliers are not evaluated on the rows: the read-outs solve the KKT
system at every row from (q, v) anyway (`tables.kkt_rows`), so the pieces carry states only (`hybrid.Piece`).

The loop ends at t_end, at a failure (code), or where the table says the transition is the Python loop's (a
stop or an impact, guards firing together, the event buffer full): the driver (`simulate_run`) then applies that
one transition in Python (`transitions.apply_transition`, the same code as the segment loop) and calls the
compiled run again from there. Events-table rows are written by `on_guard` (the same table evaluated with numpy)
from the recorded states, so kinds and messages are the segment loop's. rtol/atol/max_steps are traced: one compilation of the step loop per
model structure and solver options serves every tolerance and run length (the row function is compiled per
output-buffer size, in about a second).

The compiled loop does not re-base the coordinates (`Mechanism.rebase`); the hand-backs do.
"""
from __future__ import annotations

import threading
import time as _time
from dataclasses import dataclass, replace
from enum import IntEnum
from typing import Callable

import numpy as np

from mechsim.dynamics import kkt
from mechsim.dynamics.backend import End
from mechsim.dynamics.backends import xla_options
from mechsim.dynamics.consistent import reinitialise
from mechsim.dynamics.jax_model import JaxModel, jax_model  # also enables float64
from mechsim.dynamics.programs import kept_key, program
from mechsim.dynamics.result import FailureCode
from mechsim.dynamics.traced import compile_ahead
from mechsim.dynamics.backends.diffrax_common import DT0_FIRST, evaluations_per_step, ida_rows, mode_z, state_rows
from mechsim.dynamics.backends.jax_transitions import JaxTransitions, jax_transitions

import jax  # noqa: E402
import jax.numpy as jnp  # noqa: E402

#: events one compiled call records before it hands back (and is called again)
EVENTS_PER_CALL = 64
#: accepted steps whose dense output one compiled call keeps (for its output rows) before it ends (and is called
#: again)
STEPS_PER_CALL = 4096
#: output buffers are a multiple of this many rows
ROW_BATCH = 256
#: Gauss-Newton iterations of the position projection (quadratic convergence from the integrator's drift)
GN_ITERATIONS = 3
#: bisection iterations at most when locating a guard crossing (2^-200 of a step: the width test ends it first)
MAX_BISECTIONS = 200


#: the event buffers of a compiled run (written only where a guard fired)
EVENT_KEYS = ("n_ev", "ev_t", "ev_guard", "ev_z", "ev_k", "ev_p", "ev_after", "ev_ke")


#: columns of a step record before the interpolant's coefficients: t0, t1, the end of the step's valid interval
#: (inf for a free slot, so the taken steps stay sorted), the segment number
ST_T0, ST_T1, ST_ACC, ST_SEG, ST_DENSE = range(5)


class StepRecord:
    """The dense output of one step as one float64 row (and back): a step writes its record with one update
    of the buffer instead of one per field (docs/benchmarks.md, "Costs behind the code")."""

    def __init__(self, dense_struct):
        self.struct = dense_struct          # the dense output's shapes and dtypes (jax.ShapeDtypeStruct leaves)
        leaves, self.tree = jax.tree_util.tree_flatten(dense_struct)
        if any(x.dtype != jnp.float64 for x in leaves):
            raise TypeError("the solver's dense output must be float64")
        self.shapes = [x.shape for x in leaves]
        self.sizes = [int(np.prod(x.shape, dtype=int)) for x in leaves]
        self.width = ST_DENSE + sum(self.sizes)

    def pack(self, t0, t1, t_acc, seg, dense):
        head = jnp.stack([t0, t1, t_acc, jnp.asarray(seg, jnp.float64)])
        return jnp.concatenate([head] + [jnp.ravel(x) for x in jax.tree_util.tree_leaves(dense)])

    def dense(self, row):
        """The interpolant's coefficients of one record."""
        out, at = [], ST_DENSE
        for shape, size in zip(self.shapes, self.sizes):
            out.append(jnp.reshape(row[at:at + size], shape))
            at += size
        return jax.tree_util.tree_unflatten(self.tree, out)


def step_record(jmod: JaxModel, o) -> StepRecord:
    """The step-record layout of the solver `o` names on this model's state (traced shapes only: the dense
    output's structure depends on the solver and the state's shape, not on the vector field, so a trivial one
    stands in for the model and tracing it costs nothing)."""
    import diffrax
    from mechsim.dynamics.backends.diffrax_solvers import solver_for
    solver = solver_for(o)
    term = diffrax.ODETerm(lambda t, z, args: -z)

    def dense(z):
        sstate = solver.init(term, 0.0, 1e-3, z, None)
        return solver.step(term, 0.0, 1e-3, z, None, sstate, True)[2]
    return StepRecord(jax.eval_shape(dense, jnp.zeros(jmod.nz)))


class StepLayout:
    """A compiled run's step records: their layout (`record`, made by `step_record` when a program is traced: it
    takes diffrax) and their width, which is all the host needs to run the loaded programs (the width restored
    from a kept program's record, `RunRecord`)."""

    def __init__(self, jmod: JaxModel, o):
        self.jmod, self.o = jmod, o
        self._record: StepRecord | None = None
        self._width: int | None = None

    @property
    def record(self) -> StepRecord:
        if self._record is None:
            self._record = step_record(self.jmod, self.o)
        return self._record

    @property
    def width(self) -> int:
        return self._width if self._width is not None else self.record.width

    @width.setter
    def width(self, value: int) -> None:
        self._width = int(value)


class Outputs:
    """The step loop's small outputs (everything but the step buffer) packed into one float64 and one int32
    vector in the compiled call, and unpacked on the host as views: two transfers instead of one per output
    (docs/benchmarks.md, "Costs behind the code"). The layout is read off the outputs while the call is traced
    (`pack`), so the run is traced once."""

    def __init__(self):
        self.layout: list | None = None     # per group (floats, ints): (key, start, stop, shape, is bool)

    def pack(self, out: dict) -> dict:
        keys = [k for k in out if k != "st"]
        floats = [k for k in keys if jnp.issubdtype(out[k].dtype, jnp.floating)]
        ints = [k for k in keys if k not in floats]
        self.layout = []
        for group in (floats, ints):
            pos, rows = 0, []
            for k in group:
                n = int(np.prod(out[k].shape, dtype=int))
                rows.append((k, pos, pos + n, tuple(out[k].shape), out[k].dtype == jnp.bool_))
                pos += n
            self.layout.append(rows)
        return dict(st=out["st"], floats=jnp.concatenate([jnp.ravel(out[k]) for k in floats]),
                    ints=jnp.concatenate([jnp.ravel(out[k]).astype(jnp.int32) for k in ints]))

    def recorded(self) -> list | None:
        """The layout, for a program kept on disk (dynamics/traced.py `Record`)."""
        return self.layout

    def restore(self, layout: list) -> None:
        """The layout of a kept program (JSON: its shapes as lists)."""
        self.layout = [[(k, lo, hi, tuple(shape), is_bool) for k, lo, hi, shape, is_bool in rows] for rows in layout]

    def unpack(self, floats: np.ndarray, ints: np.ndarray) -> dict:
        out = {}
        for rows, vec in zip(self.layout, (floats, ints)):
            for k, lo, hi, shape, is_bool in rows:
                x = vec[lo:hi].reshape(shape)
                out[k] = x.astype(bool) if is_bool else x
        return out


class RunRecord:
    """What tracing the compiled run records on the host, kept with its program (dynamics/traced.py `Record`): the
    outputs' layout and the step records' width."""

    def __init__(self, outputs: Outputs, steps: StepLayout):
        self.outputs, self.steps = outputs, steps

    def recorded(self) -> dict:
        return {"outputs": self.outputs.recorded(), "step_width": self.steps.width}

    def restore(self, value: dict) -> None:
        self.outputs.restore(value["outputs"])
        self.steps.width = value["step_width"]


class Code(IntEnum):
    """The compiled call's status, an integer on the device; the driver reads it only through `OUTCOME`."""

    RUNNING = 0
    DONE = 1           # reached t_end
    HAND_BACK = 2      # a guard fired whose transition is the Python loop's (or several fired together)
    STEPS_FULL = 4     # the step buffer is full: call again
    MAX_STEPS = 5      # one segment took more than max_steps steps
    NON_FINITE = 6     # the state or the step size is not finite / the step size underflowed
    CHATTERING = 7     # a guard fired again at the instant of its own transition


#: the one table from a finished call's device code to the public vocabulary every path reports in: how the
#: call ended (`dynamics.backend.End`, as a segment of the loop ends) and, for a failure, its
#: `dynamics.result.FailureCode`
OUTCOME = {
    Code.DONE: (End.END, None),
    Code.HAND_BACK: (End.GUARD, None),
    Code.STEPS_FULL: (End.PAUSE, None),
    Code.MAX_STEPS: (End.FAILED, FailureCode.MAX_STEPS),
    Code.NON_FINITE: (End.FAILED, FailureCode.NON_FINITE),
    Code.CHATTERING: (End.FAILED, FailureCode.CHATTERING),
}


# -- constraints of mode k, padded to the largest mode ------------------------------------------------------
def padded_constraint_parts(jmod: JaxModel):
    m_max = jmod.m_max

    def branch(jm):
        def f(t, q, v, p):
            M, G, phi, phi_dot = jm.constraint_parts(t, q, v, p)
            pad = m_max - jm.m
            return (M, jnp.concatenate([G, jnp.zeros((pad, jm.nq))]), jnp.concatenate([phi, jnp.zeros(pad)]),
                    jnp.concatenate([phi_dot, jnp.zeros(pad)]), jnp.arange(m_max) >= jm.m)
        return f

    branches = [branch(jm) for jm in jmod.modes]

    def parts(k, t, q, v, p):
        """(M, G, Phi, Phi', padded-row mask) of mode k; padded rows are zero."""
        if len(branches) == 1:
            return branches[0](t, q, v, p)
        return jax.lax.switch(k, branches, t, q, v, p)
    return parts


def _reinitialise(parts, k_old, k, t, q, v, p_old, p):
    """(q, v) made consistent in mode k (`consistent.reinitialise`, GN_ITERATIONS position steps, restitution 0),
    or kept as they are for an index-1 restart into the same mode with the same constraints here
    (transitions.same_constraints: Phi and G equal to 1e-12 of their scale in the old and the new parameters)."""
    _, G, phi, _, pad = parts(k, t, q, v, p)
    _, G_old, phi_old, _, _ = parts(k_old, t, q, v, p_old)
    scale = jnp.max(jnp.abs(G_old) @ jnp.abs(q)) + jnp.max(jnp.abs(G_old))
    tol = 1e-12 * jnp.maximum(scale, jnp.finfo(q.dtype).tiny)
    keep = ((k == k_old) & jnp.all(jnp.abs(phi - phi_old) <= tol) & jnp.all(jnp.abs(G - G_old) <= tol)
            & jnp.any(~pad))
    qp, vp = reinitialise(lambda qq, vv: parts(k, t, qq, vv, p), q, v, xp=jnp, steps=GN_ITERATIONS)
    return jnp.where(keep, q, qp), jnp.where(keep, v, vp)


def _loop(cond, body, init, buffer):
    """`lax.while_loop` with the step buffer (`buffer(carry)`) written in place rather than carried: equinox's
    while loop (as diffrax's own saved outputs are kept). The same program for one run; under `vmap` a plain while
    loop selects its whole carry, the megabytes of step buffer included, between the lanes still stepping and
    those done, at every step (docs/sweeps.md, "Lanes from 64 up")."""
    import equinox.internal as eqxi
    return eqxi.while_loop(cond, body, init, buffers=buffer, kind="lax")


def make_run(jmod: JaxModel, table: JaxTransitions, o, n_events: int, n_steps: int, record: StepRecord
             ) -> Callable:
    """run(k0, t0, t_end, z0, p0, dt0, tol, max_steps, seg_steps0) -> dict of arrays; to be jitted.

    tol = (rtol, atol); o: DiffraxOptions; the output rows come from the returned step buffer (`make_rows`);
    seg_steps0: steps already taken in the current mode segment by the previous call (its buffers were full).
    """
    import diffrax
    from mechsim.dynamics.backends.diffrax_solvers import solver_for
    solver = solver_for(o)
    term = diffrax.ODETerm(lambda t, z, args: jmod.rates(args[0], t, z, args[1]))
    error_order = solver.error_order(term)
    parts = padded_constraint_parts(jmod)
    nq, nz, ngm = jmod.nq, jmod.nz, jmod.ng_max
    directions = jnp.asarray([[jm.guard_directions[j] if j < jm.ng else 0 for j in range(ngm)]
                              for jm in jmod.modes], dtype=jnp.float64)
    stops = jnp.asarray(table.stops, dtype=bool)
    real = jnp.asarray([[j < jm.ng for j in range(ngm)] for jm in jmod.modes], dtype=bool)

    def reference(k, t, z, p):
        """Per guard, the sign it is on at a segment's start; a guard at zero is referenced to where it is heading
        (diffrax_backend.make_solve: roots at the initial point are not reported)."""
        f0 = jmod.rates(k, t, z, p)
        g0, gdot0 = jax.jvp(lambda tt, zz: jmod.guards(k, tt, zz, p), (t, z), (jnp.ones_like(t), f0))
        at_zero = jnp.abs(g0) <= 1e-10 * jnp.maximum(1.0, jnp.abs(t)) * jnp.abs(gdot0)
        ref = jnp.where(at_zero, jnp.where(gdot0 != 0, gdot0, 1.0), jnp.where(g0 != 0, g0, 1.0))
        return jnp.where(real[k], jnp.sign(ref), 1.0)

    def run(k0, t0, t_end, z0, p0, dt0, tol, max_steps, seg_steps0):
        controller = diffrax.PIDController(rtol=tol[0], atol=tol[1], pcoeff=o.pcoeff, icoeff=o.icoeff,
                                           dcoeff=o.dcoeff)
        args0 = (k0, p0)
        _, cstate0 = controller.init(term, t0, t0 + dt0, z0, dt0, args0, None, error_order)
        sstate0 = solver.init(term, t0, t0 + dt0, z0, args0)
        f64, i32 = jnp.float64, jnp.int32
        # the small state goes through the per-step conds; the buffers (rows, events) are only written at the
        # top level of the loop body, where XLA updates them in place
        small = dict(
            hand=i32(-1), t=jnp.asarray(t0, f64), z=z0, k=jnp.asarray(k0, i32), p=p0, dt=jnp.asarray(dt0, f64),
            ref=reference(k0, t0, z0, p0), seg_t0=jnp.asarray(t0, f64), seg_steps=seg_steps0, seg_acc=i32(0),
            jump=jnp.bool_(True), sstate=sstate0, cstate=cstate0,
            last_guard=i32(-1), last_t=jnp.asarray(-jnp.inf, f64),
            fired=jnp.zeros(ngm, bool), code=i32(Code.RUNNING),
            steps=i32(0), accepted=i32(0), rejected=i32(0), bisections=i32(0))
        # the record of every accepted step (`StepRecord`: the interval it is valid on, its segment number, its
        # interpolant's coefficients): output rows are interpolated from it after the loop, all at once.
        # (one slot more than n_steps: the scratch slot a step not taken is written to once the buffer is full)
        slots = n_steps + 1
        big = dict(n_st=i32(0), st=jnp.zeros((slots, record.width)).at[:, ST_ACC].set(jnp.inf),
                   n_ev=i32(0), ev_t=jnp.zeros(n_events), ev_guard=jnp.zeros(n_events, i32),
                   ev_z=jnp.zeros((n_events, nz)), ev_k=jnp.zeros(n_events, i32),
                   ev_p=jnp.zeros((n_events, p0.shape[0])), ev_after=jnp.zeros((n_events, nz)),
                   ev_ke=jnp.zeros((n_events, 2)))
        c = jax.tree_util.tree_map(jnp.asarray, (small, big))  # python bools of diffrax's states as arrays

        def new_segment(s, t, z, k, p, dt):
            """A segment starting at (t, z) in mode k; its reference signs are set by the caller (`on_crossing`
            once after either branch: each trace of `reference` traces every mode's guards and their jvp)."""
            return dict(s, t=t, z=z, k=k, p=p, dt=dt, seg_t0=t, seg_steps=i32(0), seg_acc=i32(0),
                        jump=jnp.bool_(True))

        no_record = (jnp.bool_(False), jnp.zeros((), f64), i32(0), jnp.zeros(nz), i32(0), p0, jnp.zeros(nz),
                     jnp.zeros(2))

        def locate(s, lo, hi, interp):
            """Bisection for the first zero of min_j ref_j g_j on the step's interpolant in (lo, hi]: the upper end
            of the final bracket (diffrax_backend.FirstCrossing)."""
            k, p, ref = s["k"], s["p"], s["ref"]

            def cond(st):
                lo, hi, n = st
                return (hi - lo > o.event_atol + o.event_rtol * jnp.abs(hi)) & (n < MAX_BISECTIONS)

            def body(st):
                lo, hi, n = st
                mid = lo + 0.5 * (hi - lo)
                before = jnp.min(ref * jmod.guards(k, mid, interp.evaluate(mid), p)) > 0
                return jnp.where(before, mid, lo), jnp.where(before, hi, mid), n + 1
            _, hi, n = jax.lax.while_loop(cond, body, (lo, hi, i32(0)))
            return hi, n

        def on_crossing(s, t, t1, interp, full, ev):
            """A guard crossed in the step (t, t1]: locate it, then re-arm it, apply the table's transition or hand
            back. Returns (small state, the end of the step's valid interval t*, event record)."""
            k, p, ref = s["k"], s["p"], s["ref"]
            t_star, n_bis = locate(s, t, t1, interp)
            z_star = interp.evaluate(t_star)
            s = dict(s, bisections=s["bisections"] + n_bis)
            h = ref * jmod.guards(k, t_star, z_star, p)
            past = h <= 0
            i = jnp.where(jnp.any(past), jnp.argmin(jnp.where(past, h, jnp.inf)), jnp.argmin(h)).astype(i32)
            d = directions[k]
            against = (d != 0) & (ref == d)          # crossed against the guard's direction: re-arm, go on
            fired = past & ~against & real[k]
            fired = fired.at[i].set(~against[i])
            mean = (t_star - s["seg_t0"]) / jnp.maximum(s["seg_acc"], 1)
            restart_dt = jnp.maximum(0.1 * mean, 1e-12 * jnp.maximum(1.0, jnp.abs(t_star)))

            def rearm(s):
                return new_segment(s, t_star, z_star, k, p, s["dt"]), no_record

            def event(s):
                q, v = z_star[:nq], z_star[nq:2 * nq]
                k_new, p_new, back = table.apply(k, i, q, v, p)
                chatter = (i == s["last_guard"]) & (t_star - s["last_t"] <= 1e-9 * jnp.maximum(1.0, jnp.abs(t_star)))
                q_new, v_new = _reinitialise(parts, k, k_new, t_star, q, v, p, p_new)
                z_new = jnp.concatenate([q_new, v_new, z_star[2 * nq:]])
                # a stop guard of the new mode carried past zero by the restart (transitions.carried_stop)
                g_new = jmod.guards(k_new, t_star, z_new, p_new)
                d_new = directions[k_new]
                carried = jnp.any(stops[k_new] & real[k_new] & (d_new != 0) & (d_new * g_new > 0))
                code = jnp.where(chatter, Code.CHATTERING, jnp.where(
                    back | (jnp.sum(fired) > 1) | carried | full, Code.HAND_BACK, Code.RUNNING)).astype(i32)
                stay = dict(s, t=t_star, z=z_star, code=code, fired=fired, hand=i)
                go = new_segment(dict(s, last_guard=i, last_t=t_star), t_star, z_new, k_new, p_new, restart_dt)
                ok = code == Code.RUNNING
                s = jax.tree_util.tree_map(lambda a, b: jnp.where(ok, a, b), go, stay)
                # kinetic energies before and after, 1/2 v^T M v, for the events table
                ke = jnp.stack([0.5 * v @ parts(k, t_star, q, v, p)[0] @ v,
                                0.5 * v_new @ parts(k_new, t_star, q_new, v_new, p_new)[0] @ v_new])
                return s, (ok, t_star, i, z_star, k_new, p_new, z_new, ke)

            s, (do, te, ge, ze, ke, pe, za, en) = jax.lax.cond(against[i], rearm, event, s)
            s = dict(s, ref=jnp.where(s["code"] == Code.RUNNING, reference(s["k"], s["t"], s["z"], s["p"]), s["ref"]))
            n = jnp.minimum(ev["n_ev"], n_events - 1)

            def put(buf, val):
                return buf.at[n].set(jnp.where(do, val, buf[n]))
            ev = dict(n_ev=ev["n_ev"] + do, ev_t=put(ev["ev_t"], te), ev_guard=put(ev["ev_guard"], ge),
                      ev_z=put(ev["ev_z"], ze), ev_k=put(ev["ev_k"], ke), ev_p=put(ev["ev_p"], pe),
                      ev_after=put(ev["ev_after"], za), ev_ke=put(ev["ev_ke"], en))
            return s, t_star, ev

        def codes(s, b):
            """The end of the call after a step or an event: t_end, a full buffer, too many steps, a bad step."""
            code = s["code"]
            code = jnp.where((code == Code.RUNNING) & (s["t"] >= t_end - 1e-12), Code.DONE, code)
            code = jnp.where((code == Code.RUNNING) & (b["n_st"] >= n_steps), Code.STEPS_FULL, code)
            code = jnp.where((code == Code.RUNNING) & (s["seg_steps"] > max_steps), Code.MAX_STEPS, code)
            bad = ~jnp.isfinite(s["dt"]) | (s["dt"] <= 1e-14 * jnp.maximum(1.0, jnp.abs(s["t"])))
            code = jnp.where((code == Code.RUNNING) & bad, Code.NON_FINITE, code)
            return dict(s, code=code.astype(i32))

        def record_step(b, t, t1, t_acc, dense):
            """The step's dense output, valid on (t, t_acc], in the segment now running, into the first free
            slot; a step not taken (t_acc = t) is overwritten by the next one (its end time inf keeps the free
            slots sorted)."""
            m = jnp.minimum(b["n_st"], n_steps)
            took = t_acc > t
            row = record.pack(t, t1, jnp.where(took, t_acc, jnp.inf), b["n_ev"], dense)
            return dict(b, n_st=b["n_st"] + took, st=b["st"].at[m].set(row))

        def step(c):
            """One step in the current mode, no branching: the mode number is traced and each evaluation switches
            on it (which costs no more than a direct call). A step whose end is past a guard is not taken: the
            inner loop ends and hands it to `segment_end`."""
            s, b, x = c
            t, z, k, p = s["t"], s["z"], s["k"], s["p"]
            t1 = jnp.minimum(t + s["dt"], t_end)
            args = (k, p)
            z1, err, dense, sstate1, _ = solver.step(term, t, t1, z, args, s["sstate"], s["jump"])
            keep, _, next_t1, _, cstate, _ = controller.adapt_step_size(t, t1, z, z1, args, err, error_order,
                                                                         s["cstate"])
            cstate = jax.tree_util.tree_map(jnp.asarray, cstate)
            sstate1 = jax.tree_util.tree_map(jnp.asarray, sstate1)
            finite = jnp.all(jnp.isfinite(z1))
            keep = keep & finite
            dt_next = jnp.where(finite, next_t1 - jnp.where(keep, t1, t), 0.5 * (t1 - t))
            crossed = keep & jnp.any(s["ref"] * jmod.guards(k, t1, z1, p) <= 0)
            s = dict(s, steps=s["steps"] + 1, seg_steps=s["seg_steps"] + 1, cstate=cstate, dt=dt_next,
                     accepted=s["accepted"] + keep, rejected=s["rejected"] + ~keep, seg_acc=s["seg_acc"] + keep)
            go = keep & ~crossed
            moved = dict(s, t=t1, z=z1, sstate=sstate1, jump=jnp.bool_(False))
            s = jax.tree_util.tree_map(lambda a, b: jnp.where(go, a, b), moved, s)
            b = record_step(b, t, t1, jnp.where(go, t1, t), dense)
            return codes(s, b), b, dict(crossed=crossed, t=t, t1=t1, dense=dense)

        def segment(c):
            """Steps until a guard crossed (or the call ends), then the crossing: located, re-armed, applied from
            the table or handed back. The only lax.cond is here, once per crossing."""
            s, b = c
            x0 = dict(crossed=jnp.bool_(False), t=s["t"], t1=s["t"],
                      dense=jax.tree_util.tree_map(lambda d: jnp.zeros(d.shape, d.dtype), record.struct))
            s, b, x = _loop(lambda c: (c[0]["code"] == Code.RUNNING) & ~c[2]["crossed"], step, (s, b, x0),
                            lambda c: c[1]["st"])
            interp = solver.interpolation_cls(t0=x["t"], t1=x["t1"], **x["dense"])
            full = b["n_ev"] >= n_events
            ev = {key: b[key] for key in EVENT_KEYS}
            s, t_acc, ev = jax.lax.cond(x["crossed"], lambda s: on_crossing(s, x["t"], x["t1"], interp, full, ev),
                                        lambda s: (s, x["t"], ev), s)
            # the crossing step up to t*, in the segment that was running (numbered before the event record)
            b = record_step(b, x["t"], x["t1"], t_acc, x["dense"])
            return codes(s, dict(b, **ev)), dict(b, **ev)

        s, b = _loop(lambda c: c[0]["code"] == Code.RUNNING, segment, c, lambda c: c[1]["st"])
        c = dict(s, **b)
        zp_end, a_end, lam_end, _ = jmod.evaluate(c["k"], c["t"], c["z"], c["p"])
        keys = ("hand", "dt", "seg_steps", "t", "z", "k", "p", "code", "fired", "n_ev", "ev_t", "ev_guard", "ev_z",
                "ev_k", "ev_p", "ev_after", "ev_ke", "steps", "accepted", "rejected", "bisections", "n_st", "st")
        return dict({key: c[key] for key in keys}, zp_end=zp_end, a_end=a_end, lam_end=lam_end)

    return run


def interpolator(o, record: StepRecord) -> Callable:
    """interpolate(row, t) -> z: the state at t from one step record, by the solver's dense output (the one
    interpolant of the output rows and of the readings between them)."""
    from mechsim.dynamics.backends.diffrax_solvers import solver_for
    solver = solver_for(o)

    def interpolate(row, t):
        return solver.interpolation_cls(t0=row[ST_T0], t1=row[ST_T1], **record.dense(row)).evaluate(t)
    return interpolate


def make_rows(o, n_steps: int, record: StepRecord) -> Callable:
    """rows(st, ts) -> dict(rows=z, row_seg); to be jitted (one compilation per output-buffer size: the step
    loop's own does not depend on it).

    The output times (sorted; a padded tail repeats the last) and the stored steps' valid intervals (contiguous,
    sorted, free slots at +inf) are walked together in one loop: each time's step is the first whose interval
    ends at or after it (`searchsorted(..., side="left")`, capped at the scratch slot), and the state is that
    step's dense output there; row_seg is the segment number it belongs to. One loop in one kernel
    (dynamics/backends/xla_options.py) costs about half of a vectorised `searchsorted` and gather, with the same
    rows to the bit (docs/benchmarks.md)."""
    interpolate = interpolator(o, record)

    def rows(st, ts):
        ends = st[:, ST_ACC]

        def one(i, c):
            j, z, seg = c
            t = ts[i]
            j = jax.lax.while_loop(lambda j: (ends[j] < t) & (j < n_steps), lambda j: j + 1, j)
            return j, z.at[i].set(interpolate(st[j], t)), seg.at[i].set(st[j, ST_SEG].astype(jnp.int32))
        n = ts.shape[0]
        z0 = jnp.zeros((n,) + jax.eval_shape(interpolate, st[0], ts[0]).shape)
        _, z, seg = jax.lax.fori_loop(0, n, one, (jnp.int32(0), z0, jnp.zeros(n, jnp.int32)))
        return dict(rows=z, row_seg=seg)
    return rows


#: instants one call of the dense reading holds: the call evaluates only the instants it is given (its cost
#: follows their number), and one call holds the whole first pass of readings of a run's located peaks
DENSE_BATCH = 1024


def make_dense(o, record: StepRecord) -> Callable:
    """dense(rows, ts, n) -> z: the states at the instants ts[:n], ts[i] from the step record rows[i], by the
    interpolant of the output rows (`make_rows`) in one loop in one kernel as theirs (the same states to the
    bit, a fraction of a vectorised evaluation's cost, and none for the padding); rows and ts past n are not
    read, z is zero there."""
    interpolate = interpolator(o, record)

    def dense(rows, ts, n):
        z0 = jnp.zeros((rows.shape[0],) + jax.eval_shape(interpolate, rows[0], ts[0]).shape)
        return jax.lax.fori_loop(0, n, lambda i, z: z.at[i].set(interpolate(rows[i], ts[i])), z0)
    return dense


def _sorted(x: np.ndarray) -> bool:
    """Whether x is non-decreasing (False with a NaN in it)."""
    return bool(np.all(x[1:] >= x[:-1]))


_STAGING = threading.local()        # per thread: record width -> the dense reading's input buffers


class _Records:
    """The taken steps' records of a run's compiled calls, numbered one after another (or in `order`), left in the
    calls' own buffers: joining them would copy every record of the run (a 1-D thermal mesh's are thousands of
    numbers each: 37 ms a run) where a reading gathers only the few it reads."""

    def __init__(self, parts: list[np.ndarray], width: int, order: np.ndarray | None = None):
        self.parts, self.width, self.order = parts, width, order
        self.part = np.repeat(np.arange(len(parts)), [len(p) for p in parts])       # each record's call
        self.row = np.concatenate([np.arange(len(p)) for p in parts]) if parts else np.zeros(0, int)
        if order is not None:
            self.part, self.row = self.part[order], self.row[order]

    def reordered(self, order: np.ndarray) -> "_Records":
        return _Records(self.parts, self.width, order if self.order is None else self.order[order])

    def column(self, k: int) -> np.ndarray:
        """Entry k of every record, in their order."""
        if len(self.parts) == 1 and self.order is None:
            return self.parts[0][:, k]
        if not self.parts:
            return np.zeros(0)
        joined = np.concatenate([p[:, k] for p in self.parts])
        return joined if self.order is None else joined[self.order]

    def take(self, steps: np.ndarray, out: np.ndarray) -> None:
        """out[i] = record steps[i] (each in range)."""
        if len(self.parts) == 1 and self.order is None:
            np.take(self.parts[0], steps, axis=0, out=out, mode="clip")           # (in range: unbuffered)
            return
        part, row = self.part[steps], self.row[steps]
        for c in np.unique(part).tolist():
            mine = part == c
            out[mine] = self.parts[c][row[mine]]


def _staging(width: int) -> tuple[np.ndarray, np.ndarray]:
    """This thread's input buffers of the dense reading (DENSE_BATCH step records and instants; past the instants
    of a call, what an earlier call left, never read), 64-byte aligned so that the CPU client reads them in place
    instead of copying them, and kept from call to call (fresh memory costs its first touch again)."""
    kept = _STAGING.__dict__.setdefault("buffers", {})
    if width not in kept:
        def aligned(n: int) -> np.ndarray:
            raw = np.empty(n + 8)
            at = (-raw.ctypes.data % 64) // 8
            return raw[at:at + n]
        kept[width] = (aligned(DENSE_BATCH * width).reshape(DENSE_BATCH, width), aligned(DENSE_BATCH))
    return kept[width]


class DenseOutput:
    """A compiled run's states at any instants between its events, from the step buffers its output rows were
    interpolated from (`make_dense`): `read(times, lo, hi)` -> (mode, parameters, offset, y rows in the mode's
    IDA layout, multipliers NaN as on the rows), or None where the instants are not all inside one mode segment
    overlapping (lo, hi)."""

    def __init__(self, entry: CompiledRun, o, model, nq: int):
        self.entry, self.o, self.model, self.nq = entry, o, model, nq
        self.segments: list[tuple] = []       # (t start, t end, call, segment, mode, parameters, offset)
        self.buffers: list = []               # (step buffer, the steps taken into it) of each call
        self._table = None                    # the segments and their taken steps as arrays, on the host

    def add_call(self, st, n_st: int, t0: float, t1: float, ev_t, modes, params, offset) -> None:
        """A compiled call's step buffer `st` (its first n_st records the steps it took: a step not taken is
        written to the first free slot with an infinite end, `make_run`), its interval and its segments."""
        c = len(self.buffers)
        self.buffers.append((st, n_st))
        bounds = [t0] + [float(x) for x in ev_t] + [t1]
        for s, (a, b) in enumerate(zip(bounds[:-1], bounds[1:])):
            self.segments.append((a, b, c, s, modes[s], params[s], offset))
        self._table = None

    def _tables(self) -> tuple:
        """(segment starts, ends, mode-and-parameters group of each, its run (consecutive segments of one group
        share one), whether starts and ends are each in order (and not NaN); the taken steps' records (`_Records`),
        their t0, t_acc, segment (its index in `segments`), each segment's first and last step + 1, and whether t_acc
        is sorted over all of them), built once per run."""
        if self._table is None:
            groups: dict = {}
            S = self.segments
            lo = np.array([g[0] for g in S], dtype=float)
            hi = np.array([g[1] for g in S], dtype=float)
            group = np.array([groups.setdefault((g[4], np.asarray(g[5], float).tobytes(),
                                                  np.asarray(g[6], float).tobytes()), len(groups)) for g in S])
            run = np.concatenate([[0], np.cumsum(group[1:] != group[:-1])]) if len(S) else group   # runs of a group
            bounds = [g[0] for g in S], [g[1] for g in S]
            ordered = all(all(x <= y for x, y in zip(b[:-1], b[1:])) and all(x == x for x in b) for b in bounds)
            first = {}                # call -> index of its first segment
            for n, g in enumerate(S):
                first.setdefault(g[2], n)
            recs, segs = [], []
            for c, (buf, n_st) in enumerate(self.buffers):
                taken = np.asarray(buf)[:n_st]        # the taken steps lead the buffer: a view
                recs.append(taken)
                segs.append(first.get(c, 0) + taken[:, ST_SEG].astype(int))
            rec = _Records(recs, self.entry.steps.width)
            seg = segs[0] if len(segs) == 1 else np.concatenate(segs) if segs else np.zeros(0, int)
            if np.any(seg[1:] < seg[:-1]):                # each segment's steps together, in time order
                order = np.argsort(seg, kind="stable")
                rec, seg = rec.reordered(order), seg[order]
            at = np.searchsorted(seg, np.arange(len(S) + 1))
            acc = np.ascontiguousarray(rec.column(ST_ACC))
            self._table = (lo, hi, group, run, ordered, rec, rec.column(ST_T0), acc, at, seg, _sorted(acc))
        return self._table

    def _fn(self):
        key = ("dense", DENSE_BATCH)
        fn = self.entry.rows.get(key)
        if fn is None:
            example = (np.zeros((DENSE_BATCH, self.entry.steps.width)), np.zeros(DENSE_BATCH), np.int32(0))
            entry = self.entry
            fn = compile_ahead("diffrax_run_dense", entry.key and (entry.key, DENSE_BATCH),
                               lambda: jax.jit(make_dense(self.o, entry.steps.record)), example)
            self.entry.rows[key] = fn
        return fn

    def read(self, times: np.ndarray, lo: float, hi: float):
        return self.read_many([(times, lo, hi)])[0]

    def read_many(self, requests: list[tuple[np.ndarray, float, float]]) -> list:
        """`read` for each (times, lo, hi), the instants of all evaluated together (one compiled call per
        DENSE_BATCH instants). Each instant is read on the first segment overlapping (lo, hi) that holds it,
        by the step of that segment whose [t0, t_acc] holds it (at a segment's first instant, an event's: its
        first step, the limit after the event)."""
        out: list = [None] * len(requests)
        if not requests or not self.segments:
            return out
        s_lo, s_hi, group, run, ordered, rec, t0, acc, at, step_seg, acc_sorted = self._tables()
        span = np.array([(r[1], r[2]) for r in requests], dtype=float).reshape(-1, 2)
        lengths = [len(r[0]) for r in requests]
        sizes = np.array(lengths)
        rid = np.repeat(np.arange(len(requests)), sizes)
        ts = (np.asarray(requests[0][0], dtype=float) if len(requests) == 1
              else np.concatenate([np.asarray(r[0], dtype=float) for r in requests]))
        if ordered and not np.isnan(span).any():
            # segments in time order (starts and ends each sorted): those overlapping a request, and those holding
            # an instant, are each a range of them, found by searches (the same first ones as the matrices below)
            last = len(s_lo) - 1
            lo_in = np.searchsorted(s_hi, span[:, 0], side="right")      # the first ending after the request's lo
            hi_in = np.searchsorted(s_lo, span[:, 1], side="left") - 1   # the last starting before its hi
            some_in = lo_in <= hi_in
            own = np.where(some_in, lo_in, 0)
            ok = some_in & (sizes > 0) & (run[np.minimum(lo_in, last)] == run[np.maximum(hi_in, 0)])
            seg_lo = np.maximum(np.searchsorted(s_hi, ts, side="left"), lo_in[rid])   # first: ends at or after t
            seg_hi = np.minimum(np.searchsorted(s_lo, ts, side="right") - 1, hi_in[rid])   # last: starts by t
            held = seg_lo <= seg_hi
            seg = np.where(held, seg_lo, 0)
        else:
            inside = (s_lo < span[:, 1:]) & (s_hi > span[:, :1])             # requests x segments
            own = inside.argmax(axis=1)
            ok = inside.any(axis=1) & (sizes > 0) & ~(inside & (group != group[own, None])).any(axis=1)
            col = ts[:, None]
            hold = inside[rid] & (col >= s_lo) & (col <= s_hi)                # instants x segments
            seg = hold.argmax(axis=1)                                         # the first segment that holds each
            held = hold.any(axis=1)
        a, b = at[seg], at[seg + 1]
        # the step of each instant's segment whose t_acc is the first at or after it (the segment's last where
        # none): its segment's first step + its steps before the instant (t_acc < t). Where t_acc is sorted over
        # all steps (the steps of later segments end later), that is one search on the left, kept within the
        # segment; otherwise one stable sort of the steps and instants by (segment, time) counts them, an instant
        # before a step of equal time.
        if acc_sorted:
            steps = np.minimum(np.maximum(np.searchsorted(acc, ts, side="left"), a), b)
        else:
            n_rec = len(acc)
            key_seg = np.concatenate([step_seg, seg])
            order = np.lexsort((np.r_[np.ones(n_rec, bool), np.zeros(len(ts), bool)], np.concatenate([acc, ts]),
                                key_seg))
            before = np.cumsum(order < n_rec) - (order < n_rec)      # steps ahead of each entry in that order
            steps = np.empty(len(order), dtype=int)
            steps[order] = before
            steps = steps[n_rec:]
        some = b > a
        j = np.where(some, np.minimum(steps, b - 1), 0)
        good = held & some & (t0[j] <= ts) & (ts <= acc[j])
        if not good.all():
            ok &= np.bincount(rid[~good], minlength=len(requests)) == 0
        read = ok[rid]
        steps, tt = (j, ts) if read.all() else (j[read], ts[read])
        rows, at_t = _staging(rec.width)
        parts = []
        for c in range(0, len(tt), DENSE_BATCH):
            n = min(DENSE_BATCH, len(tt) - c)
            rec.take(steps[c:c + n], rows[:n])
            at_t[:n] = tt[c:c + n]
            parts.append(np.asarray(self._fn()(rows, at_t, np.int32(n)))[:n])   # (waited for: staging free again)
        z = parts[0] if len(parts) == 1 else np.concatenate(parts) if parts else np.zeros((0, self.entry.jmod.nz))
        own_at, segments, start = own.tolist(), self.segments, 0
        ys: dict = {}                           # the IDA layout, once per mode
        for r in np.flatnonzero(ok).tolist():
            g = segments[own_at[r]]
            y = ys.get(g[4])
            if y is None:
                y = ys[g[4]] = state_rows(self.model.modes[g[4]], self.nq, z)
            end = start + lengths[r]
            out[r] = (g[4], g[5], g[6], y[start:end])
            start = end
        return out


# -- compilation cache -------------------------------------------------------------------------------------
@dataclass
class CompiledRun:
    fn: Callable
    jmod: JaxModel
    compile_time: float
    compile_cpu_time: float
    rows: dict          # output-buffer size -> the compiled row function
    steps: StepLayout
    outputs: Outputs
    key: tuple | None   # the run's key on disk (dynamics/traced.py; None: not kept), its row programs' too


def row_bucket(n: int) -> int:
    """Output-buffer rows for n output times: n rounded up to an eighth of its power of two (so that runs of
    similar length share a compilation; 5001 rows -> 5120), a multiple of ROW_BATCH, at most 2^16."""
    n = max(int(n), 1)
    grain = max(ROW_BATCH, 1 << max(n.bit_length() - 3, 0))
    return int(min(-(-n // grain) * grain, 1 << 16))


def run_key(o):
    """Options that shape the compiled run (tolerances and max_steps are traced)."""
    return replace(o, rtol=0.0, atol=0.0, max_steps=0, n_save=None, projection=True)


def compiled_run(mech, model, o) -> tuple[CompiledRun | None, bool]:
    """The compiled run of a model (None if the mechanism has no transition table); True if compiled by this
    call. One per model structure and options: the output-buffer size only shapes the row function."""
    def build() -> CompiledRun | None:
        wall, cpu = _time.perf_counter(), _time.process_time()
        jmod = jax_model(model)
        table = jax_transitions(mech, model, jmod)
        if table is None:
            return None
        example = run_arguments(0, 0.0, 1.0, np.zeros(jmod.nz), np.zeros(len(model.parameter_names)), 1e-3,
                                (1e-6, 1e-8), 100)
        steps, outputs = StepLayout(jmod, o), Outputs()
        key = kept_key(model, options)

        def make():
            run = make_run(jmod, table, o, EVENTS_PER_CALL, STEPS_PER_CALL, steps.record)
            return jax.jit(lambda *a: outputs.pack(run(*a)))
        with kkt.unrolled_solves():   # the unrolled KKT solve is traced into this program only (dynamics/kkt.py)
            fn = compile_ahead("diffrax_whole_run", key, make, example, RunRecord(outputs, steps))
        return CompiledRun(fn, jmod, _time.perf_counter() - wall, _time.process_time() - cpu, {}, steps, outputs,
                           key)
    rules = mech.transition_rules()
    hand_back = None if rules is None else tuple((k, tuple(r.python_only for r in v)) for k, v in rules.items())
    # the transition table is traced in: the mechanism's class and structure shape the program too, and a numeric
    # rule (a per-station load) is handed back: another program
    options = (run_key(o), type(mech).__name__, mech.structure_key(), STEPS_PER_CALL, EVENTS_PER_CALL, hand_back)
    entry, fresh = program("diffrax_whole_run", model, options, build)
    return entry, fresh and entry is not None


def compiled_rows(entry: CompiledRun, o, n_rows: int, example: tuple) -> tuple[Callable, float, float]:
    """The row function of a compiled run for n_rows output times (compiled at first use with `example`'s
    shapes); its compile (wall, CPU) time, zero when cached."""
    hit = entry.rows.get(n_rows)
    if hit is not None:
        return hit, 0.0, 0.0
    wall, cpu = _time.perf_counter(), _time.process_time()
    fn = compile_ahead("diffrax_run_rows", entry.key and (entry.key, n_rows),
                       lambda: jax.jit(make_rows(o, STEPS_PER_CALL, entry.steps.record)), example)
    entry.rows[n_rows] = fn
    return fn, _time.perf_counter() - wall, _time.process_time() - cpu


def run_arguments(k, t0, t_end, z0, p, dt0, tol, max_steps, seg_steps=0) -> tuple:
    f64 = np.float64
    return (np.int32(k), f64(t0), f64(t_end), np.asarray(z0, f64), np.asarray(p, f64), f64(dt0),
            np.asarray(tol, f64), np.int32(max_steps), np.int32(seg_steps))


# -- the driver: compiled calls, and the Python loop's transitions where the table hands back ----------------
def _failure(model, mode: str, t: float, q, code: FailureCode, o) -> dict:
    where = {c: float(v) for c, v in zip(model.coordinates, q)}
    if code is FailureCode.MAX_STEPS:
        from mechsim.dynamics.backends.diffrax_solvers import MAX_STEPS_REACHED, result_message
        msg = result_message(MAX_STEPS_REACHED)
        return dict(time=t, mode=mode, reason=f"diffrax {o.solver} failed: {msg} ({o.max_steps} in one mode "
                    "segment)", code=code, where=where,
                    hint="raise solver.max_steps or loosen rtol; check for a singular configuration here")
    return dict(time=t, mode=mode, reason=f"diffrax {o.solver} failed: non-finite state or step size underflow",
                code=code, where=where,
                hint="check for a singular configuration here, or try another solver.diffrax_solver")


def simulate_run(mech, start, settings, o, t0: float, t_end: float, progress=None, call=None):
    """The run of `hybrid.simulate` as compiled whole-run calls: a `Trajectory` with the segment loop's pieces,
    events rows (kinds and messages as `on_guard` writes them, from the recorded states) and statistics; None when the mechanism has no
    transition table (the caller falls back to the segment loop). call(fn, args): runs one compiled call and
    fetches its outputs (default: jax.device_get(fn(*args)))."""
    from mechsim.dynamics.hybrid import Piece, Trajectory, at_breakpoint, fire, reached
    from mechsim.dynamics.stats import new_stats
    from mechsim.dynamics.transitions import chattering

    model = start.model
    entry, fresh = compiled_run(mech, model, o)
    if entry is None:
        return None
    n_rows = row_bucket(len(start.t_out))
    jmod, names = entry.jmod, list(model.parameter_names)
    mode_names = jmod.names
    t_out = start.t_out
    ordered = start.output_times_ordered()
    one_layout = len({mf_.index["mu"].stop for mf_ in model.modes.values()}) == 1
    nq = jmod.nq
    q_columns = [f"{c}_q" for c in model.coordinates]
    stats = new_stats("diffrax", o.solver, start.derive_time,
                      unavailable={"jacobian_evaluations": "not exposed by diffrax"})
    per_step = evaluations_per_step(o)
    stats["notes"]["xla_options"] = xla_options.state()     # dynamics/backends/xla_options.py
    stats["notes"]["residual_evaluations"] = ("estimated: attempted steps x new stages per step + one per step "
                                              "(guards) + one per bisection")
    if fresh:
        stats.update(compile_time_s=entry.compile_time, compile_cpu_time_s=entry.compile_cpu_time, compilations=1)
    wall0 = _time.perf_counter()
    mode, values, p, y, yp, offset = start.mode, dict(start.values), start.p, start.y, start.yp, start.offset
    pieces = [Piece(mode, p, np.array([t0]), y[None, :].copy(), yp[None, :].copy(), offset)]
    dense = DenseOutput(entry, o, model, nq)
    events, warnings, failure, last = [], [], None, None
    t, dt0, calls, seg_steps = t0, DT0_FIRST, 0, 0
    knots = list(start.knots)
    while True:
        while knots and reached(knots, t):    # a breakpoint (hybrid.schedule): the call ended there, restart
            _, updates, kind = knots.pop(0)
            values, p, y, yp, row = at_breakpoint(model, mode, values, t, y, updates, kind, offset)
            events.append(row)
            stats["restarts"] += 1
        stop = knots[0][0] if knots else t_end   # each call ends at the next breakpoint: never stepped over
        mf = model.modes[mode]
        args = run_arguments(jmod.index(mode), t, stop, mode_z(mf, y), p, dt0, (o.rtol, o.atol), o.max_steps,
                             seg_steps)
        res = call(entry.fn, args) if call else entry.fn(*args)
        out = entry.outputs.unpack(np.asarray(res["floats"]), np.asarray(res["ints"]))   # (not device_get: slower)
        calls += 1
        # the call's output rows, from its step buffer (left where it is), in chunks of the row buffer
        t_call = float(out["t"])          # the output times in (t, t_call]
        ts = (t_out[t_out.searchsorted(t, "right"):t_out.searchsorted(t_call, "right")] if ordered
              else t_out[(t_out > t) & (t_out <= t_call)])
        n_ev, n_out = int(out["n_ev"]), len(ts)
        chunks = []
        for lo in range(0, n_out, n_rows):
            chunk = ts[lo:lo + n_rows]
            ts_pad = np.full(n_rows, chunk[-1])
            ts_pad[:len(chunk)] = chunk
            row_args = (res["st"], ts_pad)
            rows_fn, c_wall, c_cpu = compiled_rows(entry, o, n_rows, row_args)
            if c_wall:
                stats["compile_time_s"] += c_wall
                stats["compile_cpu_time_s"] += c_cpu
                stats["compilations"] += 1
            r = call(rows_fn, row_args) if call else rows_fn(*row_args)
            chunks.append({key: np.asarray(v)[:len(chunk)] for key, v in r.items()})
        if len(chunks) == 1:
            out.update(chunks[0])
        elif chunks:
            out.update({key: np.concatenate([c[key] for c in chunks]) for key in chunks[0]})
        else:                   # no output time reached (a failure before the first one)
            out["rows"], out["row_seg"] = np.zeros((0, jmod.nz)), np.zeros(0, np.int32)
        stats["steps"] += int(out["steps"])
        stats["accepted_steps"] += int(out["accepted"])
        stats["rejected_steps"] += int(out["rejected"])
        stats["residual_evaluations"] += (int(out["steps"]) * (per_step or 1) + int(out["accepted"])
                                          + int(out["bisections"]))
        stats["segments"] += n_ev + 1
        modes = [mode] + [mode_names[k] for k in out["ev_k"][:n_ev].tolist()]
        params = [p] + [tuple(row) for row in out["ev_p"][:n_ev].tolist()]
        dense.add_call(res["st"], int(out["n_st"]), t, t_call, out["ev_t"][:n_ev], modes, params, offset)
        seg = out["row_seg"][:n_out]
        # rows are in segment order: one piece per segment, split where the segment number changes
        edges = [0] + (np.flatnonzero(seg[1:] != seg[:-1]) + 1).tolist() + [n_out] if n_out else []
        y_all = state_rows(mf, nq, out["rows"][:n_out]) if one_layout else None   # one layout: all rows at once
        for s, lo, hi in zip(seg[edges[:-1]].tolist(), edges[:-1], edges[1:]):
            y_rows = y_all[lo:hi] if y_all is not None else state_rows(model.modes[modes[s]], nq, out["rows"][lo:hi])
            pieces.append(Piece(modes[s], params[s], ts[lo:hi], y_rows, None, offset))
        if n_ev:        # the events' numbers as Python values, all at once
            ev_t, ev_guard, ev_ke = (out[key][:n_ev].tolist() for key in ("ev_t", "ev_guard", "ev_ke"))
            ev_q = (out["ev_z"][:n_ev, :nq] + offset).tolist()
        for e in range(n_ev):
            t_e, z_b = ev_t[e], out["ev_z"][e]
            vals = dict(values)
            vals.update(zip(names, params[e]))
            guard = model.modes[modes[e]].guard_names[ev_guard[e]]
            # (the call applied the transition: its kind and message only, as on_guard's)
            kind, message = mech.guard_outcome(modes[e], guard, vals, t_e, z_b[:nq], z_b[nq:2 * nq])
            events.append(dict(t_s=t_e, from_mode=modes[e], to_mode=modes[e + 1], kind=kind, guard=guard,
                               **dict(zip(q_columns, ev_q[e])), kinetic_energy_before_J=ev_ke[e][0],
                               kinetic_energy_after_J=ev_ke[e][1], message=message or ""))
            if message:
                warnings.append(f"t = {t_e:.6g} s: {message}")
            last = (guard, t_e)
        stats["events"] += n_ev
        stats["restarts"] += n_ev
        mode, p = modes[-1], params[-1]
        values.update(zip(names, p))
        mf = model.modes[mode]
        t = t_call
        y, yp = (r[0] for r in ida_rows(mf, nq, out["z"], out["zp_end"], out["a_end"], out["lam_end"][:mf.m]))
        dt0 = float(out["dt"])
        if progress:
            progress(t)
        end, code = OUTCOME[Code(int(out["code"]))]
        q = y[mf.index["q"]]
        if end is End.END:
            if not knots:
                break
            t, seg_steps = stop, 0
            dt0 = 0.1 * dt0
            continue
        seg_steps = int(out["seg_steps"]) if end is End.PAUSE else 0
        if end is End.PAUSE:
            continue
        if code is FailureCode.CHATTERING:
            guard = mf.guard_names[int(out["hand"])]
            failure = dict(chattering(model, mode, guard, t, q + offset, (guard, t)), code=code)
            break
        if end is End.FAILED:
            failure = _failure(model, mode, t, q + offset, code, o)
            break
        fired = [int(out["hand"])] + [int(j) for j in np.flatnonzero(out["fired"]) if j != int(out["hand"])]
        tr_out, failure, last = fire(mech, model, mode, values, t, y, q, fired, offset, last, stats)
        if tr_out is not None:
            events += tr_out.rows
            warnings += tr_out.warnings
        if failure:
            break
        mode, values, p, y, yp, offset = tr_out.mode, tr_out.values, tr_out.p, tr_out.y, tr_out.yp, tr_out.offset
        dt0 = 0.1 * dt0
    stats["notes"]["segments"] = f"mode segments, inside {calls} compiled whole-run call(s)"
    stats["solve_time_s"] = _time.perf_counter() - wall0
    traj = Trajectory(model, pieces, events, stats, failure, warnings)
    traj.dense = dense            # the run's own dense output, for readings between rows (dynamics/extrema.py)
    return traj

