"""Figures of a result: time histories, the same over one cycle of the driven member's angle (a line per
cycle), and drawings of the mechanism.

`figures(result, mechanism)` builds `matplotlib.figure.Figure` objects without pyplot's global state (a
caller may show, save or embed them); `write_plots` saves them as PNG. Every panel holds one unit (its y label
names the quantity and the unit), legends sit outside the data to the right.
"""
from __future__ import annotations

import math
import textwrap
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np
import pandas as pd
from matplotlib.backends.backend_agg import FigureCanvasAgg
from matplotlib.figure import Figure

from mechsim.dynamics.result import Result
from mechsim.mechanisms.base import DriveCycle
from mechsim.mechanisms.drawing import ARROW_CLIP

DEG = 180.0 / math.pi
DPI = 110

#: panels per figure: (suffix of the columns, quantity, unit label, scale from SI); a column joins the first
#: panel whose suffix it ends with, unless it is named in SKIP or claimed by an earlier figure
FIGURES = {
    "motion": [("_angle_rad", "angle", "deg", DEG), ("_speed_rad_s", "angular speed", "rad/s", 1.0),
               ("_accel_rad_s2", "angular acceleration", "rad/s²", 1.0)],
    "forces": [("_force_N", "force", "N", 1.0), ("_shear_N", "force", "N", 1.0), ("_N_m", "torque", "N·m", 1.0),
               ("_speed_m_s", "speed", "m/s", 1.0), ("_power_W", "power", "W", 1.0)],
    "thermal": [("_C", "temperature", "°C", 1.0), ("_K", "temperature rise", "K", 1.0),
                ("heat_rate_W", "heat rate", "W", 1.0), ("peclet_", "Péclet number", "–", 1.0),
                ("_pressure_max_Pa", "peak contact pressure", "MPa", 1e-6)],
    "energy": [("_energy_J", "energy", "J", 1.0), ("work_", "work done on the system", "J", 1.0),
               ("heat_generated_J", "heat", "J", 1.0), ("heat_pin_J", "heat", "J", 1.0),
               ("heat_convected_J", "heat", "J", 1.0)],
}
#: figures that make sense against the drive angle (energy and work accumulate over the run)
PER_CYCLE = ("motion", "forces", "thermal")
NAMES = {"rolling": "rolling link"}
WORDS = {"accel": "acceleration"}


UNITS = ("_rad_s2", "_rad_s", "_rad", "_N_m", "_N", "_m_s", "_W", "_C", "_K", "_J", "_Pa")


def _label(column: str) -> str:
    """A column's quantity in words: its name less the unit suffix, members named in full."""
    stem = next((column[:-len(u)] for u in UNITS if column.endswith(u)), column)
    words = stem.removeprefix("temp_").split("_")
    words[0] = NAMES.get(words[0], words[0])
    return " ".join(WORDS.get(w, w) for w in words)


def _hit(column: str, suffix: str) -> bool:
    return column.endswith(suffix) if suffix.startswith("_") else suffix in column


def panels(df: pd.DataFrame, figure: str, exclude: tuple[str, ...] = ()) -> list[dict]:
    """The panels of one figure present in `df`: dicts of quantity, unit, scale and (column, label) lines."""
    claimed = set(exclude)
    for name, specs in FIGURES.items():
        if name == figure:
            break
        claimed |= {c for c in df.columns for s, *_ in specs if _hit(c, s)}
    out: dict[tuple[str, str], dict] = {}
    for col in df.columns:
        if col in claimed or not pd.api.types.is_numeric_dtype(df[col]) or not df[col].notna().any():
            continue
        for suffix, quantity, unit, scale in FIGURES[figure]:
            if _hit(col, suffix):
                panel = out.setdefault((quantity, unit), dict(quantity=quantity, unit=unit, scale=scale, lines=[]))
                panel["lines"].append((col, _label(col)))
                claimed.add(col)
                break
    order = {(q, u): i for i, (_, q, u, _) in enumerate(FIGURES[figure])}
    return sorted(out.values(), key=lambda panel: order[(panel["quantity"], panel["unit"])])


