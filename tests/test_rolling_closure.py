"""Closure intervals of the rolling-pair 4-bar: ends labelled stretched/folded to 1e-12, reference
intervals of docs/theory.md §K2.2, bicursal cases (including the K7 counter-example)."""
import math

import numpy as np
import pytest

from mechsim.mechanisms.rolling.atlas import components, nonclosure_table
from mechsim.mechanisms.rolling.pair import closure_intervals, rolling_span
from mechsim.mechanisms.rolling.sets import make

REF = {
    "B": [(2.081243, 5.781935, "stretched", "stretched"), (8.475975, 11.498952, "stretched", "folded"),
          (12.879598, 17.022659, "folded", "stretched"), (18.103481, 22.773735, "stretched", "stretched")],
    "D": [(-12.878132, -6.739964, "stretched", "folded"), (-6.245489, -0.082021, "folded", "stretched")],
}


@pytest.mark.parametrize("name", ["B", "D"])
def test_closure_intervals_match_reference(name):
    m = make(name)
    iv = closure_intervals(m)
    assert [(i.start_kind, i.end_kind) for i in iv] == [r[2:] for r in REF[name]]
    got = np.array([(i.start, i.end) for i in iv])
    np.testing.assert_allclose(got, np.array([r[:2] for r in REF[name]]), atol=6e-7, rtol=0)


@pytest.mark.parametrize("name", ["B", "D"])
def test_closure_ends_exact(name):
    """|A0B| at each end equals l2 + l3 (stretched) or |l2 - l3| (folded) to 1e-12; the two branches
    merge there (A+ = A-), and the dyad closes just inside / fails just outside."""
    m = make(name)
    for iv in closure_intervals(m):
        for x, kind, inward in ((iv.start, iv.start_kind, 1), (iv.end, iv.end_kind, -1)):
            d = m.dyad_distance(np.array(x))[0]
            level = m.d_stretched if kind == "stretched" else m.d_folded
            assert abs(d - level) <= 1e-12
            Ap, Am = m.solve(np.array(x), 1).A, m.solve(np.array(x), -1).A
            assert abs(Ap - Am) <= 1e-6  # sqrt of the 1e-15 residual
            assert m.solve(np.array(x + inward * 1e-9), 1).closes
            assert not m.solve(np.array(x - inward * 1e-9), 1).closes


@pytest.mark.parametrize("name", ["B", "D"])
def test_closure_matches_dense_sampling(name):
    """Independent check: a dense grid closes exactly inside the intervals."""
    m = make(name)
    (a, b), _ = rolling_span(m)
    phi = np.linspace(a, b, 20001)
    inside = np.zeros(phi.size, bool)
    for iv in closure_intervals(m):
        inside |= (phi > iv.start) & (phi < iv.end)
    d = m.dyad_distance(phi)[0]
    assert np.array_equal(inside, (d > m.d_folded) & (d < m.d_stretched))


@pytest.mark.parametrize("name", ["A", "C"])
def test_bicursal_sets_close_everywhere(name):
    """Sets A and C: bicursal, two closed monochromatic curves (docs/theory.md §K2.2)."""
    m = make(name)
    iv = closure_intervals(m)
    assert len(iv) == 1 and iv[0].start_kind == iv[0].end_kind == "period"
    comps = components(m)
    assert [(c.kind, c.closed) for c in comps] == [("monochromatic", True)] * 2
    assert sorted(c.path[0][0] for c in comps) == [-1, 1]


def test_bicursal_without_contained_annulus_K7():
    """docs/theory.md §K1.3 (K7): the trochoid stays within |A0B| in [2.0179, 5.9923], inside the dyad annulus
    [2.0079, 6.0023], so the curve is bicursal, although the trochoid's bounding annulus seen from A0
    ([2.0, 6.0]) is not contained (the paper's condition is sufficient, not necessary)."""
    m = make("bicursal_K7")
    (a, b), periodic = rolling_span(m)
    assert periodic
    d = m.dyad_distance(np.linspace(a, b, 200001))[0]
    assert d.min() == pytest.approx(2.0179, abs=5e-5) and d.max() == pytest.approx(5.9923, abs=5e-5)
    assert (m.d_folded, m.d_stretched) == pytest.approx((2.0079, 6.0023), abs=1e-12)
    O = complex(*m.pair.O)
    R0 = m.pair.R + m.pair.r
    outer, inner = abs(O - m.a0) + R0 + m.l4, R0 - m.l4 - abs(O - m.a0)
    assert (inner, outer) == pytest.approx((2.0, 6.0))
    assert not (m.d_folded <= inner and outer <= m.d_stretched)  # not contained (inner 2.0 < 2.0079) ...
    comps = components(m)
    assert [c.kind for c in comps] == ["monochromatic"] * 2  # ... yet bicursal


def test_nonclosure_regions_complement():
    m = make("B")
    (a, b), _ = rolling_span(m)
    iv = closure_intervals(m)
    nc = nonclosure_table(iv, (a, b))
    total = sum(i.end - i.start for i in iv) + (nc.rolling_angle_end_rad - nc.rolling_angle_start_rad).sum()
    assert total == pytest.approx(b - a, rel=1e-14)
    for _, row in nc.iterrows():
        mid = 0.5 * (row.rolling_angle_start_rad + row.rolling_angle_end_rad)
        assert not m.solve(np.array(mid), 1).closes


def test_wrapped_interval_is_merged():
    """A closure interval running through the period boundary is one interval (end beyond the span)."""
    m = make("B")
    T = 8 * math.pi
    shifted = make("B", span=(10.0, 10.0 + T))
    iv = closure_intervals(shifted)
    assert len(iv) == 4
    ref = sorted(((i.start - 10.0) % T for i in closure_intervals(m)))
    assert sorted((i.start - 10.0) % T for i in iv) == pytest.approx(ref, abs=1e-12)
    wrapped = [i for i in iv if i.end > 10.0 + T]
    assert len(wrapped) == 1 and wrapped[0].start_kind in ("stretched", "folded")
