"""The one KKT solve (dynamics/kkt.py): the same (a, lam) from numpy (single and stacked), JAX and sympy, and
both equations of the system satisfied to the system's conditioning."""
import numpy as np
import pytest
import sympy as sp

from mechsim.dynamics import kkt


def system(rng, nq=3, m=2):
    A = rng.standard_normal((nq, nq))
    M = A @ A.T + nq * np.eye(nq)                  # symmetric positive definite
    G = rng.standard_normal((m, nq))               # full row rank (almost surely)
    Ql = 0.1 * rng.standard_normal((nq, m))        # friction: forces linear in the multipliers
    return M, G, Ql, rng.standard_normal(nq), rng.standard_normal(m)


def kkt_matrix(M, G, Ql):
    return np.block([[M, G.T - Ql], [G, np.zeros((G.shape[0], G.shape[0]))]])


@pytest.mark.parametrize("seed", range(5))
def test_solution_satisfies_both_equations(seed):
    M, G, Ql, Q0, c = system(np.random.default_rng(seed))
    a, lam = kkt.solve(M, G, Ql, Q0, c)
    eps = np.finfo(float).eps
    scale = np.linalg.cond(kkt_matrix(M, G, Ql)) * eps * (1 + np.abs(np.r_[a, lam]).max())
    assert np.abs(M @ a + (G.T - Ql) @ lam - Q0).max() <= 10 * scale * np.abs(M).max()
    assert np.abs(G @ a - c).max() <= 10 * scale * np.abs(G).max()


def test_stacked_equals_one_by_one_and_unconstrained_is_newton():
    rng = np.random.default_rng(7)
    systems = [system(rng) for _ in range(4)]
    stacked = kkt.solve(*(np.stack(parts) for parts in zip(*systems)))
    for j, parts in enumerate(systems):
        a, lam = kkt.solve(*parts)
        np.testing.assert_allclose(stacked[0][j], a, rtol=1e-12, atol=1e-12)
        np.testing.assert_allclose(stacked[1][j], lam, rtol=1e-12, atol=1e-12)
    M, _, _, Q0, _ = systems[0]
    a, lam = kkt.solve(M, np.zeros((0, 3)), np.zeros((3, 0)), Q0, np.zeros(0))
    np.testing.assert_allclose(M @ a, Q0, rtol=1e-12, atol=1e-12)
    assert lam.shape == (0,)


def test_jax_and_sympy_give_the_same_solution():
    import jax.numpy as jnp

    import mechsim.dynamics.jax_model  # noqa: F401  (switches JAX to float64)

    M, G, Ql, Q0, c = system(np.random.default_rng(3))
    a, lam = kkt.solve(M, G, Ql, Q0, c)
    aj, lamj = kkt.solve(*(jnp.asarray(x) for x in (M, G, Ql, Q0, c)), xp=jnp)
    np.testing.assert_allclose(np.asarray(aj), a, rtol=1e-10, atol=1e-12)
    np.testing.assert_allclose(np.asarray(lamj), lam, rtol=1e-10, atol=1e-12)
    # sympy on exact rationals of the same numbers: LU in exact arithmetic, so it checks numpy's solve too
    exact = [sp.Matrix(np.atleast_2d(x).T if x.ndim == 1 else x).applyfunc(lambda e: sp.Rational(float(e))) for x in (M, G, Ql, Q0, c)]
    acc, mult = kkt.solve_symbolic(*exact)
    np.testing.assert_allclose(np.array(acc, dtype=float).ravel(), a, rtol=1e-10, atol=1e-12)
    np.testing.assert_allclose(np.array(mult, dtype=float).ravel(), lam, rtol=1e-10, atol=1e-12)


