"""The diffrax backend's `explain`: name the cause of a solver failure where the integrator reports only the
symptom.

An explicit Runge-Kutta method (diffrax Tsit5, Dopri5/8, ...) on a stiff problem does not blow up: its step
controller keeps it stable by taking steps near c/|lambda_max| (c ~ 2-3.5, the extent of its stability region
on the negative real axis; Hairer & Wanner II, IV.2), so it "only" runs out of steps. When such a run stops on
its step limit, the fastest eigenvalue of the vector field at the last output is computed (jax.jacfwd of the
same jax vector field diffrax integrated); if the steps it implies for the remaining time exceed the limit, the
failure is reported as stiffness, with the time constant, the states that carry it and what works instead, where
the segment's steps were held near that bound (`HELD`).
"""
from __future__ import annotations

import numpy as np

from mechsim.dynamics.backends.diffrax_common import mode_z
from mechsim.dynamics.result import FailureCode

#: stability limit |h lambda| of explicit methods on the negative real axis (approximate; Hairer & Wanner II)
STABILITY_LIMIT = {"Euler": 2.0, "Heun": 2.0, "Midpoint": 2.0, "Ralston": 2.0, "Bosh3": 2.5, "Tsit5": 3.5,
                   "Dopri5": 3.3, "Dopri8": 6.0}
#: a segment whose mean step is at least this share of the stability-limited step was held there (a step
#: controller on a stiff problem hovers near that bound); one whose steps were far shorter ran out of its budget
#: on the steps its accuracy asked for (a start's first steps, a budget of a few steps), not on stiffness
HELD = 0.2


def explain(traj, settings, t_end: float) -> dict | None:
    """The trajectory's failure dict, with the cause named where it can be (a copy; None if it did not fail)."""
    f = traj.failure
    if not f or settings.backend != "diffrax" or settings.diffrax_solver not in STABILITY_LIMIT:
        return f
    if f.get("code") is not FailureCode.MAX_STEPS:
        return f
    try:
        stiff = fastest_mode(traj)
    except Exception:  # noqa: BLE001 - a diagnosis must never hide the original failure
        return f
    if stiff is None:
        return f
    size, real, names, mechanical = stiff
    c = STABILITY_LIMIT[settings.diffrax_solver]
    h = c / size
    needed = (t_end - f["time"]) / h
    if needed < 0.5 * settings.max_steps or _mean_step(traj, f["time"], settings.max_steps) < HELD * h:
        return f        # the budget ran out on the steps the accuracy asked for: the backend's hint (raise it)
    cause = (f"; cause: the problem is stiff for the explicit {settings.diffrax_solver}: the fastest eigenvalue "
             f"of the vector field has |lambda| = {size:.3g} 1/s, real part {real:.3g} (time constant "
             f"{1 / size:.2g} s, mostly in "
             f"{', '.join(names)}), which holds an explicit step below about {h:.2g} s, so the remaining "
             f"{t_end - f['time']:.3g} s need about {needed:.2g} steps (solver.max_steps = {settings.max_steps})")
    alpha, beta = settings.baumgarte_alpha, settings.baumgarte_beta
    # the gains' own eigenvalues, the roots of s^2 + 2 alpha s + beta^2 (the constraint's violation), largest |s|
    gains = alpha + np.sqrt(alpha * alpha - beta * beta) if alpha >= beta else beta
    baumgarte = mechanical and 0.5 * gains <= size <= 2.0 * gains
    hint = "use an implicit integrator: solver.backend = 'ida' (BDF), or solver.diffrax_solver = 'Kvaerno5'"
    if baumgarte:
        cause += (f"; it comes from the Baumgarte gains (baumgarte_alpha = {settings.baumgarte_alpha:g}, "
                  f"baumgarte_beta = {settings.baumgarte_beta:g}: eigenvalues near -alpha +- sqrt(alpha^2 - beta^2))")
        hint += ("; or lower solver.baumgarte_alpha/beta (about 10 suffices here), or use IDA with formulation = "
                 "'index2', which needs no gains")
    return dict(f, reason=f["reason"] + cause, hint=hint)


def _mean_step(traj, t_fail: float, steps: int) -> float:
    """The mean step of the segment that spent its budget of `steps` (diffrax's max_steps is a segment's): from
    its start (the last event at or before the failure, else the run's first instant) to the failure."""
    before = [float(e["t_s"]) for e in traj.events if float(e["t_s"]) <= t_fail]
    first = next((p for p in traj.pieces if len(p.t)), None)
    start = max(before) if before else (float(first.t[0]) if first is not None else t_fail)
    return (t_fail - start) / max(steps, 1)


def fastest_mode(traj) -> tuple[float, float, list[str], bool] | None:
    """(|lambda|, Re lambda, names of the states carrying most of its eigenvector, whether those are all
    mechanical coordinates) for the eigenvalue lambda of largest magnitude of the diffrax vector field at the
    trajectory's last output row, or None if there is no row to look at."""
    import jax

    from mechsim.dynamics.jax_model import jax_mode

    piece = next((p for p in reversed(traj.pieces) if len(p.t)), None)
    if piece is None:
        return None
    model = traj.model
    mf = model.modes[piece.mode]
    jm = jax_mode(mf, model.parameter_names)
    z = mode_z(mf, piece.y[-1])
    p = np.asarray(piece.params, float)
    # one compiled program (jit) instead of jax dispatching the lambdified rates op by op (a program each: ~100
    # small compilations for the Geneva with a 1-D wall mesh)
    J = np.asarray(jax.jit(jax.jacfwd(lambda zz, tt, pp: jm.rates(tt, zz, pp)))(z, float(piece.t[-1]), p))
    w, V = np.linalg.eig(J)
    k = int(np.argmax(np.abs(w)))
    nq = len(model.coordinates)
    names = ([f"{c} position" for c in model.coordinates] + [f"{c} speed" for c in model.coordinates]
             + [f"work {n}" for n in model.work_names] + list(model.extension_names))
    weight = np.abs(V[:, k])
    order = [i for i in np.argsort(weight)[::-1][:3] if weight[i] >= 0.2 * weight.max()]
    return float(abs(w[k])), float(np.real(w[k])), [names[i] for i in order], all(i < 2 * nq for i in order)
