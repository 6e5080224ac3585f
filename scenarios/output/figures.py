"""A result's figures as matplotlib Figure objects, keyed by the name of the PNG the CLI writes (without .png).

`Result.plot()` returns these, and `write_result` saves them, so the Python API and the CLI show the same
pictures. The per-mechanism figures come from scenarios/output/plots.py (`figures`); the figure of long
thermal runs is made here (`thermal_cycle_figure`).
"""
from __future__ import annotations

import numpy as np
from matplotlib.figure import Figure

#: the cycle-temperature figure's name (thermal_cycles.png)
THERMAL_CYCLES = "thermal_cycles"


def result_figure_makers(result, mechanism=None) -> list:
    """The figures of a result as functions that build them ({stem: Figure} each; plots.figure_makers): the plot
    writer's, then the whole-run thermal figure where there is one."""
    from mechsim.scenarios.output.plots import figure_makers

    def cycles():
        fig = thermal_cycle_figure(result)
        return {THERMAL_CYCLES: fig} if fig is not None else {}
    cycles.stem = THERMAL_CYCLES
    return figure_makers(result, mechanism) + [cycles]


def result_figures(result, mechanism=None) -> dict[str, Figure]:
    """Every figure of a result, built (`result_figure_makers`)."""
    return {stem: fig for make in result_figure_makers(result, mechanism) for stem, fig in make().items()}


def cycle_table(timeseries, angle_column: str | None = None):
    """Per drive cycle (one turn of the drive angle from its first value; the rows grouped by
    floor((angle - angle0)/2 pi)): its middle time, the cycle mean of each bulk temperature and the peak
    contact temperature (°C; NaN in a cycle without contact). A pandas DataFrame, one row per cycle."""
    angle_column = angle_column or next(c for c in timeseries.columns if c.endswith("_angle_rad"))
    angle = timeseries[angle_column].to_numpy(float)
    cycle = np.floor((angle - angle[0]) / (2 * np.pi) + 1e-12).astype(int)
    columns = [c for c in timeseries.columns if c.startswith("temp_bulk_") or c == "temp_contact_C"]
    grouped = timeseries[["t_s", *columns]].assign(cycle=cycle).groupby("cycle")
    t = grouped["t_s"]
    table = {"cycle": t.min().index.to_numpy(), "t_mid_s": (0.5 * (t.min() + t.max())).to_numpy()}
    for c in columns:
        if c == "temp_contact_C":
            table["temp_contact_peak_C"] = grouped[c].max().to_numpy()
        else:
            table[c[:-2] + "_mean_C"] = grouped[c].mean().to_numpy()
    import pandas as pd
    return pd.DataFrame(table)


def thermal_cycle_figure(result) -> Figure | None:
    """Bulk temperatures (cycle means) and the peak contact temperature of each drive cycle over the whole run,
    for runs with bulk thermal states long enough to have been cycle-averaged (summary['thermal']['cycle'])."""
    th = result.summary.get("thermal", {}) if isinstance(result.summary, dict) else {}
    cycle = th.get("cycle") or {}
    df = result.timeseries
    if not cycle.get("period_s") or "temp_contact_C" not in df or not any(c.startswith("temp_bulk_") for c in df):
        return None
    from mechsim.scenarios.output.plots import ENVELOPE_NOTE, pixel_columns, trace
    table = cycle_table(df)
    fig = Figure(figsize=(9, 4.2), layout="constrained")
    ax = fig.add_subplot()
    t_mid, columns = table["t_mid_s"].to_numpy(float), pixel_columns(fig, ax)
    enveloped = trace(ax, t_mid, table["temp_contact_peak_C"].to_numpy(float), columns, "C3", lw=1.2,
                      label="contact, the cycle's highest row")
    for i, c in enumerate(c for c in table.columns if c.startswith("temp_bulk_")):
        body = c[len("temp_bulk_"):-len("_mean_C")]
        enveloped |= trace(ax, t_mid, table[c].to_numpy(float), columns, f"C{i}", lw=1.2,
                           label=f"bulk {body}, cycle mean")
    ax.set_xlabel("time (s)")
    ax.set_ylabel("temperature (°C)")
    ax.grid(alpha=0.3)
    ax.legend(loc="upper left", bbox_to_anchor=(1.01, 1.0), fontsize=8, frameon=False)
    ax.set_title(f"{result.summary.get('scenario', '')}: temperatures per drive cycle\n({len(table)} cycles of "
                 f"{float(cycle['period_s']):.4g} s" + (f"; {ENVELOPE_NOTE})" if enveloped else ")"))
    return fig
