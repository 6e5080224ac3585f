"""`mechsim curves`: the coupler-curve atlas of a rolling-pair 4-bar (mechanisms/rolling/atlas.py) as CSV tables
and a plot, for a named set (mechanisms/rolling/sets.py), a built-in scenario or a scenario file.

Written like a run: into a temporary sibling folder, then one rename; an existing folder only with `force`.
"""
from __future__ import annotations

import json
from pathlib import Path

import mechsim.mechanisms.rolling.sets as rolling_sets
from mechsim.mechanisms.rolling.atlas import coupler_atlas
from mechsim.mechanisms.rolling.model import RollingPairFourBar
from mechsim.mechanisms.rolling.pair import RollingFourBar

from mechsim.scenarios.units import ScenarioError
from mechsim.scenarios.output.atomic import atomic_folder, check_replaceable
from mechsim.scenarios.output.paths import default_folder

#: atlas attribute -> CSV file name
TABLES = {"component_table": "components", "closure": "closure", "nonclosure": "nonclosure", "curve": "curve",
          "trochoid": "trochoid", "cusps": "cusps", "crunodes": "crunodes", "trochoid_crunodes": "trochoid_crunodes"}


def resolve(name: str) -> tuple[RollingFourBar, str]:
    """(mechanism, label) for a scenario file, a named rolling set, or a built-in rolling-pair scenario."""
    from mechsim.scenarios.loader import builtin_names, load
    path = Path(name)
    is_file = path.suffix == ".toml" or path.exists()
    if not is_file and name in rolling_sets.SETS:
        return rolling_sets.make(name), name
    if not is_file and name not in builtin_names():
        rolling = [n for n in builtin_names() if n.startswith("rolling")]
        raise ScenarioError("curves", f"no rolling-pair set, built-in scenario or file named {name!r} (sets: "
                                      f"{', '.join(rolling_sets.SETS)}; scenarios: {', '.join(rolling)})")
    sc = load(name)
    if sc.mechanism_type != "rolling_pair":
        raise ScenarioError("mechanism.type", f"curves needs a rolling_pair scenario, got {sc.mechanism_type!r}")
    try:
        kin = RollingPairFourBar.kinematics_from_config(sc.si["mechanism"])
    except ValueError as exc:
        raise ScenarioError("mechanism", str(exc)) from None
    if kin.pair.kind == "line" and kin.span is None:
        raise ScenarioError("mechanism.atlas_span", "a disc rolling on a line has no period: give the phi range "
                                                    "[start, end] to tabulate")
    return kin, sc.name


def atlas_summary(atlas, label: str) -> dict:
    comps = atlas.component_table
    return {
        "mechanism": label, "span_rad": list(atlas.span), "periodic": atlas.periodic,
        "components": int(len(comps)),
        "monochromatic": int((comps["kind"] == "monochromatic").sum()) if len(comps) else 0,
        "dichromatic": int((comps["kind"] == "dichromatic").sum()) if len(comps) else 0,
        "closure_intervals": int(len(atlas.closure)), "nonclosure_intervals": int(len(atlas.nonclosure)),
        "cusps": int(len(atlas.cusps)), "crunodes": int(len(atlas.crunodes)),
        "trochoid_crunodes": int(len(atlas.trochoid_crunodes)),
    }


def write_curves(name: str, out_dir: Path | None = None, force: bool = False,
                 samples_per_turn: int = 720) -> tuple[Path, dict]:
    """Compute the atlas of `name` and write <table>.csv, atlas.png and summary.json into out_dir."""
    kin, label = resolve(name)
    out_dir = Path(out_dir) if out_dir is not None else default_folder(label, "curves-")
    check_replaceable(out_dir, force)
    atlas = coupler_atlas(kin, samples_per_turn=samples_per_turn)
    summary = atlas_summary(atlas, label)
    with atomic_folder(out_dir, force) as tmp:
        for attr, fname in TABLES.items():
            getattr(atlas, attr).to_csv(tmp / f"{fname}.csv", index=False)
        (tmp / "summary.json").write_text(json.dumps(summary, indent=2))
        from mechsim.scenarios.output.plots import save as save_figure
        from mechsim.scenarios.output.rolling_plots import plot_coupler_atlas
        save_figure(plot_coupler_atlas(atlas, title=f"rolling-pair 4-bar: {label}"), tmp / "atlas.png")
    return out_dir, summary
