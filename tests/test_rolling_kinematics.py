"""Rolling-pair 4-bar: corrected no-slip kinematics, closed-form trochoids, dyad, derivatives.

Expected values: docs/theory.md §K2.1-2.3 and textbook epi-/trochoid formulas; derivatives are checked
against finite differences and against the Kennedy (instantaneous-centre) relation.
"""
import math

import numpy as np
import pytest
import sympy as sp

from mechsim.mechanisms.rolling.pair import CircleOnCircle, RollingFourBar, rolling_span
from mechsim.mechanisms.rolling.paper import paper_contact_slip, paper_rotation_matrix, paper_trochoid, rotation_matrix
from mechsim.mechanisms.rolling.sets import make

CIRCLE_SETS = ["A", "B", "C", "bicursal_K7", "irrational"]


def _phi_grid(m, n=4001):
    (a, b), _ = rolling_span(m)
    return np.linspace(a, b, n)


@pytest.mark.parametrize("name", CIRCLE_SETS + ["D"])
def test_no_slip_contact_material_point_at_rest(name):
    """Link 4's material point at the contact has zero velocity along the whole motion (≤ 1e-12)."""
    m = make(name)
    phi = _phi_grid(m)
    st = m.solve(phi, 1)
    v = st.contact_material_velocity(phidot=1.0)
    assert np.max(np.abs(v)) <= 1e-12
    # contact point lies on both profiles: |P - B0| = r, and on the fixed circle / line
    assert np.max(np.abs(np.abs(st.P - st.B0) - m.pair.r)) <= 1e-12
    if m.pair.kind == "circle":
        assert np.max(np.abs(np.abs(st.P - complex(*m.pair.O)) - m.pair.R)) <= 1e-12
    else:
        assert np.max(np.abs(st.P.imag - m.pair.P0[1])) <= 1e-12


@pytest.mark.parametrize("name", ["A", "C", "D"])
def test_no_slip_by_finite_differences_of_the_rigid_motion(name):
    """Independent of the derivative formulas: follow the body point that is at the contact at phi*
    (rigid motion of link 4) and difference its position."""
    m = make(name)
    h = 1e-5
    for phis in np.linspace(*rolling_span(m)[0], 37)[1:-1]:
        t0 = m.trochoid(np.array(phis))
        body = t0["P"] - t0["B0"]  # material vector at phi*

        def X(p):
            return m.trochoid(np.array(p))["B0"] + body * np.exp(1j * (p - phis))

        v = (X(phis + h) - X(phis - h)) / (2 * h)
        assert abs(v) <= 1e-9


def test_arc_lengths_equal_on_both_profiles():
    """No slip: arc rolled on the fixed circle R·Δγ equals the arc on the disc r·(φ - Δγ)."""
    for name in CIRCLE_SETS:
        p = make(name).pair
        phi = np.linspace(-30, 30, 101)
        dg = p.u_of_phi(phi) - p.gamma0
        np.testing.assert_allclose(p.R * dg, p.r * (phi - dg), atol=1e-12, rtol=0)


@pytest.mark.parametrize("R,r", [(2.0, 1.0), (3.0, 1.0)])
def test_paper_rolling_relation_slips(R, r):
    """Kar & Sen eqs. (1), (10), (11), (14): the contact slips at exactly r²/R (docs/theory.md §K2.1, K1)."""
    pair = CircleOnCircle(R=R, r=r, O=(0.5, 0.3))
    phi = np.linspace(0, 20, 501)
    slip = np.abs(paper_contact_slip(pair, phi))
    np.testing.assert_allclose(slip, r * r / R, rtol=1e-12)
    assert slip.min() > 0.3  # 0.5 and 0.3333: far from rolling


@pytest.mark.parametrize("name,expected", [("A", 6.0), ("B", 6.92), ("C", 6.92)])
def test_paper_trochoid_differs_from_the_rolling_one(name, expected):
    """The paper's B differs from the correct B by up to 6.0 (set A) and 6.92 (sets B, C) over a period."""
    m = make(name)
    phi = _phi_grid(m, 200001)
    d = np.abs(paper_trochoid(m.pair, m.l4, m.psi, phi)["B"] - m.trochoid(phi)["B"]).max()
    assert d == pytest.approx(expected, abs=0.01)


