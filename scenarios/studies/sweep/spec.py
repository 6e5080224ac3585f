"""Sweep definitions: parse `--vary section.key=SPEC` (or a sweep TOML file) into the list of cases.

A SPEC is one of
    5,7,14 N*m          a list; a unit after the last item applies to every item ("5 N*m, 7 N*m" also works)
    dae,closed-form     a list of words (strings), true/false (booleans) or bare numbers
    0.1:0.4:7           7 evenly spaced points from 0.1 to 0.4 inclusive (numpy.linspace), optional unit
                        (after the count, or the same unit on both ends: "60 mm:90 mm:4")
    log:1e-3:1e-1:5     5 points evenly spaced in log from 1e-3 to 1e-1 (numpy.geomspace), optional unit
Axes combine as a full grid (itertools.product, the first axis varying slowest) or zipped (equal lengths).

Values are kept as the text the scenario loader reads (`--set` syntax); units are converted and every value is
checked by the loader itself when the cases are validated (sweep_run.plan), so a wrong key or unit is reported
there, naming the field. This module only knows the syntax.
"""
from __future__ import annotations

import itertools
import json
import math
import re
import tomllib
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np

from mechsim.scenarios.keys import toml_literal
from mechsim.scenarios.loader import parse_toml, read_text
from mechsim.scenarios.units import ScenarioError

#: cases in one sweep (each is validated before anything runs and stored as its own file)
MAX_CASES = 100_000

NUMBER = r"[+-]?(?:\d+\.?\d*|\.\d+)(?:[eE][+-]?\d+)?"
_ITEM = re.compile(rf"^\s*({NUMBER})\s*(.*?)\s*$")
_RANGE = re.compile(rf"^\s*(log\s*:)?\s*({NUMBER})\s*:\s*({NUMBER})\s*:\s*([^\s:]+)\s*(.*?)\s*$")
#: a range with a unit on each end ("60 mm:90 mm:4"), as a list may have one on every item
_RANGE_ENDS = re.compile(rf"^\s*(log\s*:)?\s*({NUMBER})\s*([^:]*?)\s*:\s*({NUMBER})\s*([^:]*?)\s*:\s*(\d+)\s*$")
MODES = ("grid", "zip")


def _number_text(x: float, integers: bool) -> str:
    """Generated range points, cleaned of float noise (0.15000000000000002 -> 0.15); ints stay ints."""
    if integers:
        return str(int(round(x)))
    return f"{float(x):.12g}"


def _scalar(text: str):
    """One list item without a unit: TOML where it parses (numbers, true/false, quoted strings), else a word."""
    text = text.strip()
    try:
        return tomllib.loads(f"v = {text}")["v"]
    except tomllib.TOMLDecodeError:
        return text


@dataclass(frozen=True)
class Axis:
    """One varied key: its values as the loader reads them (quantity strings, numbers, booleans, words)."""

    key: str
    values: tuple
    spec: str = ""
    kind: str = "list"   # list | range | log (log axes are plotted on a log scale)

    def __len__(self) -> int:
        return len(self.values)

    def override(self, i: int) -> str:
        return f"{self.key}={toml_literal(self.values[i])}"


def _check_key(key: str, where: str) -> str:
    parts = [p.strip() for p in key.strip().split(".")]
    if not key.strip() or any(not p for p in parts):
        raise ScenarioError(where, f"expected section.key=SPEC, got key {key!r}")
    return ".".join(parts)


