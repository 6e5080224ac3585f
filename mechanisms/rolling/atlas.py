"""Coupler-curve atlas of the rolling-pair 4-bar (Kar & Sen §3; docs/theory.md §K2.2-2.4): the curve
tabulated over the trochoid's period (or a documented finite span), its components (monochromatic /
dichromatic, coloured by branch), non-closure regions, cusps and crunodes, as pandas DataFrames.

Columns follow `<quantity>_<unit>`; lengths in m, angles in rad. `rolling_angle_rad` is the input phi
(absolute rotation of the rolling link 4).
"""
from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np
import pandas as pd

from mechsim.mechanisms.planar_rolling import newton_crossing, segment_intersections
from mechsim.mechanisms.rolling.pair import ClosureInterval, RollingFourBar, closure_intervals, rolling_span

SINGULAR = ("stretched", "folded")


@dataclass(frozen=True)
class Component:
    """One component (circuit) of the coupler curve.

    monochromatic: one branch over the whole span (closure never fails); dichromatic: a closure interval,
    branch +1 one way and -1 back, the two merging at the stretched/folded ends (Kar & Sen §3.1).
    `path` is the traversal as (branch, phi_start, phi_end) pieces; `closed` says whether it closes
    (period with full closure, or singular ends at both sides).
    """

    index: int
    kind: str
    closed: bool
    interval: ClosureInterval
    path: tuple[tuple[int, float, float], ...]


def _grid(a: float, b: float, n: int, cluster_a: bool, cluster_b: bool) -> np.ndarray:
    """n+1 points from a to b, cosine-clustered towards singular ends (A ~ sqrt(phi - end) there)."""
    t = np.linspace(0.0, 1.0, n + 1)
    if cluster_a and cluster_b:
        w = 0.5 * (1.0 - np.cos(np.pi * t))
    elif cluster_a:
        w = 1.0 - np.cos(0.5 * np.pi * t)
    elif cluster_b:
        w = np.sin(0.5 * np.pi * t)
    else:
        w = t
    x = a + (b - a) * w
    x[0], x[-1] = a, b
    return x


def components(mech: RollingFourBar, intervals: list[ClosureInterval] | None = None,
               span: tuple[float, float] | None = None, periodic: bool | None = None) -> list[Component]:
    """Components of the coupler curve from the closure intervals (Kar & Sen §3.1, docs/theory.md §K2.2)."""
    if span is None:
        span, per = rolling_span(mech)
        periodic = per if periodic is None else periodic
    if intervals is None:
        intervals = closure_intervals(mech, span, periodic)
    out = []
    for iv in intervals:
        s_sing, e_sing = iv.start_kind in SINGULAR, iv.end_kind in SINGULAR
        if not s_sing and not e_sing:  # closure over the whole span: two monochromatic curves
            for br in (1, -1):
                out.append(Component(len(out), "monochromatic", bool(periodic), iv, ((br, iv.start, iv.end),)))
        elif e_sing:  # +1 from start to the merge at end, then -1 back
            out.append(Component(len(out), "dichromatic", s_sing, iv,
                                 ((1, iv.start, iv.end), (-1, iv.end, iv.start))))
        else:  # only the start is singular: -1 from the open end back to the merge, then +1 out again
            out.append(Component(len(out), "dichromatic", False, iv,
                                 ((-1, iv.end, iv.start), (1, iv.start, iv.end))))
    return out


def _sample_component(mech: RollingFourBar, comp: Component, samples_per_turn: int):
    """Vertices (phi, branch, C, B, A, theta2, theta3) of a component polyline; a closed component ends
    where it starts (a dichromatic one repeats its first vertex, a periodic one ends at phi + T).
    Merge points appear once."""
    phis, brs = [], []
    sing = {comp.interval.start: comp.interval.start_kind in SINGULAR,
            comp.interval.end: comp.interval.end_kind in SINGULAR}
    for k, (br, a, b) in enumerate(comp.path):
        n = max(16, int(math.ceil(samples_per_turn * abs(b - a) / (2 * math.pi))))
        if sing[a] or sing[b]:
            n = int(math.ceil(n * math.pi / 2))
        x = _grid(a, b, n, sing[a], sing[b])
        if k > 0:  # the merge point is already there
            x = x[1:]
        phis.append(x)
        brs.append(np.full(x.size, br))
    phi, br = np.concatenate(phis), np.concatenate(brs)
    if comp.closed and comp.kind == "dichromatic":  # last vertex equals the first: drop the duplicate
        phi, br = phi[:-1], br[:-1]
    C = np.empty(phi.size, complex)
    B = np.empty(phi.size, complex)
    A = np.empty(phi.size, complex)
    th2 = np.empty(phi.size)
    th3 = np.empty(phi.size)
    for s in (1, -1):
        m = br == s
        st = mech.solve(phi[m], s)
        C[m], B[m], A[m], th2[m], th3[m] = st.C, st.B, st.A, st.theta2, st.theta3
    if comp.closed and comp.kind == "dichromatic":  # close the loop (a periodic one ends at start + T)
        phi, br = np.append(phi, phi[0]), np.append(br, br[0])
        C, B, A = np.append(C, C[0]), np.append(B, B[0]), np.append(A, A[0])
        th2, th3 = np.append(th2, th2[0]), np.append(th3, th3[0])
    return phi, br, C, B, A, th2, th3


