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
    """Kinetic energy before and after a velocity projection (J), and the constraint impulses it applied (per
    constraint, the multiplier's unit times s; v+ = v - M^-1 G^T impulse; None where nothing was projected)."""

    energy_before: float
    energy_after: float
    impulse: np.ndarray | None = None


def _min_norm(G, r, xp, pad):
    """x of least norm with G x = r. numpy: least squares (a rank-deficient G too); traced: G^T (G G^T)^-1 r,
    with ones on the diagonal of the zero rows that pad G to a fixed size (`pad`, a boolean mask, or None)."""
    if xp is np:
        return np.linalg.lstsq(G, r, rcond=None)[0]
    K = G @ G.T
    if pad is not None:
        K = K + xp.diag(pad.astype(G.dtype))
    return G.T @ xp.linalg.solve(K, r)


def _gauss_newton(positions, q, xp, steps: int, until_roundoff: bool):
    """`reinitialise`'s position steps q -= G^+ Phi; positions(q) -> (G, Phi, pad). Returns (q, G at q) where the
    steps stop on round-off (G evaluated there already: the velocity step reuses it), else (q, None)."""
    if not until_roundoff:
        for _ in range(steps):
            G, phi, pad = positions(q)
            q = q - _min_norm(G, phi, xp, pad)
        return q, None
    G, phi, pad = positions(q)
    best = _largest(phi)
    for _ in range(steps):
        if best == 0.0:
            break
        trial = q - _min_norm(G, phi, xp, pad)
        G_trial, phi_trial, _ = positions(trial)
        r = _largest(phi_trial)
        if not r < best:
            break
        q, G, phi, previous, best = trial, G_trial, phi_trial, best, r
        if r > 0.5 * previous:
            break
    if not best <= 1e-9:
        raise ValueError(f"constraint residual {best:.3e} after projection")
    return q, G


def _impact_law(M, G, rel, v, restitution, xp, pad):
    """(v+, P): Newton's impact law v+ = v - M^-1 G^T P with the impulse P = (G M^-1 G^T)^-1 (1 + e) rel
    (`reinitialise`); pad as in `_min_norm`."""
    Minv_Gt = xp.linalg.solve(M, G.T)
    K = G @ Minv_Gt
    if pad is not None:
        K = K + xp.diag(pad.astype(K.dtype))
    impulse = xp.linalg.solve(K, (1.0 + restitution) * rel)
    return v - Minv_Gt @ impulse, impulse


def reinitialise(parts, q, v, xp=np, steps: int = 30, restitution: float = 0.0, until_roundoff: bool = False):
    """(q, v) made consistent with a mode's constraints, for numpy and JAX alike (`xp`): every path's
    re-initialisation (`consistent_state`; the compiled diffrax run, dynamics/backends/diffrax_run.py; the sensitivity
    pass, dynamics/sensitivity.py).

    Positions: minimum-norm Gauss-Newton steps q -= G^+ Phi onto Phi = 0. Velocities: Newton's impact law in the
    kinetic-energy metric, v+ = v - M^-1 G^T (G M^-1 G^T)^-1 (1 + e) (G v + Phi_t), which for e = 0 is the
    projection onto the velocity constraints (a plastic impact; consistent velocities are unchanged).

    parts(q, v) -> (M, G, Phi, G v + Phi_t, pad) of the mode at (q, v); pad: None, or a mask of zero rows that
    pad the constraints to a fixed count (traced, every mode's arrays one size).
    steps: the Gauss-Newton steps (traced: exactly this many; one step from a consistent point has the converged
    projection's derivative there, the terms it drops carry a factor Phi). until_roundoff (numpy): at most
    `steps`, at least one, going on while a step at least halves max|Phi| (round-off in Phi's own units; no
    tolerance scaled by |q| skips a step: unwrapped angles grow with every turn, and a residual accepted relative
    to them (1.75e-12 m at 175 rad) is enough for IDA's index-2 first step to fail at a restart, docs/stability.md
    'Restarts'); ValueError when max|Phi| is still above 1e-9 then.
    """
    def positions(qq):
        _, G, phi, _, pad = parts(qq, v)
        return G, phi, pad
    q, _ = _gauss_newton(positions, q, xp, steps, until_roundoff)
    M, G, _, rel, pad = parts(q, v)
    return q, _impact_law(M, G, rel, v, restitution, xp, pad)[0]


