"""The rolling-pair four-bar as it looks (lengths in mm): the fixed profile, the rolling disc and its arm, crank,
coupler triangle, the coupler point's trace and the normal contact force as an arrow (`mechanisms/drawing.py` says
what a drawing is)."""
from __future__ import annotations

import numpy as np
import pandas as pd
from matplotlib.patches import Circle, Polygon

from mechsim.mechanisms.drawing import ARROW_CLIP, CRANK, MM, STEEL, STEEL_EDGE, arrow_length, finish_axes


class RollingDrawing:
    """Fixed profile, the rolling disc with its arm B0-B, crank A0-A, coupler triangle A-B-C, the coupler point's
    trace over the run, and the normal contact force as an arrow at the contact point."""

    force_column = "contact_force_N"
    force_label = "normal contact force"

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
            # around the contact: the disc, and the force arrow at its full length
            margin = max(2.2 * p.r * MM, ARROW_CLIP * self.arrow_nominal)
            for pre in ("coupler_point", "contact"):
                xy = trace[[f"{pre}_x_m", f"{pre}_y_m"]].to_numpy(float) * MM
                box += [np.nanmin(xy, axis=0) - margin * (pre == "contact"),
                        np.nanmax(xy, axis=0) + margin * (pre == "contact")]
        else:
            box += [self.a0 - reach, self.a0 + reach]
        lo, hi = np.min(box, axis=0), np.max(box, axis=0)
        centre, half = (lo + hi) / 2, 0.55 * float((hi - lo).max())
        ax.set_xlim(centre[0] - half, centre[0] + half)
        ax.set_ylim(centre[1] - half, centre[1] + half)
        finish_axes(ax)

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
