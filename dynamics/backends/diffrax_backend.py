"""The diffrax backend: the same derived model, integrated as an ODE with the whole per-mode solve compiled.

Each mode's vector field comes from `jax_model` (accelerations and multipliers from the Baumgarte-stabilised
KKT system, work and thermal rates alongside), built from the same sympy description as the IDA residual.
A segment is one `diffrax.diffeqsolve` with one `diffrax.Event` per guard (optimistix root finder for the
crossing time); the first crossing ends it and the hybrid loop (`dynamics/hybrid.py`, the same loop as IDA's)
applies the transition, so the events table has the same rows. Parameters (slot, flank, drive, gains, ...) are
traced arguments, so one compilation per (mode, model structure, solver options) serves every segment; output
rows at the requested times come from `SaveAt(ts=...)` over a fixed-size padded array (segments with more
outputs than that are continued in chunks, re-projected onto the constraints at each restart).

Guards already at zero when a segment starts (the one that just fired) are referenced to the sign they are
heading for, so a root located a hair before the crossing does not fire again: the IDA rule that roots at the
initial point are not reported.

Known limitation of diffrax 0.7.2 (docs/diffrax.md): its implicit solvers reject many steps; the defaults here
are the best docs/diffrax.md found.
"""
from __future__ import annotations

import time as _time
from dataclasses import dataclass, replace
from typing import TYPE_CHECKING, Callable

import numpy as np

from mechsim.dynamics.consistent import consistent_state
from mechsim.dynamics.backend import Backend, End, Request, Segment
from mechsim.dynamics.jax_model import JaxModel, jax_model  # also enables float64
from mechsim.dynamics.programs import kept_key, program
from mechsim.dynamics.traced import compile_ahead
from mechsim.dynamics.backends import xla_options
from mechsim.dynamics.backends.diffrax_common import (DT0_FIRST, DT0_FLOOR, DiffraxOptions, default_options,
                                                      evaluations_per_step, ida_rows, mode_z, save_times)
from mechsim.dynamics.backends.diffrax_diagnose import explain
from mechsim.dynamics.result import FailureCode
from mechsim.dynamics.settings import SolverSettings

import jax  # noqa: E402  (after jax_model has switched on float64)
import jax.numpy as jnp  # noqa: E402

if TYPE_CHECKING:
    from mechsim.mechanisms.base import Mechanism
    from mechsim.dynamics.hybrid import Trajectory

