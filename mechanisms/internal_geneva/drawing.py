"""The internal Geneva drive as it looks (lengths in mm): the wheel, a ring whose slots open inward, with the
pockets of its locking segment; the crank and pin inside it; the normal force on the wheel as an arrow at the pin
(`mechanisms/drawing.py` says what a drawing is). The crank centre lies at c, beyond the ring's inner rim, so the
crank's hub and arm run in a plane beside the ring and only the pin reaches into it; the locking segment is not
drawn (the lock is ideal in the model, docs/internal_geneva.md)."""
from __future__ import annotations

import math

import numpy as np
from matplotlib.colors import Normalize
from matplotlib.patches import PathPatch
from matplotlib.path import Path

from mechsim.mechanisms.drawing import MM, STEEL, STEEL_EDGE, arc, finish_axes, rotate
from mechsim.mechanisms.geneva.drawing import GenevaDrawing


def pocket_radius(geometry) -> float:
    """The pockets' radius: r - 2R, a pin diameter inside the pin circle, so a pocket (about the crank centre's
    place at mid-dwell) keeps R of material to the slot flanks (r - R from that place); where a large pin leaves
    r - 2R short of the inner rim (c (1 - cos(pi/n)) away), midway between that reach and r - R."""
    g = geometry
    reach, clear = g.centre_distance - g.entry_pin_distance, g.crank_radius - g.pin_radius
    radius = g.crank_radius - 2 * g.pin_radius
    return radius if radius > reach else 0.5 * (reach + clear)


def outer_radius(geometry) -> float:
    """The ring's outer radius: the slot bottoms (c + r + R) plus one pin radius of material."""
    return geometry.deepest_pin_distance + 2 * geometry.pin_radius


def wheel_inner_outline(geometry, samples: int = 24) -> np.ndarray:
    """The ring's inner boundary (m) at wheel angle 0, slot j along angle j 2 pi/n, counter-clockwise: slot mouths
    on the inner rim c cos(pi/n), where the pin enters; slots 2R wide out to a round bottom at c + r, the pin's
    deepest point; between them a pocket of `pocket_radius` about the point at distance c mid-way between the
    slots, where the crank centre sits while the wheel rests."""
    g = geometry
    n, c, R = g.slots, g.centre_distance, g.pin_radius
    Ri, Rl, pitch, deep = g.entry_pin_distance, pocket_radius(g), g.pitch, g.deepest_pin_distance
    half_tip = math.asin(R / Ri)                           # a slot edge's inner end off the slot line
    gamma = math.acos(min(1.0, (Ri**2 + c**2 - Rl**2) / (2 * Ri * c)))   # pocket meets the rim at mid +- gamma
    s_in = math.sqrt(Ri**2 - R**2)
    pts = []
    for j in range(n):
        phi = j * pitch
        u, nrm = np.array([math.cos(phi), math.sin(phi)]), np.array([-math.sin(phi), math.cos(phi)])
        bottom = deep * u
        pts.append(s_in * u - R * nrm)                     # trailing edge, inner end ...
        pts.append(bottom - R * nrm)                       # ... out to the bottom
        pts.extend(arc(bottom, R, phi - np.pi / 2, phi + np.pi / 2, samples | 1)[1:-1])    # round bottom
        pts.append(bottom + R * nrm)
        pts.append(s_in * u + R * nrm)                     # leading edge, inner end
        mid = phi + pitch / 2
        if mid - gamma > phi + half_tip:
            pts.extend(arc((0, 0), Ri, phi + half_tip, mid - gamma, 6))
        L = c * np.array([math.cos(mid), math.sin(mid)])
        p0 = Ri * np.array([math.cos(mid - gamma), math.sin(mid - gamma)]) - L
        half = (math.atan2(p0[1], p0[0]) - mid + np.pi) % (2 * np.pi) - np.pi
        pts.extend(arc(L, Rl, mid + half, mid - half, samples))    # the pocket, through its far point c + Rl
        if mid - gamma > phi + half_tip:
            pts.extend(arc((0, 0), Ri, mid + gamma, phi + pitch - half_tip, 6))
    return np.array(pts)


def _ring_path(outer: np.ndarray, inner: np.ndarray) -> Path:
    verts = np.vstack([outer, inner[::-1]])
    codes = np.full(len(verts), Path.LINETO, dtype=Path.code_type)
    codes[0] = codes[len(outer)] = Path.MOVETO
    return Path(verts, codes)


class InternalGenevaDrawing(GenevaDrawing):
    """Ring wheel (slots 2R wide opening inward, pockets), crank arm and pin, the normal force on the wheel as an
    arrow at the pin; frame of docs/internal_geneva.md (wheel centre at the origin, crank centre at (c, 0))."""

    force_column = "contact_force_N"
    force_label = "normal contact force"

    def __init__(self, ax, mech, force_peak: float | None = None, temperature: Normalize | None = None,
                 arrow_length_mm: float | None = None, trace=None):
        g = self.geometry = mech.geometry
        self.c, self.r, self.R = g.centre_distance * MM, g.crank_radius * MM, g.pin_radius * MM
        Ro = outer_radius(g) * MM
        a = np.linspace(0.0, 2 * np.pi, 181)
        self.outer = np.column_stack([Ro * np.cos(a), Ro * np.sin(a)])
        self.inner = wheel_inner_outline(g) * MM
        self.wheel = ax.add_patch(PathPatch(_ring_path(self.outer, self.inner), fc=STEEL, ec=STEEL_EDGE, lw=1.0))
        self._crank_pin_and_force(ax, force_peak, temperature, arrow_length_mm, alpha=0.6, zorder=3)
        ax.set_xlim(-1.08 * Ro, 1.08 * Ro)
        ax.set_ylim(-1.08 * Ro, 1.08 * Ro)
        finish_axes(ax)

    def move(self, theta: float, psi: float) -> tuple[float, float]:
        """Turn the ring to psi and the crank to theta; the pin's centre (mm), on the far side of the crank centre."""
        self.wheel.set_path(_ring_path(self.outer, rotate(self.inner, psi)))
        return self.c + self.r * math.cos(theta), self.r * math.sin(theta)

    def artists(self) -> list:
        return [self.wheel, self.arm, self.pin, self.arrow]
