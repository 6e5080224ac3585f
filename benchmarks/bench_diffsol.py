"""The peer a careful diffsol user would write: the Geneva in minimal coordinates, DiffSL compiled by LLVM.

diffsol (a Rust ODE solver library) reads its equations in DiffSL and compiles them at run time with LLVM;
pydiffsol is its Python binding. A user who knows the mechanism writes its one degree of freedom, the crank
angle theta, per mode (docs/theory.md §G1 for the closed-form kinematics, §G2 for the equation of motion):

    engaged:  (J1 + J2 G^2) theta'' = T_in - c1 theta' - G (J2 G' theta'^2 + c2 G theta' + T_L),
    dwell:    J1 theta'' = T_in - c1 theta',       T_in = T0 - slope theta',

with alpha = theta - 2 pi k (slot k), D = 1 - 2 lam cos(alpha) + lam^2, G = lam (cos(alpha) - lam) / D and
G' = -lam (1 - lam^2) sin(alpha) / D^2 (lam = r / c). One DiffSL program holds both modes: the mode enters as
an input e (1 engaged, 0 dwell) that multiplies G and G', so e = 0 is the dwell's equation exactly. The mode,
the slot angle, the boundary angle and the restart state are inputs; the mode's boundary (the engagement limit
alpha = +-alpha_0, whose angle is known in advance) is DiffSL's stop function theta - bound, which diffsol
locates as a root. A Python loop calls `solve_dense` on the rest of the 1 ms output grid, and at each stop
takes the state there and restarts in the next mode (exit -> dwell, entry -> engaged in the next slot), as the
mechanism's transition rules say; the next mode comes from the event, not from the state (the located root
may sit a rounding error before the boundary).

Covered: the external Geneva without friction (case A), mechanics only. With friction the slip reversals are
mode changes (a second stop function and the slip sign as an input) that this peer does not write; thermal
states are not in it either. Needs the `peers` extra (pydiffsol).
"""
from __future__ import annotations

import math
import time
from dataclasses import dataclass

import numpy as np

from mechsim.benchmarks.bench_casadi import PeerRun, constant_load
from mechsim.mechanisms.geneva.kinematics import speed_ratio

#: the Geneva's crank angle per mode in one DiffSL program (docs/theory.md §G1-G2); inputs in this order
CODE = """
in_i { T0 = 0, slope = 0, J1 = 1, J2 = 1, c1 = 0, c2 = 0, TL = 0, lam = 0.5, e = 0, k = 0, bound = 1,
       theta0 = 0, omega0 = 0 }
u_i { theta = theta0, omega = omega0 }
alpha { theta - k }
d { 1 - 2 * lam * cos(alpha) + lam * lam }
G { e * lam * (cos(alpha) - lam) / d }
Gp { -e * lam * (1 - lam * lam) * sin(alpha) / (d * d) }
F_i {
  omega,
  (T0 - (slope + c1) * omega - G * (J2 * Gp * omega * omega + c2 * G * omega + TL)) / (J1 + J2 * G * G),
}
stop_i { theta - bound }
"""

#: the same modes in two coordinates (crank theta, wheel angle beta from the slot's line of centres) with the
#: pin-in-slot constraint and a Lagrange multiplier, as mechsim's index-1 form integrates them (docs/theory.md
#: §K4 'Index 1 + Baumgarte'): phi = lam sin(alpha + beta) - sin(beta) engaged (the slot's lateral offset over
#: c, §G1), phi = beta - lock in the dwell; one constraint, so the KKT system is solved by its Schur scalar.
#: Only to measure what the minimal coordinates save (`lever`), not a peer of its own.
CODE_INDEX1 = """
in_i { T0 = 0, slope = 0, J1 = 1, J2 = 1, c1 = 0, c2 = 0, TL = 0, lam = 0.5, e = 0, k = 0, bound = 1,
       theta0 = 0, omega0 = 0, beta0 = 0, wheel0 = 0, lock = 0, ab = 10, bb = 10 }
u_i { theta = theta0, beta = beta0, omega = omega0, wheel = wheel0 }
alpha { theta - k }
phi { e * (lam * sin(alpha + beta) - sin(beta)) + (1 - e) * (beta - lock) }
gt { e * lam * cos(alpha + beta) }
gb { e * (lam * cos(alpha + beta) - cos(beta)) + 1 - e }
gam { e * (sin(beta) * wheel * wheel - lam * sin(alpha + beta) * (omega + wheel) * (omega + wheel)) }
Q1 { T0 - (slope + c1) * omega }
Q2 { -c2 * wheel - TL }
mu { (gt * Q1 / J1 + gb * Q2 / J2 + gam + 2 * ab * (gt * omega + gb * wheel) + bb * bb * phi)
     / (gt * gt / J1 + gb * gb / J2) }
F_i { omega, wheel, (Q1 - gt * mu) / J1, (Q2 - gb * mu) / J2 }
stop_i { theta - bound }
"""
SOLVERS = ("tsit45", "bdf")


