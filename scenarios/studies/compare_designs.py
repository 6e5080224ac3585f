"""Two designs side by side (`mechsim compare A B`, `mechsim.compare(a, b)`): each a scenario to run or a saved
result folder; their headline figures as one table and their columns overlaid in figures.

The headline figures are read from each run's summary, as the sweep table names them (scenarios/studies/sweep/
rows.py): the located peaks `peak_max_<column>` / `peak_min_<column>` (the periodic regime's where a run reaches
one, the start-up's beside them as `startup_peak_...`; docs/theory.md §K5), the cycle means `cycle_mean_<column>`
(over the periodic regime's last turn where the run has one, else over the last complete drive cycle, each
located on the continuous solution; the trapezoidal mean of the output rows only for a run that has no
continuous solution to read, as one that failed), the cycle time and the work of each power flow per cycle, the
heat generated (`thermal_heat_generated_J`), and the validity conditions' worst values and violated shares
(docs/limits.md). Each row holds both values, the difference b - a, the relative difference (b - a) / |a| and
whether the runs resolve that difference (`resolved`: it exceeds their accuracy, scenarios/studies/resolution.py;
two designs whose figure is the same closed form differ by the integrator's error, which is no difference between
them, and the notes name those); the quantity's name ends in its unit. A figure of A that is zero at A's accuracy
(`zero_levels`: the mean acceleration over a periodic turn, a dwell's least speed) has no relative difference (NaN,
named in the notes): its |a| is the integrator's error, and a ratio to it is noise.

Runs of different mechanisms share only some columns: what both have is compared, what one lacks is listed
(`only_a`, `only_b`); nothing in common is a user error.
"""
from __future__ import annotations

import math
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np
import pandas as pd

from mechsim.scenarios.studies.resolution import (EXACT_FIGURES, TOLERANCES_RESOLVED, column_scale, figure_column,
                                                     floor)
from mechsim.scenarios.units import ScenarioError

#: the table's columns: the quantity (its name ends in its unit), both values, b - a, (b - a) / |a| and whether the
#: runs resolve b - a
COLUMNS = ("quantity", "a", "b", "difference", "relative_difference", "resolved")
#: the two sides, as notes and figure legends name them
SIDES = ("A", "B")


def _number(value) -> float:
    """A summary value as a float (None, e.g. a peak that grows without bound toward an event: NaN)."""
    return math.nan if value is None else float(value)


def _last_cycle(t: np.ndarray, angle: np.ndarray, cycle) -> tuple[float, float] | None:
    """(start, end) times of the last complete drive cycle (the drive angle passing cycle.start + k period), or None
    where the drive angle does not advance monotonically through one."""
    if cycle is None or not cycle.period or len(t) < 2:
        return None
    sign = 1.0 if angle[-1] >= angle[0] else -1.0
    a = sign * angle
    if not np.all(np.diff(a) > 0):
        return None
    lo, hi = sorted(((angle[0] - cycle.start) / cycle.period, (angle[-1] - cycle.start) / cycle.period))
    ks = np.arange(math.ceil(lo - 1e-12), math.floor(hi + 1e-12) + 1)
    if len(ks) < 2:
        return None
    ends = cycle.start + cycle.period * (ks[-2:] if sign > 0 else ks[:2][::-1])
    t0, t1 = np.interp(sign * ends, a, t)
    return float(t0), float(t1)


