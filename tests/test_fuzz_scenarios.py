"""Property-based fuzzing of scenario files (hypothesis): malformed values, types, units, keys, structure and
encodings over every mechanism, section and field must give exit 2, exactly one line naming the field, no
traceback and nothing written. FUZZ_EXAMPLES cases a run (docs/limits.md), drawn from a new seed every run
(MECHSIM_FUZZ_SEED, printed in pytest's header by conftest.py; set it to repeat a run). Every field is also hit
once by a fixed table (test_every_field)."""
import math
import os
import tempfile
from pathlib import Path

import pint
import pytest
import tomli_w
import tomllib
from cli_helpers import invoke, one_line_error
from hypothesis import HealthCheck, given, seed, settings
from hypothesis import strategies as st

from mechsim.scenarios.loader import builtin_text, sections_for
from mechsim.scenarios.schema import TOP
from mechsim.scenarios.units import registry

BASES = ("geneva-lc1", "chain-mech2-torque", "chain-mech1-kinematic", "rolling-a-torque", "rolling-d-line")
RAW = {b: tomllib.loads(builtin_text(b)) for b in BASES}
#: (base scenario, section or "" for top level, key, Field) for every field of every mechanism
FIELDS = [(b, "", k, f) for b in BASES for k, f in TOP.items()] + [
    (b, section, key, spec) for b in BASES for section, fields in sections_for(RAW[b]["mechanism"]["type"]).items()
    for key, spec in fields.items()]
VALUE_EXAMPLES, STRUCTURE_EXAMPLES, ENCODING_EXAMPLES = 360, 80, 60
FUZZ_EXAMPLES = VALUE_EXAMPLES + STRUCTURE_EXAMPLES + ENCODING_EXAMPLES
FUZZ_SEED = int(os.environ.get("MECHSIM_FUZZ_SEED", "0"))
FUZZ = dict(deadline=None, derandomize=False, database=None,
            suppress_health_check=[HealthCheck.function_scoped_fixture, HealthCheck.too_slow])
OTHER_UNITS = ("1 kg", "1 s", "1 m", "1 K", "1 N")
NO_DIGITS = st.text(alphabet=st.characters(blacklist_categories=("Nd", "No", "Nl", "Cs")), max_size=30)


def _dimensionality(text):
    return registry().Quantity(text).dimensionality


def bad_values(spec):
    """Values that are certainly invalid for this field (strategy)."""
    nonfinite = st.sampled_from([math.nan, math.inf, -math.inf])
    wrong_type = st.sampled_from([True, [], {"a": 1}, [1, 2, 3]])
    if spec.kind == "quantity":
        wrong_unit = [u for u in OTHER_UNITS if _dimensionality(u) != registry().Quantity(1, spec.unit).dimensionality]
        return st.one_of(
            wrong_type,
            st.integers(-10**6, 10**6),                                        # a bare number: the unit is missing
            st.floats(allow_nan=False, allow_infinity=False, width=64),
            st.sampled_from(["nan", "inf", "-inf", "1e300", "-1e300", "1e400"]).map(lambda v: f"{v} {spec.unit}"),
            st.sampled_from(wrong_unit) if wrong_unit else st.just("1 kg m s"),
            st.sampled_from(["", "9**9**9 " + spec.unit, "1 2 3", "(1)", "1e5", "0x10 m"]),
            st.sampled_from(["1 s**9**9**9", "1 m^9^9", "75 mm - 74.9999999 mm", "2 mm * 3", "1 m + 1 m",  # expressions
                             "1 (((m)))", "1 m)", "1 m^99", "1e5 m**-7", "2 mm/0"]),
            NO_DIGITS.map(lambda t: t + " " + spec.unit),
        )
    if spec.kind == "float":
        return st.one_of(nonfinite, wrong_type, st.sampled_from([1e300, -1e300, 10**400]),
                         NO_DIGITS, st.just("0.5"))
    if spec.kind == "int":
        return st.one_of(wrong_type, st.floats(width=64), st.sampled_from([10**30, 2**63, -(2**63), 10**400]),
                         st.just("4"), NO_DIGITS)
    if spec.kind == "bool":
        return st.one_of(st.integers(), st.sampled_from(["yes", "true", "", [True]]), st.floats(width=64))
    if spec.kind == "str":
        wrong = st.one_of(st.integers(), st.floats(width=64), st.sampled_from([True, [], ["a"], {"x": "y"}]),
                          st.just("x" * 10_001))
        if spec.choices:
            return st.one_of(wrong, st.text(max_size=20).filter(lambda t: t not in spec.choices))
        return wrong
    # points / list fields: not a list, bare numbers (no unit), non-finite or absurd entries, absurd length
    entry = st.one_of(st.sampled_from(["nan m", "inf m", f"1e300 {spec.unit}", "1e400 " + spec.unit]),
                      st.integers(-5, 5), st.booleans(), NO_DIGITS)
    if spec.kind == "points":
        return st.one_of(st.integers(), st.text(max_size=5), st.lists(entry, min_size=1, max_size=3),
                         st.lists(st.lists(entry, min_size=2, max_size=2), min_size=1, max_size=4),
                         st.just([["1 m", "1 m"]] * 65))
    return st.one_of(st.integers(), st.text(max_size=5), st.lists(entry, min_size=1, max_size=4),
                     st.just([f"1 {spec.unit}"] * 65))


