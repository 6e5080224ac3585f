"""Consistent (re)initialisation of a mode and the impact law at mode changes.

IDA's own initial-condition calculation does not touch differential variables and is not applicable to the
index-2/3 forms (docs/theory.md §K4), so every segment starts from a state made consistent here:
positions projected onto Phi = 0 (Gauss-Newton, minimum-norm corrections), velocities onto the velocity
constraints with the kinetic-energy metric (which is also the impact law), then accelerations and multipliers
from the KKT system  [[M, G^T - dQ/dlam], [G, 0]] [a; lam] = [Q(lam=0); -gamma].
"""
from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from mechsim.dynamics import kkt
from mechsim.dynamics.model import ModeFunctions


@dataclass(frozen=True)
class Impact:
    """Kinetic energy before and after a velocity projection (J)."""

    energy_before: float
    energy_after: float


def project_positions(mf: ModeFunctions, t: float, q: np.ndarray, p: tuple, max_iter: int = 30) -> np.ndarray:
    """Newton iteration with minimum-norm steps onto Phi(t, q) = 0, carried to round-off in Phi's own units.

    At least one step is always taken and the iteration goes on while it reduces max|Phi| (it stops when a step
    no longer halves it: round-off reached). No tolerance scaled by |q| decides to skip the step: unwrapped
    angles grow with every turn, and a residual accepted relative to them (1.75e-12 m at 175 rad) is enough
    for IDA's index-2 first step to fail at a restart (docs/stability.md, 'Restarts').
    """
    q = np.array(q, dtype=float)
    if mf.m == 0:
        return q

    def constraint(x):
        return np.atleast_1d(np.asarray(mf.phi(t, x, p), dtype=float).ravel())

    phi = constraint(q)
    best = float(np.max(np.abs(phi)))
    for _ in range(max_iter):
        if best == 0.0:
            break
        G = np.atleast_2d(np.asarray(mf.G(t, q, p), dtype=float))
        trial = q - np.linalg.lstsq(G, phi, rcond=None)[0]
        phi_trial = constraint(trial)
        r = float(np.max(np.abs(phi_trial)))
        if not r < best:
            break
        q, phi, previous, best = trial, phi_trial, best, r
        if r > 0.5 * previous:
            break
    if not best <= 1e-9:
        raise ValueError(f"mode {mf.name!r} cannot assemble: constraint residual {best:.3e} after projection")
    return q


def project_velocities(mf: ModeFunctions, t: float, q: np.ndarray, v: np.ndarray, p: tuple,
                       restitution: float = 0.0) -> tuple[np.ndarray, Impact]:
    """v+ = v- - M^-1 G^T (G M^-1 G^T)^-1 [(G v- + Phi_t) (1 + e)]: Newton's impact law with coefficient e.

    For e = 0 this is the kinetic-energy-metric projection onto G v + Phi_t = 0 (a perfectly plastic
    impact); velocities already consistent are unchanged.
    """
    M = np.atleast_2d(np.asarray(mf.mass(q, p), dtype=float))
    e_before = 0.5 * float(v @ M @ v)
    if mf.m == 0:
        return v, Impact(e_before, e_before)
    G = np.atleast_2d(np.asarray(mf.G(t, q, p), dtype=float))
    rel = np.atleast_1d(np.asarray(mf.phi_dot(t, q, v, p), dtype=float).ravel())
    Minv_Gt = np.linalg.solve(M, G.T)
    impulse = np.linalg.solve(G @ Minv_Gt, (1.0 + restitution) * rel)
    v_new = v - Minv_Gt @ impulse
    return v_new, Impact(e_before, 0.5 * float(v_new @ M @ v_new))


def accelerations(mf: ModeFunctions, t: float, q: np.ndarray, v: np.ndarray, x: np.ndarray, p: tuple
                  ) -> tuple[np.ndarray, np.ndarray]:
    """Accelerations and multipliers from the KKT system of the mode (`kkt.solve`)."""
    M = np.atleast_2d(np.asarray(mf.mass(q, p), dtype=float))
    nq = len(q)
    Q0 = np.asarray(mf.force0(t, q, v, x, p), dtype=float).ravel()
    if mf.m == 0:
        return kkt.solve(M, np.zeros((0, nq)), np.zeros((nq, 0)), Q0, np.zeros(0))
    G = np.atleast_2d(np.asarray(mf.G(t, q, p), dtype=float))
    Ql = np.asarray(mf.force_lam(t, q, v, x, p), dtype=float).reshape(nq, mf.m)
    gamma = np.asarray(mf.gamma(t, q, v, p), dtype=float).ravel()
    return kkt.solve(M, G, Ql, Q0, -gamma)


