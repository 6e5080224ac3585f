"""Plots of the roller-chain dwell kinematics, like El-Shakery (1991) Figs. 3-8, and a drawing of the mechanism.

Inputs are the DataFrames of `chain_dwell.kinematics_table` / `dwell_table` (SI columns); labels convert to
degrees and cm at this edge. Figures are built on the Agg canvas directly (no pyplot global state) and
written to `path`; each function returns the path.
"""
from __future__ import annotations

from pathlib import Path
from typing import Mapping

import numpy as np
import pandas as pd
from matplotlib.backends.backend_agg import FigureCanvasAgg
from matplotlib.figure import Figure
from matplotlib.patches import Circle

DEG = 180.0 / np.pi

_QUANTITIES = {
    "displacement": [("crank_angle_rad", "crank $\\varphi$", DEG, "angle (deg)"),
                     ("coupler_angle_rad", "coupler $\\theta_l$", DEG, "angle (deg)")],
    "velocity": [("crank_speed_rad_s", "crank $\\omega$", 1.0, "angular speed (rad/s)"),
                 ("coupler_speed_rad_s", "coupler $\\omega_l$", 1.0, "angular speed (rad/s)")],
    "acceleration": [("crank_accel_rad_s2", "crank $f$", 1.0, "angular acceleration (rad/s$^2$)"),
                     ("coupler_accel_rad_s2", "coupler $f_l$", 1.0, "angular acceleration (rad/s$^2$)")],
}


def _tables(tables) -> Mapping[str, pd.DataFrame]:
    if isinstance(tables, pd.DataFrame):
        return {"": tables}
    return dict(tables)


def _save(fig: Figure, path) -> Path:
    path = Path(path)
    path.parent.mkdir(parents=True, exist_ok=True)
    FigureCanvasAgg(fig)
    fig.savefig(path, dpi=120)
    return path


def _shade(ax, dwells):
    if dwells is None:
        return
    for _, d in dwells.iterrows():
        ax.axvspan(d.start_drive_angle_rad * DEG, d.end_drive_angle_rad * DEG, color="0.9", zorder=0)


def _panel(ax, tables, which, dwells, crank_only=False):
    qs = _QUANTITIES[which][:1] if crank_only else _QUANTITIES[which]
    ys = []
    for name, df in _tables(tables).items():
        for col, label, scale, ylabel in qs:
            lab = f"{label} {name}".strip()
            y = np.where(np.isfinite(df[col]), df[col] * scale, np.nan)   # rates diverge at a fold
            ax.plot(df["drive_angle_rad"] * DEG, y, lw=1.2, label=lab)
            ys.append(y[np.isfinite(y)])
        ax.set_ylabel(ylabel)
    y = np.concatenate(ys) if ys else np.array([])
    if y.size and which != "displacement":
        lo, hi = np.percentile(y, [1, 99])
        span = max(hi - lo, 1e-12)
        if y.max() > hi + 2 * span or y.min() < lo - 2 * span:   # spikes next to a fold: clip the view
            ax.set_ylim(lo - 0.5 * span, hi + 0.5 * span)
            ax.annotate("clipped: rates diverge at fold points", (0.01, 0.02), xycoords="axes fraction",
                        fontsize=7, color="0.4")
    _shade(ax, dwells)
    ax.set_xlabel("driving angle $\\theta_1$ (deg)")
    ax.grid(True, lw=0.3)
    ax.legend(fontsize=8, loc="upper left", bbox_to_anchor=(1.01, 1.0), frameon=False)


def quantity_figure(tables, which: str = "displacement", dwells: pd.DataFrame | None = None,
                    title: str | None = None) -> Figure:
    """One of 'displacement', 'velocity', 'acceleration' (crank and coupler) versus driving angle.

    tables: a kinematics DataFrame or {label: DataFrame} (e.g. one per branch); dwells shaded if given.
    """
    if which not in _QUANTITIES:
        raise ValueError(f"which must be one of {sorted(_QUANTITIES)}, got {which!r}")
    fig = Figure(figsize=(9, 4.5), layout="constrained")
    ax = fig.add_subplot()
    _panel(ax, tables, which, dwells)
    if title:
        ax.set_title(title)
    return fig


def plot_quantity(tables, path, which: str = "displacement", dwells: pd.DataFrame | None = None,
                  title: str | None = None) -> Path:
    """`quantity_figure` written to `path`."""
    return _save(quantity_figure(tables, which, dwells, title), path)


def plot_displacement(tables, path, dwells=None, title=None) -> Path:
    """Crank and coupler angles versus driving angle (paper Figs. 3 and 6)."""
    return plot_quantity(tables, path, "displacement", dwells, title)


def plot_velocity(tables, path, dwells=None, title=None) -> Path:
    """Crank and coupler angular speeds versus driving angle (paper Figs. 4 and 7)."""
    return plot_quantity(tables, path, "velocity", dwells, title)


