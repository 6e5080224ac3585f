"""Units at the edge: parse "75 mm", "7 N*m", "-180 deg", "300 rpm" with pint and return SI magnitudes."""
from __future__ import annotations

import re
from functools import lru_cache


#: the number at the start of a quantity string (nan/inf are read, then refused later with a clear message)
NUMBER = re.compile(r"[-+]?(?:(?:\d+\.?\d*|\.\d+)(?:[eE][-+]?\d{1,3})?|nan|infinity|inf)", re.IGNORECASE)
#: tokens of a unit expression: a unit name (letters, with the degree and micro signs), an exponent, an operator
UNIT_TOKEN = re.compile(r"\s*(?:(?P<name>[^\W\d_][^\W\d]*)|(?P<power>(?:\^|\*\*)\s*[-+]?\d+)|(?P<op>[*/\u00b7])"
                        r"|(?P<open>\()|(?P<close>\)))")
MAX_QUANTITY_TEXT = 64
#: the largest |exponent| of a unit and the deepest parenthesis nesting a quantity may have
MAX_EXPONENT = 4
MAX_NESTING = 2
QUANTITY_FORM = (f"a number and a unit expression (unit names joined by * or /, exponents ^k with |k| <= {MAX_EXPONENT}, "
                 "no arithmetic)")


def quantity_form_problem(text: str) -> str | None:
    """None if `text` is a number followed by an optional unit expression of the safe grammar, else what is wrong.

    The grammar (docs/limits.md): number [unit-expression], where a unit expression is unit names joined by `*`,
    `/`, `\u00b7` or a space, each name or parenthesised group (at most two deep) followed by at most one exponent
    `^k` or `**k` with an integer |k| <= 4. Numbers never appear inside the unit expression, so no arithmetic
    between quantities ("75 mm - 74.9999999 mm") and no towers of exponents ("1 s**9**9**9") reach pint."""
    m = NUMBER.match(text)
    if not m:
        return "it does not start with a number"
    pos, depth, expect_unit, after_unit = m.end(), 0, True, False
    rest = text[pos:].strip()
    if not rest:
        return None
    while pos < len(text):
        if not text[pos:].strip():
            break
        tok = UNIT_TOKEN.match(text, pos)
        if not tok:
            return f"unexpected {text[pos:].strip()[:12]!r}"
        pos = tok.end()
        if tok.group("name") or tok.group("open"):
            if not expect_unit and not after_unit:
                return "an operator is missing"
            if tok.group("open"):
                depth += 1
                if depth > MAX_NESTING:
                    return f"parentheses nested deeper than {MAX_NESTING}"
                expect_unit, after_unit = True, False
            else:
                expect_unit, after_unit = False, True
        elif tok.group("power"):
            if not after_unit:
                return "an exponent must follow a unit name or a parenthesis"
            k = int(re.sub(r"[\^*\s]", "", tok.group("power")))
            if abs(k) > MAX_EXPONENT:
                return f"exponent {k} out of range (|k| <= {MAX_EXPONENT})"
            after_unit = False
        elif tok.group("op"):
            if expect_unit:
                return "an operator without a unit before it"
            expect_unit, after_unit = True, False
        else:                                   # close
            if expect_unit or depth == 0:
                return "unbalanced parentheses"
            depth -= 1
            expect_unit, after_unit = False, True
    if expect_unit or depth:
        return "the unit expression is incomplete"
    return None


class ScenarioError(ValueError):
    """A user error in a scenario: `field` names the key (section.key), `problem` says what is wrong."""

    def __init__(self, field: str, problem: str):
        super().__init__(f"{field}: {problem}")
        self.field = field
        self.problem = problem