@st.composite
def malformed_value(draw):
    base, section, key, spec = draw(st.sampled_from(FIELDS))
    raw = tomllib.loads(builtin_text(base))
    value = draw(bad_values(spec))
    (raw.setdefault(section, {}) if section else raw)[key] = value
    return raw, f"{section}.{key}" if section else key


IDENT = st.from_regex(r"[a-z][a-z0-9_]{0,11}", fullmatch=True)


@st.composite
def malformed_structure(draw):
    base = draw(st.sampled_from(BASES))
    raw = tomllib.loads(builtin_text(base))
    sections = sections_for(raw["mechanism"]["type"])
    kind = draw(st.sampled_from(["unknown key", "unknown section", "section not a table", "type", "missing"]))
    if kind == "unknown key":
        section = draw(st.sampled_from(sorted(sections)))
        key = draw(IDENT.filter(lambda k: k not in sections[section] and k != "type"))
        raw.setdefault(section, {})[key] = draw(st.one_of(st.integers(), st.text(max_size=8), st.booleans()))
        return raw, f"{section}.{key}"
    if kind == "unknown section":
        name = draw(IDENT.filter(lambda k: k not in sections and k not in TOP))
        raw[name] = {"x": draw(st.integers())}
        return raw, name
    if kind == "section not a table":
        name = draw(st.sampled_from(sorted(sections)))
        raw[name] = draw(st.one_of(st.integers(), st.text(max_size=8), st.lists(st.integers(), max_size=3)))
        return raw, name
    if kind == "type":
        raw["mechanism"]["type"] = draw(st.one_of(st.integers(), st.lists(st.sampled_from(["geneva", "x"])),
                                                  st.text(max_size=10).filter(lambda t: t not in
                                                                              ("geneva", "chain_dwell",
                                                                               "rolling_pair"))))
        return raw, "mechanism.type"
    required = [k for k, f in TOP.items() if f.required] + [
        f"{s}.{k}" for s, fields in sections.items() for k, f in fields.items() if f.required]
    where = draw(st.sampled_from(required))
    section, _, key = where.rpartition(".")
    (raw[section] if section else raw).pop(key, None)
    return raw, where


@st.composite
def malformed_bytes(draw):
    """(data, the field its refusal names)."""
    text = builtin_text(draw(st.sampled_from(BASES)))
    kind = draw(st.sampled_from(["utf-16", "utf-32", "latin-1", "binary", "deep", "truncated", "garbage"]))
    if kind in ("utf-16", "utf-32"):
        return (text + '# "é"\n').encode(kind), "scenario"
    if kind == "latin-1":
        at = draw(st.integers(0, len(text)))
        return text[:at].encode() + b"\xe9\xff" + text[at:].encode(), "scenario"
    if kind == "binary":
        return draw(st.binary(min_size=1, max_size=200)) + b"\x00", "scenario"
    if kind == "deep":
        n = draw(st.integers(9, 200_000))
        return b"x = " + b"[" * n + b"]" * n, "scenario"
    if kind == "truncated":
        cut = draw(st.integers(1, len(text) - 1))
        data = text.encode()[:cut]
        # the damage on a line of its own (a cut inside a comment would keep it a comment): always malformed TOML
        return data + (b"\n[" if draw(st.booleans()) else b"\n = = \n"), "scenario"
    # a NUL is never valid TOML (not even in a comment): random bytes can spell a valid document, "#\xc2\x80"
    return draw(st.binary(min_size=1, max_size=100)).replace(b"\n", b"\x00") + b"\x00", "scenario"