def headline(result) -> dict[str, float]:
    """The headline figures of one run (module docstring), keyed by quantity name (`<quantity>_<unit>`)."""
    from mechsim.scenarios.peaks import turn_mean
    from mechsim.scenarios.studies.sweep.rows import cycle_figures
    s, df = result.summary, result.timeseries
    out: dict[str, float] = {}
    peaks = s.get("peaks") or {}
    for col, e in peaks.items():
        for side in ("max", "min"):
            out[f"peak_{side}_{col}"] = _number(e[side]["value"])
    for col, e in peaks.items():
        for side in ("max", "min"):
            if side in (e.get("startup") or {}):
                out[f"startup_peak_{side}_{col}"] = _number(e["startup"][side]["value"])
    cycle = result.mechanism.drive_cycle() if result.mechanism is not None else None
    window = None
    if cycle is not None and cycle.column in df and "t_s" in df:
        window = _last_cycle(df["t_s"].to_numpy(float), df[cycle.column].to_numpy(float), cycle)
    for col, e in peaks.items():
        located = e.get("periodic") or e.get("cycle")
        if located is not None and located.get("unbounded"):
            out[f"cycle_mean_{col}"] = math.nan         # a pole in the turn: no finite mean, as a peak's (`_number`)
            continue
        if located is not None:
            mean = _number(located["mean"])
        elif window is not None and col in df:
            mean = turn_mean(df["t_s"].to_numpy(float), df[col].to_numpy(float), *window)
        else:
            continue
        if math.isfinite(mean):                 # a column defined only in contact (NaN between) has no cycle mean
            out[f"cycle_mean_{col}"] = mean
    if cycle is not None and cycle.column in df:
        speed = cycle.column[:-len("_angle_rad")] + "_speed_rad_s" if cycle.column.endswith("_angle_rad") else None
        mech = result.mechanism
        drive = (mech is not None and mech.drive_coordinate in mech.angle_coordinates
                 and cycle.column == f"{mech.coordinates[mech.drive_coordinate]}_angle_rad")
        for name, value in cycle_figures(df, cycle.column, s.get("regime") if drive else None, speed).items():
            if name != "cycles" and not (isinstance(value, float) and math.isnan(value)):
                out[name] = float(value)
    balance = (s.get("thermal") or {}).get("heat_balance") or {}
    if "generated_J" in balance:
        out["thermal_heat_generated_J"] = float(balance["generated_J"])
    validity = s.get("validity") or {}
    if validity.get("conditions"):
        out["validity_violated_conditions"] = float(len(validity.get("violated") or []))
    for c in validity.get("conditions") or []:
        if not c.get("evaluated") or not c.get("worst"):
            continue
        from mechsim.scenarios.keys import unit_suffix
        unit = f"_{unit_suffix(c['unit'])}" if c.get("unit") else ""
        out[f"validity_{c['name']}_worst{unit}"] = _number(c["worst"].get("value"))
        out[f"validity_{c['name']}_violated_share"] = _number(c.get("violated_share"))
    return out


def run_scales(result) -> tuple[float, dict[str, float]]:
    """A run's rtol (0 where it has none) and, per column with located peaks, its largest finite |peak|: what its
    figures' accuracy is measured in (scenarios/studies/resolution.py)."""
    s = result.summary
    rtol = (s.get("model") or {}).get("rtol") or ((result.scenario or {}).get("solver") or {}).get("rtol") or 0.0
    scales = {}
    for col, e in (s.get("peaks") or {}).items():
        values = [abs(_number(e[side]["value"])) for side in ("max", "min") if side in e]
        values = [v for v in values if math.isfinite(v)]
        if values:
            scales[col] = column_scale(col, max(values))
    return float(rtol), scales


def zero_levels(result) -> dict[str, float]:
    """Per column with located peaks: the size below which a figure read from it is zero at the run's accuracy."""
    rtol, scales = run_scales(result)
    return {col: floor(rtol, scale) for col, scale in scales.items()} if rtol else {}


def difference_floor(quantity: str, a: float, b: float, scales_a: tuple, scales_b: tuple) -> float:
    """The smallest b - a of `quantity` that both runs resolve (`run_scales` of each): the larger rtol of the larger
    scale, a column's largest |peak| for a figure read from it, else the figure's own larger magnitude; 0 for a
    count."""
    if quantity in EXACT_FIGURES:
        return 0.0
    column = figure_column(quantity)
    scales = [sc[1][column] for sc in (scales_a, scales_b) if column in sc[1]]
    if not scales:
        scales = [abs(v) for v in (a, b) if math.isfinite(v)]
    return floor(max(scales_a[0], scales_b[0]), max(scales, default=0.0))


def _zero_level(quantity: str, a: float, b: float, zero_a: dict[str, float]) -> float | None:
    """A's zero level of the quantity's column where a differs from b and is nonzero but within it (the figure
    has no relative difference), else None."""
    level = zero_a.get(figure_column(quantity))
    return level if level is not None and a != b and a != 0 and abs(a) <= level else None


