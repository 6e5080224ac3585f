"""report.html: one self-contained page per run (the figures embedded as base64 PNG, no external files or
scripts) with the scenario, the model chosen and why, peaks, energy balance, events, warnings and the figures.
Every section is a table whose numbers carry their unit (a column `unit`, or the unit in the header), read from
the house naming rule `<quantity>_<unit>` of the summary's keys and from the scenario schema."""
from __future__ import annotations

import base64
import html
from pathlib import Path

from mechsim.dynamics.result import Result

STYLE = """
body { font-family: system-ui, sans-serif; margin: 2em auto; max-width: 1150px; color: #1d232a; }
h1 { font-size: 1.6em; margin-bottom: 0.2em; } h2 { border-bottom: 1px solid #ccd; padding-bottom: 0.2em; }
table { border-collapse: collapse; margin: 0.5em 0 1em; font-size: 0.92em; }
th, td { border: 1px solid #ccd; padding: 0.25em 0.6em; text-align: left; vertical-align: top; }
td.num { text-align: right; font-variant-numeric: tabular-nums; }
pre { background: #f4f6f8; padding: 0.8em; overflow-x: auto; font-size: 0.85em; }
figure { margin: 1em 0; } img { max-width: 100%; border: 1px solid #e3e6ea; }
figcaption { color: #555; font-size: 0.9em; }
.fail { color: #a00; font-weight: bold; } .ok { color: #060; font-weight: bold; }
"""

#: figures in reading order (stems of scenarios.output.plots.figures; others follow alphabetically)
ORDER = ("mechanism", "motion_vs_angle", "forces_vs_angle", "thermal_vs_angle", "motion_vs_time", "forces_vs_time",
         "thermal_vs_time", "energy_vs_time")


#: unit suffixes of the summary's keys (`<quantity>_<unit>`), longest first, and how the page writes them
UNIT_SUFFIXES = {
    "N_m_s_rad": "N·m·s/rad", "m_per_rad": "m/rad", "W_m2K": "W/(m²·K)", "J_kgK": "J/(kg·K)", "kg_m3": "kg/m³", "kg_m2": "kg·m²",
    "rad_s2": "rad/s²", "m_s2": "m/s²", "W_m2": "W/m²", "W_mK": "W/(m·K)", "m2_s": "m²/s", "rad_s": "rad/s", "m_s": "m/s", "N_m": "N·m", "N_s": "N·s", "J_K": "J/K",
    "W_K": "W/K", "deg": "deg", "rad": "rad", "Pa": "Pa", "kg": "kg", "m2": "m²", "m3": "m³", "J": "J", "W": "W", "N": "N",
    "K": "K", "C": "°C", "s": "s", "m": "m", "relative": "1 (relative)",
}
#: how the page writes a scenario unit of the schema (scenarios/schema.py)
SCHEMA_UNITS = {"N*m": "N·m", "kg*m^2": "kg·m²", "N*m*s/rad": "N·m·s/rad", "m/s^2": "m/s²", "m^2": "m²", "m^3": "m³",
                "kg/m^3": "kg/m³", "J/(kg*K)": "J/(kg·K)", "W/(m*K)": "W/(m·K)", "W/(m^2*K)": "W/(m²·K)"}
#: units a closing word that is no unit would be mistaken for
_NOT_UNITS = ("relative",)


def quantity(key: str) -> tuple[str, str]:
    """(words, unit) of a summary key: 'centre_distance_m' -> ('centre distance', 'm'); a key without a unit suffix
    is a number without dimension or a count, or text: its unit is ''."""
    for suffix, shown in UNIT_SUFFIXES.items():
        if key.endswith("_" + suffix) and len(key) > len(suffix) + 1:
            stem = key[:-len(suffix) - 1]
            if suffix == "relative":
                return f"{stem.replace('_', ' ')} (relative)", "1"
            return stem.replace("_", " "), shown
    return key.replace("_", " "), ""


