"""PNG plots of a result: time histories, the same versus the drive angle, and drawings of the mechanism."""
from __future__ import annotations

from pathlib import Path

import matplotlib

matplotlib.use("Agg")
import matplotlib.pyplot as plt  # noqa: E402
import numpy as np  # noqa: E402

from mechsim.dynamics.result import Result  # noqa: E402
import mechsim.scenarios.output.chain_plots as chain_plots  # noqa: E402

# (column, label with unit at the edge, scale to display unit)
PANELS = {
    "motion": [
        [("crank_angle_rad", "crank angle (deg)", np.degrees(1.0)), ("wheel_angle_rad", "wheel angle (deg)", np.degrees(1.0)),
         ("rolling_angle_rad", "rolling link angle (deg)", np.degrees(1.0))],
        [("crank_speed_rad_s", "crank speed (rad/s)", 1.0), ("wheel_speed_rad_s", "wheel speed (rad/s)", 1.0),
         ("rolling_speed_rad_s", "rolling link speed (rad/s)", 1.0)],
        [("crank_accel_rad_s2", "crank accel. (rad/s²)", 1.0), ("wheel_accel_rad_s2", "wheel accel. (rad/s²)", 1.0),
         ("rolling_accel_rad_s2", "rolling link accel. (rad/s²)", 1.0)],
    ],
    "forces": [
        [("contact_force_N", "normal force (N)", 1.0), ("friction_force_N", "friction force (N)", 1.0)],
        [("slip_speed_m_s", "slip speed (m/s)", 1.0), ("pin_sliding_speed_m_s", "pin sliding speed (m/s)", 1.0)],
        [("drive_torque_N_m", "drive torque (N·m)", 1.0)],
    ],
    "thermal": [
        [("temp_contact_C", "contact temperature (°C)", 1.0), ("temp_bulk_pin_C", "bulk pin (°C)", 1.0),
         ("temp_bulk_wheel_C", "bulk wheel (°C)", 1.0), ("temp_bulk_crank_C", "bulk crank (°C)", 1.0),
         ("temp_wall_surface_C", "wall track surface (°C)", 1.0)],
        [("heat_rate_W", "heat rate (W)", 1.0), ("temp_flash_rise_K", "flash rise (K)", 1.0)],
        [("peclet_pin", "Peclet pin", 1.0), ("peclet_wheel", "Peclet wheel", 1.0)],
    ],
}


def _figure(df, rows, x, xlabel, path, title):
    rows = [[c for c in row if c[0] in df] for row in rows]
    rows = [row for row in rows if row]
    if not rows:
        return
    fig, axes = plt.subplots(len(rows), 1, figsize=(9, 2.6 * len(rows)), sharex=True, squeeze=False)
    for ax, row in zip(axes[:, 0], rows):
        for col, label, scale in row:
            ax.plot(x, df[col].to_numpy(dtype=float) * scale, lw=1.0, label=label)
        ax.set_ylabel(row[0][1] if len(row) == 1 else "")
        ax.grid(alpha=0.3)
        if len(row) > 1:
            ax.legend(loc="best", fontsize=8)
    axes[-1, 0].set_xlabel(xlabel)
    fig.suptitle(title)
    fig.tight_layout()
    fig.savefig(path, dpi=110)
    plt.close(fig)


def write_plots(result: Result, folder: Path, mechanism=None) -> list[Path]:
    df = result.timeseries
    name = result.summary.get("scenario", "")
    written = []
    angle_col = next((c for c in df.columns if c.endswith("_angle_rad")), None)
    for group, rows in PANELS.items():
        path = folder / f"{group}_vs_time.png"
        _figure(df, rows, df["t_s"].to_numpy(), "time (s)", path, f"{name}: {group}")
        if path.exists():
            written.append(path)
        if angle_col:
            wrapped = np.degrees((df[angle_col].to_numpy() + np.pi) % (2 * np.pi) - np.pi)
            order = np.argsort(wrapped, kind="stable")
            path = folder / f"{group}_vs_angle.png"
            _figure(df.iloc[order], rows, wrapped[order], f"{angle_col[:-4].replace('_', ' ')} (deg, 0 = mid-engagement)",
                    path, f"{name}: {group} versus drive angle")
            if path.exists():
                written.append(path)
    drawer = _drawer(mechanism)
    if drawer is not None and len(df):
        n = result.scenario.get("output", {}).get("drawing_instants", 4)
        if n:
            idx = np.linspace(0, len(df) - 1, n).astype(int)
            fig, axes = plt.subplots(1, n, figsize=(3.2 * n, 3.4), squeeze=False)
            for ax, i in zip(axes[0], idx):
                drawer(ax, df.iloc[i])
                ax.set_title(f"t = {df['t_s'].iloc[i]:.3f} s", fontsize=9)
            fig.tight_layout()
            path = folder / "mechanism.png"
            fig.savefig(path, dpi=110)
            plt.close(fig)
            written.append(path)
    if mechanism is not None and len(df):
        extra = EXTRA_PLOTS.get(type(mechanism).__name__)
        written += extra(mechanism, folder, df, result.extra_tables) if extra else []
    return written


#: mechanism class -> drawing of the mechanism at one output row, and its mechanism-specific figures: plotting
#: lives here, not in mechanisms/ (the layer contract, docs/CONTRIBUTING.md)
DRAWERS = {"ChainDwell": chain_plots.draw}
EXTRA_PLOTS = {"ChainDwell": chain_plots.extra_plots}


def _drawer(mechanism):
    if mechanism is None:
        return None
    if type(mechanism).__name__ in DRAWERS:
        return lambda ax, row: DRAWERS[type(mechanism).__name__](mechanism, ax, row)
    return getattr(mechanism, "draw", None)