def coupler_curve_table(mech: RollingFourBar, samples_per_turn: int = 720,
                        comps: list[Component] | None = None) -> pd.DataFrame:
    """The coupler curve, one row per sample, components in traversal order, coloured by `branch`."""
    comps = components(mech) if comps is None else comps
    frames = []
    for c in comps:
        phi, br, C, B, A, th2, th3 = _sample_component(mech, c, samples_per_turn)
        frames.append(pd.DataFrame(dict(
            component=c.index, branch=br, rolling_angle_rad=phi,
            C_x_m=C.real, C_y_m=C.imag, A_x_m=A.real, A_y_m=A.imag, B_x_m=B.real, B_y_m=B.imag,
            crank_angle_rad=th2, coupler_angle_rad=th3)))
    cols = ["component", "branch", "rolling_angle_rad", "C_x_m", "C_y_m", "A_x_m", "A_y_m", "B_x_m", "B_y_m",
            "crank_angle_rad", "coupler_angle_rad"]
    return pd.concat(frames, ignore_index=True) if frames else pd.DataFrame(columns=cols)


def trochoid_table(mech: RollingFourBar, samples_per_turn: int = 720) -> pd.DataFrame:
    """The locus of B (and B0, contact P) over the span."""
    (a, b), _ = rolling_span(mech)
    phi = np.linspace(a, b, max(16, int(math.ceil(samples_per_turn * (b - a) / (2 * math.pi)))) + 1)
    t = mech.trochoid(phi)
    return pd.DataFrame(dict(rolling_angle_rad=phi, B_x_m=t["B"].real, B_y_m=t["B"].imag,
                             B0_x_m=t["B0"].real, B0_y_m=t["B0"].imag,
                             contact_x_m=t["P"].real, contact_y_m=t["P"].imag))


def closure_table(intervals: list[ClosureInterval]) -> pd.DataFrame:
    return pd.DataFrame(dict(
        rolling_angle_start_rad=[i.start for i in intervals], rolling_angle_end_rad=[i.end for i in intervals],
        start_kind=[i.start_kind for i in intervals], end_kind=[i.end_kind for i in intervals]))


def nonclosure_table(intervals: list[ClosureInterval], span: tuple[float, float]) -> pd.DataFrame:
    """phi ranges where the dyad cannot assemble (complement of the closure intervals in the span; for a
    periodic span, a wrapped interval's tail is removed from the start of the span)."""
    a, b = span
    T = b - a
    covered = []
    for i in intervals:
        if i.end > b:  # wraps
            covered += [(i.start, b), (a, i.end - T)]
        else:
            covered.append((i.start, i.end))
    covered.sort()
    rows, x = [], a
    kinds = {}
    for i in intervals:
        kinds[i.start] = i.start_kind
        kinds[i.end if i.end <= b else i.end - T] = i.end_kind
    for s, e in covered:
        if s > x:
            rows.append((x, s, kinds.get(x, "span"), kinds.get(s, "span")))
        x = max(x, e)
    if x < b:
        rows.append((x, b, kinds.get(x, "span"), "span"))
    return pd.DataFrame(rows, columns=["rolling_angle_start_rad", "rolling_angle_end_rad", "start_kind",
                                       "end_kind"])