def _value_text(value) -> str:
    if isinstance(value, bool) or value is None:
        return "" if value is None else str(value).lower()
    if isinstance(value, float):
        return f"{value:.6g}"
    if isinstance(value, (list, tuple)):
        return ", ".join(_value_text(v) for v in value)
    return str(value)


def quantity_rows(data: dict, prefix: str = "") -> list[list]:
    """[item, value, unit] rows of a (nested) summary dict: nested tables flattened to 'outer: inner', lists of
    numbers on one row, units from each key's suffix."""
    rows = []
    for key, value in data.items():
        words, unit = quantity(str(key))
        item = f"{prefix}{words}"
        if isinstance(value, dict):
            rows += quantity_rows(value, f"{item}: ")
        elif isinstance(value, (list, tuple)) and value and all(isinstance(v, dict) for v in value):
            for i, v in enumerate(value):
                rows += quantity_rows(v, f"{item} {i + 1}: ")
        elif isinstance(value, (list, tuple)) and not value:
            rows.append([item, "none", ""])
        elif value is not None:
            number = isinstance(value, (int, float)) and not isinstance(value, bool) or (
                isinstance(value, (list, tuple)) and all(isinstance(v, (int, float)) for v in value))
            rows.append([item, value if isinstance(value, (int, float)) and not isinstance(value, bool)
                         else _value_text(value), unit if number else ""])
    return rows


def scenario_rows(si: dict) -> list[list]:
    """[section, key, value, unit] rows of the resolved scenario (SI), units from the schema."""
    from mechsim.scenarios.keys import field_unit
    rows = []

    def unit_of(key: str, value) -> str:
        try:
            unit = field_unit(si, key + ("[0]" if isinstance(value, list) else ""))
        except Exception:            # a key the schema does not know (a later schema): shown without a unit
            unit = ""
        return SCHEMA_UNITS.get(unit, unit)

    for section, body in si.items():
        if isinstance(body, dict):
            for key, value in body.items():
                if isinstance(value, dict):      # a profile {t = [...], <values> = [...]}: a row per list
                    unit = unit_of(f"{section}.{key}", [0])
                    rows += [[section, f"{key}.{name}", _value_text(part), "s" if name == "t" else unit]
                             for name, part in value.items()]
                elif value is not None:
                    rows.append([section, key, value if isinstance(value, (int, float)) and not isinstance(value, bool)
                                 else _value_text(value), unit_of(f"{section}.{key}", value)])
        elif body is not None:
            rows.append(["", section, body if isinstance(body, (int, float)) and not isinstance(body, bool)
                         else _value_text(body), unit_of(section, body)])
    return rows


def _num(value) -> str:
    if isinstance(value, float):
        return f"{value:.6g}"
    return html.escape(str(value))


def _table(header: list[str], rows: list[list]) -> str:
    head = "".join(f"<th>{html.escape(h)}</th>" for h in header)
    body = "".join("<tr>" + "".join(f'<td class="num">{_num(c)}</td>' if isinstance(c, (int, float))
                                    else f"<td>{html.escape(str(c))}</td>" for c in row) + "</tr>" for row in rows)
    return f"<table><tr>{head}</tr>{body}</table>"


def _images(pngs: dict[str, bytes]) -> str:
    stems = [s for s in ORDER if s in pngs] + sorted(s for s in pngs if s not in ORDER)
    return "".join(
        f'<figure><img alt="{html.escape(s)}" src="data:image/png;base64,{base64.b64encode(pngs[s]).decode()}">'
        f"<figcaption>{html.escape(s)}.png</figcaption></figure>" for s in stems)


