"""The closed-form rolling-pair kinematics reproduce the torque-driven reference of docs/theory.md §K3
(set A, circle on circle, τ = 15 N·m on link 4, gravity, from rest at φ = 0) through the
minimal-coordinate equation M(φ)φ̈ + ½M′(φ)φ̇² = τ − dV/dφ, M = Σ m|G′|² + I θ′².

This checks the conventions (ψ, γ0, branch sign) and the second derivatives the dynamics model will
reuse; it imports nothing from `dynamics`.
"""
import numpy as np
import pytest
from scipy.integrate import solve_ivp

from mechsim.mechanisms.rolling.sets import make

G = 9.81
TAU = 15.0
# docs/theory.md §K3 bodies: crank and coupler slender rods; link 4 = disc (0.5 kg at B0) + arm (0.1 kg,
# CoM at l4/2 = 0.8), so its CoM is 0.1 * 0.8 / 0.6 = 0.13333 from B0 along the arm
M2, I2, M3, I3, M4, I4, C4 = 0.2, 0.15, 0.3, 0.30625, 0.6, 0.324667, 0.1 * 0.8 / 0.6


def _model(m, branch):
    def terms(phi):
        st = m.solve(np.array(phi), branch)
        e4 = np.exp(1j * st.theta4)
        g2 = ((m.a0 + st.A) / 2, st.dA / 2, st.ddA / 2)
        g3 = ((st.A + st.B) / 2, (st.dA + st.dB) / 2, (st.ddA + st.ddB) / 2)
        g4 = (st.B0 + C4 * e4, st.dB0 + 1j * C4 * e4, st.ddB0 - C4 * e4)
        mass = [(M2, g2), (M3, g3), (M4, g4)]
        M = sum(mm * abs(g[1]) ** 2 for mm, g in mass) + I2 * st.dtheta2 ** 2 + I3 * st.dtheta3 ** 2 + I4
        hM = sum(mm * (np.conj(g[1]) * g[2]).real for mm, g in mass) \
            + I2 * st.dtheta2 * st.ddtheta2 + I3 * st.dtheta3 * st.ddtheta3
        V = G * sum(mm * g[0].imag for mm, g in mass)
        dV = G * sum(mm * g[1].imag for mm, g in mass)
        return float(M), float(hM), float(V), float(dV)
    return terms


@pytest.mark.parametrize("branch,phi_end,w_max", [(1, 32.268, 32.77), (-1, 35.237, 35.19)])
def test_torque_driven_reference(branch, phi_end, w_max):
    assert C4 == pytest.approx(0.13333, abs=1e-5)
    m = make("A")
    terms = _model(m, branch)

    def rhs(t, y):
        M, hM, _, dV = terms(y[0])
        return [y[1], (TAU - dV - hM * y[1] ** 2) / M]

    sol = solve_ivp(rhs, (0.0, 4.0), [0.0, 0.0], method="DOP853", rtol=1e-10, atol=1e-11, dense_output=True)
    assert sol.success
    assert sol.y[0, -1] == pytest.approx(phi_end, abs=1e-3)
    assert TAU * sol.y[0, -1] == pytest.approx(TAU * phi_end, abs=0.02)  # W = τφ: 484.0 / 528.6 J
    # the reference's max ω is sampled every 0.01 s
    ts = np.linspace(0.0, 4.0, 401)
    phi, w = sol.sol(ts)
    assert w.max() == pytest.approx(w_max, abs=0.01)
    # energy E = T + V − τφ is conserved (docs/theory.md §K3: drift ~1e-8)
    E = np.array([0.5 * terms(p)[0] * v * v + terms(p)[2] - TAU * p for p, v in zip(phi, w)])
    assert np.max(np.abs(E - E[0])) <= 1e-6