# -- one compiled segment solve ----------------------------------------------------------------------------
def make_solve(jmod: JaxModel, o: DiffraxOptions) -> Callable:
    """solve(k, t0, t1, z0, p, enabled, ts) -> dict of arrays, for mode number k; to be jitted.

    The segment's single event function is min_i sign(ref_i) g_i over the enabled guards: positive at the
    start (ref_i = g_i there, or the sign a guard at zero is heading for), and it first reaches zero exactly
    where the first guard crosses, whatever the units of the others.
    """
    import diffrax
    from mechsim.dynamics.backends.diffrax_solvers import ADJOINT, FirstCrossing, solver_for
    term = diffrax.ODETerm(lambda t, z, args: jmod.rates(args[0], t, z, args[1]))

    def heading(t, y, args):
        k, p, t_start, ref, enabled = args
        h = jnp.where(t == t_start, jnp.abs(ref), jnp.sign(ref) * jmod.guards(k, t, y, p))
        return jnp.where(enabled, h, jnp.inf)

    def cond(t, y, args, **kwargs):
        return jnp.minimum(jnp.min(heading(t, y, args)), 1.0)

    event = diffrax.Event(cond, FirstCrossing(rtol=o.event_rtol, atol=o.event_atol), direction=False)
    solver = solver_for(o)

    def solve(k, t0, t1, z0, p, enabled, ts, dt0, tol):
        # the step controller's (rtol, atol) are traced: one compilation serves every tolerance (compile_key)
        controller = diffrax.PIDController(rtol=tol[0], atol=tol[1], pcoeff=o.pcoeff, icoeff=o.icoeff,
                                           dcoeff=o.dcoeff)
        f0 = jmod.rates(k, t0, z0, p)
        g0, gdot0 = jax.jvp(lambda tt, zz: jmod.guards(k, tt, zz, p), (t0, z0), (jnp.ones_like(t0), f0))
        # a guard at zero (it would cross within 1e-10 relative time) is referenced to where it is heading
        at_zero = jnp.abs(g0) <= 1e-10 * jnp.maximum(1.0, jnp.abs(t0)) * jnp.abs(gdot0)
        ref = jnp.where(at_zero, jnp.where(gdot0 != 0, gdot0, 1.0), jnp.where(g0 != 0, g0, 1.0))
        args = (k, p, t0, ref, enabled)
        saveat = diffrax.SaveAt(subs=[diffrax.SubSaveAt(ts=ts), diffrax.SubSaveAt(t1=True)])
        sol = diffrax.diffeqsolve(term, solver, t0, t1, jnp.minimum(dt0, t1 - t0), z0, args=args, saveat=saveat,
                                  stepsize_controller=controller, max_steps=o.max_steps, throw=False,
                                  event=event, adjoint=ADJOINT)
        ts_out, zs = sol.ts[0], sol.ys[0]
        zp, acc, lam, _ = jax.vmap(jmod.evaluate, in_axes=(None, 0, 0, None))(k, ts_out, zs, p)
        t_end, z_end = sol.ts[1][0], sol.ys[1][0]
        zp_end, acc_end, lam_end, _ = jmod.evaluate(k, t_end, z_end, p)
        return dict(ts=ts_out, z=zs, zp=zp, a=acc, lam=lam, t_end=t_end, z_end=z_end, zp_end=zp_end,
                    a_end=acc_end, lam_end=lam_end, h_end=heading(t_end, z_end, args), ref=ref,
                    result=sol.result._value, steps=sol.stats["num_steps"],
                    accepted=sol.stats["num_accepted_steps"], rejected=sol.stats["num_rejected_steps"])

    return solve


@dataclass
class _Compiled:
    fn: Callable
    compile_time: float
    compile_cpu_time: float


def segment_arguments(k, t0, t1, z0, p, enabled, ts, dt0, tol):
    """Arguments of the compiled solve as numpy values of the compiled dtypes (cheaper than jnp.asarray);
    tol = (rtol, atol) of the step controller."""
    f64 = np.float64
    return (np.int32(k), f64(t0), f64(t1), np.asarray(z0, f64), np.asarray(p, f64), np.asarray(enabled, np.bool_),
            np.asarray(ts, f64), f64(dt0), np.asarray(tol, f64))


def compile_key(o: DiffraxOptions) -> DiffraxOptions:
    """The options that shape the compiled segment solve: an explicit solver's tolerances are traced arguments,
    so every tolerance shares one compilation; an implicit solver's stage root finder takes them as constants.
    `compiled_run` only picks the driver (the segment solve is the same program either way)."""
    o = replace(o, compiled_run=False)
    return o if o.implicit else replace(o, rtol=0.0, atol=0.0)


def compiled_solve(model, o: DiffraxOptions) -> tuple[_Compiled, JaxModel, bool]:
    """The compiled segment solve of a model (all its modes; AOT-compiled once per model structure and
    options); True if it was compiled by this call."""
    def build() -> _Compiled:
        wall, cpu = _time.perf_counter(), _time.process_time()
        jmod = jax_model(model)      # sympy -> jax lambdification (once per model), counted with the compilation
        example = segment_arguments(0, 0.0, 1.0, np.zeros(jmod.nz), np.zeros(len(model.parameter_names)),
                                    np.ones(jmod.ng_max, bool), np.ones(o.rows(jmod.nz)), 1e-3, (o.rtol, o.atol))
        fn = compile_ahead("diffrax_segment_solve", kept_key(model, (compile_key(o),)),
                           lambda: jax.jit(make_solve(jmod, o)), example)
        return _Compiled(fn, _time.perf_counter() - wall, _time.process_time() - cpu)
    entry, fresh = program("diffrax_segment_solve", model, (compile_key(o),), build)
    return entry, jax_model(model), fresh


