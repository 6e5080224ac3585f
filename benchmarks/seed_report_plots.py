"""Figures of the seed reproduction report: one PNG per quantity (a 2 x 3 grid: mu by load case, the models as
curves on the seed's 0..90 deg axis), and one bar chart of the conclusions. Small files: dpi 90."""
from __future__ import annotations

import io
from pathlib import Path

import matplotlib

matplotlib.use("Agg")
import matplotlib.pyplot as plt  # noqa: E402
import numpy as np  # noqa: E402

DPI = 90
#: palette size of the saved PNGs (line plots need few colours; 4x smaller files than RGBA)
PALETTE_COLORS = 64
STYLE = {"seed": dict(color="C0", ls="--", lw=1.4), "corrected": dict(color="C1", ls="-", lw=1.4),
         "mechsim": dict(color="C2", ls="-", lw=2.2, alpha=0.75), "mechsim_1h": dict(color="C3", ls=":", lw=1.6)}

#: file stem -> (title, y label, [(column suffix, models, label suffix, extra style)], scale to display unit)
FIGURES = {
    "normal_load": ("Normal load", "N (N)", [("normal_load_N", ("seed", "corrected", "mechsim"), "", {})], 1.0),
    "half_width": ("Hertz half-width", "b (µm)", [
        ("half_width_m", ("seed", "corrected", "mechsim"), "", {}),
        ("half_width_printed_m", ("seed",), ", S(9) as printed (E' = 2E*)", dict(ls=":", lw=1.0))], 1e6),
    "pressure": ("Peak contact pressure", "p (MPa)", [
        ("pressure_max_Pa", ("seed", "corrected", "mechsim"), "", {}),
        ("pressure_max_printed_Pa", ("seed",), ", S(9) as printed (E' = 2E*)", dict(ls=":", lw=1.0))], 1e-6),
    "peclet": ("Peclet numbers L = Ub/(2χ)", "L (-)", [
        ("peclet_pin", ("seed", "corrected", "mechsim"), ", pin", {}),
        ("peclet_wheel", ("corrected", "mechsim"), ", wall", dict(ls="-.", lw=1.0))], 1.0),
    "heat": ("Frictional heat rate", "Q (W)", [("heat_rate_W", ("seed", "corrected", "mechsim"), "", {})], 1.0),
    "flash_rise": ("Flash temperature rise", "ΔT_flash (K)", [
        ("temp_flash_rise_K", ("seed", "corrected", "mechsim"), "", {})], 1.0),
    "contact_temperature": ("Contact temperature", "T_c (°C)", [
        ("temp_contact_C", ("seed", "corrected", "mechsim", "mechsim_1h"), "", {})], 1.0),
}


def _save(fig, path: Path) -> Path:
    """Save as a small palette PNG (dpi DPI, PALETTE_COLORS colours) and close the figure."""
    from PIL import Image
    buffer = io.BytesIO()
    fig.savefig(buffer, dpi=DPI, format="png")
    plt.close(fig)
    buffer.seek(0)
    with Image.open(buffer) as image:
        image.convert("RGB").quantize(colors=PALETTE_COLORS, method=Image.Quantize.MEDIANCUT).save(path, optimize=True)
    return path


def _grid(report):
    """Cases as a 2 x 3 grid: rows mu, columns load case."""
    mus = sorted({c.mu for c in report.cases})
    lcs = sorted({c.load_case for c in report.cases})
    return mus, lcs, {(c.mu, c.load_case): c for c in report.cases}


def quantity_figure(report, stem: str, path: Path) -> Path:
    from mechsim.benchmarks.seed_report import MODEL_LABELS
    title, ylabel, series, scale = FIGURES[stem]
    mus, lcs, cases = _grid(report)
    fig, axes = plt.subplots(len(mus), len(lcs), figsize=(11, 5.6), sharex=True, sharey=True, squeeze=False)
    for i, mu in enumerate(mus):
        for j, lc in enumerate(lcs):
            ax = axes[i, j]
            case = cases[(mu, lc)]
            table = report.tables[case.name]
            phi = table["phi_deg"].to_numpy(float)
            for suffix, models, label_suffix, extra in series:
                for model in models:
                    col = f"{model}_{suffix}"
                    if col not in table:
                        continue
                    y = table[col].to_numpy(float)
                    shown = np.isfinite(y)          # the hour's run leaves the full report's finer rows empty
                    ax.plot(phi[shown], y[shown] * scale, label=MODEL_LABELS[model] + label_suffix,
                            **{**STYLE[model], **extra})
            ax.axvline(45.0, color="0.6", lw=0.6)
            ax.set_title(f"LC{lc}: {case.torque:g} N·m, {case.speed:g} rad/s, μ = {mu:g}", fontsize=9)
            ax.grid(alpha=0.3)
            ax.set_xticks(np.arange(0, 91, 15))
            if i == len(mus) - 1:
                ax.set_xlabel("angular position φ (deg)")
            if j == 0:
                ax.set_ylabel(ylabel)
    axes[0, 0].legend(fontsize=7, loc="best")
    fig.suptitle(f"{title}: seed as printed, seed corrected, mechsim", fontsize=11)
    fig.tight_layout()
    return _save(fig, path)


def conclusions_figure(report, path: Path) -> Path:
    """Peak flash rise, peak contact temperature and mean heat rate per load case (bars: models), per mu."""
    from mechsim.benchmarks.seed_report import MODEL_LABELS, MODELS
    c = report.comparison
    mus = sorted(c["mu"].unique())
    metrics = [("peak_flash_rise_K", "peak flash rise (K)", ("seed", "corrected", "mechsim")),
               ("peak_contact_temp_C", "peak contact temperature (°C)", MODELS),
               ("mean_heat_rate_W", "mean heat rate (W)", ("seed", "corrected", "mechsim"))]
    fig, axes = plt.subplots(len(mus), len(metrics), figsize=(11, 5.6), squeeze=False)
    for i, mu in enumerate(mus):
        for j, (col, label, models) in enumerate(metrics):
            ax = axes[i, j]
            width = 0.8 / len(models)
            for m, model in enumerate(models):
                sub = c[(c["mu"] == mu) & (c["model"] == model)].sort_values("load_case")
                x = sub["load_case"].to_numpy() + (m - (len(models) - 1) / 2) * width
                ax.bar(x, sub[col].to_numpy(float), width, color=STYLE[model]["color"], label=MODEL_LABELS[model])
            ax.set_xticks([1, 2, 3], ["LC1", "LC2\n2× torque", "LC3\n2× speed"], fontsize=8)
            ax.set_title(f"{label}, μ = {mu:g}", fontsize=9)
            ax.grid(alpha=0.3, axis="y")
    axes[0, 1].legend(fontsize=7, loc="upper left")
    fig.suptitle("Doubling the torque (LC2) or the speed (LC3): which heats more?", fontsize=11)
    fig.tight_layout()
    return _save(fig, path)


def write_figures(report, folder: Path) -> dict[str, Path]:
    """Every figure into folder; {stem: path}."""
    out = {stem: quantity_figure(report, stem, folder / f"{stem}.png") for stem in FIGURES}
    out["conclusions"] = conclusions_figure(report, folder / "conclusions.png")
    return out
