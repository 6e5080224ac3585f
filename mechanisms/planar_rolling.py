"""Small planar helpers for the rolling-pair 4-bar: complex-number vector algebra, the dyad solution
(Chace's circle-circle intersection) with its derivatives, polyline self-intersections and a 2x2 Newton
refinement of curve crossings.

Points are complex numbers x + iy (numpy complex arrays); angles in rad, lengths in m.
"""
from __future__ import annotations

import numpy as np


def cross(a, b):
    """z-component of a x b for complex-encoded 2-vectors."""
    return a.real * b.imag - a.imag * b.real


def dot(a, b):
    """a . b for complex-encoded 2-vectors."""
    return a.real * b.real + a.imag * b.imag


def xy(z) -> np.ndarray:
    """Complex points -> float array of shape (..., 2)."""
    z = np.asarray(z)
    return np.stack([z.real, z.imag], axis=-1)


def dyad_tip(A0, B, l2: float, l3: float, sigma: int, clip_tol: float = 1e-12):
    """Tip A of the dyad A0-A-B: |A - A0| = l2, |B - A| = l3 (Kar & Sen eq. 18, Chace's equation).

    A = A0 + e D^ + sigma sqrt(l2^2 - e^2) (D^ x k^), D = B - A0, e = (l2^2 - l3^2 + d^2)/(2d);
    D^ x k^ is D^ turned by -90 deg, so branch sigma = +1 puts A on the right of the ray A0 -> B.
    Returns (A, closes): A is nan where the dyad cannot close. Round-off below clip_tol*l2^2 at a
    stretched/folded configuration is clipped to zero so the singular end itself evaluates.
    """
    D = np.asarray(B, dtype=complex) - A0
    d = np.abs(D)
    with np.errstate(divide="ignore", invalid="ignore"):
        e = (l2 * l2 - l3 * l3 + d * d) / (2.0 * d)
        h2 = l2 * l2 - e * e
        h2 = np.where((h2 < 0.0) & (h2 > -clip_tol * l2 * l2), 0.0, h2)
        closes = h2 >= 0.0
        h = np.sqrt(np.where(closes, h2, np.nan))
        A = A0 + (e - 1j * sigma * h) * D / d
    return A, closes


def dyad_derivatives(A0, A, B, dB, ddB):
    """First and second derivatives of the dyad tip A and of the crank/coupler angles with respect to
    the input parameter, by implicit differentiation of |A - A0|^2 = l2^2 and |B - A|^2 = l3^2
    (docs/theory.md §K2.2).

    With u = A - A0, w = B - A, A' = i th2' u and
        th2'  = (w.B') / (u x w),
        th2'' = (w.B'' + th2'^2 (w.u) + |B' - A'|^2) / (u x w),
        th3'  = (w x w') / |w|^2,  th3'' = (w x w'') / |w|^2.
    u x w = l2 l3 sin(th3 - th2) vanishes at stretched/folded configurations (derivatives infinite).
    Returns dict with dA, ddA, dth2, ddth2, dth3, ddth3.
    """
    u = A - A0
    w = B - A
    det = cross(u, w)
    with np.errstate(divide="ignore", invalid="ignore"):
        dth2 = dot(w, dB) / det
        dA = 1j * dth2 * u
        dw = dB - dA
        ddth2 = (dot(w, ddB) + dth2 * dth2 * dot(w, u) + dot(dw, dw)) / det
        ddA = (1j * ddth2 - dth2 * dth2) * u
        ddw = ddB - ddA
        l3sq = dot(w, w)
        dth3 = cross(w, dw) / l3sq
        ddth3 = cross(w, ddw) / l3sq
    return dict(dA=dA, ddA=ddA, dth2=dth2, ddth2=ddth2, dth3=dth3, ddth3=ddth3)


