"""Rolling-pair 4-bar dynamics in the single coordinate phi (rolling link's absolute rotation): an independent
reference for the DAE of `rolling_model` (docs/theory.md §K3, 'Minimal coordinate').

    M(phi) phi'' + 1/2 M'(phi) phi'^2 = tau(phi') - dV/dphi - (b2 theta2'^2 + b4) phi',
    M = sum m |G'|^2 + I theta'^2,  1/2 M' = sum m G' . G'' + I theta' theta'',

with G the centres of mass and theta the body angles as closed-form functions of phi (`RollingFourBar.solve`,
docs/theory.md §K2.2: implicit derivatives of the dyad, not the DAE's sympy model), tau = T0 - slope phi' the drive
on the rolling link. Regular only while the dyad stays away from its stretched/folded configurations, where
theta2' and theta3' become infinite; the integration stops with an error if it gets there.
"""
from __future__ import annotations

import numpy as np
from scipy.integrate import solve_ivp

from mechsim.mechanisms.rolling.model import RollingPairFourBar


def terms(mech: RollingPairFourBar, phi):
    """M(phi), 1/2 M'(phi), V(phi), dV/dphi and theta2'(phi) on the mechanism's branch (arrays)."""
    k, b = mech.kin, mech.bodies
    st = k.solve(np.atleast_1d(np.asarray(phi, float)), mech.branch)
    if not np.all(st.closes):
        raise ValueError(f"the dyad does not close at phi = {np.atleast_1d(phi)[~st.closes][0]:.6g} rad")
    f2, f3 = b.c2 / k.l2, b.c3 / k.l3
    e4 = np.exp(1j * (st.theta4 + b.d4))
    bodies = [
        (b.m2, k.a0 + f2 * (st.A - k.a0), f2 * st.dA, f2 * st.ddA),
        (b.m3, st.A + f3 * (st.B - st.A), st.dA + f3 * (st.dB - st.dA), st.ddA + f3 * (st.ddB - st.ddA)),
        (b.m4, st.B0 + b.c4 * e4, st.dB0 + 1j * b.c4 * e4, st.ddB0 - b.c4 * e4),
    ]
    M = sum(m * np.abs(d1) ** 2 for m, _, d1, _ in bodies) + b.I2 * st.dtheta2 ** 2 + b.I3 * st.dtheta3 ** 2 + b.I4
    half_dM = sum(m * (np.conj(d1) * d2).real for m, _, d1, d2 in bodies) \
        + b.I2 * st.dtheta2 * st.ddtheta2 + b.I3 * st.dtheta3 * st.ddtheta3
    V = mech.gravity * sum(m * g.imag for m, g, _, _ in bodies)
    dV = mech.gravity * sum(m * d1.imag for m, _, d1, _ in bodies)
    return M, half_dM, V, dV, st.dtheta2


def acceleration(mech: RollingPairFourBar, phi: float, omega: float, drive_T0: float, drive_slope: float) -> float:
    """phi'' of the reduced equation."""
    M, hM, _, dV, d2 = (float(x[0]) for x in terms(mech, phi))
    tau = drive_T0 - drive_slope * omega
    damping = (mech.crank_damping * d2 ** 2 + mech.rolling_damping) * omega
    return (tau - dV - damping - hM * omega ** 2) / M


def energy(mech: RollingPairFourBar, phi, omega):
    """Kinetic + potential energy 1/2 M phi'^2 + V (J)."""
    M, _, V, _, _ = terms(mech, phi)
    return 0.5 * M * np.asarray(omega) ** 2 + V


def integrate(mech: RollingPairFourBar, drive_T0: float, drive_slope: float, phi0: float, omega0: float,
              t_eval: np.ndarray, rtol: float = 1e-12, atol: float = 1e-12) -> tuple[np.ndarray, np.ndarray]:
    """phi(t), phi'(t) at t_eval (t_eval[0] is the start) with scipy's DOP853."""
    if mech.driven_link != "rolling":
        raise ValueError("the reduced reference is written in phi: the drive must act on the rolling link")

    def rhs(_t, y):
        return [y[1], acceleration(mech, y[0], y[1], drive_T0, drive_slope)]

    sol = solve_ivp(rhs, (float(t_eval[0]), float(t_eval[-1])), [phi0, omega0], method="DOP853", rtol=rtol,
                    atol=atol, t_eval=t_eval)
    if not sol.success:
        raise RuntimeError(sol.message)
    return sol.y[0], sol.y[1]