def test_paper_rotation_matrix_sign_error():
    """Kar & Sen eq. (3) as printed maps P = (1, 2), α = 0.7 to (−2.047, 2.348); the corrected one fixes P."""
    P = np.array([1.0, 2.0, 1.0])
    np.testing.assert_allclose(paper_rotation_matrix(0.7, P[:2]) @ P, [-2.047, 2.348, 1.0], atol=5e-4)
    np.testing.assert_allclose(rotation_matrix(0.7, P[:2]) @ P, P, atol=1e-15)
    Q = np.array([3.0, -1.0, 1.0])
    c, s = math.cos(0.7), math.sin(0.7)
    expect = np.array([1 + c * 2 - s * (-3), 2 + s * 2 + c * (-3), 1.0])
    np.testing.assert_allclose(rotation_matrix(0.7, P[:2]) @ Q, expect, atol=1e-14)


@pytest.mark.parametrize("name", CIRCLE_SETS)
def test_epitrochoid_closed_form(name):
    """B(φ) equals the textbook epitrochoid x = (R+r)cos t − d cos((R+r)t/r), y = (R+r)sin t − d sin((R+r)t/r)
    (point initially at angle π from the outward normal), rotated by γ0 and with the arm phase ψ − π,
    where t = γ − γ0 is the angle turned by the line of centres."""
    m = make(name)
    p = m.pair
    phi = _phi_grid(m)
    t = phi * p.r / (p.R + p.r)
    k = (p.R + p.r) / p.r
    d = m.l4
    ph = m.psi - math.pi
    x = (p.R + p.r) * np.cos(t) - d * np.cos(k * t + ph)
    y = (p.R + p.r) * np.sin(t) - d * np.sin(k * t + ph)
    expect = complex(*p.O) + np.exp(1j * p.gamma0) * (x + 1j * y)
    B = m.trochoid(phi)["B"]
    assert np.max(np.abs(B - expect)) <= 1e-12
    # the (x, y) primitive used for symbolic reuse gives the same
    bx, by = m.point_B(phi)
    assert np.max(np.abs(bx + 1j * by - B)) <= 1e-13


def test_epitrochoid_with_psi_pi_is_the_standard_one():
    m = RollingFourBar(pair=CircleOnCircle(R=2.5, r=0.7), l2=1, l3=1, l4=0.4, psi=math.pi)
    t = np.linspace(0, 20, 301)
    phi = t * (2.5 + 0.7) / 0.7
    x = 3.2 * np.cos(t) - 0.4 * np.cos(3.2 / 0.7 * t)
    y = 3.2 * np.sin(t) - 0.4 * np.sin(3.2 / 0.7 * t)
    assert np.max(np.abs(m.trochoid(phi)["B"] - (x + 1j * y))) <= 1e-12


def test_line_trochoid_closed_form():
    """Circle on a line: x = x0 + r t − d sin t, y = y0 + r − d cos t, t = −φ (clockwise rolling to +x)."""
    m = make("D", psi=math.pi)
    t = np.linspace(0, 6 * math.pi, 501)
    x0, y0 = m.pair.P0
    r, d = m.pair.r, m.l4
    B = m.trochoid(-t)["B"]
    np.testing.assert_allclose(B.real, x0 + r * t - d * np.sin(t), atol=1e-12, rtol=0)
    np.testing.assert_allclose(B.imag, y0 + r - d * np.cos(t), atol=1e-12, rtol=0)


@pytest.mark.parametrize("name,T", [("A", 6 * math.pi), ("B", 8 * math.pi), ("C", 8 * math.pi)])
def test_trochoid_period(name, T):
    """φ-period 2π(p + q) for R/r = p/q (docs/theory.md §K2.2): 6π (set A), 8π (sets B, C)."""
    m = make(name)
    (a, b), periodic = rolling_span(m)
    assert periodic and b - a == pytest.approx(T, rel=1e-15)
    phi = np.linspace(0, T, 97)
    B = m.trochoid(phi)["B"]
    assert np.max(np.abs(m.trochoid(phi + T)["B"] - B)) <= 1e-12
    # minimal: the body has turned p+q times, the centre q times; no shorter period
    for frac in range(1, int(round(T / (2 * math.pi)))):
        assert np.max(np.abs(m.trochoid(phi + 2 * math.pi * frac)["B"] - B)) > 1e-3


