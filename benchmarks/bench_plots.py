"""The work-precision figure of `mechsim bench`: error against warm CPU time, error against the requested
tolerance, and the cold setup time (derivation, compilation, construction) shown apart.

Built on a Figure of its own (no pyplot state); the legend sits below the panels, off the data; the setup
panel's labels get room for every method."""
from __future__ import annotations

import numpy as np
import pandas as pd
from matplotlib import colormaps, rcParams
from matplotlib.backends.backend_agg import FigureCanvasAgg
from matplotlib.figure import Figure
from matplotlib.ticker import LogLocator, NullFormatter

STYLE = {"mechsim IDA": ("-", "o"), "mechsim diffrax": (":", "D"), "scipy": ("--", "s"), "CasADi": ("-.", "^")}


def work_precision_figure(rows: pd.DataFrame, summary: dict, path=None) -> Figure:
    """The figure; written as PNG to `path` when given."""
    methods = list(dict.fromkeys(rows.method))
    fig = Figure(figsize=(17, max(6.4, 2.2 + 0.42 * len(methods))), layout="constrained")
    ax1, ax2, ax3 = fig.subplots(1, 3, gridspec_kw={"width_ratios": [1.25, 1.0, 0.8]})
    colors = rcParams["axes.prop_cycle"].by_key()["color"]
    if len(methods) > len(colors):      # more methods than the default cycle: 20 distinct colours
        colors = [colormaps["tab20"](k) for k in range(20)]
    for i, name in enumerate(methods):
        d = rows[rows.method == name].sort_values("rtol", ascending=False)
        family = d.family.iloc[0]
        ls, marker = STYLE.get(family, ("-", "o"))
        color = colors[i % len(colors)]
        ok = d[(d.status == "ok") & (d.error_rad > 0)]
        bad = d[(d.status != "ok") & np.isfinite(d.cpu_time_s)]
        # IDA's compiled callbacks compute what its Python ones compute: dashed with open markers, so that the line
        # it lies on stays visible
        style = dict(ls="--", mfc="white") if "compiled" in name else dict(ls=ls)
        ax1.plot(ok.cpu_time_s, ok.error_rad, marker=marker, color=color, label=name, **style)
        ax2.plot(ok.rtol, ok.error_rad, marker=marker, color=color, label=name, **style)
        if len(bad):
            ax1.plot(bad.cpu_time_s, bad.error_rad.fillna(np.pi), ls="none", marker="x", color=color, ms=8)
            ax2.plot(bad.rtol, bad.error_rad.fillna(np.pi), ls="none", marker="x", color=color, ms=8)
    r = np.array([rows.rtol.min(), rows.rtol.max()])
    ax2.plot(r, r, color="0.6", lw=1, label="error = rtol")
    for ax in (ax1, ax2):
        ax.set_xscale("log")
        ax.set_yscale("log")
        ax.grid(True, which="both", alpha=0.3)
        ax.set_ylabel(f"max error of {summary.get('error_column', 'crank_angle_rad')} (rad)")
    ax1.set_xlabel("warm CPU time per run (s)")
    independent = summary.get("reference", {}).get("independent", True)
    ref_note = "" if independent else f"\nreference: {summary['reference_label']}"
    ax1.set_title(f"{summary['scenario']}: {summary['duration_s']:g} s, {summary['output_points']} output points\n"
                  f"x = run failed (error over what ran){ref_note}", fontsize=10)
    ax2.set_xlabel("requested rtol (atol = 1e-2 rtol)")
    ax2.set_title("achieved error against requested tolerance", fontsize=10)
    ax2.invert_xaxis()
    handles, labels = ax2.get_legend_handles_labels()
    fig.legend(handles, labels, loc="outside lower center", ncol=min(7, len(labels)), fontsize=8, frameon=False)
    setup = rows.groupby("method", sort=False).agg(setup=("setup_time_s", "max"), scope=("setup_scope", "first"))
    setup = setup[np.isfinite(setup.setup) & (setup.setup > 0)]
    y = np.arange(len(setup))
    ax3.barh(y, setup.setup, color=[colors[methods.index(m) % len(colors)] for m in setup.index])
    ax3.set_yticks(y, [f"{m}: {s}" for m, s in zip(setup.index, setup.scope)], fontsize=8)
    ax3.set_xscale("log")
    # labels at 1, 2 and 5 of each decade only: matplotlib labels every minor tick of a span near a decade, and
    # they ran into each other
    ax3.xaxis.set_major_locator(LogLocator(base=10.0, subs=(1.0, 2.0, 5.0)))
    ax3.xaxis.set_minor_formatter(NullFormatter())
    ax3.set_xlabel("cold setup time (s)")
    ax3.set_title("derivation / compilation / construction,\nnot in the run times", fontsize=10)
    ax3.invert_yaxis()
    ax3.grid(True, axis="x", which="both", alpha=0.3)
    FigureCanvasAgg(fig)
    if path is not None:
        fig.savefig(path, dpi=110)
    return fig