def supports(problem) -> bool:
    """The external Geneva without friction, a constant load, torque or motor drive, no thermal states (`problem`: a
    `bench_methods.Problem`)."""
    mech = problem.mech
    g = getattr(mech, "geometry", None)
    return (mech.name == "geneva" and g is not None and getattr(g, "crank_sense", 0) == -1
            and mech.friction == 0 and problem.ext is None and not problem.drive.is_prescribed
            and constant_load(mech))


@dataclass
class DiffsolModel:
    ode: object            # pydiffsol.Ode, JIT-compiled
    inputs: np.ndarray     # the DiffSL inputs; the last five (e, k, bound, theta0, omega0) set per segment
    half_angle: float      # alpha_0, the engagement half angle
    build_time_s: float


def build(problem, rtol: float, atol: float, solver: str = "tsit45",
          coordinates: str = "minimal") -> DiffsolModel:
    """Compile the DiffSL program (LLVM) and set the tolerances; coordinates "index1": `CODE_INDEX1`."""
    import pydiffsol as ds

    if not supports(problem):
        raise ValueError("the diffsol peer integrates the external Geneva without friction or thermal states")
    wall = time.perf_counter()
    ode = ds.Ode(CODE if coordinates == "minimal" else CODE_INDEX1, ode_solver=getattr(ds, solver))
    ode.rtol, ode.atol = rtol, atol
    m, g = problem.mech, problem.mech.geometry
    dv = problem.drive.parameter_values(problem.angle0)
    inputs = [dv["drive_T0"], dv["drive_slope"], m.crank_inertia, m.wheel_inertia, m.crank_damping,
              m.wheel_damping, m.wheel_torque, g.ratio, 0.0, 0.0, 0.0, 0.0, 0.0]
    if coordinates != "minimal":
        inputs += [0.0, 0.0, 0.0, *problem.baumgarte]
    return DiffsolModel(ode, np.array(inputs, float), g.engagement_half_angle, time.perf_counter() - wall)


def simulate(model: DiffsolModel, grid: np.ndarray, angle0: float, speed0: float,
             max_events: int = 10000) -> PeerRun:
    """Crank angle on `grid` (grid[0] = 0 is the start): solve_dense from each restart to the end of the grid,
    cut short by the stop function at the mode's boundary."""
    ode, p, a0 = model.ode, model.inputs.copy(), model.half_angle
    two_pi = 2.0 * math.pi
    k = math.floor((angle0 + math.pi) / two_pi)          # slot: alpha = theta - 2 pi k in [-pi, pi)
    alpha = angle0 - two_pi * k
    if -a0 <= alpha < a0:
        engaged, bound = True, two_pi * k + a0
    else:
        if alpha >= a0:
            k += 1
        engaged, bound = False, two_pi * k - a0
    n = len(grid)
    out = np.full(n, np.nan)
    out[0] = angle0
    theta, omega, t, j, events = angle0, speed0, float(grid[0]), 0, 0
    failure = None
    index1 = len(p) > 13
    lam = p[7]
    while j < n - 1:
        p[8:13] = (1.0 if engaged else 0.0), two_pi * k, bound, theta, omega
        if index1:          # the wheel consistent with the crank (on the constraint), locked in the dwell
            a = theta - two_pi * k
            beta = math.atan2(lam * math.sin(a), 1 - lam * math.cos(a))
            p[13:16] = (beta, speed_ratio(lam, a) * omega, 0.0) if engaged else (beta, 0.0, beta)
        ode.t0 = t
        try:
            sol = ode.solve_dense(p, np.concatenate(([t], grid[j + 1:])))
        except RuntimeError as exc:
            failure = f"diffsol failed at t = {t:.6g} s: {exc}"
            break
        ts, ys = sol.ts, sol.ys
        if ts[-1] >= grid[-1]:                          # reached the end
            out[j + 1:] = ys[0, 1:]
            break
        inside = len(ts) - 2                             # outputs strictly between the restart and the stop
        out[j + 1:j + 1 + inside] = ys[0, 1:1 + inside]
        j += inside
        t, theta, omega = float(ts[-1]), float(ys[0, -1]), float(ys[len(ys) // 2, -1])    # (q, v) states
        events += 1
        if events > max_events:
            failure = f"t = {t:.6g} s: too many events"
            break
        if engaged:                                      # exit: dwell until the next slot's entry
            k += 1
            engaged, bound = False, two_pi * k - a0
        else:                                            # entry into slot k
            engaged, bound = True, two_pi * k + a0
    ok = np.isfinite(out)
    return PeerRun(grid[ok], out[ok], {"events": events, "segments": events + 1}, [], failure)