def test_rational_ratio_detection():
    assert CircleOnCircle(R=1.2, r=0.7).period() == pytest.approx(2 * math.pi * 19)
    assert CircleOnCircle(R=math.sqrt(2), r=1.0).period() is None
    assert CircleOnCircle(R=math.pi, r=1.0).period() is None


@pytest.mark.parametrize("name", ["A", "B", "D"])
@pytest.mark.parametrize("branch", [1, -1])
def test_dyad_constraints_and_branch_side(name, branch):
    m = make(name)
    phi = _phi_grid(m)
    st = m.solve(phi, branch)
    ok = st.closes
    assert ok.any()
    a0 = m.a0
    assert np.max(np.abs(np.abs(st.A[ok] - a0) - m.l2)) <= 1e-12
    assert np.max(np.abs(np.abs(st.B[ok] - st.A[ok]) - m.l3)) <= 1e-12
    assert np.max(np.abs(np.abs(st.C[ok] - st.A[ok]) - m.lc)) <= 1e-12
    # C at angle alpha from AB
    ang = np.angle((st.C[ok] - st.A[ok]) / (st.B[ok] - st.A[ok]))
    assert np.max(np.abs(ang - m.alpha)) <= 1e-12
    # branch +1: A on the right of the ray A0 -> B (Kar & Sen eq. 18 with D^ x k^)
    side = np.sign((np.conj(st.B[ok] - a0) * (st.A[ok] - a0)).imag)
    inner = np.abs(np.abs(st.B[ok] - a0) - m.d_stretched) > 1e-6
    inner &= np.abs(np.abs(st.B[ok] - a0) - m.d_folded) > 1e-6
    assert np.all(side[inner] == -branch)
    assert np.all(np.isnan(st.A[~ok]))


def _fd_cases():
    out = []
    for name in ["A", "B", "D"]:
        for branch in (1, -1):
            out.append((name, branch))
    return out


@pytest.mark.parametrize("name,branch", _fd_cases())
def test_velocity_and_acceleration_against_finite_differences(name, branch):
    """Analytic φ-derivatives vs central differences of the closed-form positions (h = 1e-5 for the
    first, 1e-4 for the second derivative), away from the singular ends (|sin(θ3 − θ2)| > 0.2)."""
    m = make(name)
    phi = _phi_grid(m, 400)
    st = m.solve(phi, branch)
    dets = np.abs(np.sin(st.theta3 - st.theta2))
    phi = phi[st.closes & (dets > 0.2)]
    assert phi.size > 20
    st = m.solve(phi, branch)
    h1, h2 = 1e-5, 1e-4
    p1, m1 = m.solve(phi + h1, branch), m.solve(phi - h1, branch)
    p2, m2 = m.solve(phi + h2, branch), m.solve(phi - h2, branch)
    for q in ["B0", "B", "A", "C", "theta2", "theta3", "theta4"]:
        x, xp, xm = getattr(st, q), getattr(p1, q), getattr(m1, q)
        Xp, Xm = getattr(p2, q), getattr(m2, q)
        if q.startswith("theta"):  # unwrap
            xp, xm = x + np.angle(np.exp(1j * (xp - x))), x + np.angle(np.exp(1j * (xm - x)))
            Xp, Xm = x + np.angle(np.exp(1j * (Xp - x))), x + np.angle(np.exp(1j * (Xm - x)))
        d1 = (xp - xm) / (2 * h1)
        d2 = (Xp - 2 * x + Xm) / h2 ** 2
        scale1 = 1 + np.abs(getattr(st, "d" + q))
        scale2 = 1 + np.abs(getattr(st, "dd" + q))
        assert np.max(np.abs(d1 - getattr(st, "d" + q)) / scale1) <= 1e-7, q
        assert np.max(np.abs(d2 - getattr(st, "dd" + q)) / scale2) <= 1e-5, q
        # and the analytic second derivative against differences of the analytic first
        dd = (getattr(p1, "d" + q) - getattr(m1, "d" + q)) / (2 * h1)
        assert np.max(np.abs(dd - getattr(st, "dd" + q)) / scale2) <= 1e-7, q


