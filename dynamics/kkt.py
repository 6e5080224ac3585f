"""The one KKT solve of a constrained mode, for numpy, JAX and sympy alike.

Accelerations a and multipliers lam of a mode with mass matrix M, constraint Jacobian G and generalized forces
Q(lam) = Q0 + Ql lam (friction makes the forces depend on the multipliers, docs/theory.md §G1, §K4):

    [[M, G^T - Ql], [G, 0]] [a; lam] = [Q0; c],

with c = -gamma (exact constraint acceleration, consistent initialisation and read-outs) or
c = -gamma - 2 alpha Phi' - beta^2 Phi (the Baumgarte-stabilised index-1 ODE of the diffrax backend).
Every caller assembles and solves it here: `consistent.accelerations` (one state, numpy), `tables.kkt_rows`
(every output row at once, numpy, entry by entry: a short stack by LAPACK, `solve_short`; a long one eliminated
an entry of all its systems at a time, `solve_entries`, `_stacked`),
`jax_model.JaxModel.kkt` (traced, jax.numpy) and `model` (guards that read a or lam, solved symbolically with
sympy).
"""
from __future__ import annotations

from contextlib import contextmanager

import numpy as np


#: traced (jax) systems up to this size are solved by unrolled elimination instead of LAPACK's getrf/getrs
UNROLLED_MAX = 8


def unrolled_solve(K, b, xp, spd_block: int = 0):
    """x with K x = b for one small system (n <= UNROLLED_MAX): Gaussian elimination, unrolled into elementwise
    operations (Golub & Van Loan, Matrix Computations, Alg. 3.4.1). Traced by JAX it fuses into the
    surrounding step instead of a LAPACK call per evaluation, which costs microseconds on a 3 x 3 system (the
    compiled diffrax run, docs/diffrax.md 'The compiled run').

    The first `spd_block` columns are eliminated in their natural order, without pivoting: K's leading block is
    then symmetric positive definite (the mass matrix of a KKT system), whose LU factorisation needs no pivoting
    for stability (Golub & Van Loan, Matrix Computations, 4th ed., §4.2), and what is left of the constraint
    rows after it is their Schur complement -G M^-1 (G^T - Ql) (the range-space method, Nocedal & Wright,
    Numerical Optimization, 2nd ed., §16.2). The remaining columns take partial pivoting; a column with one
    candidate row needs no search. The pivot searches (argmax and row gathers) are a chain of small kernels on
    the CPU, so the compiled run's step loop is cheaper without them (docs/benchmarks.md, "Costs behind the
    code"); the pivots that remain are chosen by comparisons and `where`, as argmax would (first largest).
    Works on jax.numpy and numpy scalars alike."""
    n = K.shape[-1]
    return xp.stack(_eliminate([[K[i, j] for j in range(n)] + [b[i]] for i in range(n)], xp, spd_block))


def _eliminate(A, xp, spd_block: int) -> list:
    """`unrolled_solve` on the augmented matrix [K | b] given as rows of entries (scalars, or arrays over a stack
    of systems: every operation is elementwise); returns the entries of x. On numpy, a pivot exchange that no
    system of the stack makes is skipped (it would leave every entry as it was) and one that every system makes
    exchanges the rows' entries whole (`_stacked`): the same values either way."""
    n = len(A)
    for j in range(n):
        if spd_block <= j:
            for r in range(j + 1, n):     # partial pivoting: the first largest |A[r][j]|, r >= j, to row j
                if xp is np:              # (abs: Python's on a float, numpy's on an array)
                    take = abs(A[r][j]) > abs(A[j][j])
                    taken = int(take) if type(take) is bool else np.count_nonzero(take)
                    if taken == 0:
                        continue
                    if taken == np.size(take):
                        A[j], A[r] = A[j][:j] + A[r][j:], A[r][:j] + A[j][j:]
                        continue
                else:
                    take = xp.abs(A[r][j]) > xp.abs(A[j][j])  # (columns left of j are read no more: kept)
                A[j], A[r] = (A[j][:j] + [xp.where(take, x, y) for x, y in zip(A[r][j:], A[j][j:])],
                              A[r][:j] + [xp.where(take, y, x) for x, y in zip(A[r][j:], A[j][j:])])
        for r in range(j + 1, n):
            factor = A[r][j] / A[j][j]
            A[r] = A[r][:j + 1] + [A[r][col] - factor * A[j][col] for col in range(j + 1, n + 1)]
    x = [None] * n
    for i in reversed(range(n)):
        acc = A[i][n]
        for j in range(i + 1, n):
            acc = acc - A[i][j] * x[j]
        x[i] = acc / A[i][i]
    return x


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