def _resolved(a: float, b: float, level: float) -> bool:
    """Whether b differs from a by more than `level` (one value NaN and the other not differs; two NaN do not)."""
    if math.isnan(a) or math.isnan(b):
        return math.isnan(a) != math.isnan(b)
    return abs(b - a) > level


def headline_table(a: dict[str, float], b: dict[str, float], zero_a: dict[str, float] | None = None,
                   floors: dict[str, float] | None = None) -> pd.DataFrame:
    """One row per quantity both runs have (in a's order): both values, b - a, (b - a) / |a| (0 where both are
    equal, NaN where a is 0 and b is not, or where |a| is within A's zero level of its column, `zero_a`), and
    whether |b - a| exceeds the quantity's floor (`difference_floor`; 0 where `floors` lacks it)."""
    zero_a, floors = zero_a or {}, floors or {}
    rows = []
    for q, x in a.items():
        if q not in b:
            continue
        y = b[q]
        d = y - x
        rel = (0.0 if d == 0 else math.nan) if x == 0 else d / abs(x)
        if _zero_level(q, x, y, zero_a) is not None:
            rel = math.nan
        rows.append((q, x, y, d, rel, _resolved(x, y, floors.get(q, 0.0))))
    return pd.DataFrame(rows, columns=list(COLUMNS)).astype({c: float for c in COLUMNS[1:-1]} | {"resolved": bool})


def within_accuracy(table: pd.DataFrame) -> list[str]:
    """The table's quantities whose values differ, but by no more than the runs resolve."""
    return [r.quantity for r in table.itertuples() if r.difference != 0 and not r.resolved
            and not (math.isnan(r.a) and math.isnan(r.b))]


def zero_figures(table: pd.DataFrame, zero_a: dict[str, float]) -> list[str]:
    """The table's quantities with no relative difference because A's value is zero at A's accuracy, with both
    sizes."""
    out = []
    for r in table.itertuples():
        level = _zero_level(r.quantity, r.a, r.b, zero_a)
        if level is not None:
            out.append(f"{r.quantity} (|A| = {abs(r.a):.2g} <= {level:.2g})")
    return out