def legend_outside(ax) -> None:
    """The axes' legend outside the data, to the right (every figure's placement)."""
    handles, labels = ax.get_legend_handles_labels()
    if handles:
        ax.legend(handles, labels, loc="upper left", bbox_to_anchor=(1.01, 1.0), fontsize=8, frameon=False,
                  borderaxespad=0.0)


def column_panels(df: pd.DataFrame, columns: list[str]) -> list[dict]:
    """Panels (as `panels` makes them) of chosen columns: each column with the quantity, unit and scale of the
    first FIGURES entry it matches (angles in degrees, pressures in MPa), else its own unit suffix; a panel per
    unit, in the order the columns come."""
    out: dict[tuple[str, str], dict] = {}
    for col in columns:
        spec = next(((q, u, s) for specs in FIGURES.values() for suffix, q, u, s in specs if _hit(col, suffix)), None)
        if spec is None:
            suffix = next((u for u in UNITS if col.endswith(u)), "")
            spec = (_label(col), suffix[1:].replace("_", "/") or "–", 1.0)
        quantity, unit, scale = spec
        panel = out.setdefault((quantity, unit), dict(quantity=quantity, unit=unit, scale=scale, lines=[]))
        panel["lines"].append((col, _label(col)))
    return list(out.values())


#: a line with more samples than this per pixel column is drawn as its envelope (`trace`): a line through many
#: samples per pixel fills the column between its extremes anyway, as a solid block that reads like noise
ROWS_PER_COLUMN = 4
#: the suptitle's note on a figure that holds envelopes
ENVELOPE_NOTE = "long run: each line drawn as its envelope, min to max per pixel column"


def pixel_columns(fig: Figure, ax) -> int:
    """About how many pixel columns the axes span in the saved PNG (before the layout engine moves it)."""
    return max(int(fig.get_figwidth() * DPI * ax.get_position().width), 10)


def envelope(x: np.ndarray, y: np.ndarray, columns: int) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """(column edges, min, max) of y over `columns` equal spans of x (sorted): each span's extremes, taken with
    the last sample before it so that the line joining the two is covered; NaN ignored, spans without a sample
    left out (NaN where a gap breaks the band)."""
    edges = np.linspace(x[0], x[-1], columns + 1)
    start = np.searchsorted(x, edges[:-1], side="left")
    start[0] = 0
    stop = np.r_[start[1:], len(x)]
    keep = stop > start
    lo = np.full(columns, np.nan)
    hi = np.full(columns, np.nan)
    with np.errstate(invalid="ignore"):
        lo[keep] = np.fmin.reduceat(y, start[keep])
        hi[keep] = np.fmax.reduceat(y, start[keep])
        before = np.clip(start - 1, 0, None)
        lo[keep] = np.fmin(lo[keep], y[before[keep]])
        hi[keep] = np.fmax(hi[keep], y[before[keep]])
    return edges, lo, hi