@lru_cache(maxsize=1)
def registry():
    """The unit registry (pint is imported here, on first use: a cost `mechsim --help` and the
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
        # "units-3": conversions stored before Hz was read as a rotation rate and angle exponents were checked
        return JsonCache(f"units-3-pint-{metadata.version('pint')}")
    except metadata.PackageNotFoundError:
        return None


def forget_unsaved_conversions() -> None:
    """Drop the conversions this process has not yet written to the disk cache (called on a refused command)."""
    cache = _disk_cache.cache_info().currsize and _disk_cache()
    if cache:
        cache.discard_unsaved()


#: the unit a scenario usually writes a field of this SI unit in (the built-in scenarios write lengths in mm, the
#: ambient temperature in degC): a bare number's hint uses it, as "75 m" would be 1000x what "75" usually means
USUAL_UNITS = {"m": "mm", "m^2": "mm^2", "m^3": "mm^3", "Pa": "GPa", "K": "degC"}


def unit_hint(number: str, unit: str) -> str:
    """`e.g. ...` for a bare number in a field of SI `unit`: written in the field's usual unit."""
    if unit == "rad":
        return f"e.g. \"{number} deg\" or \"{number} rad\""
    return f"e.g. \"{number} {USUAL_UNITS.get(unit, unit)}\""


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
        raise ScenarioError(field, f"needs a unit, {unit_hint(shown, unit)}")
    if not isinstance(value, str):
        raise ScenarioError(field, f"expected a quantity such as \"1 {unit}\", got {type(value).__name__}")
    text = value.strip()
    problem = (f"longer than {MAX_QUANTITY_TEXT} characters" if len(text) > MAX_QUANTITY_TEXT
               else quantity_form_problem(text))
    if problem:
        shown = repr(text if len(text) <= 40 else text[:40] + "...")
        raise ScenarioError(field, f"cannot read {shown} as a quantity: {problem}; write {QUANTITY_FORM}, "
                                   f"e.g. \"1 {unit}\"")
    try:
        q = _parse_quantity(text)
    except Exception:
        raise ScenarioError(field, f"cannot read {value!r} as a quantity (number and unit, e.g. \"1 {unit}\")") \
            from None
    if not isinstance(q, pint.Quantity) or q.unitless:    # pint reads a bare "1e5" as a dimensionless Quantity
        if unit:
            raise ScenarioError(field, f"needs a unit, {unit_hint(text, unit)}")
        q = ureg.Quantity(float(q), "")
    try:
        if unit == "K" or unit == "degC":
            return float(q.to("K").magnitude) if unit == "K" else float(q.to("degC").magnitude)
        magnitude = _angles_by_definition(field, value, q, unit).to(unit).magnitude
    except ScenarioError:
        raise
    except pint.DimensionalityError:
        raise ScenarioError(field, f"wrong unit in {value!r}: expected a quantity convertible to {unit}") from None
    except (ArithmeticError, ValueError, TypeError):
        raise ScenarioError(field, f"cannot convert {value!r} to {unit}") from None
    try:
        return float(magnitude)
    except (TypeError, ValueError):
        raise ScenarioError(field, f"cannot read {value!r} as a number") from None


def _radian_exponent(q) -> int:
    """The power of the angle in a quantity's root units (pint keeps radian as a dimensionless base unit:
    "300 rpm" -> rad/s, "5 Hz" -> 1/s)."""
    return q.to_root_units()._units.get("radian", 0)


def _angles_by_definition(field: str, value, q, unit: str):
    """q with its angles read by their definitions before converting to `unit` (docs/limits.md, "Units"):
    a frequency in Hz where a rotation rate is asked is one turn per second (so "5 Hz" is 10 pi rad/s, not 5);
    a quantity with an explicit angle unit must carry the asked angle's power ("1 N*m*s/rad**2" is no damping);
    a quantity with no angle unit at all takes radians implicitly ("2 N*m*s" for a damping in N*m*s/rad)."""
    ureg = registry()
    asked = _radian_exponent(ureg.Quantity(1.0, unit))
    given = _radian_exponent(q)
    if given == asked:
        return q
    if given == 0:
        if asked == 1 and "hertz" in str(q.units):
            return q.to("Hz") * ureg.Quantity(1.0, "turn")
        return q
    raise ScenarioError(field, f"wrong unit in {value!r}: expected a quantity convertible to {unit} "
                               f"(its angle to the power {asked}, not {given})")


def format_si(value: float, unit: str) -> str:
    """A quantity string in SI for the resolved scenario file."""
    return f"{value:.12g} {unit}" if unit else f"{value:.12g}"