@pytest.mark.parametrize("nq, m", [(2, 1), (3, 2), (4, 3), (3, 0)])
def test_unrolled_solve_of_the_compiled_run_matches_lapack(nq, m):
    """The compiled diffrax run's unrolled solve (`kkt.unrolled_solves`: the mass-matrix block eliminated without
    pivoting, the constraint block with partial pivoting) against LAPACK's pivoted LU on the same systems, to
    the systems' conditioning; with badly scaled blocks too (mass 1e-3, constraint rows 1e2)."""
    import jax.numpy as jnp

    import mechsim.dynamics.jax_model  # noqa: F401  (switches JAX to float64)

    rng = np.random.default_rng(11 + nq + m)
    eps = np.finfo(float).eps
    for scale_m, scale_g in ((1.0, 1.0), (1e-3, 1e2), (1e2, 1e-2)):
        for _ in range(10):
            M, G, Ql, Q0, c = system(rng, nq, m)
            M, G, Ql = scale_m * M, scale_g * G, scale_g * Ql
            a, lam = kkt.solve(M, G, Ql, Q0, c)
            with kkt.unrolled_solves():
                aj, lamj = kkt.solve(*(jnp.asarray(x) for x in (M, G, Ql, Q0, c)), xp=jnp)
            K = kkt_matrix(M, G, Ql) if m else M
            x, xj = np.r_[a, lam], np.r_[np.asarray(aj), np.asarray(lamj)]
            bound = 100 * np.linalg.cond(K) * eps * np.abs(x).max()
            assert np.abs(xj - x).max() <= bound, (nq, m, scale_m, scale_g)


@pytest.mark.parametrize("nq, m", [(1, 0), (2, 0), (2, 1), (3, 2), (4, 3)])
def test_long_stack_by_columns_matches_lapack_system_by_system(nq, m):
    """A stack long enough for the column-wise elimination (`kkt._stacked`, the output rows of a run) against
    LAPACK on each system alone, to each system's conditioning; badly scaled blocks too."""
    rng = np.random.default_rng(5 + nq + m)
    eps = np.finfo(float).eps
    rows = kkt.STACK_MIN + kkt.STACK_ROWS * (nq + m) ** 2
    for scale_m, scale_g in ((1.0, 1.0), (1e-3, 1e2), (1e2, 1e-2)):
        systems = [system(rng, nq, m) for _ in range(rows)]
        systems = [(scale_m * M, scale_g * G, scale_g * Ql, Q0, c) for M, G, Ql, Q0, c in systems]
        a, lam = kkt.solve(*(np.stack(parts) for parts in zip(*systems)))
        assert a.shape == (rows, nq) and lam.shape == (rows, m)
        for j in range(0, rows, 7):
            M, G, Ql, Q0, c = systems[j]
            K = kkt_matrix(M, G, Ql) if m else M
            x = np.linalg.solve(K, np.r_[Q0, c])
            bound = 100 * np.linalg.cond(K) * eps * np.abs(x).max()
            assert np.abs(np.r_[a[j], lam[j]] - x).max() <= bound, (nq, m, j)


def test_long_stack_with_a_singular_or_nan_system_answers_as_lapack():
    """A stack whose column-wise elimination is not finite goes to LAPACK whole: a singular system raises as
    numpy.linalg.solve does; a NaN entry gives LAPACK's answer for the whole stack."""
    rng = np.random.default_rng(9)
    rows = kkt.STACK_MIN + kkt.STACK_ROWS * 9
    M, G, Ql, Q0, c = (np.stack(parts) for parts in zip(*[system(rng, 2, 1) for _ in range(rows)]))
    G_singular = G.copy()
    G_singular[3] = 0.0                            # no constraint direction: K singular
    with pytest.raises(np.linalg.LinAlgError):
        kkt.solve(M, G_singular, np.zeros_like(Ql), Q0, c)
    Q0_nan = Q0.copy()
    Q0_nan[5, 0] = np.nan
    a, lam = kkt.solve(M, G, Ql, Q0_nan, c)
    K = np.concatenate([np.concatenate([M, np.swapaxes(G, 1, 2) - Ql], -1),
                        np.concatenate([G, np.zeros((rows, 1, 1))], -1)], -2)
    x = np.linalg.solve(K, np.concatenate([Q0_nan, c], -1)[..., None])[..., 0]
    np.testing.assert_array_equal(np.c_[a, lam], x)


