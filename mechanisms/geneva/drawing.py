"""The Geneva drive as it looks (lengths in mm): the wheel with its slots and locking arcs, the crank with its
locking disc and pin, the normal force on the wheel as an arrow (`mechanisms/drawing.py` says what a drawing is)."""
from __future__ import annotations

import math

import numpy as np
from matplotlib.colors import Normalize
from matplotlib.patches import Circle, Polygon

from mechsim.mechanisms.drawing import CRANK, MM, STEEL, STEEL_EDGE, arc, arrow_length, colour, finish_axes, rotate


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
        pts.extend(arc(bottom, R, phi - np.pi / 2, phi - 3 * np.pi / 2, samples | 1)[1:-1])   # round bottom
        pts.append(bottom + R * nrm)
        pts.append(s_out * u + R * nrm)                        # leading edge, outer end
        mid = phi + pitch / 2
        if gamma is None:                                      # the locking disc stays clear of the rim
            pts.extend(arc((0, 0), Rw, phi + half_tip, phi + pitch - half_tip, 12))
            continue
        tip0, tip1 = phi + half_tip, mid - gamma
        if tip1 > tip0:
            pts.extend(arc((0, 0), Rw, tip0, tip1, 6))
        L = c * np.array([math.cos(mid), math.sin(mid)])
        p0 = Rw * np.array([math.cos(mid - gamma), math.sin(mid - gamma)]) - L
        inward = mid + np.pi                                   # from L towards the wheel centre
        half = (math.atan2(p0[1], p0[0]) - inward + np.pi) % (2 * np.pi) - np.pi
        pts.extend(arc(L, Rl, inward + half, inward - half, samples))   # concave locking arc, through `inward`
        if tip1 > tip0:
            pts.extend(arc((0, 0), Rw, mid + gamma, phi + pitch - half_tip, 6))
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

    force_column = "contact_force_N"
    force_label = "normal contact force"

    def __init__(self, ax, mech, force_peak: float | None = None, temperature: Normalize | None = None,
                 arrow_length_mm: float | None = None, trace=None):
        g = self.geometry = mech.geometry
        self.c, self.r, self.R = g.centre_distance * MM, g.crank_radius * MM, g.pin_radius * MM
        self.wheel_shape = geneva_wheel_outline(g) * MM
        self.disc_shape = locking_disc_outline(g) * MM
        self.wheel = ax.add_patch(Polygon(self.wheel_shape, closed=True, fc=STEEL, ec=STEEL_EDGE, lw=1.0))
        self.disc = ax.add_patch(Polygon(self.disc_shape + [self.c, 0], closed=True, fc="#e8d9c8", ec="#6b5a48",
                                         lw=1.0))
        self._crank_pin_and_force(ax, force_peak, temperature, arrow_length_mm)
        Rw, Rl = g.entry_pin_distance * MM, locking_radius(g) * MM
        ax.set_xlim(-1.08 * Rw, self.c + 1.1 * max(Rl, self.r + self.R))
        ax.set_ylim(-1.1 * max(Rw, self.r + self.R), 1.1 * max(Rw, self.r + self.R))
        finish_axes(ax)

    def _crank_pin_and_force(self, ax, force_peak, temperature, arrow_length_mm, **arm_style) -> None:
        """The crank arm, the pin, the two centres' marks and the normal force's arrow (its length scaled so the
        peak force draws `arrow_length_mm`, by default 0.45 r), shared by every Geneva drawing."""
        self.arm, = ax.plot([], [], color=CRANK, lw=3.0, solid_capstyle="round", **arm_style)
        self.pin = ax.add_patch(Circle((0, 0), self.R, fc=CRANK, ec="k", lw=0.6, zorder=4))
        ax.plot([0, self.c], [0, 0], "k+", ms=9, mew=1.2)
        self.arrow_nominal = arrow_length_mm or 0.45 * self.r
        self.force_scale = self.arrow_nominal / force_peak if force_peak else 0.0
        self.arrow = ax.quiver([0], [0], [0], [0], angles="xy", scale_units="xy", scale=1, color="tab:blue",
                               width=0.012, zorder=5)
        self.temperature = temperature

    def move(self, theta: float, psi: float) -> tuple[float, float]:
        """Turn the wheel to psi and the crank to theta; the pin's centre (mm)."""
        self.wheel.set_xy(rotate(self.wheel_shape, psi))
        self.disc.set_xy(rotate(self.disc_shape, np.pi - theta) + [self.c, 0])
        return self.c - self.r * math.cos(theta), self.r * math.sin(theta)

    def artists(self) -> list:
        return [self.wheel, self.disc, self.arm, self.pin, self.arrow]

    def update(self, row) -> list:
        """The drawing at one table row: wheel, crank and pin, the normal force's arrow, the pin's temperature."""
        px, py = self.move(float(row["crank_angle_rad"]), float(row["wheel_angle_rad"]))
        self.arm.set_data([self.c, px], [0, py])
        self.pin.set_center((px, py))
        force = float(row.get("contact_force_N", 0.0) or 0.0)
        slot = math.atan2(py, px)   # the pin lies on the engaged slot's centre line; N > 0 turns the wheel forward
        self.arrow.set_offsets([[px, py]])
        f = arrow_length(force, self.force_scale, self.arrow_nominal)
        self.arrow.set_UVC([-math.sin(slot) * f], [math.cos(slot) * f])
        if self.temperature is not None and "temp_contact_C" in row:   # no contact (dwell): the pin's own colour
            temp = float(row["temp_contact_C"])
            self.pin.set_facecolor(colour(self.temperature, temp) if math.isfinite(temp) else CRANK)
        return self.artists()
