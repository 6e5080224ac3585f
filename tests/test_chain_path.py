"""Chain loop geometry (docs/theory.md §K1.1, §1.3 path-piece table) and layout validation."""
import math

import numpy as np
import pytest

from mechsim.mechanisms.chain.path import ChainPath, circle_circle_intersection, cross

CM = 0.01
MECH1 = (np.array([[5, 0], [0, 5], [-5, 0]]) * CM, [3 * CM] * 3)
MECH2 = (np.array([[5, 0], [0, 5], [-5, 0], [0, -5]]) * CM, [3 * CM] * 4)
DEG_TOL = 5e-7  # docs/theory.md (Part K) prints driving angles to 6 decimals


def drive_deg(path, s):
    return math.degrees(s / path.r1)


def test_mech1_length_and_piece_ranges():
    p = ChainPath(*MECH1)
    assert p.length / CM == pytest.approx(42.99169, abs=5e-6)
    assert drive_deg(p, p.length) == pytest.approx(821.080827, abs=DEG_TOL)
    assert p.piece_names == ["line 1-2", "arc 2", "line 2-3", "arc 3", "line 3-1", "arc 1"]
    ends = [135.047447, 225.047447, 360.094895, 495.094895, 686.080827, 821.080827]
    assert [drive_deg(p, q.s1) for q in p.pieces] == pytest.approx(ends, abs=DEG_TOL)
    lines = [q.length / CM for q in p.pieces if q.kind == "line"]
    assert lines == pytest.approx([50 ** 0.5, 50 ** 0.5, 10.0], abs=1e-12)
    wraps = [math.degrees(q.wrap) for q in p.pieces if q.kind == "arc"]
    assert wraps == pytest.approx([90, 135, 135], abs=1e-9)


def test_mech2_length_and_arcs():
    p = ChainPath(*MECH2)
    assert p.length / CM == pytest.approx(47.13383, abs=5e-6)
    assert drive_deg(p, p.length) == pytest.approx(900.189790, abs=DEG_TOL)
    arcs = {q.name: (drive_deg(p, q.s0), drive_deg(p, q.s1)) for q in p.pieces if q.kind == "arc"}
    expected = {"arc 2": (135.047447, 225.047447), "arc 3": (360.094895, 450.094895),
                "arc 4": (585.142342, 675.142342), "arc 1": (810.189790, 900.189790)}
    for k, v in expected.items():
        assert arcs[k] == pytest.approx(v, abs=DEG_TOL)


def test_origin_is_where_chain_leaves_sprocket_1():
    p = ChainPath(*MECH1)
    B0 = p.B(np.array(0.0))
    O1, r1 = MECH1[0][0], MECH1[1][0]
    assert np.hypot(*(B0 - O1)) == pytest.approx(r1, abs=1e-15)
    t = p.derivatives(np.array(0.0), 1)[1]
    # tangent to sprocket 1, heading towards sprocket 2, counter-clockwise about sprocket 1
    assert abs(np.dot(t, B0 - O1)) < 1e-15
    assert np.dot(t, MECH1[0][1] - MECH1[0][0]) > 0
    assert cross(B0 - O1, t) > 0


UNEQUAL = (np.array([[0.0, 0.0], [0.30, -0.02], [0.38, 0.17], [0.12, 0.25]]), [0.05, 0.02, 0.07, 0.03])


@pytest.mark.parametrize("layout", [MECH1, MECH2, UNEQUAL])
def test_pieces_closed_form_and_c1(layout):
    p = ChainPath(*layout)
    # total wrap is one turn and the length adds up (docs/theory.md §K1.1, not the paper's eq. 32, E6)
    assert p.wraps.sum() == pytest.approx(2 * math.pi, abs=1e-12)
    c, r = layout[0], np.asarray(layout[1])
    Z = np.hypot(*(np.roll(c, -1, 0) - c).T)
    lines = np.sqrt(Z ** 2 - (r - np.roll(r, -1)) ** 2)
    assert p.length == pytest.approx(lines.sum() + (r * p.wraps).sum(), rel=1e-14)
    for q in p.pieces:
        s = np.linspace(q.s0, q.s1, 7)
        B, B1, B2, B3 = (q.derivative(s, k) for k in range(4))
        assert np.allclose(np.hypot(*B1.T), 1.0, atol=1e-14)          # arc-length parameter
        h = 1e-5
        for k, hi in enumerate((B1, B2, B3)):
            fd = (q.derivative(s + h, k) - q.derivative(s - h, k)) / (2 * h)
            assert np.abs(fd - hi).max() < 1e-7 * max(1.0, np.abs(hi).max())
        if q.kind == "line":
            # the tangent line touches both sprockets: radius perpendicular to the direction
            for i, P in ((q.sprocket, B[0]), (q.to_sprocket, B[-1])):
                assert np.hypot(*(P - c[i])) == pytest.approx(r[i], abs=1e-14)
                assert abs(np.dot(P - c[i], B1[0])) < 1e-14
        else:
            assert np.allclose(np.hypot(*(B - c[q.sprocket]).T), r[q.sprocket], atol=1e-14)
    # continuity of B and B' at every junction (the path is C1, docs/theory.md §K1.5 point 5)
    for b in p.boundaries:
        m, pl = p.derivatives(np.array(b), 1, side=-1), p.derivatives(np.array(b), 1, side=+1)
        assert np.abs(m[0] - pl[0]).max() < 1e-14
        assert np.abs(m[1] - pl[1]).max() < 1e-12