@dataclass
class Comparison:
    """Two runs side by side: `table` (one row per headline quantity both have: a, b, difference, relative
    difference), `a` and `b` (the Results), their `names`, `only_a` / `only_b` (columns and headline quantities one
    run has and the other lacks), `notes` (what a reader must know: different regimes, failures, figures not
    folded). `plot()` the overlaid figures; `save(folder)` the table, the notes and the figures."""

    a: object
    b: object
    names: tuple[str, str]
    table: pd.DataFrame
    only_a: list[str] = field(default_factory=list)
    only_b: list[str] = field(default_factory=list)
    notes: list[str] = field(default_factory=list)

    def __repr__(self) -> str:
        return (f"<mechsim.Comparison A={self.names[0]!r} B={self.names[1]!r}: {len(self.table)} quantities, "
                f"{len(self.common_columns())} common columns>")

    def common_columns(self) -> list[str]:
        """The timeseries columns both runs have (in a's order)."""
        return [c for c in self.a.timeseries.columns if c in self.b.timeseries.columns]

    def _cycles(self):
        """(cycle of a, cycle of b) where both fold over the same drive angle column, else None."""
        ca, cb = (r.mechanism.drive_cycle() if r.mechanism is not None else None for r in (self.a, self.b))
        if ca is None or cb is None or ca.column != cb.column or (ca.period is None) != (cb.period is None):
            return None
        if ca.column not in self.a.timeseries or cb.column not in self.b.timeseries:
            return None
        return ca, cb

    def plot(self, which=None, x: str = "time"):
        """Overlaid figures, A solid and B dashed in the same colour. which None: every figure group of a run's
        figures (motion, forces, thermal, energy against time; motion, forces, thermal folded per drive cycle where
        both runs fold over the same angle), keyed by name (`forces_vs_time`, ...). which a column or columns: one
        Figure of them against time, or x="angle" per drive cycle. KeyError for a column not in both runs."""
        from mechsim.scenarios.output.plots import FIGURES, PER_CYCLE, column_panels, panels
        if x not in ("time", "angle"):
            raise ValueError(f"plot(x={x!r}): x is \"time\" or \"angle\"")
        common = self.common_columns()
        title = f"{self.names[0]} (A, solid) vs {self.names[1]} (B, dashed)"
        if which is not None:
            wanted = [which] if isinstance(which, str) else list(which)
            missing = [w for w in wanted if w not in common]
            if missing or not wanted:
                raise KeyError(f"no column {', '.join(map(repr, missing)) or '(none given)'} in both runs; their "
                               f"common columns: {', '.join(common)}")
            rows = column_panels(self.a.timeseries, wanted)
            if x == "time":
                return self._time(rows, title)
            if self._cycles() is None:
                raise ValueError("plot(x=\"angle\"): the two runs do not fold over the same drive angle; use "
                                 "x=\"time\"")
            return self._angle(rows, title)
        df = self.a.timeseries[common]
        figs = {}
        cycles = self._cycles()
        for group in FIGURES:
            rows = panels(df, group)
            if rows:
                figs[f"{group}_vs_time"] = self._time(rows, f"{group}: {title}")
            if cycles is not None and group in PER_CYCLE:
                rows = panels(df, group, exclude=(cycles[0].column,))
                if rows:
                    figs[f"{group}_vs_angle"] = self._angle(rows, f"{group}: {title}")
        return figs

    def _time(self, rows, title):
        from mechsim.scenarios.output.plots import (POLE_GUARD, artist_colours, clip_poles, pixel_columns, poles_of,
                                                    time_figure, trace)
        fig = time_figure(self.a.timeseries, "", title, rows=rows)
        ta, t = self.a.timeseries["t_s"].to_numpy(float), self.b.timeseries["t_s"].to_numpy(float)
        poles = poles_of(self.a.summary), poles_of(self.b.summary)
        span = max(ta[-1] - ta[0], t[-1] - t[0]) if len(ta) and len(t) else 0.0
        for ax, panel in zip(fig.axes, rows):
            colours = artist_colours(ax)              # a long run's lines are envelopes (plots.trace)
            for col, label in panel["lines"]:
                trace(ax, t, self.b.timeseries[col].to_numpy(float) * panel["scale"], pixel_columns(fig, ax),
                      colours[col], lw=1.0, ls="--", label=f"{label} (B)", gid=f"B:{col}")
            if any(poles) and span > 0:               # a column unbounded toward events in either run
                clip_poles(ax, _drawn(panel, [(ta, self.a.timeseries, poles[0]), (t, self.b.timeseries, poles[1])]),
                           POLE_GUARD * span)
            _relabel(ax)
        return fig

    def _angle(self, rows, title):
        from mechsim.scenarios.output.plots import (DEG, POLE_GUARD, Cycles, angle_figure, clip_poles,
                                                    cycle_index, poles_in_cycle, poles_of)
        ca, cb = self._cycles()
        fig = angle_figure(self.a.timeseries, "", title, ca, rows=rows)
        df = self.b.timeseries
        drive = df[cb.column].to_numpy(float)
        cycles = Cycles.of(drive, cb)
        # a column unbounded toward events in either run, each event at its place in its run's cycle
        da = self.a.timeseries
        drive_a = da[ca.column].to_numpy(float)
        poles = [poles_in_cycle(poles_of(r.summary), d["t_s"].to_numpy(float), dr, c) if c.period else {}
                 for r, d, dr, c in ((self.a, da, drive_a, ca), (self.b, df, drive, cb))]
        xa = (cycle_index(drive_a, ca)[1] + ca.start) * DEG
        for ax, panel in zip(fig.axes, rows):
            colours = {line.get_gid().split("#")[0]: line.get_color() for line in ax.get_lines()}
            for col, label in panel["lines"]:
                # as A's: a line per cycle, or the envelope of many and the last complete cycle, dashed
                cycles.draw(ax, fig, panel, col, df[col].to_numpy(float) * panel["scale"], label, colours[col],
                            f"B:{col}", ls="--")
            if any(poles) and panel["unit"] != "deg":       # (an angle panel shows turns since the cycle start)
                clip_poles(ax, _drawn(panel, [(xa, da, poles[0]), (cycles.x, df, poles[1])]),
                           POLE_GUARD * max(ca.period or 0.0, cb.period or 0.0) * DEG)
            _relabel(ax)
        return fig

    def save(self, folder: str | Path, force: bool = False, plots: bool = True) -> Path:
        """Write compare.csv (the table, full precision), compare.json (names, what one run lacks, the
        notes and the table) and with plots the overlaid figures as PNG, atomically (scenarios/output/atomic.py):
        all or nothing; an existing folder is replaced only with force and only if mechsim wrote it."""
        from mechsim.scenarios.output.atomic import atomic_folder
        from mechsim.scenarios.output.plots import save as save_png
        folder = Path(folder)
        figs = self.plot() if plots else {}
        with atomic_folder(folder, force) as tmp:
            (tmp / "compare.csv").write_text(self.table.to_csv(index=False, float_format="%.17g"))
            (tmp / "compare.json").write_text(render(self, "json"))
            for stem, fig in figs.items():
                save_png(fig, tmp / f"{stem}.png")
        return folder