def test_time_derivatives_chain_rule():
    """For φ(t) = 0.3 + 1.7 t + 0.4 t², v = C'φ̇ and a = C''φ̇² + C'φ̈ match differences in t."""
    m = make("A")
    phi = lambda t: 0.3 + 1.7 * t + 0.4 * t * t  # noqa: E731
    t, h = 0.8, 1e-4
    st = m.solve(np.array(phi(t)), -1)
    phid, phidd = 1.7 + 0.8 * t, 0.8
    Cp, Cm = m.coupler(np.array(phi(t + h)), -1), m.coupler(np.array(phi(t - h)), -1)
    assert abs((Cp - Cm) / (2 * h) - st.velocity("C", phid)) <= 1e-7
    assert abs((Cp - 2 * st.C + Cm) / h ** 2 - st.acceleration("C", phid, phidd)) <= 1e-5


@pytest.mark.parametrize("name", ["A", "B", "C"])
@pytest.mark.parametrize("branch", [1, -1])
def test_kennedy_relation(name, branch):
    """|ω3/ω4| = |BP|/|B I13| and V_C = ω3 k × (C − I13), I13 = A0A ∩ PB (docs/theory.md §K2.3)."""
    m = make(name)
    phi = _phi_grid(m, 300)
    st = m.solve(phi, branch)
    ok = st.closes & (np.abs(np.sin(st.theta3 - st.theta2)) > 0.05)
    a0 = m.a0
    u, w = st.A[ok] - a0, st.B[ok] - st.P[ok]
    den = (np.conj(u) * w).imag
    good = np.abs(den) > 1e-3 * np.abs(u) * np.abs(w)
    lam = ((np.conj(st.P[ok] - a0) * w).imag / den)[good]
    I13 = a0 + lam * u[good]
    B, P, C = st.B[ok][good], st.P[ok][good], st.C[ok][good]
    w3 = st.dtheta3[ok][good]
    np.testing.assert_allclose(np.abs(w3), np.abs(B - P) / np.abs(B - I13), rtol=1e-10)
    VC = 1j * w3 * (C - I13)
    assert np.max(np.abs(VC - st.dC[ok][good]) / (1 + np.abs(VC))) <= 1e-10


def test_rolling_primitives_are_symbolic():
    """The pair's B0(γ), contact(γ) and B(φ) evaluate with sympy (for the dynamics model)."""
    m = make("A")
    g, phi = sp.symbols("gamma phi", real=True)
    x, y = m.pair.centre(g, lib=sp)
    dx, dy = m.pair.centre_du(g, lib=sp)
    assert sp.simplify(sp.diff(x, g) - dx) == 0 and sp.simplify(sp.diff(y, g) - dy) == 0
    bx, by = m.point_B(phi, lib=sp)
    val = complex(bx.subs(phi, 1.3).evalf() + 1j * by.subs(phi, 1.3).evalf())
    assert abs(val - m.trochoid(np.array(1.3))["B"]) <= 1e-12
    # θ4 as a function of the rolling parameter: φ(γ) = (γ − γ0)(R + r)/r
    assert m.pair.phi_of_u(m.pair.u_of_phi(2.7)) == pytest.approx(2.7, abs=1e-15)


@pytest.mark.parametrize("name", ["A", "D"])
def test_theta4_and_rolling_parameter_are_inverse(name):
    """θ4(u) and u(θ4) (for a Cartesian rolling constraint B0 = centre(u(θ4))) are inverse and consistent
    with the φ-parameterisation."""
    m = make(name)
    phi = np.linspace(-7, 7, 29)
    u = m.pair.u_of_phi(phi)
    np.testing.assert_allclose(m.theta4_of_param(u), m.theta4(phi), atol=1e-13, rtol=0)
    np.testing.assert_allclose(m.param_of_theta4(m.theta4(phi)), u, atol=1e-13, rtol=0)
    cx, cy = m.pair.centre(m.param_of_theta4(m.theta4(phi)))
    np.testing.assert_allclose(cx + 1j * cy, m.trochoid(phi)["B0"], atol=1e-13, rtol=0)
