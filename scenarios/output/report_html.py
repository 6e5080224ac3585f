"""report.html: one self-contained page per run (the figures embedded as base64 PNG, no external files or
scripts) with the scenario, the model chosen and why, peaks, energy balance, events, warnings and the figures."""
from __future__ import annotations

import base64
import html
import json
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
            state = "VIOLATED" if c["violated_rows"] else "holds"
            share = f"{100 * c['violated_share']:.3g} %"
            worst = f"{w['value']:.6g}{unit}" if w else "never applies"
            when = f"{w['t_s']:.6g}" if w else ""
        cells = [c["name"], state, f"{c['sense']} {c['bound']:g}{unit}", share, worst, when, c["description"],
                 c["source"]]
        style = ' class="fail"' if state == "VIOLATED" else ""
        rows.append(f"<tr{style}>" + "".join(f"<td>{html.escape(str(x))}</td>" for x in cells) + "</tr>")
    header = "".join(f"<th>{h}</th>" for h in ("condition", "state", "must be", "time violated", "worst value",
                                               "worst at t (s)", "what it means", "source"))
    return ["<h2>Validity</h2>", head, f"<table><tr>{header}</tr>{''.join(rows)}</table>"]


def report_html(result: Result, pngs: dict[str, bytes], scenario_toml: str = "") -> str:
    """The page as a string; `pngs` maps figure stems to PNG bytes."""
    s = result.summary
    model = s.get("model", {})
    status = (f'<p class="fail">failed: {html.escape(result.failure.message())}</p>' if result.failure
              else '<p class="ok">completed</p>')
    parts = [f"<h1>{html.escape(str(s.get('scenario', 'run')))}</h1>",
             f"<p>{html.escape(str(result.scenario.get('description', '')))}</p>", status,
             "<h2>Model</h2>",
             _table(["item", "value"], [[k, v] for k, v in model.items() if v is not None]
                    + [[f"geometry: {k}", v] for k, v in s.get("geometry", {}).items()
                       if isinstance(v, (int, float, str))])]
    peaks = s.get("peaks", {})
    if peaks:
        regime = s.get("regime")
        if regime:
            parts += ["<h2>Peaks</h2>", f"<p>periodic from t = {regime['from_t_s']:.6g} s after "
                      f"{regime['startup_turns']} start-up turn(s), period {regime['period_s']:.6g} s: max and min "
                      "are the periodic regime's, the start-up's are listed beside them</p>"]
        else:
            parts += ["<h2>Peaks</h2>"]
        rows = []
        for c, p in peaks.items():
            picks = [(side, p[side]) for side in ("max", "min")]
            picks += [(f"start-up {side}", x) for side, x in p.get("startup", {}).items()]
            rows += [[c, side, "unbounded" if x["value"] is None else x["value"], x["t_s"],
                      x["drive_angle_wrapped_deg"], x.get("at", ""), p.get("how", "")] for side, x in picks]
        parts += [_table(["column", "", "value", "t (s)", "drive angle, wrapped (deg)", "at", "how"], rows)]
    parts += _validity(s.get("validity"))
    energy = s.get("energy", {})
    if energy:
        rows = [[f"work: {k}", v] for k, v in energy.get("work_J", {}).items()]
        rows += [["kinetic energy change", energy["kinetic_energy_change_J"]],
                 ["impact losses", energy["impact_losses_J"]], ["closure error", energy["closure_error_J"]],
                 ["closure error / drive work", energy["closure_error_relative"]]]
        parts += ["<h2>Energy balance (J)</h2>", _table(["term", "J"], rows)]
    if s.get("events"):
        parts += ["<h2>Events</h2>", _table(["kind", "count"], [[k, v] for k, v in s["events"].items()])]
    groups = s.get("warning_groups", [])
    parts += ["<h2>Warnings</h2>", _table(["count", "kind", "first t (s)", "last t (s)", "first message"],
                                          [[g["count"], g["kind"], g["first_t_s"] if g["first_t_s"] is not None
                                            else "", g["last_t_s"] if g["last_t_s"] is not None else "", g["first"]]
                                           for g in groups]) if groups else "<p>none</p>"]
    solver = {k: v for k, v in s.get("solver", {}).items() if isinstance(v, (int, float, str))}
    parts += ["<h2>Solver</h2>", _table(["item", "value"], [[k, v] for k, v in solver.items()])]
    if pngs:
        parts += ["<h2>Figures</h2>", _images(pngs)]
    if scenario_toml:
        parts += ["<h2>Scenario (resolved, SI)</h2>", f"<pre>{html.escape(scenario_toml)}</pre>"]
    if s.get("thermal"):
        parts += ["<h2>Thermal model</h2>", f"<pre>{html.escape(json.dumps(s['thermal'], indent=2, default=str))}</pre>"]
    title = html.escape(f"mechsim: {s.get('scenario', 'run')}")
    return (f'<!DOCTYPE html><html lang="en"><head><meta charset="utf-8"><title>{title}</title>'
            f"<style>{STYLE}</style></head><body>{''.join(parts)}</body></html>\n")


def write_report(result: Result, folder: Path, scenario_toml: str = "") -> Path:
    """report.html in `folder`, embedding every PNG figure written there."""
    folder = Path(folder)
    pngs = {p.stem: p.read_bytes() for p in sorted(folder.glob("*.png"))}
    path = folder / "report.html"
    path.write_text(report_html(result, pngs, scenario_toml), encoding="utf-8")
    return path
