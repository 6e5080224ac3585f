"""Drawings of the mechanisms that look like the machine (lengths in mm), as reusable matplotlib artists.

Each drawing is built once on an axes (the parts that never move drawn there for good) and `update(row)` moves
the parts to one output row and returns the artists it changed, so an animation redraws only those. The
contact force is an arrow, `arrow_length_mm` long at the run's typical peak (99th percentile of |force| while in
contact, so that a few impact spikes do not shrink it to nothing; longer arrows are cut at ARROW_CLIP times
that length); with a thermal model the
contact colours with the contact temperature. Geometry comes from the mechanisms' public attributes; no
plotting lives in mechanisms/ (docs/architecture.md, the layer contract).
"""
from __future__ import annotations

import math

import numpy as np
import pandas as pd
from matplotlib.colors import Normalize
from matplotlib.patches import Circle, Polygon

MM = 1e3
TEMPERATURE_MAP = "inferno"
STEEL, STEEL_EDGE, CRANK = "#c9d3dc", "#3b4b5a", "tab:red"
ARROW_CLIP = 1.6


def arrow_length(force: float, scale: float, nominal: float) -> float:
    """Signed arrow length (mm) of a force: force x scale, cut at +-ARROW_CLIP x nominal."""
    return float(np.clip(force * scale, -ARROW_CLIP * nominal, ARROW_CLIP * nominal))


def _rotate(points: np.ndarray, angle: float) -> np.ndarray:
    c, s = math.cos(angle), math.sin(angle)
    return points @ np.array([[c, s], [-s, c]])


def _arc(centre, radius, a0, a1, n=24) -> np.ndarray:
    a = np.linspace(a0, a1, n)
    return np.column_stack([centre[0] + radius * np.cos(a), centre[1] + radius * np.sin(a)])


# -- Geneva ------------------------------------------------------------------------------------------------
def locking_radius(geometry) -> float:
    """Radius of the locking disc on the crank as drawn: r - 2R, one pin diameter inside the pin circle, so its
    arc clears the slots (a slot flank is r - R from the locking-arc centre). Where a large pin leaves r - 2R too
    small to reach the wheel's rim (c - c cos(pi/n) from the arc centre), midway between that reach and r - R; where
    no radius both reaches the rim and clears the flanks (many slots, a large pin), 0.9 (r - R), a disc that
    stays clear of the wheel. Not part of the model: the lock is ideal (docs/theory.md §G2)."""
    g = geometry
    reach, clear = g.centre_distance - g.entry_pin_distance, g.crank_radius - g.pin_radius
    radius = g.crank_radius - 2 * g.pin_radius
    if radius > reach:
        return radius
    return 0.5 * (reach + clear) if reach < clear else 0.9 * clear


