"""The scenario-key vocabulary: a dotted key with list indices ('mechanism.sprockets[1][0]'), its value in a
resolved scenario, its SI unit and column-name suffix, and a value written back as `--set` text.

Shared by the faces and the studies (sweep columns, sizing bounds, sensitivity columns).
"""
from __future__ import annotations

import functools

from mechsim.scenarios.loader import sections_for, toml_literal  # noqa: F401 (re-exported)
from mechsim.scenarios.schema import TOP


def unit_suffix(unit: str) -> str:
    """'N*m' -> 'N_m', 'rad/s' -> 'rad_s', 'kg*m^2' -> 'kg_m2' (column-name form of an SI unit)."""
    return unit.replace("*", "_").replace("/", "_").replace("^", "").replace(" ", "")


def key_path(key: str) -> list:
    """'mechanism.sprockets[1][0]' -> ['mechanism', 'sprockets', 1, 0]: a list entry as the loader's `--set` and its
    messages name it."""
    out: list = []
    for part in key.split("."):
        name, *idx = part.split("[")
        out.append(name)
        out += [int(i.rstrip("]")) for i in idx]
    return out


def field_unit(si: dict, key: str) -> str:
    """The SI unit of a scenario key ('' for dimensionless, words, booleans); a list entry
    ('mechanism.sprocket_radii[0]', 'mechanism.sprockets[1][0]') has its list's unit."""
    return _field_unit(si["mechanism"]["type"], key)


@functools.lru_cache(maxsize=1024)
def _field_unit(mtype: str, key: str) -> str:
    """(cached: the schema's units are fixed, and a sweep asks for every key of every case)"""
    parts = [p for p in key_path(key) if isinstance(p, str)]
    indexed = len(parts) < len(key_path(key))
    if len(parts) == 1:
        spec = TOP.get(parts[0])
    else:
        spec = sections_for(mtype).get(parts[0], {}).get(parts[1])
    if spec is None:
        return ""
    if spec.kind == "quantity" or (indexed and spec.kind in ("list", "points", "profile")):
        return spec.unit or ""
    return ""


def lookup(si: dict, key: str):
    """The value at a scenario key, list entries included ('mechanism.sprocket_radii[0]')."""
    node = si
    for part in key_path(key):
        node = node[part]
    return node