def cusps_table(mech: RollingFourBar, comps: list[Component] | None = None, rtol: float = 1e-12) -> pd.DataFrame:
    """Cusps at B on the fixed profile when l4 = r (Kar & Sen §3.3; docs/theory.md §K2.3).

    B touches the profile at phi_k = (pi - psi + 2 pi k)(R + r)/R (circle) or -pi - psi + 2 pi k (line);
    there B = contact = instantaneous centre of link 4, so B' = 0, A' = 0, theta3' = 0 and C' = 0 for every
    coupler point and both branches. Only phi_k inside closure are listed (one row per branch).
    The other cusp condition, C at the coupler's instantaneous centre I13, is non-generic for a
    one-parameter curve and is not searched.
    """
    cols = ["rolling_angle_rad", "branch", "component", "B_x_m", "B_y_m", "C_x_m", "C_y_m",
            "coupler_rate_m_per_rad"]
    if abs(mech.l4 - mech.pair.r) > rtol * mech.pair.r:
        return pd.DataFrame(columns=cols)
    comps = components(mech) if comps is None else comps
    (a, b), periodic = rolling_span(mech)
    T = b - a
    kmax = int(math.ceil((max(abs(a), abs(b)) + abs(mech.psi)) / (2 * math.pi))) + 2  # spacing >= 2 pi
    cand = mech.pair.touch_phi(mech.psi, -kmax, kmax)
    cand = cand[(cand >= a) & (cand < b)] if periodic else cand[(cand >= a) & (cand <= b)]
    rows = []
    for phi in np.sort(cand):
        for c in comps:
            iv = c.interval
            for x in ((phi, phi + T) if periodic else (phi,)):
                if iv.start < x < iv.end:
                    for br in sorted({p[0] for p in c.path}, reverse=True):
                        st = mech.solve(np.array([x]), br)
                        rows.append((x, br, c.index, st.B[0].real, st.B[0].imag, st.C[0].real, st.C[0].imag,
                                     abs(st.dC[0])))
    return pd.DataFrame(rows, columns=cols)


def _crossings(f, df, verts_phi, verts_br, verts, closed, ends, period, other=None):
    """Refined crossings of a sampled curve with itself (or with `other` = (phi, br, verts)).

    f(x, br), df(x, br): the curve and its phi-derivative; Newton on f(x1, b1) = f(x2, b2).
    """
    if other is None:
        i, j, s, t = segment_intersections(verts, closed=closed)
        ophi, obr = verts_phi, verts_br
    else:
        ophi, obr, overts = other
        i, j, s, t = segment_intersections(verts, overts)

    def seg(phis, brs, k, w):
        x = phis[k] + w * (phis[k + 1] - phis[k])
        br = brs[k + 1] if any(abs(phis[k] - e) < 1e-14 for e in ends) else brs[k]
        return x, int(br)

    out = []
    for k1, k2, w1, w2 in zip(i, j, s, t):
        x1, b1 = seg(verts_phi, verts_br, k1, w1)
        x2, b2 = seg(ophi, obr, k2, w2)
        y1, y2, res, ok = newton_crossing(lambda x: f(x, b1), lambda x: df(x, b1),
                                          lambda x: f(x, b2), lambda x: df(x, b2), x1, x2)
        if not ok:  # keep the chord estimate, flagged
            y1, y2, res = x1, x2, abs(f(x1, b1) - f(x2, b2))
        if period is not None:
            y1, y2 = (period[0] + (y - period[0]) % (period[1] - period[0]) for y in (y1, y2))
        same = abs(y1 - y2) < 1e-7 or (period is not None and abs(abs(y1 - y2) - (period[1] - period[0])) < 1e-7)
        if same and (b1 == b2 or any(abs(y1 - e) < 1e-6 for e in ends)):
            continue  # degenerate: the same configuration (a cusp tip or a merge point)
        if (y2, b2) < (y1, b1):
            y1, b1, y2, b2 = y2, b2, y1, b1
        out.append((y1, b1, y2, b2, f(y1, b1), res, ok))
    # de-duplicate
    uniq = []
    for r in sorted(out):
        if not any(r[1] == u[1] and r[3] == u[3] and abs(r[0] - u[0]) < 1e-8 and abs(r[2] - u[2]) < 1e-8
                   for u in uniq):
            uniq.append(r)
    return uniq


def trochoid_crunodes_table(mech: RollingFourBar, samples_per_turn: int = 720) -> pd.DataFrame:
    """Self-intersections of the locus of B, refined by Newton on B(phi1) = B(phi2) (docs/theory.md §K2.4)."""
    (a, b), periodic = rolling_span(mech)
    n = max(16, int(math.ceil(samples_per_turn * (b - a) / (2 * math.pi))))
    phi = np.linspace(a, b, n + 1)
    B = mech.trochoid(phi)["B"]
    f = lambda x, br: complex(mech.trochoid(np.array([x]))["B"][0])  # noqa: E731
    df = lambda x, br: complex(mech.trochoid(np.array([x]))["dB"][0])  # noqa: E731
    rows = _crossings(f, df, phi, np.ones(phi.size), B, periodic, [], (a, b) if periodic else None)
    return pd.DataFrame([(r[0], r[2], r[4].real, r[4].imag, r[5], r[6]) for r in rows],
                        columns=["rolling_angle_1_rad", "rolling_angle_2_rad", "x_m", "y_m", "residual_m",
                                 "converged"])