def geneva_wheel_outline(geometry, samples: int = 24) -> np.ndarray:
    """Outline of the wheel (m) at wheel angle 0, slot j along angle j 2 pi/n, counter-clockwise.

    Outer radius c cos(pi/n) (where the pin enters, docs/theory.md §G1); each slot has width 2R (pin radius R)
    and a round bottom at c - r, the pin's deepest point; between slots a concave locking arc of the locking
    disc's radius, centred where the crank centre sits during the dwell (distance c, mid-way between slots), or
    the plain rim where that disc does not reach it.
    """
    g = geometry
    n, c, r, R = g.slots, g.centre_distance, g.crank_radius, g.pin_radius
    Rw, Rl, pitch = g.entry_pin_distance, locking_radius(g), g.pitch
    half_tip = math.asin(R / Rw)                  # angle of a slot edge's outer end off the slot line
    cos_gamma = (Rw**2 + c**2 - Rl**2) / (2 * Rw * c)
    gamma = math.acos(cos_gamma) if cos_gamma < 1 else None   # locking arc meets the rim at mid +- gamma (if at all)
    s_out = math.sqrt(Rw**2 - R**2)
    pts = []
    for j in range(n):
        phi = j * pitch
        u, nrm = np.array([math.cos(phi), math.sin(phi)]), np.array([-math.sin(phi), math.cos(phi)])
        bottom = (c - r) * u
        pts.append(s_out * u - R * nrm)                        # trailing edge, outer end ...
        pts.append(bottom - R * nrm)                           # ... down to the bottom
        pts.extend(_arc(bottom, R, phi - np.pi / 2, phi - 3 * np.pi / 2, samples | 1)[1:-1])   # round bottom
        pts.append(bottom + R * nrm)
        pts.append(s_out * u + R * nrm)                        # leading edge, outer end
        mid = phi + pitch / 2
        if gamma is None:                                      # the locking disc stays clear of the rim
            pts.extend(_arc((0, 0), Rw, phi + half_tip, phi + pitch - half_tip, 12))
            continue
        tip0, tip1 = phi + half_tip, mid - gamma
        if tip1 > tip0:
            pts.extend(_arc((0, 0), Rw, tip0, tip1, 6))
        L = c * np.array([math.cos(mid), math.sin(mid)])
        p0 = Rw * np.array([math.cos(mid - gamma), math.sin(mid - gamma)]) - L
        inward = mid + np.pi                                   # from L towards the wheel centre
        half = (math.atan2(p0[1], p0[0]) - inward + np.pi) % (2 * np.pi) - np.pi
        pts.extend(_arc(L, Rl, inward + half, inward - half, samples))   # concave locking arc, through `inward`
        if tip1 > tip0:
            pts.extend(_arc((0, 0), Rw, mid + gamma, phi + pitch - half_tip, 6))
    return np.array(pts)


def locking_disc_outline(geometry, samples: int = 120) -> np.ndarray:
    """Outline of the crank's locking disc (m), centre at the origin, its clearance cut facing +x: the disc of
    `locking_radius` less the wheel's rim circle placed where the wheel centre sits at mid-engagement, so the
    wheel can turn while the pin drives it."""
    g = geometry
    c, Rw, Rl = g.centre_distance, g.entry_pin_distance, locking_radius(g)
    a = np.linspace(-np.pi, np.pi, samples)
    rho = np.full_like(a, Rl)
    disc = Rw**2 - (c * np.sin(a)) ** 2
    cut = np.where((np.cos(a) > 0) & (disc > 0), c * np.cos(a) - np.sqrt(np.clip(disc, 0, None)), np.inf)
    rho = np.minimum(rho, cut)
    return np.column_stack([rho * np.cos(a), rho * np.sin(a)])


