"""The chain dwell mechanism as it looks (lengths in mm): sprockets, the chain loop, the dyad and its stops, the
coupler force as an arrow (`mechanisms/drawing.py` says what a drawing is)."""
from __future__ import annotations

import math

import numpy as np
from matplotlib.patches import Circle

from mechsim.mechanisms.drawing import ARROW_CLIP, CRANK, MM, STEEL, STEEL_EDGE, arrow_length, finish_axes


class ChainDrawing:
    """Sprockets (numbered), the chain loop, crank pivot Q, crank Q-A and coupler A-B with B on the chain; the
    coupler force as an arrow along the coupler at B."""

    force_column = "coupler_force_N"
    force_label = "coupler force"

    def __init__(self, ax, mech, force_peak: float | None = None, temperature=None, arrow_length_mm=None,
                 trace=None):
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
        pad = max(0.08 * (hi - lo).max(), ARROW_CLIP * self.arrow_nominal)     # (an arrow at full length)
        ax.set_xlim(lo[0] - pad, hi[0] + pad)
        ax.set_ylim(lo[1] - pad, hi[1] + pad)
        finish_axes(ax)

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
