"""Cusps of the rolling-pair coupler curve (l4 = r): docs/theory.md §K2.3, Kar & Sen §3.3."""
import numpy as np
import pytest

from mechsim.mechanisms.rolling.atlas import cusps_table
from mechsim.mechanisms.rolling.sets import make

# docs/theory.md §K2.3, set C: phi_k, B (= contact), C on branch +1, C on branch -1
SET_C_CUSPS = [
    (3.522124, (2.910226, 2.813231), (3.822356, 0.508538), (0.646837, 1.802951)),
    (11.899704, (-1.958430, 0.997688), (-0.190889, 2.735328), (-0.395719, -0.926247)),
    (20.277284, (2.048204, -2.310919), (-0.227805, -3.292436), (1.308552, 0.054775)),
]


def test_set_C_cusp_table():
    m = make("C")
    t = cusps_table(m)
    assert len(t) == 6
    for phi, B, Cp, Cm in SET_C_CUSPS:
        rows = t[np.isclose(t.rolling_angle_rad, phi, atol=1e-6)]
        assert sorted(rows.branch) == [-1, 1]
        for _, row in rows.iterrows():
            assert (row.B_x_m, row.B_y_m) == pytest.approx(B, abs=1e-6)
            assert (row.C_x_m, row.C_y_m) == pytest.approx(Cp if row.branch == 1 else Cm, abs=1e-6)


@pytest.mark.parametrize("name", ["C", "D", "bicursal_K7"])
def test_coupler_velocity_vanishes_at_every_cusp(name):
    """At every predicted cusp, both branches: B is the contact point, |C'| ≈ 1e-16 analytically and
    ≈ 1e-10 by central differences (h = 1e-6); |C'| grows linearly; the tangent reverses."""
    m = make(name)
    t = cusps_table(m)
    assert len(t) >= 4
    for _, row in t.iterrows():
        phi, br = row.rolling_angle_rad, int(row.branch)
        st = m.solve(np.array(phi), br)
        assert abs(st.B - st.P) <= 1e-12
        assert abs(st.dC) <= 1e-12 and abs(st.dB) <= 1e-12 and abs(st.dA) <= 1e-12
        h = 1e-6
        fd = (m.coupler(np.array(phi + h), br) - m.coupler(np.array(phi - h), br)) / (2 * h)
        assert abs(fd) <= 1e-8
        speeds = [abs(m.solve(np.array(phi + d), br).dC) / d for d in (1e-2, 1e-3, 1e-4)]
        assert speeds[1] == pytest.approx(speeds[2], rel=1e-2)
        assert speeds[0] == pytest.approx(speeds[2], rel=1e-1)
        before, after = m.solve(np.array(phi - 1e-3), br).dC, m.solve(np.array(phi + 1e-3), br).dC
        cosang = (np.conj(before) * after).real / abs(before) / abs(after)
        assert cosang <= -0.999


def test_line_cusps_reference():
    """Set D: cusps at φ = −10.124778 and −3.841593; the one at −16.407963 lies in non-closure."""
    m = make("D")
    t = cusps_table(m)
    phis = sorted(set(np.round(t.rolling_angle_rad, 6)))
    assert phis == pytest.approx([-10.124778, -3.841593], abs=1e-6)
    assert not m.solve(np.array(-16.407963), 1).closes
    st = m.solve(np.array(-16.407963), 1)
    assert abs(st.B - st.P) <= 1e-6  # B touches the line there nonetheless


def test_cusp_positions_from_the_touch_condition():
    """φ_k = (π − ψ + 2πk)(R + r)/R: the arm points at the contact, i.e. B = contact when l4 = r."""
    m = make("C")
    phik = m.pair.touch_phi(m.psi, 0, 2)
    np.testing.assert_allclose(phik, [3.522124, 11.899704, 20.277284], atol=1e-6)
    t = m.trochoid(phik)
    assert np.max(np.abs(t["B"] - t["P"])) <= 1e-12


def test_no_cusps_when_l4_differs_from_r():
    assert len(cusps_table(make("A"))) == 0
    assert len(cusps_table(make("B"))) == 0
