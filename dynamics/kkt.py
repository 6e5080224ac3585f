"""The one KKT solve of a constrained mode, for numpy, JAX and sympy alike.

Accelerations a and multipliers lam of a mode with mass matrix M, constraint Jacobian G and generalized forces
Q(lam) = Q0 + Ql lam (friction makes the forces depend on the multipliers, docs/theory.md §G1, §K4):

    [[M, G^T - Ql], [G, 0]] [a; lam] = [Q0; c],

with c = -gamma (exact constraint acceleration, consistent initialisation and read-outs) or
c = -gamma - 2 alpha Phi' - beta^2 Phi (the Baumgarte-stabilised index-1 ODE of the diffrax backend).
Every caller assembles and solves it here: `consistent.accelerations` (one state, numpy), `tables.kkt_rows`
(every output row at once, numpy), `jax_model.JaxModel.kkt` (traced, jax.numpy) and `model` (guards that read
a or lam, solved symbolically with sympy).
"""
from __future__ import annotations

from contextlib import contextmanager

import numpy as np


#: traced (jax) systems up to this size are solved by unrolled elimination instead of LAPACK's getrf/getrs
UNROLLED_MAX = 8


def unrolled_solve(K, b, xp):
    """x with K x = b for one small system (n <= UNROLLED_MAX): Gaussian elimination with partial pivoting,
    unrolled into elementwise operations (Golub & Van Loan, Matrix Computations, Alg. 3.4.1). Traced by JAX it
    fuses into the surrounding step instead of a LAPACK call per evaluation, which costs microseconds on a
    3 x 3 system (the compiled diffrax run, docs/diffrax.md 'The compiled run')."""
    n = K.shape[-1]
    A = xp.concatenate([K, b[:, None]], axis=1)
    rows = xp.arange(n)
    for j in range(n):
        piv = xp.argmax(xp.where(rows >= j, xp.abs(A[:, j]), -1.0))
        swap = (rows == j)[:, None] * A[piv][None, :] + (rows == piv)[:, None] * A[j][None, :]
        A = xp.where(((rows == j) | (rows == piv))[:, None], swap, A)
        factor = xp.where(rows > j, A[:, j] / A[j, j], 0.0)
        A = A - factor[:, None] * A[j][None, :]
    x = [None] * n
    for i in reversed(range(n)):
        acc = A[i, n]
        for j in range(i + 1, n):
            acc = acc - A[i, j] * x[j]
        x[i] = acc / A[i, i]
    return xp.stack(x)


#: set while the compiled diffrax run is traced (`unrolled_solves`): only that program takes the unrolled solve
_UNROLLED = False


@contextmanager
def unrolled_solves():
    """Within the block, traced single systems up to UNROLLED_MAX are solved by `unrolled_solve` (the compiled
    diffrax run, where it was measured to pay: docs/diffrax.md 'The compiled run'). Everything else (the segment
    loop, the sensitivity pass) keeps jax.numpy.linalg.solve, as before the compiled run existed."""
    global _UNROLLED
    before, _UNROLLED = _UNROLLED, True
    try:
        yield
    finally:
        _UNROLLED = before


def _linear_solve(K, b, xp):
    if _UNROLLED and xp is not np and K.ndim == 2 and K.shape[-1] <= UNROLLED_MAX:
        return unrolled_solve(K, b, xp)
    return xp.linalg.solve(K, b[..., None])[..., 0]


def solve(M, G, Ql, Q0, c, xp=np):
    """(a, lam) for one system or a stack of them (leading axes): M (..., nq, nq), G (..., m, nq),
    Ql (..., nq, m), Q0 (..., nq), c (..., m); xp is numpy or jax.numpy."""
    nq, m = M.shape[-1], G.shape[-2]
    if m == 0:
        return _linear_solve(M, Q0, xp), xp.zeros(Q0.shape[:-1] + (0,))
    top = xp.concatenate([M, xp.swapaxes(G, -1, -2) - Ql], axis=-1)
    bottom = xp.concatenate([G, xp.zeros(G.shape[:-1] + (m,))], axis=-1)
    K = xp.concatenate([top, bottom], axis=-2)
    sol = _linear_solve(K, xp.concatenate([Q0, c], axis=-1), xp)
    return sol[..., :nq], sol[..., nq:]


def solve_symbolic(M, G, Ql, Q0, c):
    """(a, lam) as sympy column matrices: the same system, solved by LU on the symbolic matrix."""
    import sympy as sp

    nq, m = M.shape[0], G.shape[0]
    if m == 0:
        return M.LUsolve(sp.Matrix(list(Q0))), sp.zeros(0, 1)
    K = sp.Matrix(sp.BlockMatrix([[M, G.T - Ql], [G, sp.zeros(m, m)]]))
    sol = K.LUsolve(sp.Matrix(list(Q0) + list(c)))
    return sol[:nq, :], sol[nq:, :]