class GenevaDrawing:
    """Wheel (slots 2R wide, locking arcs), crank with its locking disc and pin, the normal force on the wheel
    as an arrow at the pin; frame of docs/theory.md §G1 (wheel centre at the origin, crank centre at (c, 0))."""

    def __init__(self, ax, mech, force_peak: float | None = None, temperature: Normalize | None = None,
                 arrow_length_mm: float | None = None):
        g = self.geometry = mech.geometry
        self.c, self.r, self.R = g.centre_distance * MM, g.crank_radius * MM, g.pin_radius * MM
        self.wheel_shape = geneva_wheel_outline(g) * MM
        self.disc_shape = locking_disc_outline(g) * MM
        self.wheel = ax.add_patch(Polygon(self.wheel_shape, closed=True, fc=STEEL, ec=STEEL_EDGE, lw=1.0))
        self.disc = ax.add_patch(Polygon(self.disc_shape + [self.c, 0], closed=True, fc="#e8d9c8", ec="#6b5a48",
                                         lw=1.0))
        self.arm, = ax.plot([], [], color=CRANK, lw=3.0, solid_capstyle="round")
        self.pin = ax.add_patch(Circle((0, 0), self.R, fc=CRANK, ec="k", lw=0.6, zorder=4))
        ax.plot([0, self.c], [0, 0], "k+", ms=9, mew=1.2)
        self.arrow_nominal = arrow_length_mm or 0.45 * self.r
        self.force_scale = self.arrow_nominal / force_peak if force_peak else 0.0
        self.arrow = ax.quiver([0], [0], [0], [0], angles="xy", scale_units="xy", scale=1, color="tab:blue",
                               width=0.012, zorder=5)
        self.temperature = temperature
        Rw, Rl = g.entry_pin_distance * MM, locking_radius(g) * MM
        ax.set_xlim(-1.08 * Rw, self.c + 1.1 * max(Rl, self.r + self.R))
        ax.set_ylim(-1.1 * max(Rw, self.r + self.R), 1.1 * max(Rw, self.r + self.R))
        _finish_axes(ax)

    def update(self, row) -> list:
        theta, psi = float(row["crank_angle_rad"]), float(row["wheel_angle_rad"])
        self.wheel.set_xy(_rotate(self.wheel_shape, psi))
        self.disc.set_xy(_rotate(self.disc_shape, np.pi - theta) + [self.c, 0])
        px, py = self.c - self.r * math.cos(theta), self.r * math.sin(theta)
        self.arm.set_data([self.c, px], [0, py])
        self.pin.set_center((px, py))
        force = float(row.get("contact_force_N", 0.0) or 0.0)
        slot = math.atan2(py, px)   # the pin lies on the engaged slot's centre line; N > 0 turns the wheel forward
        self.arrow.set_offsets([[px, py]])
        f = arrow_length(force, self.force_scale, self.arrow_nominal)
        self.arrow.set_UVC([-math.sin(slot) * f], [math.cos(slot) * f])
        if self.temperature is not None and "temp_contact_C" in row:   # no contact (dwell): the pin's own colour
            temp = float(row["temp_contact_C"])
            self.pin.set_facecolor(_colour(self.temperature, temp) if math.isfinite(temp) else CRANK)
        return [self.wheel, self.disc, self.arm, self.pin, self.arrow]


# -- chain dwell mechanism -----------------------------------------------------------------------------------
class ChainDrawing:
    """Sprockets (numbered), the chain loop, crank pivot Q, crank Q-A and coupler A-B with B on the chain; the
    coupler force as an arrow along the coupler at B."""

    def __init__(self, ax, mech, force_peak: float | None = None, temperature=None, arrow_length_mm=None):
        self.mech = mech
        kin = mech.kin
        path = kin.path
        for i, (O, rad) in enumerate(zip(path.centres, path.radii)):
            ax.add_patch(Circle(np.asarray(O) * MM, rad * MM, fc=STEEL, ec=STEEL_EDGE, lw=0.8))
            ax.annotate(f"{i + 1}", np.asarray(O) * MM, ha="center", va="center", fontsize=8, color="0.25")
        loop = path.sample(721) * MM
        ax.plot(loop[:, 0], loop[:, 1], color="k", lw=2.2, solid_capstyle="round")
        self.Q = kin.Q * MM
        ax.plot(*self.Q, "ks", ms=6)
        ax.annotate("Q", self.Q, xytext=(4, 4), textcoords="offset points", fontsize=8)
        if mech.apex == "stop":
            for i in mech.tuned:
                a = mech.stop_angle(i)
                tip = self.Q + 1.12 * kin.R * MM * np.array([math.cos(a), math.sin(a)])
                ax.plot(*tip, marker=(3, 0, math.degrees(a) - 90), color="0.2", ms=7)
        self.crank, = ax.plot([], [], color=CRANK, lw=3.0, solid_capstyle="round")
        self.coupler, = ax.plot([], [], "-o", color="tab:green", lw=2.2, ms=4)
        self.arrow_nominal = arrow_length_mm or 0.6 * kin.L * MM
        self.force_scale = self.arrow_nominal / force_peak if force_peak else 0.0
        self.arrow = ax.quiver([0], [0], [0], [0], angles="xy", scale_units="xy", scale=1, color="tab:blue",
                               width=0.012, zorder=5)
        span = np.vstack([loop, self.Q + 1.2 * kin.R * MM * np.array([[1, 1], [-1, -1]])])
        lo, hi = span.min(axis=0), span.max(axis=0)
        pad = 0.08 * (hi - lo).max()
        ax.set_xlim(lo[0] - pad, hi[0] + pad)
        ax.set_ylim(lo[1] - pad, hi[1] + pad)
        _finish_axes(ax)

    def update(self, row) -> list:
        A = np.array([row["crank_tip_x_m"], row["crank_tip_y_m"]], float) * MM
        B = np.array([row["joint_B_x_m"], row["joint_B_y_m"]], float) * MM
        self.crank.set_data([self.Q[0], A[0]], [self.Q[1], A[1]])
        self.coupler.set_data([A[0], B[0]], [A[1], B[1]])
        d = (B - A) / max(float(np.hypot(*(B - A))), 1e-12)
        f = arrow_length(float(row.get("coupler_force_N", 0.0) or 0.0), self.force_scale, self.arrow_nominal)
        self.arrow.set_offsets([B])
        self.arrow.set_UVC([d[0] * f], [d[1] * f])
        return [self.crank, self.coupler, self.arrow]