class LinesEnvelope:
    """The envelope over `columns` equal spans of x of several lines drawn against the same x (`line`: each
    sample's line, a line's samples consecutive in drawing order, x in any order): each column's extremes over the
    samples in it and over every segment of a line that crosses one of its edges (its value there, linear between
    the two samples), so that the band holds every line where the columns are finer than a line's samples (many
    drive cycles sampled at other phases: the column's samples alone miss the cycles that have none in it). NaN
    ignored. Built once per x (the samples' columns, the crossings and their weights, each sorted by column), then
    called with each column's values: an hour's run at 1 degree (1.1 million rows, 3060 cycles) is 2.6 million
    crossings a line."""

    def __init__(self, x: np.ndarray, line: np.ndarray, columns: int):
        ok = np.isfinite(x)
        self.columns = columns
        self.edges = np.linspace(np.min(x[ok]), np.max(x[ok]), columns + 1)
        key = np.uint16 if columns < 2**16 else np.int64          # (a radix sort of 16-bit keys: linear time)
        rows = np.flatnonzero(ok)
        column = np.clip(np.searchsorted(self.edges, x[rows], side="right") - 1, 0, columns - 1)
        order = np.argsort(column.astype(key), kind="stable")
        self.samples, self.sample_columns, self.sample_starts = rows[order], *self._runs(column[order])
        i = np.flatnonzero((line[1:] == line[:-1]) & ok[1:] & ok[:-1])          # the segments of each line
        x0, x1 = x[i], x[i + 1]
        first = np.searchsorted(self.edges, np.minimum(x0, x1), side="right")   # the edges strictly inside one
        n = np.maximum(np.searchsorted(self.edges, np.maximum(x0, x1), side="left") - first, 0)
        seg = np.repeat(np.arange(len(i)), n)
        edge = np.repeat(first - np.cumsum(n) + n, n) + np.arange(int(n.sum()))
        order = np.argsort(edge.astype(key), kind="stable")
        seg, edge = seg[order], edge[order]
        self.crossing_rows = i[seg]
        self.crossing_weights = (self.edges[edge] - x0[seg]) / (x1[seg] - x0[seg])
        self.crossing_edges, self.crossing_starts = self._runs(edge)

    @staticmethod
    def _runs(sorted_keys: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """(each distinct key, where its run starts) of sorted keys."""
        starts = np.flatnonzero(np.r_[True, sorted_keys[1:] != sorted_keys[:-1]]) if len(sorted_keys) else \
            np.zeros(0, np.int64)
        return sorted_keys[starts], starts

    def __call__(self, y: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        """(column edges, min, max) of the lines with values y."""
        lo, hi = np.full(self.columns, np.nan), np.full(self.columns, np.nan)
        if len(self.samples):
            v = y[self.samples]
            lo[self.sample_columns] = np.fmin.reduceat(v, self.sample_starts)
            hi[self.sample_columns] = np.fmax.reduceat(v, self.sample_starts)
        if len(self.crossing_rows):
            a, b = y[self.crossing_rows], y[self.crossing_rows + 1]
            with np.errstate(invalid="ignore"):
                at = a + self.crossing_weights * (b - a)
            low, high = np.fmin.reduceat(at, self.crossing_starts), np.fmax.reduceat(at, self.crossing_starts)
            for c in (self.crossing_edges - 1, self.crossing_edges):   # an edge bounds the columns on both sides
                inside = (c >= 0) & (c < self.columns)
                lo[c[inside]] = np.fmin(lo[c[inside]], low[inside])
                hi[c[inside]] = np.fmax(hi[c[inside]], high[inside])
        return self.edges, lo, hi


def trace(ax, x: np.ndarray, y: np.ndarray, columns: int, color: str, **style) -> bool:
    """Draw y against x (sorted) on ax: a line, or where there are more than ROWS_PER_COLUMN samples per pixel
    column, the envelope (min to max in each column: a band whose edges are a line where the signal is smooth,
    the swing of the signal where it oscillates faster than a pixel). True where it drew an envelope."""
    if len(x) <= ROWS_PER_COLUMN * columns:
        ax.plot(x, y, color=color, **style)
        return False
    from matplotlib.colors import to_rgba
    edges, lo, hi = envelope(x, y, columns)
    xs = np.repeat(edges, 2)[1:-1]
    colour = color
    style.pop("lw", None)
    ax.fill_between(xs, np.repeat(lo, 2), np.repeat(hi, 2), facecolor=to_rgba(colour, 0.45), edgecolor=colour,
                    linewidth=0.6, **style)
    return True


def artist_colours(ax) -> dict[str, str]:
    """{column: colour} of what `time_figure` and `angle_figure` drew on ax, lines and envelopes alike (keyed by
    their gid, less any '#...' part), for a caller that overlays more in the same colours."""
    from matplotlib.colors import to_hex
    out = {}
    for artist in [*ax.get_lines(), *ax.collections]:
        gid = artist.get_gid()
        if gid:
            colour = artist.get_color() if hasattr(artist, "get_xdata") else to_hex(artist.get_edgecolor()[0])
            out.setdefault(gid.split("#")[0], colour)
    return out


#: a column that grows without bound toward an event is drawn to the height it reaches this share of the run (of
#: the cycle, against angle) away from those events, and clipped nearer
POLE_GUARD = 0.02


def poles_of(summary: dict) -> dict[str, np.ndarray]:
    """{column: the instants of the events it grows without bound toward} (the summary's peaks, `singular`:
    docs/theory.md §K5), for the columns that have any."""
    out = {}
    for column, entry in (summary.get("peaks") or {}).items():
        times = sorted({float(s["t_s"]) for s in entry.get("singular") or () if s.get("t_s") is not None})
        if times:
            out[column] = np.array(times)
    return out


def clip_poles(ax, runs: list[tuple[np.ndarray, list[tuple[str, str, np.ndarray]], dict[str, np.ndarray]]],
               guard: float) -> None:
    """Where a line's column grows without bound toward events, the panel's y-range is what its lines reach
    farther than `guard` from those events, each event is marked by a dotted line and the panel says so: the rows
    next to a pole reach a height set by how near the last row fell to it (the chain's coupler force 3 to 83 N
    before four alike stops at 10 ms rows), which is no property of the design. Every line of a run that has such
    a column is ranged so (the chain's joint force, no located column, shares the coupler force's pole).
    runs: per run drawn on the panel (one, or a comparison's two), (its x, its lines as (column, label, values as
    drawn at x), its poles: {column: the events' x}, `poles_of`)."""
    names, marks, kept = {}, [], []
    for x, lines, poles in runs:
        own = []
        for c, label, _ in lines:
            if c in poles:
                names.setdefault(label, None)           # (each column named once, in the panel's order)
                own.append(poles[c])
        at = np.unique(np.concatenate(own)) if own else np.zeros(0)
        far = np.ones(len(x), dtype=bool)
        if len(at):
            i = np.clip(np.searchsorted(at, x), 1, max(len(at) - 1, 1))
            far = np.minimum(np.abs(x - at[i - 1]), np.abs(x - at[np.minimum(i, len(at) - 1)])) > guard
        marks.append(at)
        kept += [y[far & np.isfinite(y)] for _, _, y in lines]
    marks = np.unique(np.concatenate(marks)) if marks else np.zeros(0)
    if not len(marks):
        return
    # (the same place of two runs' cycles, read from each run's rows, is one mark)
    marks = marks[np.r_[True, np.diff(marks) > 1e-6 * max(float(np.ptp(marks)), guard)]]
    kept = [y for y in kept if len(y)]
    if kept:
        lo, hi = min(float(y.min()) for y in kept), max(float(y.max()) for y in kept)
        pad = 0.08 * (hi - lo) if hi > lo else max(abs(hi), 1.0) * 0.1
        ax.set_ylim(lo - pad, hi + pad)
    ax.vlines(marks, 0.0, 1.0, transform=ax.get_xaxis_transform(), colors="0.45", linestyles=":", linewidths=0.9,
              zorder=0, label="_poles")        # (a collection without gid: no column's line among the data's)
    ax.text(0.005, 0.98, f"{', '.join(names)}: grows without bound toward {len(marks)} "
            f"event{'s' if len(marks) != 1 else ''} (dotted); drawn clipped near them", transform=ax.transAxes,
            ha="left", va="top", fontsize=8, color="0.3")


def poles_in_cycle(poles: dict[str, np.ndarray], t: np.ndarray, drive: np.ndarray,
                   cycle: DriveCycle) -> dict[str, np.ndarray]:
    """`poles_of`'s instants as places in the drive cycle (deg, the x of `angle_figure`), sorted (each instant's own
    place: not `cycle_index`, whose last row closes the cycle before it)."""
    return {c: np.sort((np.mod(np.interp(p, t, drive) - cycle.start, cycle.period) + cycle.start) * DEG)
            for c, p in poles.items()}


def time_figure(df: pd.DataFrame, figure: str, title: str, rows: list[dict] | None = None,
                poles: dict[str, np.ndarray] | None = None) -> Figure | None:
    """One panel per unit against time (the panels of `figure`, or `rows` as `column_panels` makes them); a
    line with more rows than ROWS_PER_COLUMN per pixel column as its envelope (`trace`), which the title says.
    poles: {column: instants} of the events a column grows without bound toward (`poles_of`), drawn clipped
    (`clip_poles`)."""
    rows = panels(df, figure) if rows is None else rows
    if not rows:
        return None
    fig = Figure(figsize=(10, 2.4 * len(rows) + 0.8), layout="constrained")
    axes = fig.subplots(len(rows), 1, sharex=True, squeeze=False)[:, 0]
    t = df["t_s"].to_numpy(float)
    enveloped = False
    for ax, panel in zip(axes, rows):
        drawn = []
        for j, (col, label) in enumerate(panel["lines"]):
            y = df[col].to_numpy(float) * panel["scale"]
            enveloped |= trace(ax, t, y, pixel_columns(fig, ax), f"C{j % 10}", lw=1.0, label=label, gid=col)
            drawn.append((col, label, y))
        if poles and len(t) > 1:
            clip_poles(ax, [(t, drawn, poles)], POLE_GUARD * (t[-1] - t[0]))
        ax.set_ylabel(f"{panel['quantity']} ({panel['unit']})")
        ax.grid(alpha=0.3)
        legend_outside(ax)
    axes[-1].set_xlabel("time (s)")
    fig.suptitle(f"{title}\n({ENVELOPE_NOTE}; {len(t):,} rows)" if enveloped else title)
    return fig


def cycle_index(angle: np.ndarray, cycle: DriveCycle) -> tuple[np.ndarray, np.ndarray]:
    """(cycle number, angle within the cycle in rad measured from the cycle's start) of every row."""
    if cycle.period is None:
        return np.zeros(len(angle), int), angle - cycle.start
    k = np.floor((angle - cycle.start) / cycle.period + 1e-12).astype(int)
    if len(k) > 1 and k[-1] != k[-2]:   # a run that ends where a cycle starts closes the previous one
        k[-1] = k[-2]
    return k, angle - cycle.start - k * cycle.period


#: above this many cycles, the angle figures draw the envelope over all cycles and the last cycle as a line
MAX_CYCLE_LINES = 40


@dataclass(frozen=True)
class Cycles:
    """A run's rows split into its drive cycles, as the angle figures draw them: x (deg, the drive angle within
    its cycle from the cycle's start angle), k (each row's cycle), bounds (row spans), last (the last complete
    cycle's rows, drawn as a line among many)."""

    cycle: DriveCycle
    drive: np.ndarray
    x: np.ndarray
    k: np.ndarray
    bounds: np.ndarray
    last: tuple[int, int]
    envelopes: dict = field(default_factory=dict, compare=False)     # LinesEnvelope by pixel columns

    @classmethod
    def of(cls, drive: np.ndarray, cycle: DriveCycle) -> "Cycles":
        k, within = cycle_index(drive, cycle)
        bounds = np.r_[0, np.flatnonzero(np.diff(k)) + 1, len(k)]
        spans = list(zip(bounds[:-1], bounds[1:]))
        complete = [(a, b) for a, b in spans if cycle.period and np.ptp(within[a:b]) >= 0.98 * cycle.period]
        return cls(cycle, drive, (within + cycle.start) * DEG, k, bounds, (complete or spans)[-1])

    @property
    def count(self) -> int:
        return len(self.bounds) - 1

    @property
    def many(self) -> bool:
        return self.count > MAX_CYCLE_LINES

    def draw(self, ax, fig: Figure, panel: dict, col: str, y: np.ndarray, label: str, colour, gid: str,
             ls: str = "-") -> None:
        """Column `col` (values y, in the panel's unit) against the angle on ax: a line per cycle, later cycles
        darker; above MAX_CYCLE_LINES cycles, the envelope over all of them (`LinesEnvelope`) and the last
        complete cycle as a line. An angle is shown as its change since its cycle started."""
        from matplotlib.colors import to_rgba
        bounds, x, k = self.bounds, self.x, self.k
        if panel["unit"] == "deg" and col.endswith("_angle_rad"):
            y = y - np.repeat([cycle_start_value(self.drive, y, a, b, self.cycle)
                               for a, b in zip(bounds[:-1], bounds[1:])], np.diff(bounds))
        if self.many:
            columns = pixel_columns(fig, ax)
            if columns not in self.envelopes:
                self.envelopes[columns] = LinesEnvelope(x, k, columns)
            edges, lo, hi = self.envelopes[columns](y)
            xs = np.repeat(edges, 2)[1:-1]
            ax.fill_between(xs, np.repeat(lo, 2), np.repeat(hi, 2), facecolor=to_rgba(colour, 0.3),
                            edgecolor=to_rgba(colour, 0.6), linewidth=0.5, linestyle=ls, gid=f"{gid}#envelope",
                            label=f"{label}, all cycles (envelope)")
            a, b = self.last
            ax.plot(x[a:b], y[a:b], lw=1.0, ls=ls, color=colour, gid=f"{gid}#cycle{k[a]}",
                    label=f"{label}, last cycle")
            return
        for n, (a, b) in enumerate(zip(bounds[:-1], bounds[1:])):
            ax.plot(x[a:b], y[a:b], lw=1.0, ls=ls, color=colour, alpha=0.35 + 0.65 * (n + 1) / self.count,
                    gid=f"{gid}#cycle{k[a]}", label=label if n == self.count - 1 else "_nolegend_")


def angle_figure(df: pd.DataFrame, figure: str, title: str, cycle: DriveCycle,
                 rows: list[dict] | None = None, poles: dict[str, np.ndarray] | None = None) -> Figure | None:
    """One panel per unit against the driven member's angle within its cycle, a line per cycle (later cycles
    darker); above MAX_CYCLE_LINES cycles, the envelope over all of them (min to max per pixel column of the
    angle) with the last cycle as a line. Angles of the other members are shown as their change since the cycle
    started. The panels of `figure`, or `rows` as `column_panels` makes them. poles: as `time_figure`'s, each
    event at its place in the cycle."""
    rows = panels(df, figure, exclude=(cycle.column,)) if rows is None else rows
    if not rows or cycle.column not in df:
        return None
    drive = df[cycle.column].to_numpy(float)
    cycles = Cycles.of(drive, cycle)
    x, x0 = cycles.x, cycle.start * DEG
    fig = Figure(figsize=(10, 2.4 * len(rows) + 0.9), layout="constrained")
    axes = fig.subplots(len(rows), 1, sharex=True, squeeze=False)[:, 0]
    if poles and cycle.period:          # each pole at its place in the cycle, as the rows' x
        poles = poles_in_cycle(poles, df["t_s"].to_numpy(float), drive, cycle)
    for ax, panel in zip(axes, rows):
        drawn = []
        for j, (col, label) in enumerate(panel["lines"]):
            y = df[col].to_numpy(float) * panel["scale"]
            drawn.append((col, label, y))
            cycles.draw(ax, fig, panel, col, y, label, f"C{j % 10}", col)
        if poles and cycle.period:
            clip_poles(ax, [(x, drawn, poles)], POLE_GUARD * cycle.period * DEG)
        since = "the cycle start" if cycle.period else "the start"
        quantity = f"angle turned since {since}" if panel["unit"] == "deg" else panel["quantity"]
        ax.set_ylabel(f"{quantity} ({panel['unit']})")
        ax.grid(alpha=0.3)
        legend_outside(ax)
    axes[-1].set_xlim(*((x0, x0 + cycle.period * DEG) if cycle.period else (np.nanmin(x), np.nanmax(x))))
    axes[-1].set_xlabel(cycle.label)
    n = cycles.count
    if not cycle.period:
        fig.suptitle(f"{title}\n(no period: the whole run)")     # the note on a line of its own, as time figures'
    elif cycles.many:
        fig.suptitle(f"{title}\n({n:,} cycles: their envelope, min to max per pixel column, and the last complete one as a line)")
    else:
        fig.suptitle(f"{title}\n({n} cycle{'s' if n != 1 else ''}, a line each, later darker)")
    return fig


def cycle_start_value(drive: np.ndarray, y: np.ndarray, a: int, b: int, cycle: DriveCycle) -> float:
    """The value of y where this cycle started (interpolated in the drive angle; the first rows if the run
    began inside the cycle)."""
    if a == 0 or cycle.period is None:
        return float(y[a])
    start = cycle.start + math.floor((drive[a] - cycle.start) / cycle.period + 1e-12) * cycle.period
    if a > 0:
        return float(np.interp(start, drive[a - 1:a + 1], y[a - 1:a + 1]))
    return float(y[a])


def drawing_figure(df: pd.DataFrame, mech, instants: int, cycle: DriveCycle | None) -> Figure | None:
    """The mechanism at `instants` over the last complete cycle of the run (over the run if no cycle): evenly over
    the contact and once in the contact-free part (`_instants`), the nearest of them moved to the row of the largest
    force in that stretch (the arrows are drawn to one scale: evenly spaced instants may all fall where the
    force is a hundredth of it), its panel titled so."""
    from mechsim.scenarios.output.drawings import drawing_for
    drawing_class = mech.drawing_class() if mech is not None else None
    if drawing_class is None or not instants or not len(df):
        return None
    if cycle is not None and cycle.period and cycle.column in df:
        k, within = cycle_index(df[cycle.column].to_numpy(float), cycle)
        complete = [c for c in np.unique(k) if np.ptp(within[k == c]) >= 0.98 * cycle.period]
        last = np.flatnonzero(k == (complete[-1] if complete else k[-1]))
        idx = _instants(df.iloc[last], instants, drawing_class.force_column) + last[0]
    else:
        last = np.arange(len(df))
        idx = np.linspace(0, len(df) - 1, instants).astype(int)
    peak = _largest_force_row(df, drawing_class.force_column, last)
    idx = _with_row(np.asarray(idx, dtype=int), peak)
    fig = Figure(figsize=(3.6 * instants, 3.9), layout="constrained")
    axes = fig.subplots(1, instants, squeeze=False)[0]
    for ax, i in zip(axes, idx):
        row = df.iloc[i]
        drawing = drawing_for(ax, mech, df)
        drawing.update(row)
        where = f", {cycle.column.split('_')[0]} {math.degrees(float(row[cycle.column])):.0f}°" if cycle else ""
        ax.set_title(f"t = {row['t_s']:.3f} s{where}" + ("\nits largest force" if i == peak else ""), fontsize=9)
    note = (f"mechanism (mm); arrow: {drawing_class.force_label}, one scale (the run's 99th percentile force at "
            f"full length, longer ones cut at {ARROW_CLIP:g}x)")
    fig.suptitle(textwrap.fill(note, 26 * instants))        # (as wide as the panels allow: 3.6 in each)
    return fig


def _largest_force_row(df: pd.DataFrame, force_column: str | None, rows: np.ndarray) -> int | None:
    """The row among `rows` where |force| is largest (the drawing's arrow at full length), None where the force is
    nowhere finite and nonzero."""
    if force_column not in df or not len(rows):
        return None
    f = np.abs(df[force_column].to_numpy(float)[rows])
    if not np.isfinite(f).any() or not np.nanmax(f) > 0:
        return None
    return int(rows[int(np.nanargmax(f))])


def _with_row(idx: np.ndarray, row: int | None) -> np.ndarray:
    """The drawing's rows with `row` in place of the nearest of them (kept in order), so one panel shows the
    largest force the arrow is scaled to."""
    if row is None or not len(idx) or row in idx:
        return idx
    out = idx.copy()
    out[int(np.argmin(np.abs(idx - row)))] = row
    return np.sort(out)


def _instants(rows: pd.DataFrame, n: int, force_column: str | None) -> np.ndarray:
    """Row positions of `n` drawings in one cycle: evenly over the rows in contact (force != 0) and one farthest
    from contact where the cycle has a contact-free part (mid-dwell of a Geneva), else evenly over the cycle."""
    force = rows[force_column].to_numpy(float) if force_column in rows else np.ones(len(rows))
    contact = np.flatnonzero(force != 0)
    free = np.flatnonzero(force == 0)
    if n < 2 or not len(contact) or not len(free):
        return ((np.arange(n) + 0.5) * len(rows) / n).astype(int)
    picks = contact[((np.arange(n - 1) + 0.5) * len(contact) / (n - 1)).astype(int)]
    gap = np.abs(free[:, None] - contact[None, :])
    farthest = free[np.argmax(np.minimum(gap, len(rows) - gap).min(axis=1))]   # the cycle wraps around
    return np.sort(np.r_[picks, farthest])


def figure_makers(result: Result, mechanism=None) -> list:
    """The figures of a run as functions that build them, in order: each returns {file stem: Figure} (empty where
    the run has nothing to show), so a caller may build them apart (scenarios/output/writer.py renders them in
    two processes). Stems: <group>_vs_time, <group>_vs_angle, mechanism, and the mechanism's own figures (chain:
    El-Shakery's kinematics figures). `mechanism` defaults to the scenario's."""
    df = result.timeseries
    if mechanism is None and result.scenario:
        from mechsim.scenarios.loader import build_mechanism
        mechanism = build_mechanism(result.scenario)
    if not len(df):
        return []
    name = result.summary.get("scenario", "")
    cycle = mechanism.drive_cycle() if mechanism is not None else None

    def one(stem, build, *args):
        def make():
            return {stem: fig} if (fig := build(*args)) is not None else {}
        make.stem = stem            # names the figure in a warning if it cannot be drawn (render.save_or_skip)
        return make

    makers = []
    poles = poles_of(result.summary)
    for group in FIGURES:
        rows = with_impacts(df, result.events) if group == "energy" else df
        makers.append(one(f"{group}_vs_time", time_figure, rows, group, f"{name}: {group}", None, poles))
        if cycle is not None and group in PER_CYCLE:
            makers.append(one(f"{group}_vs_angle", angle_figure, df, group, f"{name}: {group}", cycle, None, poles))
    instants = result.scenario.get("output", {}).get("drawing_instants", 4)
    makers.append(one("mechanism", drawing_figure, df, mechanism, instants, cycle))
    if mechanism is not None:
        makers.append(lambda: mechanism.extra_figures(df, result.extra_tables))
    return makers


def with_impacts(df: pd.DataFrame, events: pd.DataFrame | None) -> pd.DataFrame:
    """The rows with `work_impacts_J`, the work the impacts did on the system up to each row (minus the energy they
    took, dynamics/invariants.py `impact_losses`), where the run lost energy in impacts and has work columns: the
    energy figure's works then add up to the kinetic energy's change, as summary.json's energy balance (docs/api.md)."""
    if not any(c.startswith("work_") for c in df.columns) or "t_s" not in df:
        return df
    from mechsim.dynamics.invariants import impact_losses
    lost = impact_losses(df["t_s"].to_numpy(float), events)
    return df if lost is None or not lost.any() else df.assign(work_impacts_J=-lost)


def figures(result: Result, mechanism=None) -> dict[str, Figure]:
    """Every figure of a run by file stem (`figure_makers`, all built)."""
    return {stem: fig for make in figure_makers(result, mechanism) for stem, fig in make().items()}


def save(fig: Figure, path: Path) -> Path:
    """Write one figure as PNG (Agg canvas, no pyplot state), drawn once: `savefig` draws a figure that has a
    layout engine twice (a draw without rendering for the layout, then the real one). Here the layout is executed
    once at the PNG's dpi, the axes stay where it put them, and the canvas is drawn once and encoded by
    scenarios/output/png.py: the same pixels and metadata as `savefig`, about 15 % less CPU per figure for the
    single draw and as much again for the encoding (docs/benchmarks.md, "Cold start")."""
    from mechsim.scenarios.output.png import write_png
    canvas = FigureCanvasAgg(fig)
    engine = fig.get_layout_engine()
    fig.set_dpi(DPI)
    if engine is not None and fig.axes:
        engine.execute(fig)
        fig.set_layout_engine("none")
    canvas.draw()
    return write_png(canvas.buffer_rgba(), path, DPI)


def write_plots(result: Result, folder: Path, mechanism=None) -> list[Path]:
    """Save every figure of `figures` as <stem>.png in `folder`."""
    return [save(fig, Path(folder) / f"{stem}.png") for stem, fig in figures(result, mechanism).items()]
