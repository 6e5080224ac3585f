"""What `mechsim size` is asked (docs/sensitivity.md, "Sizing"): a varied value's bounds (`--vary
section.key=LOW:HIGH unit`, list entries as `--set` names them) and a limit on a headline quantity (`--subject-to
"QUANTITY <= VALUE"`), parsed into SI with one line naming the problem where the text is not understood."""
from __future__ import annotations

import math
import re
from dataclasses import dataclass

from mechsim.scenarios.keys import key_path, lookup
from mechsim.scenarios.units import ScenarioError

#: the slot count (an integer: enumerated, not optimised continuously)
SLOTS = "mechanism.slots"

NUMBER = r"[+-]?(?:\d+\.?\d*|\.\d+)(?:[eE][+-]?\d+)?"
_BOUND = re.compile(rf"^\s*({NUMBER})\s*([^:]*?)\s*:\s*({NUMBER})\s*(.*?)\s*$")
_LIMIT = re.compile(rf"^\s*([A-Za-z_][A-Za-z0-9_.]*)\s*(<=|>=)\s*({NUMBER})\s*$")

@dataclass(frozen=True)
class Bound:
    """One varied scenario value: its key, bounds in SI and SI unit ('' for a number without unit)."""

    key: str
    low: float
    high: float
    unit: str

    @property
    def column(self) -> str:
        from mechsim.scenarios.keys import unit_suffix
        return f"{self.key}_{unit_suffix(self.unit)}" if self.unit else self.key


@dataclass(frozen=True)
class Limit:
    """A limit on a headline quantity: quantity <= value or quantity >= value (value in the quantity's unit)."""

    quantity: str
    sense: str
    value: float

    @property
    def text(self) -> str:
        return f"{self.quantity} {self.sense} {self.value:.12g}"

    @property
    def scale(self) -> float:
        return abs(self.value) or 1.0

    def margin(self, q: float) -> float:
        """The scaled constraint, >= 0 when satisfied: (limit - q) / |limit| for <=, (q - limit) / |limit| for >=."""
        return ((self.value - q) if self.sense == "<=" else (q - self.value)) / self.scale


def parse_bound(text: str, si: dict) -> Bound:
    """'section.key=LOW:HIGH unit' (or 'LOW unit:HIGH unit') -> Bound in SI. ScenarioError naming the problem."""
    from mechsim.scenarios.loader import sections_for
    from mechsim.scenarios.units import to_si
    if "=" not in text:
        raise ScenarioError("--vary", f"expected section.key=LOW:HIGH, got {text!r}")
    key, spec = (s.strip() for s in text.split("=", 1))
    try:
        path = key_path(key)
    except ValueError:
        raise ScenarioError("--vary", f"unknown scenario key {key!r} for a {si['mechanism']['type']} scenario") from None
    parts = [p for p in path if isinstance(p, str)]
    index = path[len(parts):] if len(parts) == 2 and path[:2] == parts else None
    fields = sections_for(si["mechanism"]["type"]).get(parts[0], {}) if index is not None else {}
    spec_field = fields.get(parts[-1]) if index is not None else None
    if spec_field is not None and (index or spec_field.kind in ("list", "points")):
        spec_field = _list_entry(key, spec_field, index, si)
    if spec_field is None:
        raise ScenarioError("--vary", f"unknown scenario key {key!r} for a {si['mechanism']['type']} scenario")
    m = _BOUND.match(spec)
    if not m:
        raise ScenarioError(f"--vary {key}", f"expected LOW:HIGH with an optional unit (e.g. 40:120 mm), got {spec!r}")
    low_t, low_unit, high_t, high_unit = m.groups()
    unit = spec_field.unit if spec_field.kind == "quantity" else ""
    if key == SLOTS:
        if low_unit or high_unit or not re.fullmatch(r"\d+", low_t) or not re.fullmatch(r"\d+", high_t):
            raise ScenarioError(f"--vary {key}", f"the slot count takes whole numbers LOW:HIGH, got {spec!r}")
        low, high = float(low_t), float(high_t)
    elif unit:
        low_unit = low_unit or high_unit
        high_unit = high_unit or low_unit
        low = to_si(key, f"{low_t} {low_unit}".strip(), unit)
        high = to_si(key, f"{high_t} {high_unit}".strip(), unit)
    elif spec_field.kind in ("float", "int"):
        if low_unit or high_unit:
            raise ScenarioError(f"--vary {key}", f"takes plain numbers (no unit), got {spec!r}")
        low, high = float(low_t), float(high_t)
    else:
        raise ScenarioError(f"--vary {key}", "is not a numeric scenario value")
    if not (math.isfinite(low) and math.isfinite(high)) or low >= high:
        raise ScenarioError(f"--vary {key}", f"LOW must be below HIGH, got {spec!r}")
    return Bound(key, low, high, unit)


def _list_entry(key: str, spec_field, index: list, si: dict):
    """A list entry's field ('mechanism.sprocket_radii[0]', 'mechanism.sprockets[1][0]': one index per nesting of
    the list, as the loader's messages name them) as a quantity of the list's unit; ScenarioError where the key
    names a whole list, an index the scenario's list does not have, or a list of non-numbers."""
    from mechsim.scenarios.schema import Field
    depth = 2 if spec_field.kind == "points" else 1
    if len(index) != depth:
        raise ScenarioError(f"--vary {key}", f"a list: name one entry, e.g. {key.split('[')[0]}{'[0]' * depth}")
    node = lookup(si, key.split("[")[0])
    for i in index:
        if not isinstance(node, list) or not 0 <= i < len(node):
            raise ScenarioError(f"--vary {key}", "no such entry in the scenario's list")
        node = node[i]
    if not spec_field.unit or isinstance(node, bool) or not isinstance(node, (int, float)):
        raise ScenarioError(f"--vary {key}", "is not a numeric scenario value")
    return Field("quantity", spec_field.unit)


def set_list_entries(raw: dict, si: dict, entries: list[tuple[str, str]]) -> dict:
    """raw with the list entries set (key as `parse_bound` takes it, value as TOML text, e.g. '0.05 m'): the
    loader's --set names whole keys only, so the list is written whole, its other entries as the scenario gave
    them (or, where the scenario leaves the list to its default, as resolved, in SI with the list's unit)."""
    import copy

    from mechsim.scenarios.loader import sections_for
    out = copy.deepcopy(raw)
    for key, text in entries:
        section, name, *index = key_path(key)
        table = out.setdefault(section, {})
        if table.get(name) is None:
            unit = sections_for(si["mechanism"]["type"])[section][name].unit
            table[name] = _with_unit(copy.deepcopy(si[section][name]), unit)
        node = table[name]
        for i in index[:-1]:
            node = node[i]
        node[index[-1]] = text
    return out


def _with_unit(value, unit: str):
    return [_with_unit(v, unit) for v in value] if isinstance(value, list) else f"{float(value)!r} {unit}"


def parse_limit(text: str) -> Limit:
    """'QUANTITY <= VALUE' (or >=) -> Limit; the value is in the quantity's own unit (its name's suffix)."""
    m = _LIMIT.match(text)
    if not m:
        raise ScenarioError("--subject-to", f"expected \"QUANTITY <= VALUE\" or \"QUANTITY >= VALUE\" with VALUE a "
                            f"number in the quantity's unit, got {text!r}")
    value = float(m.group(3))
    if not math.isfinite(value):
        raise ScenarioError("--subject-to", f"the limit must be a finite number, got {text!r}")
    return Limit(m.group(1), m.group(2), value)