# -- rolling pair 4-bar -----------------------------------------------------------------------------------------
class RollingDrawing:
    """Fixed profile, the rolling disc with its arm B0-B, crank A0-A, coupler triangle A-B-C, the coupler point's
    trace over the run, and the normal contact force as an arrow at the contact point."""

    def __init__(self, ax, mech, force_peak: float | None = None, temperature=None, arrow_length_mm=None,
                 trace: pd.DataFrame | None = None):
        self.mech = mech
        k = mech.kin
        p = k.pair
        self.a0 = np.array([k.a0.real, k.a0.imag]) * MM
        if p.kind == "circle":
            ax.add_patch(Circle(np.asarray(p.O) * MM, p.R * MM, fc=STEEL, ec=STEEL_EDGE, lw=1.0, hatch="//"))
            reach = abs(complex(*p.O) - k.a0) + p.R + 2 * p.r + k.l4
        else:
            tdir = np.exp(1j * p.tangent)
            P0 = complex(*p.P0)
            reach = abs(((k.a0 - P0) * np.conj(tdir)).imag) + 2 * p.r + k.l4
            foot = P0 + ((k.a0 - P0) * np.conj(tdir)).real * tdir
            ends = (foot + np.array([-1, 1]) * 10 * (reach + k.l2 + k.l3) * tdir) * MM
            ax.plot(ends.real, ends.imag, color=STEEL_EDGE, lw=1.5)
        reach = max(reach, k.l2 + k.l3 + k.lc) * MM
        if trace is not None and "coupler_point_x_m" in trace:
            ax.plot(trace["coupler_point_x_m"] * MM, trace["coupler_point_y_m"] * MM, color="tab:purple", lw=0.9,
                    alpha=0.6, label="coupler-point trace")
        self.disc = ax.add_patch(Circle((0, 0), p.r * MM, fc="#d7ecd9", ec="tab:green", lw=1.5))
        self.arm, = ax.plot([], [], color="tab:green", lw=2.5)
        self.crank, = ax.plot([], [], color=CRANK, lw=3.0, solid_capstyle="round")
        self.coupler = ax.add_patch(Polygon(np.zeros((3, 2)), closed=True, fc="#cfe0f3", ec="tab:blue", lw=1.5))
        self.point, = ax.plot([], [], "o", color="tab:purple", ms=5, zorder=5)
        self.contact, = ax.plot([], [], "ko", ms=3, zorder=5)
        ax.plot(*self.a0, "k^", ms=8)
        self.arrow_nominal = arrow_length_mm or 0.25 * reach
        self.force_scale = self.arrow_nominal / force_peak if force_peak else 0.0
        self.arrow = ax.quiver([0], [0], [0], [0], angles="xy", scale_units="xy", scale=1, color="tab:blue",
                               width=0.012, zorder=6)
        box = [self.a0 - k.l2 * MM, self.a0 + k.l2 * MM]
        if p.kind == "circle":
            box += [(np.asarray(p.O) - p.R) * MM, (np.asarray(p.O) + p.R) * MM]
        if trace is not None and "contact_x_m" in trace:
            for pre in ("coupler_point", "contact"):
                xy = trace[[f"{pre}_x_m", f"{pre}_y_m"]].to_numpy(float) * MM
                box += [np.nanmin(xy, axis=0) - 2.2 * p.r * MM * (pre == "contact"),
                        np.nanmax(xy, axis=0) + 2.2 * p.r * MM * (pre == "contact")]
        else:
            box += [self.a0 - reach, self.a0 + reach]
        lo, hi = np.min(box, axis=0), np.max(box, axis=0)
        centre, half = (lo + hi) / 2, 0.55 * float((hi - lo).max())
        ax.set_xlim(centre[0] - half, centre[0] + half)
        ax.set_ylim(centre[1] - half, centre[1] + half)
        _finish_axes(ax)

    def update(self, row) -> list:
        q = [float(row["crank_angle_rad"]), float(row["coupler_angle_rad"]), float(row["rolling_angle_rad"])]
        pts = {name: xy * MM for name, xy in self.mech.points(q).items()}
        A, B, B0, P, C = (pts[n] for n in ("A", "B", "B0", "P", "C"))
        self.disc.set_center(B0)
        self.arm.set_data([B0[0], B[0]], [B0[1], B[1]])
        self.crank.set_data([self.a0[0], A[0]], [self.a0[1], A[1]])
        self.coupler.set_xy(np.array([A, B, C]))
        self.point.set_data([C[0]], [C[1]])
        self.contact.set_data([P[0]], [P[1]])
        n = (B0 - P) / max(float(np.hypot(*(B0 - P))), 1e-12)       # profile -> disc: the force on the disc
        f = arrow_length(float(row.get("contact_force_N", 0.0) or 0.0), self.force_scale, self.arrow_nominal)
        self.arrow.set_offsets([P])
        self.arrow.set_UVC([n[0] * f], [n[1] * f])
        return [self.disc, self.arm, self.crank, self.coupler, self.point, self.contact, self.arrow]


