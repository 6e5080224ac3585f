"""Plot of a rolling-pair coupler-curve atlas (matplotlib, Agg; no pyplot state): the coupler curve
coloured by branch (Kar & Sen's colouring of dichromatic components), the trochoid of B, the fixed
profile, the dyad annulus about A0, cusps and crunodes.
"""
from __future__ import annotations

import numpy as np
from matplotlib.backends.backend_agg import FigureCanvasAgg
from matplotlib.figure import Figure
from matplotlib.patches import Circle

from mechsim.mechanisms.rolling.atlas import Atlas, coupler_atlas
from mechsim.mechanisms.rolling.pair import RollingFourBar

BRANCH_COLOURS = {1: "tab:blue", -1: "tab:red"}


def plot_coupler_atlas(atlas: Atlas | RollingFourBar, ax=None, show_trochoid: bool = True,
                       show_annulus: bool = True, show_profile: bool = True, title: str | None = None):
    """Draw the atlas (or compute it for a mechanism) and return the Figure.

    Branch +1 blue, branch -1 red; cusps as black triangles, coupler crunodes as open circles,
    trochoid crunodes as grey crosses. Axis labels in m.
    """
    if isinstance(atlas, RollingFourBar):
        atlas = coupler_atlas(atlas)
    mech = atlas.mechanism
    if ax is None:
        fig = Figure(figsize=(9.5, 7), layout="constrained")
        FigureCanvasAgg(fig)
        ax = fig.add_subplot(111)
    else:
        fig = ax.figure
    cur = atlas.curve
    for _, comp in cur.groupby("component", sort=True):
        br = comp["branch"].to_numpy()
        x, y = comp["C_x_m"].to_numpy(), comp["C_y_m"].to_numpy()
        cuts = np.nonzero(br[1:] != br[:-1])[0] + 1
        starts = np.r_[0, cuts]
        ends = np.r_[cuts, len(br)]
        for s, e in zip(starts, ends):
            e2 = min(e + 1, len(br))  # include the merge vertex so the colours join
            ax.plot(x[s:e2], y[s:e2], color=BRANCH_COLOURS[int(br[s])], lw=1.2)
    for b, c in BRANCH_COLOURS.items():
        ax.plot([], [], color=c, label=f"coupler curve, branch {b:+d}")
    if show_trochoid:
        ax.plot(atlas.trochoid["B_x_m"], atlas.trochoid["B_y_m"], color="0.6", lw=0.7, label="trochoid of B")
        tc = atlas.trochoid_crunodes
        if len(tc):
            ax.plot(tc["x_m"], tc["y_m"], "x", color="0.4", label="trochoid crunodes")
    if show_profile:
        p = mech.pair
        if p.kind == "circle":
            ax.add_patch(Circle(p.O, p.R, fill=False, color="k", lw=1.0, hatch="//", alpha=0.4))
        else:
            s = np.array([atlas.span[0], atlas.span[1]]) * p.du_dphi
            t = np.exp(1j * p.tangent)
            q = complex(*p.P0) + np.array([s.min() - 2 * p.r, s.max() + 2 * p.r]) * t
            ax.plot(q.real, q.imag, "k-", lw=1.0)
    if show_annulus:
        for rad in (mech.d_folded, mech.d_stretched):
            ax.add_patch(Circle(mech.A0, rad, fill=False, ls="--", color="0.5", lw=0.7))
        ax.plot(*mech.A0, "ks", ms=4, label="A0")
    if len(atlas.cusps):
        ax.plot(atlas.cusps["C_x_m"], atlas.cusps["C_y_m"], "k^", ms=7, label="cusps")
    if len(atlas.crunodes):
        ax.plot(atlas.crunodes["x_m"], atlas.crunodes["y_m"], "o", mfc="none", mec="k", ms=8, label="crunodes")
    ax.set_aspect("equal")
    ax.set_xlabel("x (m)")
    ax.set_ylabel("y (m)")
    ax.set_title(title if title is not None else (mech.name and f"rolling-pair 4-bar, set {mech.name}"))
    ax.legend(loc="upper left", bbox_to_anchor=(1.01, 1.0), fontsize=8, frameon=False)   # off the curves
    return fig