def plot_acceleration(tables, path, dwells=None, title=None) -> Path:
    """Crank and coupler angular accelerations versus driving angle (paper Figs. 5 and 8)."""
    return plot_quantity(tables, path, "acceleration", dwells, title)


def kinematics_figure(tables, dwells=None, title=None) -> Figure:
    """Crank angle, speed and acceleration in three stacked panels."""
    fig = Figure(figsize=(9, 9), layout="constrained")
    axes = fig.subplots(3, 1, sharex=True)
    for ax, which in zip(axes, ("displacement", "velocity", "acceleration")):
        _panel(ax, tables, which, dwells, crank_only=True)
    if title:
        axes[0].set_title(title)
    return fig


def plot_kinematics(tables, path, dwells=None, title=None) -> Path:
    """`kinematics_figure` written to `path`."""
    return _save(kinematics_figure(tables, dwells, title), path)


def draw_layout(ax, mechanism, scale: float = 100.0) -> np.ndarray:
    """Sprockets (numbered), the chain loop and the crank pivot Q on matplotlib axes, lengths times `scale`
    (100: cm). Returns Q scaled."""
    p = mechanism.path
    for i, (O, r) in enumerate(zip(p.centres, p.radii)):
        ax.add_patch(Circle(O * scale, r * scale, fill=False, lw=0.8, color="0.5"))
        ax.annotate(f"{i + 1}", O * scale, ha="center", va="center", fontsize=9, color="0.3")
    loop = p.sample(721) * scale
    ax.plot(loop[:, 0], loop[:, 1], color="k", lw=1.5, label="chain")
    Q = mechanism.Q * scale
    ax.plot(*Q, "ks", ms=6)
    ax.annotate("Q", Q, xytext=(4, 4), textcoords="offset points")
    ax.set_aspect("equal")
    return Q


def draw_dyad(ax, Q, A, B, color="C0", label=None) -> None:
    """The dyad Q-A-B (crank and coupler) in the units of the points given."""
    ax.plot([Q[0], A[0], B[0]], [Q[1], A[1], B[1]], "-o", color=color, ms=3, lw=1.5, label=label)


def plot_mechanism(mechanism, table: pd.DataFrame, path, drive_angles=None, n_positions: int = 4,
                   title: str | None = None) -> Path:
    """Sprockets, chain loop, crank pivot and the dyad Q-A-B at a few rows of `table` (cm on the axes).

    mechanism: a `chain_dwell.ChainDwellMechanism` (for the sprockets and the chain loop); drive_angles:
    theta1 values (rad) to draw, default n_positions rows spread over the table (closing rows only).
    """
    cm = 100.0
    fig = Figure(figsize=(6.5, 6.5))
    ax = fig.add_subplot()
    Q = draw_layout(ax, mechanism, cm)
    ok = table[table["closes"]]
    if drive_angles is None:
        frac = (np.arange(n_positions) + 0.35) / n_positions
        rows = ok.iloc[(frac * (len(ok) - 1)).astype(int)] if len(ok) else ok
    else:
        idx = [int(np.argmin(np.abs(ok["drive_angle_rad"].to_numpy() - a))) for a in np.atleast_1d(drive_angles)]
        rows = ok.iloc[idx]
    colors = ["C0", "C1", "C2", "C3", "C4", "C5", "C6", "C7"]
    for k, (_, row) in enumerate(rows.iterrows()):
        A = np.array([row.crank_tip_x_m, row.crank_tip_y_m]) * cm
        B = np.array([row.joint_B_x_m, row.joint_B_y_m]) * cm
        draw_dyad(ax, Q, A, B, colors[k % len(colors)], f"$\\theta_1$ = {row.drive_angle_rad * 180 / np.pi:.0f} deg")
    ax.set_xlabel("x (cm)")
    ax.set_ylabel("y (cm)")
    ax.grid(True, lw=0.3)
    ax.legend(fontsize=8, loc="upper right")
    ax.set_title(title or getattr(mechanism.params, "name", ""))
    fig.tight_layout()
    return _save(fig, path)


# -- the mechanism's own figures (`ChainDwell.extra_figures`, collected by scenarios/output/plots.py) -----------
def extra_figures(mech, timeseries, tables: dict) -> dict[str, Figure]:
    """El-Shakery Figs. 3-8 style: crank and coupler displacement, velocity, acceleration versus the
    driving angle (dwells shaded), and the crank's three in one figure."""
    dw = tables.get("dwells")
    dw = dw[dw["kind"] == "exact"] if dw is not None and len(dw) else None
    title = f"chain dwell ({mech.apex})"
    out = {f"chain_{w}": quantity_figure(timeseries, w, dw, f"{title}: {w}")
           for w in ("displacement", "velocity", "acceleration")}
    out["chain_crank"] = kinematics_figure(timeseries, dw, title)
    return out