def check_refused(tmp_path, data: bytes, field: str | None):
    """Exit 2, one line naming `field` (None: any field), nothing written. Each example in a folder of its own
    (tmp_path is one folder for all of a hypothesis test's examples)."""
    with tempfile.TemporaryDirectory(dir=tmp_path) as folder:
        folder = Path(folder)
        case, out = folder / "case.toml", folder / "out"
        case.write_bytes(data)
        r = invoke("run", case, "--out", out, "--quiet")
        assert r.exit_code == 2, (field, r.output)
        line = one_line_error(r)
        assert field is None or field in line, (field, line)
        assert not out.exists() and sorted(p.name for p in folder.iterdir()) == ["case.toml"]


@seed(FUZZ_SEED)
@settings(max_examples=VALUE_EXAMPLES, **FUZZ)
@given(case=malformed_value())
def test_fuzz_values(tmp_path, case):
    raw, field = case
    check_refused(tmp_path, tomli_w.dumps(raw).encode(), field)


@seed(FUZZ_SEED)
@settings(max_examples=STRUCTURE_EXAMPLES, **FUZZ)
@given(case=malformed_structure())
def test_fuzz_structure(tmp_path, case):
    raw, field = case
    check_refused(tmp_path, tomli_w.dumps(raw).encode(), field)


@seed(FUZZ_SEED)
@settings(max_examples=ENCODING_EXAMPLES, **FUZZ)
@given(data=malformed_bytes())
def test_fuzz_encodings_and_syntax(tmp_path, data):
    check_refused(tmp_path, *data)



@pytest.mark.parametrize("base,section,key,spec", FIELDS,
                         ids=[f"{b}:{s}.{k}" if s else f"{b}:{k}" for b, s, k, _ in FIELDS])
def test_every_field_refuses_a_wrong_type(tmp_path, base, section, key, spec):
    raw = tomllib.loads(builtin_text(base))
    (raw.setdefault(section, {}) if section else raw)[key] = {"not": "a value"}
    check_refused(tmp_path, tomli_w.dumps(raw).encode(), f"{section}.{key}" if section else key)


def test_every_quantity_unit_has_a_physical_range():
    from mechsim.scenarios.schema import UNIT_RANGES
    units = {spec.unit for _, _, _, spec in FIELDS if spec.unit}
    assert units <= set(UNIT_RANGES), units - set(UNIT_RANGES)
    for unit in UNIT_RANGES:                              # each is a real SI unit pint knows
        assert isinstance(registry().Quantity(1, unit), pint.Quantity)


def test_valid_values_are_not_refused(monkeypatch):
    """Every built-in scenario validates, and values at the edge of the ranges are accepted (the memory estimate,
    which depends on the machine, lifted: the row count's own limit is the edge here)."""
    from mechsim.scenarios import schema
    from mechsim.scenarios.loader import builtin_names, load
    monkeypatch.setattr(schema, "memory_budget", lambda: math.inf)
    for name in builtin_names():
        assert load(name).si["duration"] > 0, name
    si = load("geneva-lc1", ["mechanism.slots=72", "contact.friction=2", "initial.crank_angle=-180 deg",
                             "mechanism.wheel_inertia=1e-15 kg*m^2", "duration=10000 s", "output_step=1 ms",
                             "solver.baumgarte_beta=1e6", "output.drawing_instants=24",
                             "thermal.model=1d", "thermal.mesh_growth=10"]).si
    # accepted, and held in SI as given (the angle in radians)
    assert (si["mechanism"]["slots"], si["contact"]["friction"], si["output"]["drawing_instants"]) == (72, 2.0, 24)
    assert si["initial"]["crank_angle"] == pytest.approx(-math.pi, rel=1e-15)
    assert (si["mechanism"]["wheel_inertia"], si["duration"], si["output_step"]) == (1e-15, 10000.0, 1e-3)
    assert (si["solver"]["baumgarte_beta"], si["thermal"]["mesh_growth"]) == (1e6, 10.0)
