"""Units at the edge: parse "75 mm", "7 N*m", "-180 deg", "300 rpm" with pint and return SI magnitudes."""
from __future__ import annotations

import re
from functools import lru_cache


#: a quantity string: a number (or nan/inf, refused later with a clear message) and a unit expression; checked
#: before pint sees it, so that pint never evaluates an arbitrary arithmetic expression ("9**9**9 s")
QUANTITY_TEXT = re.compile(r"^[-+]?(?:(?:\d+\.?\d*|\.\d+)(?:[eE][-+]?\d+)?|nan|inf|infinity)"
                           r"(?:\s*(?:[^\W\d]|[\u00b0\u00b5])[\w\s*/^().\u00b7\u00b0\u00b5-]*)?$", re.IGNORECASE)
MAX_QUANTITY_TEXT = 64


class ScenarioError(ValueError):
    """A user error in a scenario: `field` names the key (section.key), `problem` says what is wrong."""

    def __init__(self, field: str, problem: str):
        super().__init__(f"{field}: {problem}")
        self.field = field
        self.problem = problem


@lru_cache(maxsize=1)
def registry():
    """The unit registry (pint is imported here, on first use: it costs ~0.3 s, which `mechsim --help` and the
    error paths should not pay)."""
    import pint
    ureg = pint.UnitRegistry(autoconvert_offset_to_baseunit=True)
    return ureg


@lru_cache(maxsize=4096)
def _parse_quantity(text: str):
    """pint parsing is the slow part of validation (sweeps validate thousands of cases): memoized."""
    return registry().Quantity(text)


def to_si(field: str, value, unit: str) -> float:
    """Convert a quantity string to the SI `unit`. Every quantity needs its unit written out, angles included
    ("-180 deg", "0 rad"); only a field without a unit (`unit` = "") takes a bare number.

    A pure function of its arguments, so it is memoized (sweeps validate thousands of cases with the same
    strings); errors are not cached and raise again."""
    try:
        return _to_si_cached(field, value, unit)
    except TypeError as exc:            # unhashable value (a list, a table): convert uncached, same messages
        if "unhashable" not in str(exc):
            raise
        return _to_si(field, value, unit)


@lru_cache(maxsize=65536)
def _to_si_cached(field: str, value, unit: str) -> float:
    if isinstance(value, bool) or not isinstance(value, (str, int, float)):
        return _to_si(field, value, unit)
    key = f"{type(value).__name__}:{value!r}->{unit}"
    cache = _disk_cache()
    hit = cache.get(key) if cache is not None else None
    if isinstance(hit, float):
        return hit
    result = _to_si(field, value, unit)          # raises on a bad value: errors are never stored
    if cache is not None:
        cache.put(key, result)
    return result


@lru_cache(maxsize=1)
def _disk_cache():
    """Successful conversions on disk (scenarios/diskcache.py), keyed by pint's version: a fresh `mechsim run`
    of a scenario it has seen converts every quantity without importing pint."""
    from importlib import metadata

    from mechsim.scenarios.diskcache import JsonCache
    try:
        # "units-2": conversions stored before bare numbers in strings were refused ("1e5" for an angle) are not read
        return JsonCache(f"units-2-pint-{metadata.version('pint')}")
    except metadata.PackageNotFoundError:
        return None


def _to_si(field: str, value, unit: str) -> float:
    import pint
    ureg = registry()
    if isinstance(value, bool):
        raise ScenarioError(field, f"expected a quantity in {unit}, got a boolean")
    if isinstance(value, (int, float)):
        if not unit:
            try:
                return float(value)
            except OverflowError:
                raise ScenarioError(field, "number too large for a float (at most about 1.8e308)") from None
        shown = f"{value:.6g}" if isinstance(value, float) or abs(value) < 10**15 else "1"
        example = f"\"{shown} deg\" or \"{shown} rad\"" if unit == "rad" else f"\"{shown} {unit}\""
        raise ScenarioError(field, f"needs a unit, e.g. {example}")
    if not isinstance(value, str):
        raise ScenarioError(field, f"expected a quantity such as \"1 {unit}\", got {type(value).__name__}")
    text = value.strip()
    if len(text) > MAX_QUANTITY_TEXT or not QUANTITY_TEXT.match(text):
        shown = repr(text if len(text) <= 40 else text[:40] + "...")
        raise ScenarioError(field, f"cannot read {shown} as a quantity (a number and a unit, e.g. \"1 {unit}\")")
    try:
        q = _parse_quantity(text)
    except Exception:
        raise ScenarioError(field, f"cannot read {value!r} as a quantity (number and unit, e.g. \"1 {unit}\")") \
            from None
    if not isinstance(q, pint.Quantity) or q.unitless:    # pint reads a bare "1e5" as a dimensionless Quantity
        if unit:
            raise ScenarioError(field, f"needs a unit, e.g. \"{text} {unit}\"")
        q = ureg.Quantity(float(q), "")
    try:
        if unit == "K" or unit == "degC":
            return float(q.to("K").magnitude) if unit == "K" else float(q.to("degC").magnitude)
        magnitude = q.to(unit).magnitude
    except pint.DimensionalityError:
        raise ScenarioError(field, f"wrong unit in {value!r}: expected a quantity convertible to {unit}") from None
    except (ArithmeticError, ValueError, TypeError):
        raise ScenarioError(field, f"cannot convert {value!r} to {unit}") from None
    try:
        return float(magnitude)
    except (TypeError, ValueError):
        raise ScenarioError(field, f"cannot read {value!r} as a number") from None


def format_si(value: float, unit: str) -> str:
    """A quantity string in SI for the resolved scenario file."""
    return f"{value:.12g} {unit}" if unit else f"{value:.12g}"