def test_one_sided_lookup_at_junctions():
    p = ChainPath(*MECH1)
    b = p.boundaries[1]
    assert p.piece_index(np.array(b), -1) == 0 and p.piece_index(np.array(b), +1) == 1
    assert p.piece_index(np.array(0.0), -1) == len(p.pieces) - 1
    assert p.piece_index(np.array(p.length), +1) == 0
    # curvature jumps at a line/arc junction
    c_m = p.derivatives(np.array(b), 2, -1)[2]
    c_p = p.derivatives(np.array(b), 2, +1)[2]
    assert np.hypot(*c_m) == 0 and np.hypot(*c_p) == pytest.approx(1 / (3 * CM))
    # periodic in the chain length
    assert np.abs(p.B(np.array(0.123)) - p.B(np.array(0.123 + 3 * p.length))).max() < 1e-14


@pytest.mark.parametrize("layout", [MECH1, UNEQUAL])
def test_radial_quantities_against_direct_evaluation(layout):
    p = ChainPath(*layout)
    Q = np.array([0.013, -0.004])
    s = np.linspace(0, p.length, 401)
    B, B1 = p.derivatives(s, 1)
    d = B - Q
    for c in (0.02, 0.08):
        gp, gm, rr = p.radial(s, Q, c, c)
        assert np.abs(-gp - (np.einsum("ij,ij->i", d, d) - c * c)).max() < 1e-15
        assert np.abs(rr - np.einsum("ij,ij->i", d, B1)).max() < 1e-15
    # closed-form roots and extrema of |B - Q|
    for q in p.pieces:
        for s0, kind in q.sq_dist_extrema(Q):
            assert abs(q.radial_rate(s0, Q)) < 1e-15
        for s0 in q.sq_dist_roots(Q, 0.1):
            assert np.hypot(*(q.derivative(np.array(s0)) - Q)) == pytest.approx(0.1, abs=1e-14)


def test_sympy_pieces_match_numeric():
    import sympy as sp

    p = ChainPath(*UNEQUAL)
    s = sp.Symbol("s", real=True)
    for q in p.pieces:
        expr = q.sympy_B(s)
        x = 0.3 * q.s0 + 0.7 * q.s1
        for k in range(3):
            val = np.array(sp.diff(expr, s, k).subs(s, x).evalf(), float).ravel()
            assert np.abs(val - q.derivative(np.array(x), k)).max() < 1e-13


def test_circle_circle_intersection_sides():
    Pr, Pl = circle_circle_intersection((0, 0), 5.0, (8, 0), 3.0 + 1e-3)
    assert Pr[1] < 0 < Pl[1]
    for P in (Pr, Pl):
        assert np.hypot(*P) == pytest.approx(5.0) and np.hypot(P[0] - 8, P[1]) == pytest.approx(3.001)
    with pytest.raises(ValueError, match="do not intersect"):
        circle_circle_intersection((0, 0), 1.0, (5, 0), 1.0)


@pytest.mark.parametrize("centres, radii, message", [
    ([[5, 0], [-5, 0], [0, 5]], [3, 3, 3], "listed clockwise"),
    ([[5, 0], [0, 5], [0, 4], [-5, 0]], [1, 1, 1, 1], "overlap"),
    ([[10, 0], [0, 10], [-10, 0], [0, 2]], [1, 1, 1, 1], r"sprocket\(s\) \[4\] would be wrapped from inside"),
    ([[0, 0], [10, 0], [5, 1]], [1, 1, 3], "sprocket 3 sticks out of the chain loop"),
    ([[0, 0], [5, 0], [10, 0], [5, 8]], [1, 1, 1, 1], "sprocket 2 is not wrapped"),
    ([[0, 0]], [1], "at least 2 sprockets"),
    ([[0, 0], [5, 0]], [1, -1], "radius must be positive"),
    ([[0, 0], [5, 0]], [1, 1, 1], "one radius per sprocket"),
])
def test_bad_layouts_are_rejected_with_a_reason(centres, radii, message):
    with pytest.raises(ValueError, match=message):
        ChainPath(np.array(centres, float) * CM, np.array(radii, float) * CM)


def test_two_sprockets_any_radii():
    p = ChainPath(np.array([[0, 0], [0.3, 0.1]]), [0.08, 0.03])
    Z = math.hypot(0.3, 0.1)
    assert p.tangent_lengths == pytest.approx([math.sqrt(Z * Z - 0.05 ** 2)] * 2, rel=1e-14)
    assert p.wraps.sum() == pytest.approx(2 * math.pi, abs=1e-12)
    assert p.wraps[0] > math.pi > p.wraps[1]   # the big sprocket carries the longer wrap
