"""Constraint formulations of the equations of motion as residuals F(t, y, y') = 0 (symbolic).

With q positions, v velocities, Phi(t, q) = 0 the m constraints, G = dPhi/dq, and M v' + G^T lam = Q:

- index3: q' = v;  M v' + G^T lam = Q;  Phi = 0.                       (docs/theory.md §K4, 'Index 3')
- index2: q' = v - G^T mu;  M v' + G^T lam = Q;  Phi = 0;  G v + Phi_t = 0.
          Stabilized index 2 of Gear, Gupta & Leimkuhler (1985); mu = 0 on the exact solution.
- index1: q' = v;  M v' + G^T lam = Q;  Phi'' + 2 a Phi' + b^2 Phi = 0 (acceleration level with
          Baumgarte's (1972) stabilisation; a = b = 0 gives the plain index-1 form).

Phi' and Phi'' are derived by sympy from Phi (no hand-written derivatives).
"""
from __future__ import annotations

from dataclasses import dataclass
from typing import TYPE_CHECKING

if TYPE_CHECKING:      # sympy is loaded by the functions that derive (the solver settings only need the names)
    import sympy as sp

FORMULATIONS = ("index1", "index2", "index3")


@dataclass(frozen=True)
class ConstraintDerivatives:
    """Phi, its time derivatives along the motion, and the pieces of the KKT system."""

    phi: sp.Matrix          # m x 1
    G: sp.Matrix            # m x nq
    phi_dot: sp.Matrix      # G v + Phi_t
    phi_ddot: sp.Matrix     # G a + (G v)_q v + 2 G_t v + Phi_tt, with a = v'
    gamma: sp.Matrix        # phi_ddot - G a  (acceleration right-hand side, with sign: G a = -gamma)


def differentiate_constraints(phi: list[sp.Expr], t: sp.Symbol, q, v, a) -> ConstraintDerivatives:
    """Time derivatives of Phi(t, q) along q' = v, v' = a."""
    import sympy as sp
    phi_m = sp.Matrix(phi) if phi else sp.zeros(0, 1)
    G = phi_m.jacobian(list(q)) if phi else sp.zeros(0, len(q))

    def ddt(expr_matrix, with_a: bool):
        out = expr_matrix.diff(t)
        for qi, vi in zip(q, v):
            out += expr_matrix.diff(qi) * vi
        if with_a:
            for vi, ai in zip(v, a):
                out += expr_matrix.diff(vi) * ai
        return out

    phi_dot = ddt(phi_m, False) if phi else sp.zeros(0, 1)
    phi_ddot = ddt(phi_dot, True) if phi else sp.zeros(0, 1)
    gamma = (phi_ddot - G * sp.Matrix(a)) if phi else sp.zeros(0, 1)
    return ConstraintDerivatives(phi_m, G, phi_dot, phi_ddot, gamma)


def mechanical_residual(formulation: str, M: sp.Matrix, Q: sp.Matrix, cd: ConstraintDerivatives,
                        q, v, qp, vp, lam, mu, baumgarte: tuple[sp.Symbol, sp.Symbol]) -> list[sp.Expr]:
    """Residual rows for q, v and the constraint block in the chosen formulation.

    qp, vp are the symbols standing for q', v' (IDA's yp). Returns rows in the order
    [q rows (nq), v rows (nq), constraint rows (m, or 2m for index2)].
    """
    import sympy as sp
    if formulation not in FORMULATIONS:
        raise ValueError(f"formulation must be one of {FORMULATIONS}, got {formulation!r}")
    nq = len(q)
    Gt = cd.G.T
    lam_v = sp.Matrix(lam) if lam else sp.zeros(0, 1)
    q_rows = [qp[i] - v[i] for i in range(nq)]
    if formulation == "index2" and mu:
        corr = Gt * sp.Matrix(mu)
        q_rows = [q_rows[i] + corr[i] for i in range(nq)]
    force = M * sp.Matrix(vp) - Q + (Gt * lam_v if lam else sp.zeros(nq, 1))
    v_rows = list(force)
    if formulation == "index3":
        c_rows = list(cd.phi)
    elif formulation == "index2":
        c_rows = list(cd.phi) + list(cd.phi_dot)
    else:
        a_b, b_b = baumgarte
        # phi_ddot with a = v' (the yp of v)
        c_rows = list(cd.phi_ddot + 2 * a_b * cd.phi_dot + b_b ** 2 * cd.phi)
    return q_rows + v_rows + c_rows