def unrolled() -> bool:
    """Whether traced solves are unrolled here (inside `unrolled_solves`): what a cached trace must be keyed by."""
    return _UNROLLED


def _linear_solve(K, b, xp, spd_block: int = 0):
    """K x = b; within `unrolled_solves`, traced single systems are solved unrolled (`unrolled_solve`, whose
    leading spd_block columns are a symmetric positive definite block taken without pivoting)."""
    if _UNROLLED and xp is not np and K.ndim == 2 and K.shape[-1] <= UNROLLED_MAX:
        return unrolled_solve(K, b, xp, spd_block)
    return xp.linalg.solve(K, b[..., None])[..., 0]


def solve(M, G, Ql, Q0, c, xp=np):
    """(a, lam) for one system or a stack of them (leading axes): M (..., nq, nq), G (..., m, nq),
    Ql (..., nq, m), Q0 (..., nq), c (..., m); xp is numpy or jax.numpy."""
    nq, m = M.shape[-1], G.shape[-2]
    if xp is np and M.ndim == 3 and long_stack(len(M), nq + m):
        solved = _stacked(len(M), [[M[:, i, j] for j in range(nq)] for i in range(nq)],
                          [[G[:, k, j] for j in range(nq)] for k in range(m)],
                          [[Ql[:, i, k] for k in range(m)] for i in range(nq)], list(Q0.T), list(c.T))
        if solved is not None:
            return solved
    return _direct(M, G, Ql, Q0, c, xp)


def _direct(M, G, Ql, Q0, c, xp):
    """`solve` by the linear solver of xp (numpy's LAPACK; traced, `_linear_solve`)."""
    nq, m = M.shape[-1], G.shape[-2]
    if m == 0:
        return _linear_solve(M, Q0, xp, spd_block=nq), xp.zeros(Q0.shape[:-1] + (0,))
    if xp is np and M.ndim == 2:
        return _one_system(M, G, Ql, Q0, c)
    top = xp.concatenate([M, xp.swapaxes(G, -1, -2) - Ql], axis=-1)
    bottom = xp.concatenate([G, xp.zeros(G.shape[:-1] + (m,))], axis=-1)
    K = xp.concatenate([top, bottom], axis=-2)
    sol = _linear_solve(K, xp.concatenate([Q0, c], axis=-1), xp, spd_block=nq)   # M: mass matrix, SPD
    return sol[..., :nq], sol[..., nq:]


def _one_system(M, G, Ql, Q0, c):
    """`_direct` on one numpy system (a re-initialisation's, `consistent.accelerations`): K written into one array,
    the entries of the concatenations with fewer numpy calls, and the same LAPACK solve."""
    nq, m = M.shape[-1], G.shape[-2]
    K = np.zeros((nq + m, nq + m))
    K[:nq, :nq], K[:nq, nq:], K[nq:, :nq] = M, G.T - Ql, G
    sol = np.linalg.solve(K, np.concatenate([Q0, c]))
    return sol[:nq], sol[nq:]


def solve_entries(rows: int, M, G, Ql, Q0, c):
    """`solve` on a numpy stack of `rows` systems given entry by entry, as lambdified matrices give them: M, G, Ql
    as lists of rows of entries (nq x nq, m x nq, nq x m), Q0 and c as lists (nq, m); each entry an array over the
    systems or a scalar that every system shares. A long stack is solved on the entries themselves (`_stacked`:
    a shared entry's operations done once, on the scalar); otherwise on the stacked arrays (`stack_entries`)."""
    nq, m = len(Q0), len(c)
    if long_stack(rows, nq + m):
        solved = _stacked(rows, M, G, Ql, Q0, c)
        if solved is not None:
            return solved
    return _direct(stack_entries([e for row in M for e in row], rows, (nq, nq)),
                   stack_entries([e for row in G for e in row], rows, (m, nq)),
                   stack_entries([e for row in Ql for e in row], rows, (nq, m)),
                   stack_entries(Q0, rows, (nq,)), stack_entries(c, rows, (m,)), np)