def _validity(section: dict | None) -> list[str]:
    """The Validity section: each condition of the model, whether it held, the share of time violated, the worst
    value and when; violations in red (scenarios/validity.py)."""
    if section is None:
        return []
    if not section["conditions"]:
        return ["<h2>Validity</h2>", "<p>this model declares no validity conditions for this run</p>"]
    head = ('<p class="ok">every condition holds on every row</p>' if section["valid"] else
            f'<p class="fail">the model leaves its validity: {html.escape(", ".join(section["violated"]))}</p>')
    rows = []
    for c in section["conditions"]:
        unit = f" {c['unit']}" if c["unit"] else ""
        if not c.get("evaluated"):
            state, share, worst, when = f"not evaluated ({c.get('why', '')})", "", "", ""
        else:
            w = c.get("worst") or {}
            state = "VIOLATED" if c["violated_rows"] or c.get("violated_between_rows") else "holds"
            share = f"{100 * c['violated_share']:.3g} %"
            worst = ("unbounded" if w.get("unbounded") else f"{w['value']:.6g}{unit}") if w else "never applies"
            when = f"{w['t_s']:.6g}" if w else ""
        cells = [c["name"], state, f"{c['sense']} {c['bound']:g}{unit}", share, worst, when, c["description"],
                 c["source"]]
        style = ' class="fail"' if state == "VIOLATED" else ""
        rows.append(f"<tr{style}>" + "".join(f"<td>{html.escape(str(x))}</td>" for x in cells) + "</tr>")
    header = "".join(f"<th>{h}</th>" for h in ("condition", "state", "must be", "time violated", "worst value",
                                               "worst at t (s)", "what it means", "source"))
    return ["<h2>Validity</h2>", head, f"<table><tr>{header}</tr>{''.join(rows)}</table>"]


def _angle_shown(deg):
    """A wrapped drive angle (-180..180 deg) as read: round-off of 0 shown as 0 (`console.as_shown` over half a
    turn: a Geneva's mid-engagement at 1.5e-11 deg)."""
    from mechsim.scenarios.console import as_shown
    return deg if deg is None else as_shown(deg, 180.0)