def _colour(norm: Normalize, value) -> tuple:
    from matplotlib import colormaps
    return colormaps[TEMPERATURE_MAP](norm(float(value)))


def _finish_axes(ax) -> None:
    ax.set_aspect("equal")
    ax.set_xlabel("x (mm)")
    ax.set_ylabel("y (mm)")
    ax.grid(True, lw=0.3, alpha=0.5)


#: mechanism class name -> its drawing
DRAWINGS = {"Geneva": GenevaDrawing, "ChainDwell": ChainDrawing, "RollingPairFourBar": RollingDrawing}

#: the column whose arrow each drawing shows
FORCE_COLUMNS = {"Geneva": "contact_force_N", "ChainDwell": "coupler_force_N",
                 "RollingPairFourBar": "contact_force_N"}


def drawing_for(ax, mech, df: pd.DataFrame, with_temperature: bool = True):
    """The drawing of `mech` on `ax`, its arrow scaled to the typical peak force of `df`, coloured by the contact
    temperature range of `df` where it has one; None if the mechanism has no drawing."""
    kind = type(mech).__name__
    if kind not in DRAWINGS:
        return None
    col = FORCE_COLUMNS[kind]
    force = np.abs(df[col].to_numpy(float)) if col in df else np.zeros(0)
    force = force[np.isfinite(force) & (force > 0)]
    peak = float(np.percentile(force, 99)) if force.size else 0.0
    norm = None
    if with_temperature and "temp_contact_C" in df and df["temp_contact_C"].notna().any():
        lo, hi = float(np.nanmin(df["temp_contact_C"])), float(np.nanmax(df["temp_contact_C"]))
        norm = Normalize(lo, hi if hi > lo else lo + 1.0)
    extra = {"trace": df} if kind == "RollingPairFourBar" else {}
    return DRAWINGS[kind](ax, mech, force_peak=peak or None, temperature=norm, **extra)