def parse_values(key: str, spec: str) -> tuple[tuple, str]:
    """SPEC text -> (values, kind). Raises ScenarioError('--vary KEY', ...) on bad syntax."""
    where = f"--vary {key}"
    text = spec.strip()
    if not text:
        raise ScenarioError(where, "empty SPEC (expected a list 5,7 N*m, a range 0.1:0.4:7 or log:1e-3:1e-1:5)")
    ends = _RANGE_ENDS.match(text) if "," not in text else None
    if ends and (ends.group(3) or ends.group(5)):
        is_log, start_t, start_unit, stop_t, stop_unit, n_t = ends.groups()
        if start_unit != stop_unit:
            raise ScenarioError(where, f"give the unit once after the count or the same on both ends: {spec!r}")
        text = f"{is_log or ''}{start_t}:{stop_t}:{n_t} {start_unit}"
    m = _RANGE.match(text)
    if m and "," not in text:
        is_log, start_t, stop_t, n_t, unit = m.groups()
        if unit.startswith(":"):
            raise ScenarioError(where, f"cannot read {spec!r} as a range: expected start:stop:n or "
                                       "log:start:stop:n, then an optional unit")
        try:
            n = int(n_t)
        except ValueError:
            raise ScenarioError(where, f"the number of points in {spec!r} must be a whole number, got {n_t!r}") \
                from None
        if n < 1:
            raise ScenarioError(where, f"the number of points in {spec!r} must be at least 1, got {n}")
        if n > MAX_CASES:
            raise ScenarioError(where, f"{n} points; a sweep has at most {MAX_CASES:,} cases (docs/limits.md)")
        start, stop = float(start_t), float(stop_t)
        if is_log:
            if not (start > 0 and stop > 0):
                raise ScenarioError(where, f"a log range needs positive ends, got {spec!r}")
            points = np.geomspace(start, stop, n)
            integers = False
        else:
            points = np.linspace(start, stop, n)
            integers = (re.fullmatch(r"[+-]?\d+", start_t) and re.fullmatch(r"[+-]?\d+", stop_t)
                        and np.allclose(points, np.round(points)))
        numbers = [_number_text(x, bool(integers)) for x in points]
        values = tuple(f"{x} {unit}" for x in numbers) if unit else tuple(_scalar(x) for x in numbers)
        return values, "log" if is_log else "range"
    if text.startswith("log:") or (":" in text and "," not in text):
        raise ScenarioError(where, f"cannot read {spec!r} as a range: expected start:stop:n or "
                                   "log:start:stop:n with numbers, then an optional unit")
    items = [s.strip() for s in text.split(",")]
    if any(not s for s in items):
        raise ScenarioError(where, f"empty item in the list {spec!r}")
    items = [s[1:-1].strip() if len(s) >= 2 and s[0] == s[-1] and s[0] in "'\"" else s for s in items]
    parsed = [_ITEM.match(s) for s in items]
    units = [m.group(2) if m else None for m in parsed]
    numeric = [m is not None for m in parsed]
    if all(numeric):
        with_unit = [bool(u) for u in units]
        if with_unit[-1] and not any(with_unit[:-1]):          # "5,7,14 N*m": one unit for all
            unit = units[-1]
            return tuple(f"{m.group(1)} {unit}" for m in parsed), "list"
        if all(with_unit):                                      # "5 N*m, 7 N*m"
            return tuple(f"{m.group(1)} {u}" for m, u in zip(parsed, units)), "list"
        if not any(with_unit):
            return tuple(_scalar(m.group(1)) for m in parsed), "list"
        raise ScenarioError(where, f"give the unit once after the last item or on every item: {spec!r}")
    if any(numeric) and any(u for u in units if u):
        raise ScenarioError(where, f"mixed numbers with units and words in {spec!r}")
    return tuple(_scalar(s) for s in items), "list"


def parse_vary(text: str) -> Axis:
    """'section.key=SPEC' -> Axis."""
    if "=" not in text:
        raise ScenarioError("--vary", f"expected section.key=SPEC, got {text!r}")
    key, spec = text.split("=", 1)
    key = _check_key(key, "--vary")
    values, kind = parse_values(key, spec)
    return Axis(key, values, spec.strip(), kind)


def axis_from_toml(key: str, value) -> Axis:
    """A [sweep.vary] entry: a SPEC string, or an explicit TOML list of values (numbers, quantity strings, ...)."""
    key = _check_key(key, "sweep.vary")
    if isinstance(value, str):
        values, kind = parse_values(key, value)
        return Axis(key, values, value, kind)
    if isinstance(value, list) and value and all(isinstance(v, (str, int, float, bool)) for v in value):
        return Axis(key, tuple(value), json.dumps(value), "list")
    raise ScenarioError(f"sweep.vary.{key}", "expected a SPEC string (\"0.1:0.4:7\") or a non-empty list of values")


@dataclass(frozen=True)
class SweepSpec:
    """The scenario, the overrides every case shares (`base`, --set syntax), and the varied axes."""

    scenario: str
    axes: tuple[Axis, ...]
    mode: str = "grid"
    base: tuple[str, ...] = field(default_factory=tuple)

    def __post_init__(self):
        if self.mode not in MODES:
            raise ScenarioError("sweep.mode", f"must be one of {', '.join(MODES)}; got {self.mode!r}")
        if not self.axes:
            raise ScenarioError("--vary", "nothing to sweep: give at least one --vary section.key=SPEC")
        keys = [a.key for a in self.axes]
        for k in keys:
            if keys.count(k) > 1:
                raise ScenarioError(f"--vary {k}", "varied twice")
        base_keys = {b.split("=", 1)[0].strip() for b in self.base}
        for k in keys:
            if k in base_keys:
                raise ScenarioError(f"--vary {k}", "is also fixed by --set; give it in one place")
        if self.mode == "zip" and len({len(a) for a in self.axes}) > 1:
            sizes = ", ".join(f"{a.key}: {len(a)}" for a in self.axes)
            raise ScenarioError("--zip", f"zipped axes need equal lengths; got {sizes}")

    @property
    def keys(self) -> list[str]:
        return [a.key for a in self.axes]

    def __len__(self) -> int:
        return len(self.axes[0]) if self.mode == "zip" else math.prod(len(a) for a in self.axes)

    def indices(self) -> list[tuple[int, ...]]:
        """Per case, the index into each axis."""
        if self.mode == "zip":
            return [(i,) * len(self.axes) for i in range(len(self.axes[0]))]
        return list(itertools.product(*(range(len(a)) for a in self.axes)))

    def case_overrides(self) -> list[list[str]]:
        """Per case, the --set overrides: the shared base, then one per axis."""
        return [list(self.base) + [a.override(i) for a, i in zip(self.axes, idx)] for idx in self.indices()]

    def describe(self) -> dict:
        """The definition as data (written to the output folder as sweep.toml, valid sweep-file input)."""
        return {"sweep": {"scenario": self.scenario, "mode": self.mode, "set": list(self.base),
                          "vary": {a.key: list(a.values) for a in self.axes}}}