def solve_short(rows: int, M, G, Ql, Q0, gamma):
    """(M, a, lam): `solve` on a short numpy stack of `rows` systems (LAPACK's, one system at a time) with c = -gamma,
    given as lambdified matrices give them, flat (M nq x nq, G m x nq and Ql nq x m row by row, Q0 nq, gamma m; each
    entry an array over the systems or a scalar they share), M returned stacked (rows, nq, nq). K and [Q0; c] are
    written entry by entry into one array each: the same values as `_direct`'s concatenation of the stacked arrays
    (an entry of G^T - Ql the difference of the two entries, exact for integers as they are in a matrix of
    coefficients; c the negated gamma), without its intermediate arrays, and the same solve."""
    nq, m = len(Q0), len(gamma)
    K = np.zeros((rows, nq + m, nq + m))
    b = np.empty((rows, nq + m))
    for e, entry in enumerate(M):
        K[:, e // nq, e % nq] = entry            # a scalar entry broadcasts over the systems
    for e, entry in enumerate(G):
        k, j = divmod(e, nq)
        K[:, nq + k, j] = entry
        K[:, j, nq + k] = entry - Ql[j * m + k]
    for i, entry in enumerate(Q0):
        b[:, i] = entry
    for k, entry in enumerate(gamma):
        b[:, nq + k] = np.negative(entry, dtype=float)      # (an integer 0 negated as a float: -0.0)
    sol = np.linalg.solve(K, b[..., None])[..., 0]
    return K[:, :nq, :nq].copy(), sol[..., :nq], sol[..., nq:]


def stack_entries(entries, rows: int, shape: tuple[int, ...]) -> np.ndarray:
    """Flat entries (arrays over the rows, or scalars) as an (rows, *shape) array."""
    out = np.empty((rows, len(entries)))
    for i, e in enumerate(entries):
        out[:, i] = e                   # a scalar entry broadcasts over the rows
    return out.reshape(rows, *shape)


#: a numpy stack of at least STACK_MIN + STACK_ROWS * n**2 systems of size n <= UNROLLED_MAX is solved by `_stacked`
STACK_MIN, STACK_ROWS = 64, 40


def long_stack(rows: int, n: int) -> bool:
    """Whether a numpy stack of `rows` systems of size n is solved by `_stacked`."""
    return n <= UNROLLED_MAX and rows >= STACK_MIN + STACK_ROWS * n ** 2


def _stacked(rows: int, M, G, Ql, Q0, c):
    """`solve_entries` on a long stack: the elimination of `unrolled_solve` with partial pivoting in every column,
    as LAPACK's getrf pivots (the first largest in the column), each operation on an entry of every system at once
    (`_eliminate` on [K | b] held entry by entry: an array over the systems, or a scalar where every system shares
    the entry, such as a constant mass matrix's; the same operations on the same values either way). With
    LAPACK's pivots a row that fixes one coordinate (a prescribed drive's speed constraint) is eliminated as LAPACK
    eliminates it, so that coordinate's acceleration comes out zero where LAPACK's does; the mass block unpivoted
    would not (a round-off residue instead). numpy.linalg.solve loops over the stack, one small LAPACK call per
    system, which costs more than these elementwise operations on whole columns once the stack holds more than
    about STACK_MIN + STACK_ROWS * n**2 systems (docs/benchmarks.md, "A warm run end to end"). (a (rows, nq),
    lam (rows, m)); None where a solution is not finite (a singular system, a NaN entry): the caller's LAPACK
    solve answers then, or raises."""
    nq, m = len(Q0), len(c)

    def entry(e):           # a shared entry as a Python float: its operations cost a fraction of numpy's
        return np.asarray(e, dtype=float) if getattr(e, "ndim", 0) else float(e)
    A = [[entry(e) for e in M[i]] + [entry(G[k][i]) - entry(Ql[i][k]) for k in range(m)] + [entry(Q0[i])]
         for i in range(nq)]
    A += [[entry(e) for e in G[k]] + [0.0] * m + [entry(c[k])] for k in range(m)]
    try:
        with np.errstate(all="ignore"):      # a zero pivot: not finite, answered below
            solved = _eliminate(A, np, 0)
    except ZeroDivisionError:                # a zero pivot that every system shares (a float's division)
        return None
    x = np.empty((nq + m, rows))
    for i, e in enumerate(solved):
        x[i] = e                             # a shared entry broadcasts over the systems
    if not np.isfinite(x).all():
        return None
    return x[:nq].T, x[nq:].T


def solve_symbolic(M, G, Ql, Q0, c):
    """(a, lam) as sympy column matrices: the same system, solved by LU on the symbolic matrix."""
    import sympy as sp

    nq, m = M.shape[0], G.shape[0]
    if m == 0:
        return M.LUsolve(sp.Matrix(list(Q0))), sp.zeros(0, 1)
    K = sp.Matrix(sp.BlockMatrix([[M, G.T - Ql], [G, sp.zeros(m, m)]]))
    sol = K.LUsolve(sp.Matrix(list(Q0) + list(c)))
    return sol[:nq, :], sol[nq:, :]