def segment_intersections(P, Q=None, chunk: int = 256, skip_adjacent: bool = True, closed: bool = False):
    """Crossings of the polylines P (and Q, or P with itself) given as complex vertex arrays.

    Returns (i, j, s, t): segment P[i]->P[i+1] meets Q[j]->Q[j+1] at P[i] + s (P[i+1]-P[i]),
    0 <= s, t < 1. For self-intersections only i < j is reported and neighbouring segments are skipped
    (also the last/first pair if `closed`, i.e. P[-1] == P[0]). Bounding boxes prefilter the pairs;
    the exact test is the usual 2x2 solve. Vertices containing nan split the polyline.
    """
    self_mode = Q is None
    Q = P if self_mode else Q
    p0, p1 = P[:-1], P[1:]
    q0, q1 = Q[:-1], Q[1:]
    n, m = len(p0), len(q0)
    qx_lo, qx_hi = np.minimum(q0.real, q1.real), np.maximum(q0.real, q1.real)
    qy_lo, qy_hi = np.minimum(q0.imag, q1.imag), np.maximum(q0.imag, q1.imag)
    dq = q1 - q0
    out_i, out_j, out_s, out_t = [], [], [], []
    for a in range(0, n, chunk):
        b = min(n, a + chunk)
        pa, pb = p0[a:b, None], p1[a:b, None]
        with np.errstate(invalid="ignore"):
            box = ((np.minimum(pa.real, pb.real) <= qx_hi) & (np.maximum(pa.real, pb.real) >= qx_lo)
                   & (np.minimum(pa.imag, pb.imag) <= qy_hi) & (np.maximum(pa.imag, pb.imag) >= qy_lo))
        if self_mode:
            ii = np.arange(a, b)[:, None]
            jj = np.arange(m)[None, :]
            box &= jj > ii + (1 if skip_adjacent else 0)
            if closed and skip_adjacent:
                box &= ~((ii == 0) & (jj == m - 1))
        ri, rj = np.nonzero(box)
        if ri.size == 0:
            continue
        gi = ri + a
        dp = p1[gi] - p0[gi]
        dqq = dq[rj]
        den = cross(dp, dqq)
        r0 = q0[rj] - p0[gi]
        with np.errstate(divide="ignore", invalid="ignore"):
            s = cross(r0, dqq) / den
            t = cross(r0, dp) / den
        ok = (den != 0) & (s >= 0) & (s < 1) & (t >= 0) & (t < 1)
        out_i.append(gi[ok]); out_j.append(rj[ok]); out_s.append(s[ok]); out_t.append(t[ok])
    if not out_i:
        e = np.zeros(0, dtype=int)
        return e, e, np.zeros(0), np.zeros(0)
    return tuple(np.concatenate(v) for v in (out_i, out_j, out_s, out_t))


def newton_crossing(f1, df1, f2, df2, x1: float, x2: float, tol: float = 1e-14, maxiter: int = 50):
    """Solve f1(x1) = f2(x2) for two complex-valued curves by Newton's method.

    Jacobian [f1'(x1), -f2'(x2)] (2x2 real). Returns (x1, x2, |f1 - f2|, converged).
    """
    res = np.inf
    for _ in range(maxiter):
        F = f1(x1) - f2(x2)
        res = abs(F)
        if not np.isfinite(res):
            return x1, x2, res, False
        if res <= tol:
            return x1, x2, res, True
        J1, J2 = df1(x1), -df2(x2)
        det = cross(J1, J2)
        if det == 0 or not np.isfinite(det):
            return x1, x2, res, False
        # solve J1*d1 + J2*d2 = -F
        d1 = cross(-F, J2) / det
        d2 = cross(J1, -F) / det
        x1, x2 = x1 + d1, x2 + d2
        if abs(d1) + abs(d2) < 1e-16 * (1 + abs(x1) + abs(x2)):
            break
    F = f1(x1) - f2(x2)
    res = abs(F)
    return x1, x2, res, bool(res <= 1e3 * tol)