def _flatten(table: dict, prefix: str = "") -> dict:
    out = {}
    for k, v in table.items():
        key = f"{prefix}{k}"
        if isinstance(v, dict):
            out.update(_flatten(v, key + "."))
        else:
            out[key] = v
    return out


def is_sweep_file(target: str) -> bool:
    """A TOML file with a top-level [sweep] table (anything else is a scenario name or file)."""
    path = Path(target)
    if path.suffix != ".toml" or not path.is_file():
        return False
    try:
        return isinstance(parse_toml(read_text(path), str(path)).get("sweep"), dict)
    except ScenarioError:
        return False          # the scenario loader reports it


def read_sweep_file(path: str | Path) -> tuple[str, str, list[str], list[Axis]]:
    """A sweep TOML file -> (scenario, mode, base overrides, axes). Format: docs/sweeps.md.

        [sweep]
        scenario = "geneva-lc1"          # built-in name, or a scenario file relative to this file
        mode = "grid"                    # or "zip"
        set = ['duration="0.5 s"']       # optional overrides shared by every case (--set syntax) ...
        [sweep.set]                      # ... or as a table (either form, not both)
        solver.method = "dae"
        [sweep.vary]
        contact.friction = "0.1:0.4:7"              # a SPEC, as after --vary KEY=
        load.wheel_torque = ["5 N*m", "7 N*m"]      # or an explicit list
    """
    path = Path(path)
    doc = parse_toml(read_text(path), str(path))
    sweep = doc.get("sweep")
    if not isinstance(sweep, dict):
        raise ScenarioError("sweep", f"{path} has no [sweep] table")
    unknown = set(sweep) - {"scenario", "mode", "set", "vary"}
    if unknown:
        raise ScenarioError(f"sweep.{sorted(unknown)[0]}", "unknown key (known keys: mode, scenario, set, vary)")
    scenario = sweep.get("scenario")
    if not isinstance(scenario, str) or not scenario:
        raise ScenarioError("sweep.scenario", "missing (a built-in scenario name or a scenario TOML file)")
    if scenario.endswith(".toml") and not Path(scenario).is_absolute():
        scenario = str((path.parent / scenario).resolve())
    mode = sweep.get("mode", "grid")
    base = sweep.get("set", [])
    if isinstance(base, dict):
        base = [f"{k}={toml_literal(v)}" for k, v in _flatten(base).items()]
    if not isinstance(base, list) or not all(isinstance(b, str) and "=" in b for b in base):
        raise ScenarioError("sweep.set", "expected a list of \"section.key=value\" strings or a table")
    vary = sweep.get("vary", {})
    if not isinstance(vary, dict):
        raise ScenarioError("sweep.vary", "must be a table of section.key = SPEC")
    axes = [axis_from_toml(k, v) for k, v in _flatten(vary).items()]
    return scenario, mode, list(base), axes


def build_spec(target: str, vary: list[str], base: list[str], zip_: bool) -> SweepSpec:
    """The sweep from the command line: TARGET is a scenario or a sweep file; --vary/--set/--zip add to a file."""
    axes = [parse_vary(v) for v in vary]
    if is_sweep_file(target):
        scenario, mode, file_base, file_axes = read_sweep_file(target)
        spec = SweepSpec(scenario, tuple(file_axes + axes), "zip" if zip_ else mode, tuple(file_base + list(base)))
    else:
        spec = SweepSpec(target, tuple(axes), "zip" if zip_ else "grid", tuple(base))
    if spec.axes and (spec.mode == "grid" or all(len(a) == len(spec.axes[0]) for a in spec.axes)) \
            and len(spec) > MAX_CASES:
        raise ScenarioError("--vary", f"{len(spec):,} cases; a sweep has at most {MAX_CASES:,} (each is validated "
                                      "before anything runs and stored as its own file; docs/limits.md)")
    return spec