def crunodes_table(mech: RollingFourBar, samples_per_turn: int = 720, comps: list[Component] | None = None,
                   between_components: bool = False, trochoid: pd.DataFrame | None = None) -> pd.DataFrame:
    """Crunodes (self-intersections) of each coupler-curve component, located on the sampled polyline and
    refined by Newton on C(phi1, b1) = C(phi2, b2) (docs/theory.md §K2.4).

    `induced` marks crunodes at the phi pair of a trochoid crunode (Kar & Sen §3.2: every trochoid
    crunode gives one on each branch). With `between_components`, crossings of different components are
    listed too (component_1 != component_2).
    """
    comps = components(mech) if comps is None else comps
    (a, b), periodic = rolling_span(mech)
    T = b - a
    trochoid = trochoid_crunodes_table(mech, samples_per_turn) if trochoid is None else trochoid
    tpairs = trochoid[["rolling_angle_1_rad", "rolling_angle_2_rad"]].to_numpy()

    def f(x, br):
        return complex(mech.solve(np.array([x]), br).C[0])

    def df(x, br):
        return complex(mech.solve(np.array([x]), br).dC[0])

    sampled = [(c, _sample_component(mech, c, samples_per_turn)) for c in comps]
    rows = []

    def induced(y1, b1, y2, b2):
        if b1 != b2 or tpairs.size == 0:
            return False
        z1, z2 = sorted(((y1 - a) % T + a, (y2 - a) % T + a)) if periodic else (y1, y2)
        return bool(np.any((np.abs(tpairs[:, 0] - z1) < 1e-7) & (np.abs(tpairs[:, 1] - z2) < 1e-7)))

    for ci, (c, (phi, br, C, *_)) in enumerate(sampled):
        ends = [c.interval.start, c.interval.end]
        per = (a, b) if (periodic and c.kind == "monochromatic") else None
        for y1, b1, y2, b2, z, res, ok in _crossings(f, df, phi, br, C, c.closed, ends, per):
            rows.append((c.index, c.index, y1, b1, y2, b2, z.real, z.imag, res, ok, induced(y1, b1, y2, b2)))
        if between_components:
            for c2, (phi2, br2, C2, *_) in sampled[ci + 1:]:
                for y1, b1, y2, b2, z, res, ok in _crossings(
                        f, df, phi, br, C, False, ends + [c2.interval.start, c2.interval.end], None,
                        other=(phi2, br2, C2)):
                    rows.append((c.index, c2.index, y1, b1, y2, b2, z.real, z.imag, res, ok, False))
    return pd.DataFrame(rows, columns=["component_1", "component_2", "rolling_angle_1_rad", "branch_1",
                                       "rolling_angle_2_rad", "branch_2", "x_m", "y_m", "residual_m",
                                       "converged", "induced"])


@dataclass(frozen=True)
class Atlas:
    """Everything about one coupler curve (see `coupler_atlas`)."""

    mechanism: RollingFourBar
    span: tuple[float, float]
    periodic: bool
    components: list[Component]
    component_table: pd.DataFrame
    closure: pd.DataFrame
    nonclosure: pd.DataFrame
    curve: pd.DataFrame
    trochoid: pd.DataFrame
    cusps: pd.DataFrame
    crunodes: pd.DataFrame
    trochoid_crunodes: pd.DataFrame


def coupler_atlas(mech: RollingFourBar, samples_per_turn: int = 720, between_components: bool = False) -> Atlas:
    """Tabulate the coupler curve over the trochoid period (rational R/r) or the finite span (irrational
    R/r, or a line), with components, non-closure regions, cusps and crunodes."""
    span, periodic = rolling_span(mech)
    intervals = closure_intervals(mech, span, periodic)
    comps = components(mech, intervals, span, periodic)
    ctab = pd.DataFrame(dict(
        component=[c.index for c in comps], kind=[c.kind for c in comps], closed=[c.closed for c in comps],
        branches=[",".join(f"{p[0]:+d}" for p in c.path) for c in comps],
        rolling_angle_start_rad=[c.interval.start for c in comps],
        rolling_angle_end_rad=[c.interval.end for c in comps],
        start_kind=[c.interval.start_kind for c in comps], end_kind=[c.interval.end_kind for c in comps]))
    troc_x = trochoid_crunodes_table(mech, samples_per_turn)
    return Atlas(
        mechanism=mech, span=span, periodic=periodic, components=comps, component_table=ctab,
        closure=closure_table(intervals), nonclosure=nonclosure_table(intervals, span),
        curve=coupler_curve_table(mech, samples_per_turn, comps), trochoid=trochoid_table(mech, samples_per_turn),
        cusps=cusps_table(mech, comps),
        crunodes=crunodes_table(mech, samples_per_turn, comps, between_components, troc_x),
        trochoid_crunodes=troc_x)