def floats(a) -> list:
    """A vector argument of the mode's generated functions (`ModeFunctions.phi`, `G`, `mass`, ...) as a list of
    floats: they unpack it into scalars, which a list does directly, while unpacking an ndarray ends in an
    IndexError raised and caught at every call. Python floats round as numpy's float64 scalars do (the same IEEE
    operations, to the bit); only a division by a state exactly zero would differ (ZeroDivisionError, not inf)."""
    return np.asarray(a, dtype=float).tolist()


def _largest(phi: np.ndarray) -> float:
    """max |phi| (NaN where phi has one), by the reduction ndarray.max calls, without its Python wrapper."""
    return float(np.maximum.reduce(np.abs(phi), axis=None))


def matrix(a) -> np.ndarray:
    """A generated function's matrix (`ModeFunctions.mass`, `G`) as a 2-D float array: np.atleast_2d where it is not
    one already (lambdified matrices are)."""
    a = np.asarray(a, dtype=float)
    return a if a.ndim == 2 else np.atleast_2d(a)


def _mass(mf: ModeFunctions, q: list, p) -> np.ndarray:
    return matrix(mf.mass(q, p))


def _G(mf: ModeFunctions, t: float, q: list, p) -> np.ndarray:
    return matrix(mf.G(t, q, p))


def _projected_positions(mf: ModeFunctions, t: float, q: np.ndarray, p: tuple, max_iter: int = 30):
    """(q projected onto Phi(t, q) = 0 to round-off, G there or None) (`reinitialise`'s steps, until_roundoff),
    evaluating only what the steps use (G and Phi)."""
    q = np.array(q, dtype=float)
    if mf.m == 0:
        return q, None

    def positions(qq):
        qs = floats(qq)
        return _G(mf, t, qs, p), np.asarray(mf.phi(t, qs, p), dtype=float).ravel(), None
    try:
        return _gauss_newton(positions, q, np, max_iter, until_roundoff=True)
    except ValueError as exc:
        raise ValueError(f"mode {mf.name!r} cannot assemble: {exc}") from None


def project_positions(mf: ModeFunctions, t: float, q: np.ndarray, p: tuple, max_iter: int = 30) -> np.ndarray:
    """q projected onto Phi(t, q) = 0 to round-off (`reinitialise`, until_roundoff)."""
    return _projected_positions(mf, t, q, p, max_iter)[0]


def _projected_velocities(mf: ModeFunctions, t: float, q: np.ndarray, v: np.ndarray, p: tuple, restitution: float,
                          G: np.ndarray | None = None):
    """(v+, Impact, M, G) of `project_velocities`, with M(q) and G(q) for what follows at the same q (G given:
    evaluated there already)."""
    qs = floats(q)
    M = _mass(mf, qs, p)
    e_before = 0.5 * float(v @ M @ v)
    if mf.m == 0:
        return v, Impact(e_before, e_before), M, G
    G = _G(mf, t, qs, p) if G is None else G
    rel = np.asarray(mf.phi_dot(t, qs, floats(v), p), dtype=float).ravel()
    v_new, impulse = _impact_law(M, G, rel, v, restitution, np, None)
    return v_new, Impact(e_before, 0.5 * float(v_new @ M @ v_new), impulse), M, G


def project_velocities(mf: ModeFunctions, t: float, q: np.ndarray, v: np.ndarray, p: tuple,
                       restitution: float = 0.0) -> tuple[np.ndarray, Impact]:
    """Newton's impact law with coefficient e at positions q (`reinitialise` without position steps) and the
    kinetic energy before and after; the impulse is the law's own (G M^-1 G^T)^-1 (1 + e) (G v + Phi_t)."""
    return _projected_velocities(mf, t, q, v, p, restitution)[:2]