def _drawn(panel: dict, runs: list[tuple]) -> list[tuple]:
    """`plots.clip_poles`' runs: per (x, table, poles), the panel's columns of that table as drawn at x."""
    return [(x, [(c, label, df[c].to_numpy(float) * panel["scale"]) for c, label in panel["lines"]], poles)
            for x, df, poles in runs]


def _relabel(ax) -> None:
    """Each run's lines named "(A)" or "(B)" (B's by their gid "B:..."), the legend redrawn (plots.py's
    placement)."""
    from mechsim.scenarios.output.plots import legend_outside
    for line in [*ax.get_lines(), *ax.collections]:           # lines, and the envelopes of long runs
        label, gid = line.get_label(), line.get_gid()
        if gid is None or label.startswith("_"):
            continue
        run = " (B)" if gid.startswith("B:") else " (A)"
        if not label.endswith(run):
            line.set_label(label + run)
    legend_outside(ax)


def _is_result_folder(arg: str) -> bool:
    """Whether a command-line argument names a result folder: an existing folder, unless a built-in scenario of
    that name wins (as `mechsim.load` reads a bare name; "./name" forces the folder)."""
    from mechsim.scenarios.loader import builtin_names
    path = Path(arg)
    if not path.is_dir():
        return False
    return "/" in arg or arg not in builtin_names()


def is_finished_run(arg) -> bool:
    """Whether one side of a comparison is a finished run: a Result, or a path naming a result folder."""
    from mechsim.dynamics.result import Result as RunResult
    return isinstance(arg, RunResult) or (isinstance(arg, (str, Path)) and _is_result_folder(str(arg)))


def compare_runs(ra, rb, name_a: str, name_b: str) -> Comparison:
    """Compare two finished runs labelled name_a and name_b (`mechsim.compare` runs or reads them; see the module
    docstring). ScenarioError where they have nothing in common."""
    if name_a == name_b and ra.scenario and rb.scenario:    # one scenario twice: the labels say what differs
        diff = _differences(ra.scenario, rb.scenario)
        if diff:
            name_a, name_b = (f"{name_a} with {', '.join(d)}" for d in zip(*diff))
    cols_a, cols_b = list(ra.timeseries.columns), list(rb.timeseries.columns)
    ha, hb = headline(ra), headline(rb)
    cols_only_a, cols_only_b = [c for c in cols_a if c not in cols_b], [c for c in cols_b if c not in cols_a]
    only_a = cols_only_a + [q for q in ha if q not in hb and not _of(q, cols_only_a)]
    only_b = cols_only_b + [q for q in hb if q not in ha and not _of(q, cols_only_b)]
    zero_a = zero_levels(ra)
    scales_a, scales_b = run_scales(ra), run_scales(rb)
    floors = {q: difference_floor(q, x, hb[q], scales_a, scales_b) for q, x in ha.items() if q in hb}
    table = headline_table(ha, hb, zero_a, floors)
    common = [c for c in cols_a if c in cols_b and c not in ("t_s", "mode")]
    if table.empty and not common:
        raise ScenarioError("compare", f"{name_a} and {name_b} have no column or headline figure in common "
                                       f"({ra.summary.get('mechanism', '?')} and {rb.summary.get('mechanism', '?')})")
    comparison = Comparison(ra, rb, (name_a, name_b), table, only_a, only_b)
    comparison.notes = _notes(comparison)
    if zeros := zero_figures(table, zero_a):
        comparison.notes.append(f"zero at A's accuracy ({TOLERANCES_RESOLVED:g} x rtol x the column's largest "
                                f"|peak|), so no relative difference: {', '.join(zeros)}")
    if equal := within_accuracy(table):
        comparison.notes.append(f"equal within the runs' accuracy ({TOLERANCES_RESOLVED:g} x the larger rtol x the "
                                f"column's largest |peak|, or x the figure for one not read from a column; "
                                f"resolved = False): {', '.join(equal)}")
    return comparison