# -- the backend ----------------------------------------------------------------------------------------------
class DiffraxBackend(Backend):
    """diffrax on the mode's index-1 ODE (`jax_model`), one compiled `diffeqsolve` per segment, under the
    contract of `dynamics/backend.py`.

    `integrate` = `arguments` (the compiled solve's inputs) + the compiled call + `segment` (its outputs as a
    `Segment`); `dynamics.backends.diffrax_batch` uses the two halves around one vmapped call for many lanes.
    A segment with more output times than one call holds (`DiffraxOptions.rows`) ends in a pause at the last
    row (restarted from the state projected onto the constraints when `options.projection`).
    """

    name = "diffrax"
    initial_step = DT0_FIRST
    recoverable = frozenset({FailureCode.INTEGRATOR_FAILED})

    def __init__(self, settings: SolverSettings, options: DiffraxOptions | None = None):
        self.settings = settings
        self.o = options or default_options(settings)
        self.solver = self.o.solver
        self.per_step = evaluations_per_step(self.o)
        self.unavailable = {"jacobian_evaluations": "not exposed by diffrax"}
        self.notes = {"xla_options": xla_options.state()}   # dynamics/backends/xla_options.py
        if self.per_step:
            self.notes["residual_evaluations"] = "estimated: attempted steps x new stages per step + 3 per segment"
        else:
            self.unavailable["residual_evaluations"] = "not exposed by diffrax for implicit solvers"

    def whole_run(self, mech: Mechanism, start, t0: float, t_end: float, progress=None) -> Trajectory | None:
        """The run as compiled whole-run calls (`diffrax_run.simulate_run`), or None where that path does not
        apply (no transition table, an implicit solver, events off, `options.compiled_run` False)."""
        if not (self.o.compiled_run and not self.o.implicit and self.settings.events):
            return None
        from mechsim.dynamics.backends.diffrax_run import simulate_run
        return simulate_run(mech, start, self.settings, self.o, t0, t_end, progress, call=self.call_compiled)

    @classmethod
    def explain(cls, traj, settings: SolverSettings, t_end: float) -> dict | None:
        """The failure with its cause named where an explicit solver only ran out of steps
        (`diffrax_diagnose.explain`: stiffness)."""
        return explain(traj, settings, t_end)

    def call_compiled(self, fn, args) -> dict:
        """One call of a compiled function of the whole run (the step loop or its rows), waited for: a hook for
        timing it. Its outputs stay jax arrays (the step buffer goes on to the row function without a copy)."""
        return jax.block_until_ready(fn(*args))

    def hint(self, code: FailureCode) -> str:
        return ("raise solver.max_steps, loosen rtol, or try another solver.diffrax_solver (Kvaerno5 if the "
                "motion is stiff); check for a singular configuration here")

    def integrate(self, request: Request) -> Segment:
        entry, jmod, fresh = compiled_solve(request.model, self.o)
        args, n_chunk = self.arguments(request, jmod)
        seg = self.segment(request, jmod, jax.device_get(entry.fn(*args)), n_chunk)
        if fresh:
            seg.counts.update(compile_time_s=entry.compile_time, compile_cpu_time_s=entry.compile_cpu_time,
                              compilations=1)
        return seg

    def arguments(self, r: Request, jmod: JaxModel) -> tuple[tuple, int]:
        """Arguments of the compiled solve for the request, and the number of real output times in them."""
        n_save = self.o.rows(jmod.nz)
        chunk = r.t_out[:n_save]
        t1 = r.t_end if len(r.t_out) <= n_save else float(chunk[-1])
        ts = save_times(chunk, r.t0, t1, n_save)
        enabled = np.zeros(jmod.ng_max, bool)
        enabled[:len(r.mf.guard_names)] = bool(self.settings.events)
        dt0 = r.first_step if r.first_step > 0 else DT0_FIRST    # > 0 and t1 >= t0: diffrax's check of dt0 holds
        return segment_arguments(jmod.index(r.mode), r.t0, t1, mode_z(r.mf, r.y0), np.asarray(r.p), enabled, ts,
                                 dt0, (self.o.rtol, self.o.atol)), len(chunk)

    def segment(self, r: Request, jmod: JaxModel, out: dict, n_chunk: int) -> Segment:
        """The compiled solve's outputs (numpy values) as a Segment in the IDA layout of the mode."""
        o, mf, t = self.o, r.mf, r.t0
        n_save = o.rows(jmod.nz)
        counts = dict(steps=int(out["steps"]), accepted_steps=int(out["accepted"]),
                      rejected_steps=int(out["rejected"]))
        if self.per_step:
            counts["residual_evaluations"] = int(out["steps"]) * self.per_step + 3
        t_seg = float(out["t_end"])
        # the next call starts with this one's mean accepted step (the loop takes a tenth after a mode change)
        next_step = max((t_seg - t) / max(int(out["accepted"]), 1), DT0_FLOOR * max(1.0, abs(t)))
        keep = np.arange(n_save) < n_chunk
        keep &= np.isfinite(out["ts"]) & (out["ts"] <= t_seg)
        y_rows, yp_rows = ida_rows(mf, jmod.nq, out["z"][keep], out["zp"][keep], out["a"][keep], out["lam"][keep])
        t_rows = out["ts"][keep].copy()
        y_end, yp_end = (row[0] for row in ida_rows(mf, jmod.nq, out["z_end"], out["zp_end"], out["a_end"],
                                                     out["lam_end"]))
        seg = Segment(t_rows, y_rows, yp_rows, End.END, t_seg, y_end, yp_end, counts=counts, next_step=next_step)
        from mechsim.dynamics.backends.diffrax_solvers import (EVENT_OCCURRED, MAX_STEPS_REACHED, SUCCESSFUL,
                                                               result_message)
        code = int(out["result"])
        is_event = code == EVENT_OCCURRED
        ok = code == SUCCESSFUL or is_event
        if not ok or not np.all(np.isfinite(out["z_end"])):
            msg = result_message(code) if not ok else "non-finite state"
            seg.end, seg.message = End.FAILED, f"diffrax {o.solver} failed: {msg}"
            seg.code = (FailureCode.NON_FINITE if ok else FailureCode.MAX_STEPS
                        if code == MAX_STEPS_REACHED else FailureCode.INTEGRATOR_FAILED)
            return seg
        ix = mf.index
        if not is_event:
            if t_seg >= r.t_end - 1e-12:
                return seg
            seg.end = End.PAUSE
            if o.projection:     # an output-chunk boundary: restart from the state projected onto the constraints
                seg.y_end, seg.yp_end, _ = consistent_state(mf, t_seg, y_end[ix["q"]], y_end[ix["v"]],
                                                            y_end[ix["work"]], y_end[ix["ext"]], r.p)
            return seg
        # a guard crossed: the one whose heading value is at or past zero at the (just-past) crossing time
        ng = len(mf.guard_names)
        h = np.asarray(out["h_end"])[:ng]
        i = int(np.argmin(np.where(h <= 0, h, np.inf))) if (h <= 0).any() else int(np.argmin(h))
        direction = mf.guard_directions[i]
        if direction and np.sign(out["ref"][i]) == direction:
            seg.end = End.PAUSE          # crossed against its direction: not an event; re-armed, go on
            return seg
        # every guard past zero at the crossing instant, in the allowed direction (as IDA reports its roots)
        fired = [j for j in np.flatnonzero(h <= 0) if j != i and not (
            mf.guard_directions[j] and np.sign(out["ref"][j]) == mf.guard_directions[j])]
        seg.end, seg.fired = End.GUARD, (i, *(int(j) for j in fired))
        return seg