def accelerations(mf: ModeFunctions, t: float, q: np.ndarray, v: np.ndarray, x: np.ndarray, p: tuple,
                  M: np.ndarray | None = None, G: np.ndarray | None = None) -> tuple[np.ndarray, np.ndarray]:
    """Accelerations and multipliers from the KKT system of the mode (`kkt.solve`); M(q) and G(t, q) where the
    caller has them at this q already."""
    qs, vs, xs = floats(q), floats(v), floats(x)
    M = _mass(mf, qs, p) if M is None else M
    nq = len(qs)
    Q0 = np.asarray(mf.force0(t, qs, vs, xs, p), dtype=float).ravel()
    if mf.m == 0:
        return kkt.solve(M, np.zeros((0, nq)), np.zeros((nq, 0)), Q0, np.zeros(0))
    G = _G(mf, t, qs, p) if G is None else G
    Ql = np.asarray(mf.force_lam(t, qs, vs, xs, p), dtype=float).reshape(nq, mf.m)
    gamma = np.asarray(mf.gamma(t, qs, vs, p), dtype=float).ravel()
    return kkt.solve(M, G, Ql, Q0, -gamma)


def consistent_state(mf: ModeFunctions, t: float, q: np.ndarray, v: np.ndarray, work: np.ndarray,
                     ext: np.ndarray, p: tuple, restitution: float | None = None, project: bool = True
                     ) -> tuple[np.ndarray, np.ndarray, Impact]:
    """(y0, yp0) satisfying every residual row of the mode, and the impact record of the projection.

    project=False (index-1 form only, no impact): q and v are kept as they are and the accelerations and
    multipliers solve the mode's own v and constraint rows, Baumgarte terms included (`_rows_off_manifold`).
    """
    if project:
        q, G = _projected_positions(mf, t, q, p)
        v, impact, M, G = _projected_velocities(mf, t, q, np.asarray(v, dtype=float), p,
                                                0.0 if restitution is None else restitution, G)
    else:
        q, v = np.array(q, dtype=float), np.array(v, dtype=float)
        M, G = _mass(mf, floats(q), p), None
        energy = 0.5 * float(v @ M @ v)
        impact = Impact(energy, energy)
    a, lam = accelerations(mf, t, q, v, ext, p, M, G)
    ix = mf.index
    y = np.zeros(mf.ny)
    yp = np.zeros(mf.ny)
    y[ix["q"]], y[ix["v"]], y[ix["lam"]] = q, v, lam
    y[ix["work"]], y[ix["ext"]] = work, ext
    yp[ix["q"]], yp[ix["v"]] = v, a
    if not project:
        _rows_off_manifold(mf, t, y, yp, p)
    _state_rates(mf, t, y, yp, p)
    return y, yp, impact


def _state_rates(mf: ModeFunctions, t: float, y: np.ndarray, yp: np.ndarray, p: tuple) -> None:
    """y' of the work and extension states, in place (zero there on entry): their rows are linear in their own y',
    F = A y'_block + b, so y'_block = -A^-1 F with F the residual at y'_block = 0.

    A is the difference of the Jacobian at cj = 1 and cj = 0. Without extension states the rows are the work rows
    W' - P (`dynamics.model`), whose A is the identity: y'_work = -F, the values LAPACK's solve of that system gives
    (F is never -0 there: W' = +0 enters it as a term), without the Jacobian's two evaluations."""
    ix = mf.index
    block = slice(ix["work"].start, ix["ext"].stop)
    if block.stop == block.start:
        return
    res = np.zeros(mf.ny)
    mf.residual(t, y, yp, res, p)
    if ix["ext"].stop == ix["ext"].start:
        yp[block] = -res[block]
        return
    J1, J0 = np.zeros((mf.ny, mf.ny)), np.zeros((mf.ny, mf.ny))
    mf.jacobian(t, y, yp, res, 1.0, J1, p)
    mf.jacobian(t, y, yp, res, 0.0, J0, p)
    yp[block] = -np.linalg.solve(J1[block, block] - J0[block, block], res[block])


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
    v, lam = ix["v"], ix["lam"]
    rows = slice(v.start, lam.stop) if v.stop == lam.start else np.r_[v, lam]      # adjacent in the layout
    res = np.zeros(mf.ny)
    mf.residual(t, y, yp, res, p)
    J1, J0 = np.zeros((mf.ny, mf.ny)), np.zeros((mf.ny, mf.ny))
    mf.jacobian(t, y, yp, res, 1.0, J1, p)
    mf.jacobian(t, y, yp, res, 0.0, J0, p)
    A = np.concatenate([(J1 - J0)[rows][:, v], J0[rows][:, lam]], axis=1)
    step = np.linalg.solve(A, res[rows])
    nv = ix["v"].stop - ix["v"].start
    yp[ix["v"]] -= step[:nv]
    y[ix["lam"]] -= step[nv:]