def _differences(si_a: dict, si_b: dict) -> list[tuple[str, str]]:
    """[("key=value_a unit", "key=value_b unit")] for each scenario value (SI) that differs, name and description
    aside."""
    from mechsim.scenarios.keys import field_unit

    def flat(d: dict, prefix: str = "") -> dict:
        out = {}
        for k, v in d.items():
            out.update(flat(v, f"{prefix}{k}.") if isinstance(v, dict) else {f"{prefix}{k}": v})
        return out
    fa, fb = flat(si_a), flat(si_b)
    out = []
    for key in [k for k in fa if k not in ("name", "description")] + [k for k in fb if k not in fa]:
        x, y = fa.get(key), fb.get(key)
        if x != y:
            try:
                unit = f" {field_unit(si_a, key)}".rstrip() if key in fa and key in fb else ""
            except (KeyError, ValueError):
                unit = ""
            out.append(tuple(f"{key}={v:g}{unit}" if isinstance(v, float) else f"{key}={v}" for v in (x, y)))
    return out


def _of(quantity: str, columns: list[str]) -> bool:
    """Whether a headline quantity is read from one of `columns` (already listed as a column one run lacks)."""
    return any(quantity.endswith(f"_{c}") for c in columns)


def _notes(c: Comparison) -> list[str]:
    """What a reader of the table must know: what one run lacks, different regimes, failures, no folding."""
    notes = []
    ma, mb = (r.summary.get("mechanism", "?") for r in (c.a, c.b))
    if ma != mb:
        notes.append(f"different mechanisms ({ma}, {mb}): only what both have is compared")
    for side, only in (("A", c.only_a), ("B", c.only_b)):
        if only:
            notes.append(f"only in {side} ({c.names[SIDES.index(side)]}): {', '.join(only)}")
    ra, rb = (r.summary.get("regime") for r in (c.a, c.b))
    if bool(ra) != bool(rb):
        has, lacks = ("A", "B") if ra else ("B", "A")
        notes.append(f"{has}'s peaks are its periodic regime's (from t = {(ra or rb)['from_t_s']:.6g} s); {lacks} "
                     f"reaches none, its peaks are the whole run's")
    for side, r in zip(SIDES, (c.a, c.b)):
        if r.failure is not None:
            notes.append(f"{side} failed: {r.failure.message()}; its figures are of what ran")
    if c._cycles() is None:
        notes.append("the runs do not fold over the same drive angle: figures against time only")
    return notes


def render(c: Comparison, fmt: str) -> str:
    """The comparison as text: "csv" (the table, full precision), "json" (the names, what one run lacks,
    notes and the table's rows) or "text" (aligned plain columns, full precision, for pipes)."""
    from mechsim.scenarios.studies.compare import aligned
    if fmt == "csv":
        return c.table.to_csv(index=False, float_format="%.17g")
    if fmt == "json":
        import json

        from mechsim.scenarios.output.atomic import json_default
        rows = [{k: (None if isinstance(v, float) and math.isnan(v) else v) for k, v in row.items()}
                for row in c.table.to_dict(orient="records")]
        facts = {"a": c.names[0], "b": c.names[1],
                 "only_a": c.only_a, "only_b": c.only_b, "notes": c.notes, "quantities": rows}
        return json.dumps(facts, indent=2, default=json_default, allow_nan=False) + "\n"
    if fmt != "text":
        raise ValueError(f"format must be csv, json or text, got {fmt!r}")
    cells = [list(COLUMNS)] + [[r.quantity] + [f"{v:.17g}" for v in (r.a, r.b, r.difference, r.relative_difference)]
                               + [str(r.resolved)] for r in c.table.itertuples()]
    return aligned(cells, left=(0,))