def consistent_state(mf: ModeFunctions, t: float, q: np.ndarray, v: np.ndarray, work: np.ndarray,
                     ext: np.ndarray, p: tuple, restitution: float | None = None, project: bool = True
                     ) -> tuple[np.ndarray, np.ndarray, Impact]:
    """(y0, yp0) satisfying every residual row of the mode, and the impact record of the projection.

    project=False (index-1 form only, no impact): q and v are kept as they are and the accelerations and
    multipliers solve the mode's own v and constraint rows, Baumgarte terms included (`_rows_off_manifold`).
    """
    if project:
        q = project_positions(mf, t, q, p)
        v, impact = project_velocities(mf, t, q, np.asarray(v, dtype=float), p,
                                       0.0 if restitution is None else restitution)
    else:
        q, v = np.array(q, dtype=float), np.array(v, dtype=float)
        M = np.atleast_2d(np.asarray(mf.mass(q, p), dtype=float))
        energy = 0.5 * float(v @ M @ v)
        impact = Impact(energy, energy)
    a, lam = accelerations(mf, t, q, v, ext, p)
    ix = mf.index
    y = np.zeros(mf.ny)
    yp = np.zeros(mf.ny)
    y[ix["q"]], y[ix["v"]], y[ix["lam"]] = q, v, lam
    y[ix["work"]], y[ix["ext"]] = work, ext
    yp[ix["q"]], yp[ix["v"]] = v, a
    if not project:
        _rows_off_manifold(mf, t, y, yp, p)
    # rows of work and extension states are linear in their own y': F = A yp_block + b
    block = np.r_[ix["work"].start:ix["ext"].stop]
    if len(block):
        res = np.zeros(mf.ny)
        mf.residual(t, y, yp, res, p)
        J1, J0 = np.zeros((mf.ny, mf.ny)), np.zeros((mf.ny, mf.ny))
        mf.jacobian(t, y, yp, res, 1.0, J1, p)
        mf.jacobian(t, y, yp, res, 0.0, J0, p)
        A = (J1 - J0)[np.ix_(block, block)]
        yp[block] = -np.linalg.solve(A, res[block])
    return y, yp, impact


def _rows_off_manifold(mf: ModeFunctions, t: float, y: np.ndarray, yp: np.ndarray, p: tuple) -> None:
    """Correct a and lam in place so that the v rows and the index-1 constraint rows
    Phi'' + 2 alpha Phi' + beta^2 Phi = 0 (dynamics/formulation.py) hold at a state off Phi = 0.

    Both row blocks are affine in (a, lam) (M a - Q0 - Ql lam + G^T lam; Phi'' is linear in a), so one Newton
    step with the exact Jacobian, from the KKT solution without the Baumgarte terms, solves them to round-off.
    """
    ix = mf.index
    if mf.m == 0:
        return
    if ix["mu"].stop != ix["mu"].start:
        raise ValueError("a restart without projection is only defined for the index-1 form")
    rows = np.r_[ix["v"], ix["lam"]]
    res = np.zeros(mf.ny)
    mf.residual(t, y, yp, res, p)
    J1, J0 = np.zeros((mf.ny, mf.ny)), np.zeros((mf.ny, mf.ny))
    mf.jacobian(t, y, yp, res, 1.0, J1, p)
    mf.jacobian(t, y, yp, res, 0.0, J0, p)
    A = np.hstack([(J1 - J0)[np.ix_(rows, np.r_[ix["v"]])], J0[np.ix_(rows, np.r_[ix["lam"]])]])
    step = np.linalg.solve(A, res[rows])
    nv = ix["v"].stop - ix["v"].start
    yp[ix["v"]] -= step[:nv]
    y[ix["lam"]] -= step[nv:]