def test_long_stack_keeps_a_prescribed_coordinate_at_zero_acceleration():
    """A prescribed drive's speed row (a = 0 for the driven coordinate) in a long stack: pivoted as LAPACK pivots
    it (the largest entry of its column against the small inertias), that acceleration is exactly zero, as
    LAPACK's; the other unknowns agree to the systems' conditioning."""
    rng = np.random.default_rng(13)
    rows = kkt.STACK_MIN + kkt.STACK_ROWS * 16
    parts = []
    for _ in range(rows):
        M, G, Ql, Q0, c = system(rng, 2, 1)
        G2 = np.vstack([0.1 * G, [1.0, 0.0]])                 # the speed constraint on coordinate 0
        parts.append((1e-3 * M, G2, np.hstack([0.1 * Ql, np.zeros((2, 1))]), Q0, np.r_[c, 0.0]))
    a, lam = kkt.solve(*(np.stack(p) for p in zip(*parts)))
    assert np.all(a[:, 0] == 0.0)
    for j in range(0, rows, 11):
        M, G, Ql, Q0, c = parts[j]
        x = np.linalg.solve(kkt_matrix(M, G, Ql), np.r_[Q0, c])
        assert x[0] == 0.0
        bound = 100 * np.linalg.cond(kkt_matrix(M, G, Ql)) * np.finfo(float).eps * np.abs(x).max()
        assert np.abs(np.r_[a[j], lam[j]] - x).max() <= bound


@pytest.mark.parametrize("nq, m", [(1, 0), (2, 1), (3, 2), (4, 3)])
def test_long_stack_rows_eliminate_as_the_unrolled_elimination(nq, m):
    """The long stack's elimination (`kkt._eliminate` on entries that are arrays over the systems, or one scalar
    where every system shares the entry) performs on every system the operations of the elimination of that system
    alone, on its own scalars: the same values to the last bit, where no system, some or all exchange rows at a
    pivot, on systems with zero blocks, and with a leading block that every system shares."""
    rng = np.random.default_rng(17 + nq + m)
    rows, n = 300, nq + m
    for case in range(5):
        A = rng.standard_normal((n, n + 1, rows))
        if case == 1:       # a dominant diagonal: no exchange
            A[np.arange(n), np.arange(n)] += 100.0 * np.sign(A[np.arange(n), np.arange(n)])
        elif case == 2:     # the first column's largest entry in the last row of every system: all exchange
            A[-1, 0] = 100.0 + np.abs(A[-1, 0])
        elif case == 3:     # zero blocks, as a KKT matrix has
            A[nq:, nq:n] = 0.0
            A[:, 0][rng.random((n, rows)) < 0.3] = 0.0
        elif case == 4:     # a leading block every system shares (a constant mass matrix), zeros in it
            A[:nq, :nq] = A[:nq, :nq, :1] * (rng.random((nq, nq, 1)) < 0.7)
        entries = [[np.float64(A[i, j, 0]) if np.all(A[i, j] == A[i, j, 0]) else A[i, j].copy()
                    for j in range(n + 1)] for i in range(n)]
        with np.errstate(all="ignore"):        # a zero column gives zero pivots: the same NaN in both
            got = np.array([np.broadcast_to(e, (rows,)) for e in kkt._eliminate(entries, np, 0)])
            expected = np.array([kkt._eliminate([[np.float64(A[i, j, s]) for j in range(n + 1)] for i in range(n)],
                                                np, 0) for s in range(rows)]).T
        np.testing.assert_array_equal(got.view(np.int64), expected.view(np.int64))


def test_entries_with_shared_scalars_solve_as_the_stacked_arrays():
    """`kkt.solve_entries` on lambdified entries, some of them one scalar every system shares (a constant mass
    matrix, a zero friction block), gives the long stack's solution of the same systems stacked as arrays, to the
    last bit; a short stack, LAPACK's."""
    rng = np.random.default_rng(23)
    nq, m = 2, 1
    for rows in (kkt.STACK_MIN + kkt.STACK_ROWS * 9, 50):
        M = np.diag([0.02, 0.0015])
        G = rng.standard_normal((rows, m, nq))
        Q0, c = rng.standard_normal((rows, nq)), rng.standard_normal((rows, m))
        a, lam = kkt.solve_entries(rows, [[0.02, 0], [0, 0.0015]], [list(G[:, 0].T)], [[0], [0.0]], list(Q0.T),
                                   list(c.T))
        a_ref, lam_ref = kkt.solve(np.broadcast_to(M, (rows, nq, nq)).copy(), G, np.zeros((rows, nq, m)), Q0, c)
        np.testing.assert_array_equal(np.c_[a, lam].view(np.int64), np.c_[a_ref, lam_ref].view(np.int64))