def report_html(result: Result, pngs: dict[str, bytes]) -> str:
    """The page as a string; `pngs` maps figure stems to PNG bytes."""
    s = result.summary
    model = s.get("model", {})
    status = (f'<p class="fail">failed: {html.escape(result.failure.message())}</p>' if result.failure
              else '<p class="ok">completed</p>')
    parts = [f"<h1>{html.escape(str(s.get('scenario', 'run')))}</h1>",
             f"<p>{html.escape(str(result.scenario.get('description', '')))}</p>", status,
             "<h2>Model</h2>",
             _table(["item", "value", "unit"], quantity_rows({k: v for k, v in model.items() if k not in ("rtol", "atol")})
                    + [["relative tolerance (rtol)", model["rtol"], "1"]] * ("rtol" in model)
                    + [["absolute tolerance (atol)", model["atol"], "SI unit of each state"]] * ("atol" in model)
                    + quantity_rows({k: v for k, v in s.get("geometry", {}).items()
                                     if isinstance(v, (int, float, str))}, "geometry: "))]
    peaks = s.get("peaks", {})
    if peaks:
        regime = s.get("regime")
        if regime:
            parts += ["<h2>Peaks</h2>", f"<p>periodic from t = {regime['from_t_s']:.6g} s after "
                      f"{regime['startup_turns']} start-up turn(s), period {regime['period_s']:.6g} s: max and min "
                      "are the periodic regime's, the start-up's are listed beside them</p>"]
        else:
            parts += ["<h2>Peaks</h2>"]
        from mechsim.scenarios.console import as_shown, column_scale
        rows = []
        for c, p in peaks.items():
            picks = [(side, p[side]) for side in ("max", "min")]
            picks += [(f"start-up {side}", x) for side, x in p.get("startup", {}).items()]
            words, unit = quantity(c)
            scale = column_scale(p)                 # a round-off zero shown as 0 (summary.json keeps it)
            rows += [[words, side, "unbounded" if x["value"] is None else as_shown(x["value"], scale), unit or "1",
                      x["t_s"], _angle_shown(x["drive_angle_wrapped_deg"]), x.get("at", ""), p.get("how", "")]
                     for side, x in picks]
            turn = p.get("periodic") or p.get("cycle")
            if turn and (turn.get("mean") is not None or turn.get("unbounded")):   # (none: defined only in contact)
                a, b = turn["mean_over"]
                rows.append([words, "mean over the periodic turn" if "periodic" in p else "mean over the last drive "
                             "cycle", "unbounded" if turn.get("unbounded") else as_shown(turn["mean"], scale),
                             unit or "1",
                             f"{a:.6g} .. {b:.6g}", "", "", turn.get("how", p.get("how", ""))])
        parts += [_table(["quantity", "", "value", "unit", "t (s)", "drive angle, wrapped (deg)", "at", "how"], rows)]
    parts += _validity(s.get("validity"))
    energy = s.get("energy", {})
    if energy:
        from mechsim.scenarios.console import as_shown
        largest = energy.get("largest_term_J", 0.0)      # a term within round-off of it shown as 0 (the json keeps it)
        rows = [[f"work: {k}", as_shown(v, largest), "J"] for k, v in energy.get("work_J", {}).items()]
        rows += [["kinetic energy change", as_shown(energy["kinetic_energy_change_J"], largest), "J"],
                 ["impact losses", as_shown(energy["impact_losses_J"], largest), "J"],
                 ["closure error", energy["closure_error_J"], "J"],
                 ["closure error / the largest energy term", energy["closure_error_relative"], "1"]]
        parts += ["<h2>Energy balance (J)</h2>", _table(["term", "value", "unit"], rows)]
    if s.get("impacts"):
        parts += ["<h2>Impacts</h2>", "<p>pin-flank impacts of the slot clearance (docs/geneva.md, 'Clearance and "
                  "impacts'); every impact in impacts.csv</p>",
                  _table(["item", "value", "unit"], quantity_rows(s["impacts"]))]
    if s.get("lock_impacts"):
        parts += ["<p>the wheel's impacts on the ends of its locking play (mechanism.lock_clearance; impulse at the "
                  "crank radius); every one in lock_impacts.csv</p>",
                  _table(["item", "value", "unit"], quantity_rows(s["lock_impacts"], "lock impacts: "))]
    if s.get("events"):
        parts += ["<h2>Events</h2>", _table(["kind", "count"], [[k, v] for k, v in s["events"].items()])]
    groups = s.get("warning_groups", [])
    parts += ["<h2>Warnings</h2>", _table(["count", "kind", "first t (s)", "last t (s)", "first message"],
                                          [[g["count"], g["kind"], g["first_t_s"] if g["first_t_s"] is not None
                                            else "", g["last_t_s"] if g["last_t_s"] is not None else "", g["first"]]
                                           for g in groups]) if groups else "<p>none</p>"]
    solver = {k: v for k, v in s.get("solver", {}).items() if isinstance(v, (int, float, str))}
    parts += ["<h2>Solver</h2>", _table(["item", "value", "unit"], quantity_rows(solver))]
    if pngs:
        parts += ["<h2>Figures</h2>", _images(pngs)]
    if result.scenario:
        parts += ["<h2>Scenario (resolved, SI)</h2>",
                  "<p>every value as run, defaults filled in; scenario.toml beside this page is the same as a file "
                  "`mechsim run` takes</p>",
                  _table(["section", "key", "value", "unit"], scenario_rows(result.scenario))]
    if s.get("thermal"):
        parts += ["<h2>Thermal model</h2>", _table(["item", "value", "unit"], quantity_rows(s["thermal"]))]
    title = html.escape(f"mechsim: {s.get('scenario', 'run')}")
    return (f'<!DOCTYPE html><html lang="en"><head><meta charset="utf-8"><title>{title}</title>'
            f"<style>{STYLE}</style></head><body>{''.join(parts)}</body></html>\n")


def write_report(result: Result, folder: Path) -> Path:
    """report.html in `folder`, embedding every PNG figure written there."""
    folder = Path(folder)
    pngs = {p.stem: p.read_bytes() for p in sorted(folder.glob("*.png"))}
    path = folder / "report.html"
    path.write_text(report_html(result, pngs), encoding="utf-8")
    return path
