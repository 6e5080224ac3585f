"""Sweep plots (matplotlib Figures, no pyplot state): each key summary figure against each varied parameter, and
heat maps over the first two varied parameters; drawn half in a forked process where the platform allows
(scenarios/output/render.py: the plots were most of a small sweep's time).

    plots/vs_<parameter>.png     one panel per figure; a line per combination of the other parameters (up to
                                 8, else points); failed cases marked with a red x on the axis
    plots/heatmap_<figure>.png   figure over (parameter 1, parameter 2), mean over any other parameters;
                                 plus heatmap_success.png (fraction of cases that ran to the end)
"""
from __future__ import annotations

import functools
import re
from pathlib import Path

import numpy as np
import pandas as pd
from matplotlib.figure import Figure

from mechsim.scenarios.studies.sweep.rows import KEY_FIGURES

MAX_LINES = 8


def _safe(name: str) -> str:
    return re.sub(r"[^A-Za-z0-9_.-]+", "_", name)


def _label(column: str) -> str:
    """'load.wheel_torque_N_m' -> 'load.wheel_torque (N_m)' style labels from the column naming rule."""
    for unit in ("N_m_s_rad", "kg_m2", "rad_s2", "rad_s", "m_s", "N_m", "t_s", "deg", "rad", "N", "W", "J",
                 "C", "K", "m", "s"):
        if column.endswith("_" + unit):
            shown = {"N_m": "N·m", "rad_s": "rad/s", "rad_s2": "rad/s²", "m_s": "m/s", "kg_m2": "kg·m²",
                     "N_m_s_rad": "N·m·s/rad", "C": "°C", "t_s": "s"}.get(unit, unit)
            return f"{column[:-len(unit) - 1]} ({shown})"
    return column


def _numeric(series: pd.Series) -> bool:
    return pd.api.types.is_numeric_dtype(series) and not pd.api.types.is_bool_dtype(series)


def _positions(series: pd.Series):
    """x positions: the values if numeric, else category indices (with their labels)."""
    if _numeric(series):
        return series.to_numpy(float), None
    cats = list(dict.fromkeys(series.astype(str)))
    return series.astype(str).map({c: i for i, c in enumerate(cats)}).to_numpy(float), cats


def _log_axes(pl) -> set[str]:
    """Parameter columns of axes given as log ranges (plotted on a log scale)."""
    logs = [a.key for a in pl.spec.axes if a.kind == "log"]
    return {c for c in pl.param_columns for k in logs if c == k or c.startswith(k + "_")}


def figure_columns(df: pd.DataFrame) -> list[str]:
    return [c for c in KEY_FIGURES if c in df and _numeric(df[c]) and df[c].notna().any()]


def plot_against(df: pd.DataFrame, param: str, others: list[str], figures: list[str], log_x: bool = False) -> Figure:
    ok = df[df["success"].astype(bool)]
    bad = df[~df["success"].astype(bool)]
    n = len(figures)
    cols = 2 if n > 1 else 1
    rows = int(np.ceil(n / cols))
    fig = Figure(figsize=(6.5 * cols, 2.8 * rows))
    axes = fig.subplots(rows, cols, squeeze=False)
    groups = list(ok.groupby(others, sort=True)) if others else [((), ok)]
    as_lines = len(groups) <= MAX_LINES
    for ax, figname in zip(axes.flat, figures):
        for name, g in groups:
            g = g.sort_values(param)
            x, cats = _positions(g[param])
            label = ", ".join(f"{_label(o)}={v:.4g}" if isinstance(v, (int, float, np.number)) else f"{o}={v}"
                              for o, v in zip(others, name if isinstance(name, tuple) else (name,)))
            if as_lines:
                ax.plot(x, g[figname].to_numpy(float), "o-", ms=3, lw=1.2, label=label or None)
            else:
                ax.plot(x, g[figname].to_numpy(float), ".", ms=3, color="C0", alpha=0.5)
            if cats:
                ax.set_xticks(range(len(cats)), cats)
        if len(bad):
            xb, _ = _positions(bad[param])
            ax.plot(xb, np.zeros_like(xb), "x", color="red", transform=ax.get_xaxis_transform(), clip_on=False,
                    label="failed case")
        if log_x:
            ax.set_xscale("log")
        ax.set_ylabel(_label(figname), fontsize=8)
        ax.set_xlabel(_label(param), fontsize=8)
        ax.grid(alpha=0.3)
    for ax in list(axes.flat)[n:]:
        ax.set_visible(False)
    handles, labels = axes.flat[0].get_legend_handles_labels()
    if handles and len(handles) > 1:
        fig.legend(handles, labels, loc="upper center", ncol=min(4, len(handles)), fontsize=7, frameon=False)
        fig.tight_layout(rect=(0, 0, 1, 0.93))
    else:
        fig.tight_layout()
    return fig


def heatmap(df: pd.DataFrame, a: str, b: str, value: str) -> Figure:
    data = df.copy()
    data["success"] = data["success"].astype(float)
    table = data.pivot_table(index=b, columns=a, values=value, aggfunc="mean", dropna=False)
    fig = Figure(figsize=(6.5, 4.8))
    ax = fig.subplots()
    im = ax.imshow(table.to_numpy(float), origin="lower", aspect="auto", cmap="viridis")
    ax.set_xticks(range(len(table.columns)), [f"{v:.4g}" if isinstance(v, (float, int)) else str(v)
                                              for v in table.columns], rotation=45, fontsize=7)
    ax.set_yticks(range(len(table.index)), [f"{v:.4g}" if isinstance(v, (float, int)) else str(v)
                                            for v in table.index], fontsize=7)
    ax.set_xlabel(_label(a))
    ax.set_ylabel(_label(b))
    fig.colorbar(im, ax=ax, label=_label(value) if value != "success" else "fraction of cases that succeeded")
    ax.set_title(_label(value) + ("" if value == "success" else " (successful cases)"), fontsize=9)
    fig.tight_layout()
    return fig


def write_plots(df: pd.DataFrame, pl, folder: Path) -> list[Path]:
    """Every plot of a sweep table into `folder` (returns the files written)."""
    from mechsim.scenarios.output.render import FigureWriter
    folder.mkdir(parents=True, exist_ok=True)
    params = [p for p in pl.param_columns if p in df and df[p].nunique() > 1]
    figures = figure_columns(df)
    if not params or not figures:
        return []
    logs = _log_axes(pl)
    makers = [functools.partial(_one, f"vs_{_safe(p)}", plot_against, df, p, [o for o in params if o != p], figures,
                                log_x=p in logs) for p in params]
    if len(params) >= 2 and pl.spec.mode == "grid":
        a, b = params[0], params[1]
        ok = df[df["success"].astype(bool)]
        if len(ok):
            makers += [functools.partial(_one, f"heatmap_{_safe(value)}", heatmap, ok, a, b, value) for value in figures]
        makers.append(functools.partial(_one, "heatmap_success", heatmap, df, a, b, "success"))
    with FigureWriter(makers, folder) as writer:
        writer.finish()
    return [folder / f"{make.args[0]}.png" for make in makers]


def _one(stem: str, draw, *args, **kwargs) -> dict[str, Figure]:
    """{stem: figure} of one plot (a figure maker for FigureWriter)."""
    return {stem: draw(*args, **kwargs)}
