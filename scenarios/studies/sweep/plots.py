"""Sweep plots (matplotlib Figures, no pyplot state): each key summary figure against each varied parameter, and
heat maps over the first two varied parameters; drawn half in a forked process where the platform allows
(scenarios/output/render.py: the plots were most of a small sweep's time).

    plots/vs_<parameter>.png     one panel per figure; a line per combination of the other parameters (up to
                                 8, else points); failed cases marked with a red x on the axis
    plots/heatmap_<figure>.png   figure over (parameter 1, parameter 2), a panel per value of parameter 3
                                 (small multiples, one colour scale); cases differing only in further
                                 parameters share a cell, reduced by the aggregate the title names (max of a
                                 peak_max_*, min of a peak_min_*, else mean); plus heatmap_success.png (share
                                 of cases that ran to the end)

Cases are compared only as finely as their runs resolve them (`resolution`, the rule of scenarios/studies/
resolution.py): a quantity whose cases differ by less than TOLERANCES_RESOLVED x the runs' rtol of its column's
scale is drawn as one value, its panel or colour scale not stretched over integration noise, and says so.
"""
from __future__ import annotations

import functools
import re
from pathlib import Path

import numpy as np
import pandas as pd
from matplotlib.figure import Figure

from mechsim.scenarios.studies.resolution import EXACT_FIGURES, column_scale, figure_column, floor
from mechsim.scenarios.studies.sweep.rows import KEY_FIGURES

MAX_LINES = 8
#: at most this many small multiples (values of the third parameter); beyond, it joins the aggregated ones
MAX_PANELS = 16


def _safe(name: str) -> str:
    return re.sub(r"[^A-Za-z0-9_.-]+", "_", name)


