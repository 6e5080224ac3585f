"""The clearance model's figures: the gap and the impacts over a crank turn, the wheel in its locking play
(docs/geneva.md 'Clearance and impacts'); the tables they draw are `impacts.py`'s."""
from __future__ import annotations

import numpy as np
import pandas as pd
from matplotlib.figure import Figure

from mechsim.mechanisms.geneva.impacts import local_angle_deg


def gap_figure(timeseries, impacts: pd.DataFrame, clearance: float, force: bool = False) -> Figure:
    """Gap (the lesser of the two flanks', mm) and the pin's offset from the slot's centre line against the crank
    angle within its turn, one line per turn; below it the impulse of every impact at its crank angle (force: the
    peak contact force of every contact episode of the compliant model)."""
    column, scale, label = (("peak_force_N", 1.0, "contact episode's peak force (N)") if force else
                            ("impulse_N_s", 1e3, "impact impulse |J| (mN s)"))
    fig = Figure(figsize=(9, 6.5), layout="constrained")
    ax, bx = fig.subplots(2, 1, sharex=True)
    theta = timeseries["crank_angle_rad"].to_numpy(float)
    mode = np.asarray(timeseries["mode"])
    angle = local_angle_deg(theta)
    turn = np.floor((theta + np.pi) / (2 * np.pi))
    offset = timeseries["pin_offset_m"].to_numpy(float) * 1e3
    for k in np.unique(turn):
        rows = (turn == k) & ~np.isin(mode, ("dwell", "play"))
        if np.count_nonzero(rows) > 1:
            ax.plot(angle[rows], offset[rows], lw=1.2, label=f"turn {int(k)}")
    _ends(ax, clearance / 2 * 1e3, ("driving flank", "trailing flank"))
    ax.set_ylabel("pin centre offset from the slot's\ncentre line (mm)")
    ax.set_title(f"Geneva with slot clearance {clearance * 1e3:g} mm: the pin in its slot over a crank turn")
    if len(ax.get_lines()) > 2:
        ax.legend(fontsize=8, loc="lower right")
    if len(impacts):
        for flank, colour in (("driving", "C3"), ("trailing", "C0")):
            sel = impacts[impacts["flank"] == flank]
            if len(sel):
                bx.vlines(sel["crank_angle_deg"], 0, sel[column].abs() * scale, color=colour, lw=1.2)
                bx.plot(sel["crank_angle_deg"], sel[column].abs() * scale, "o", color=colour, ms=4,
                        label=f"{flank} flank")
        bx.legend(fontsize=8)
    bx.set_ylabel(label)
    bx.set_xlabel("crank angle within its turn (deg; 0 = mid-engagement)")
    engaged = angle[~np.isin(mode, ("dwell", "play"))]
    if len(engaged):
        bx.set_xlim(engaged.min() - 3, engaged.max() + 3)
    return fig


def lock_figure(timeseries, lock_impacts: pd.DataFrame, play: float, pitch: float, exit_angle: float) -> Figure:
    """The wheel in its locking play: its offset from the nominal dwell angle (mrad) against the crank angle since
    the pin left the slot (exit_angle: the engagement's half angle, rad), one line per dwell, the play's ends dashed;
    below it the impulse of every lock impact (the exit's included) at its crank angle."""
    fig = Figure(figsize=(9, 6.5), layout="constrained")
    ax, bx = fig.subplots(2, 1, sharex=True)
    theta = timeseries["crank_angle_rad"].to_numpy(float)
    psi = timeseries["wheel_angle_rad"].to_numpy(float)
    mode = np.asarray(timeseries["mode"])
    since = np.mod(local_angle_deg(theta) - np.degrees(exit_angle), 360.0)
    dwell = np.isin(mode, ("dwell", "play"))
    offset = (psi - (np.round(psi / pitch - 0.5) + 0.5) * pitch) * 1e3
    start = np.floor((theta - exit_angle) / (2 * np.pi))            # one number per dwell (counted from its exit)
    for k in np.unique(start[dwell]):
        rows = dwell & (start == k)
        if np.count_nonzero(rows) > 1:
            ax.plot(since[rows], offset[rows], lw=1.2, label=f"dwell {int(k) + 1}")
    _ends(ax, play / 2 * 1e3, ("leading end", "trailing end"))
    ax.set_ylabel("wheel offset from its nominal\ndwell angle (mrad)")
    ax.set_title(f"Geneva with lock play {play * 1e3:g} mrad: the wheel in its locking arc during the dwell")
    if len(ax.get_lines()) > 2:
        ax.legend(fontsize=8, loc="lower right")
    if len(lock_impacts):
        at = np.mod(lock_impacts["crank_angle_deg"].to_numpy(float) - np.degrees(exit_angle), 360.0)
        for end, colour in (("leading", "C3"), ("trailing", "C0")):
            sel = (lock_impacts["end"] == end).to_numpy()
            if sel.any():
                size = lock_impacts["impulse_N_s"].abs().to_numpy(float)[sel] * 1e3
                bx.vlines(at[sel], 0, size, color=colour, lw=1.2)
                bx.plot(at[sel], size, "o", color=colour, ms=4, label=f"{end} end")
        bx.legend(fontsize=8)
    bx.set_ylabel("lock impact impulse |J| at the\ncrank radius (mN s)")
    bx.set_xlabel("crank angle since the pin left the slot (deg)")
    return fig


def _ends(ax, half: float, names: tuple[str, str]) -> None:
    """The two ends of a gap or play at +-half, dashed and named, with the axis a little wider than the gap."""
    for y, name in ((half, names[0]), (-half, names[1])):
        ax.axhline(y, color="0.3", lw=0.8, ls="--")
        ax.annotate(name, (0.01, y), xycoords=("axes fraction", "data"), va="bottom", fontsize=8, color="0.3")
    ax.set_ylim(-1.35 * half, 1.35 * half)