def _label(column: str) -> str:
    """'load.wheel_torque_N_m' -> 'load.wheel_torque (N_m)' style labels from the column naming rule."""
    for unit in ("N_m_s_rad", "kg_m2", "rad_s2", "rad_s", "m_s", "N_m", "N_s", "t_s", "deg", "rad", "N", "W", "J",
                 "C", "K", "m", "s"):
        if column.endswith("_" + unit):
            shown = {"N_m": "N·m", "N_s": "N·s", "rad_s": "rad/s", "rad_s2": "rad/s²", "m_s": "m/s", "kg_m2": "kg·m²",
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


def run_tolerance(pl) -> float:
    """The largest solver.rtol among a sweep's cases (a closed form's columns are exact to round-off, but its
    thermal states are integrated at that rtol; below it no difference between cases matters in a figure)."""
    return max((float(c.scenario.si["solver"]["rtol"]) for c in pl.cases), default=0.0)


def resolution(df: pd.DataFrame, figure: str, tolerance: float) -> float:
    """The smallest difference between cases' `figure` that their runs resolve (scenarios/studies/resolution.py):
    TOLERANCES_RESOLVED x `tolerance` (`run_tolerance`) of the figure's scale, for a figure read from a column the
    largest magnitude the column's peaks and turn mean reach over the successful cases, else the figure's own; 0
    for EXACT_FIGURES."""
    if figure in EXACT_FIGURES:
        return 0.0
    ok = df[df["success"].astype(bool)]
    column = figure_column(figure)
    related = ([f"{s}{k}_{column}" for s in ("", "startup_") for k in ("peak_max", "peak_min")]
               + [f"cycle_mean_{column}"] if column else [])
    shown = [c for c in dict.fromkeys([figure] + related) if c in ok and _numeric(ok[c])]
    values = np.abs(ok[shown].to_numpy(float)) if shown else np.empty(0)
    scale = float(np.nanmax(values)) if np.isfinite(values).any() else 0.0
    return floor(tolerance, column_scale(column or figure, scale))


def unresolved(values: np.ndarray, floor: float) -> float | None:
    """The spread of `values` where it is positive but below `floor` (`resolution`): cases equal within their runs'
    tolerance; else None."""
    finite = values[np.isfinite(values)]
    if len(finite) < 2:
        return None
    spread = float(finite.max() - finite.min())
    return spread if 0.0 < spread <= floor else None


def _unresolved_note(spread: float) -> str:
    return f"equal in every case within the runs' tolerance (spread {spread:.2g})"


def plot_against(df: pd.DataFrame, param: str, others: list[str], figures: list[str], log_x: bool = False,
                 tolerance: float = 0.0) -> Figure:
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
        spread = unresolved(ok[figname].to_numpy(float), resolution(df, figname, tolerance))
        if spread is not None:
            middle = float(np.nanmedian(ok[figname].to_numpy(float)))
            ax.set_ylim(ax.yaxis.get_major_locator().nonsingular(middle, middle))
            ax.text(0.5, 0.95, _unresolved_note(spread), transform=ax.transAxes, ha="center", va="top", fontsize=7,
                    color="0.3")
        ax.set_ylabel(_label(figname), fontsize=8)
        ax.set_xlabel(_label(param), fontsize=8)
        ax.grid(alpha=0.3)
    for ax in list(axes.flat)[n:]:
        ax.set_visible(False)
    handles, labels = axes.flat[0].get_legend_handles_labels()
    if handles:                               # the combinations of the other parameters, and the failed cases' mark
        fig.legend(handles, labels, loc="upper center", ncol=min(4, len(handles)), fontsize=7, frameon=False)
        fig.tight_layout(rect=(0, 0, 1, 1 - 0.45 / fig.get_figheight()))     # the legend's two lines above
    else:
        fig.tight_layout()
    return fig


#: how a heat map reduces the cases that share a cell (the parameters it does not show): a peak by its extreme
AGGREGATES = ("auto", "max", "min", "mean")


def aggregate_for(value: str, choice: str = "auto") -> str:
    """The aggregate of `value` over hidden parameters: `choice` unless "auto", which takes the max of a maximum
    (peak_max_*, startup_peak_max_*), the min of a minimum (peak_min_*, startup_peak_min_*), the share of
    successes, else the mean."""
    if choice != "auto":
        return choice
    if value == "success":
        return "mean"
    value = value.removeprefix("startup_")
    return "min" if value.startswith("peak_min_") else "max" if value.startswith("peak_") else "mean"


def check_aggregate(choice) -> str:
    """`choice` if it names an aggregate (ScenarioError naming heatmap_aggregate otherwise)."""
    from mechsim.scenarios.units import ScenarioError
    if choice not in AGGREGATES:
        raise ScenarioError("heatmap_aggregate", f"must be one of {', '.join(AGGREGATES)}; got {choice!r}")
    return choice


def _tick(v) -> str:
    return f"{v:.4g}" if isinstance(v, (float, int, np.number)) else str(v)


def heatmap(df: pd.DataFrame, a: str, b: str, value: str, facet: str | None = None, hidden: list[str] = (),
            aggregate: str = "auto", tolerance: float = 0.0) -> Figure:
    """`value` over (a, b): one panel, or with `facet` one panel per value of that parameter (small multiples on
    one colour scale). Cases that differ only in the `hidden` parameters share a cell and are reduced by
    `aggregate` (aggregate_for), which the title names with the parameters it runs over; a cell without a case
    is left blank, one whose cases all failed says so. Cells equal within the runs' tolerance (`resolution`) take
    one colour, as equal ones do."""
    data = df.copy()
    data["success"] = data["success"].astype(float)
    how = aggregate_for(value, aggregate)
    panels = [(None, data)] if facet is None else list(data.groupby(facet, sort=True))
    cols_a = sorted(data[a].unique(), key=_order)
    rows_b = sorted(data[b].unique(), key=_order)
    tables = []
    for _, part in panels:
        cases = part if value == "success" else part[part["success"] > 0]
        table = cases.pivot_table(index=b, columns=a, values=value, aggfunc=how, dropna=False)
        counts = part.pivot_table(index=b, columns=a, values="success", aggfunc="size", dropna=False)
        tables.append((table.reindex(index=rows_b, columns=cols_a).to_numpy(float),
                       counts.reindex(index=rows_b, columns=cols_a).to_numpy(float)))
    finite = np.concatenate([t[np.isfinite(t)] for t, _ in tables]) if tables else np.empty(0)
    lo, hi = (float(finite.min()), float(finite.max())) if len(finite) else (0.0, 1.0)
    spread = None if value == "success" else unresolved(finite, resolution(df, value, tolerance))
    if value == "success":
        lo, hi = 0.0, 1.0
    elif hi == lo or spread is not None:             # one value everywhere: one colour, not a stretched scale
        middle = 0.5 * (lo + hi)
        lo, hi = middle - max(abs(middle), 1.0), middle + max(abs(middle), 1.0)
    n = len(panels)
    ncols = min(n, 4)
    nrows = int(np.ceil(n / ncols))
    fig = Figure(figsize=(1.0 + 4.0 * ncols + 0.9, 0.9 + 3.6 * nrows), layout="constrained")
    axes = fig.subplots(nrows, ncols, squeeze=False, sharex=True, sharey=True)
    annotate = len(cols_a) * len(rows_b) <= 64
    im = None
    for ax, (key, _), (table, count) in zip(axes.flat, panels, tables):
        drawn = table if spread is None else np.where(np.isfinite(table), 0.5 * (lo + hi), table)   # one value
        im = ax.imshow(drawn, origin="lower", aspect="auto", cmap="viridis", vmin=lo, vmax=hi)
        if annotate:
            for (i, j), v in np.ndenumerate(table):
                text = _tick(v) if np.isfinite(v) else ("all failed" if count[i, j] > 0 else "")
                shade = "white" if not np.isfinite(v) or v < lo + 0.6 * (hi - lo) else "black"
                ax.text(j, i, text, ha="center", va="center", fontsize=7, color="grey" if not np.isfinite(v)
                        else shade)
        ax.set_xticks(range(len(cols_a)), [_tick(v) for v in cols_a], rotation=45, fontsize=7)
        ax.set_yticks(range(len(rows_b)), [_tick(v) for v in rows_b], fontsize=7)
        if facet is not None:
            ax.set_title(f"{_label(facet)} = {_tick(key)}", fontsize=9)
    for ax in axes[-1, :]:
        ax.set_xlabel(_label(a))
    for ax in axes[:, 0]:
        ax.set_ylabel(_label(b))
    for ax in list(axes.flat)[n:]:
        ax.set_visible(False)
    name = "share of cases that succeeded" if value == "success" else _label(value)
    fig.colorbar(im, ax=axes, label=name, shrink=0.9 if nrows > 1 else 1.0)
    fig.suptitle(name + ("" if value == "success" else " (successful cases)") + "\n" + _reduction(how, value, hidden,
                 data, [a, b] + ([facet] if facet else [])) + ("" if spread is None else "; " + _unresolved_note(spread)),
                 fontsize=9)
    return fig


def _order(v):
    return (0, float(v), "") if isinstance(v, (int, float, np.number)) else (1, 0.0, str(v))


def _reduction(how: str, value: str, hidden: list[str], data: pd.DataFrame, shown: list[str]) -> str:
    """The title's account of what a cell holds: one case, or the aggregate over the hidden parameters."""
    per_cell = data.groupby(shown).size()
    if not hidden or int(per_cell.max()) <= 1:
        return "one case per cell"
    word = "pooled" if value == "success" and how == "mean" else how
    return (f"{word} over {', '.join(_label(h) for h in hidden)} "
            f"({int(per_cell.min())}-{int(per_cell.max())} cases per cell)" if per_cell.min() != per_cell.max()
            else f"{word} over {', '.join(_label(h) for h in hidden)} ({int(per_cell.max())} cases per cell)")


def write_plots(df: pd.DataFrame, pl, folder: Path, aggregate: str = "auto") -> list[Path]:
    """Every plot of a sweep table into `folder` (returns the files written). Heat maps (grid sweeps of two or more
    parameters) show the first two parameters, a panel per value of the third, and reduce the cases that differ
    in the others by `aggregate` (aggregate_for)."""
    from mechsim.scenarios.output.render import FigureWriter
    folder.mkdir(parents=True, exist_ok=True)
    params = [p for p in pl.param_columns if p in df and df[p].nunique() > 1]
    figures = figure_columns(df)
    if not params or not figures:
        return []
    logs = _log_axes(pl)
    tolerance = run_tolerance(pl)
    makers = [functools.partial(_one, f"vs_{_safe(p)}", plot_against, df, p, [o for o in params if o != p], figures,
                                log_x=p in logs, tolerance=tolerance) for p in params]
    if len(params) >= 2 and pl.spec.mode == "grid":
        a, b = params[0], params[1]
        facet = params[2] if len(params) >= 3 and df[params[2]].nunique() <= MAX_PANELS else None
        hidden = params[3:] if facet is not None else params[2:]
        ok = df[df["success"].astype(bool)]
        if len(ok):
            makers += [functools.partial(_one, f"heatmap_{_safe(value)}", heatmap, df, a, b, value, facet, hidden,
                                         aggregate, tolerance) for value in figures]
        makers.append(functools.partial(_one, "heatmap_success", heatmap, df, a, b, "success", facet, hidden,
                                        aggregate))
    with FigureWriter(makers, folder) as writer:
        writer.finish()
    return [folder / f"{make.args[0]}.png" for make in makers]


def _one(stem: str, draw, *args, **kwargs) -> dict[str, Figure]:
    """{stem: figure} of one plot (a figure maker for FigureWriter)."""
    return {stem: draw(*args, **kwargs)}
