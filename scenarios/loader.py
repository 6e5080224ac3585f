"""Load a scenario (built-in name or TOML file), apply --set overrides, validate, convert to SI; write it back as
TOML, plain or with every key commented (`mechsim show`).

Scenario files are data: parsed with tomllib, never executed; they are untrusted input, so a file must be
UTF-8 text of at most MAX_FILE_BYTES with tables nested at most MAX_DEPTH deep (docs/limits.md).
"""
from __future__ import annotations

import copy
import functools
import json
import math
import os
import re
import tomllib
from dataclasses import dataclass
from importlib import resources
from pathlib import Path

from mechsim.mechanisms import MECHANISMS, Mechanism
from mechsim.mechanisms.base import Field

from mechsim.scenarios.schema import (COMMON_SECTIONS, REQUIRED_FOR_DRIVE, TOP, check_derived, check_section,
                                      did_you_mean)
from mechsim.scenarios.units import ScenarioError

BUILTIN_PACKAGE = "mechsim.scenarios.builtin"
#: a scenario file is a page of settings (the built-ins are under 2 kB)
MAX_FILE_BYTES = 1_000_000
#: tables and arrays nest at most this deep (a scenario needs 3: [section] key = [[x, y], ...])
MAX_DEPTH = 8


@dataclass
class Scenario:
    """A validated scenario: `raw` as written (after overrides), `si` the resolved values in SI.

    `sc["mechanism.crank_radius"]` is a resolved value (SI float; "duration" for a top-level key),
    `sc.set(...)` a new validated scenario with overrides applied, `sc.to_toml()` the scenario as written."""

    name: str
    raw: dict
    si: dict
    source: str

    @property
    def mechanism_type(self) -> str:
        return self.si["mechanism"]["type"]

    def __getitem__(self, key: str):
        """The resolved value of "section.key" (or a top-level key): SI, as the run uses it (a float in the
        field's SI unit for a quantity, defaults filled in). KeyError naming the known keys otherwise."""
        node = self.si
        for part in key.split("."):
            if not isinstance(node, dict) or part not in node:
                section = key.split(".")[0]
                known = (sorted(f"{section}.{k}" for k in self.si[section]) if isinstance(self.si.get(section), dict)
                         else sorted(k for k in self.si))
                raise KeyError(f"{key!r} is not a key of this scenario{did_you_mean(key, known)}; "
                               f"known: {', '.join(known)}")
            node = node[part]
        return node

    def set(self, overrides) -> "Scenario":
        """A new validated Scenario: this one's values as written with `overrides` applied (["section.key=value",
        ...] as `--set`, or {"section.key": value}). Raises ScenarioError naming the field on a bad value."""
        return from_raw(self.raw, self.source, override_strings(overrides))

    def to_toml(self, comments: bool = False) -> str:
        """The scenario as written (units as the user gave them, overrides applied) as TOML text; `load` reads it
        back to the same values. comments=True (`mechsim show`): every key with its meaning and SI unit as a
        comment, and every optional key left out as a commented line with its default (`annotated_toml`)."""
        if comments:
            return annotated_toml(self)
        import tomli_w
        return f"# {self.name} (from {self.source})\n" + tomli_w.dumps(self.raw)

    def __repr__(self) -> str:
        lines = [f"<mechsim.Scenario {self.name!r}: {self.mechanism_type}, from {self.source}"]
        top = ", ".join(f"{k} = {v}" for k, v in self.raw.items() if not isinstance(v, dict) and k != "description")
        if top:
            lines.append(f"  {top}")
        for section, values in self.raw.items():
            if isinstance(values, dict):
                text = f"  [{section}] " + ", ".join(f"{k} = {v}" for k, v in values.items())
                lines.append(text if len(text) <= 110 else text[:108] + " …")
        return "\n".join(lines) + ">"


def toml_literal(value) -> str:
    """A value as the right-hand side of `--set key=value` (TOML: quantities and words quoted)."""
    if isinstance(value, bool):
        return "true" if value else "false"
    if isinstance(value, int):
        return str(value)
    if isinstance(value, float):
        if math.isnan(value):
            return "nan"
        if math.isinf(value):
            return "inf" if value > 0 else "-inf"
        return repr(value)
    return json.dumps(str(value))   # a JSON string is a valid TOML basic string


def override_strings(overrides) -> list[str]:
    """Overrides as the CLI's --set strings: a list of "section.key=value" (or one such string), or a dict
    {"section.key": value} whose values are written as TOML ("75 mm" stays a quantity string, 3 a number, a list
    an array, a dict an inline table)."""
    from collections.abc import Mapping
    if overrides is None:
        return []
    if isinstance(overrides, str):
        return [overrides]
    if isinstance(overrides, Mapping):
        return [f"{key}={literal(value)}" for key, value in overrides.items()]
    return [str(o) for o in overrides]


def builtin_names() -> list[str]:
    files = resources.files(BUILTIN_PACKAGE)
    return sorted(p.name[:-5] for p in files.iterdir() if p.name.endswith(".toml"))


def builtin_text(name: str) -> str:
    path = resources.files(BUILTIN_PACKAGE) / f"{name}.toml"
    if not path.is_file():
        raise ScenarioError("scenario", f"no built-in scenario or file named {name!r}"
                                        f"{did_you_mean(name, builtin_names())} "
                                        f"(built-in: {', '.join(builtin_names())})")
    return path.read_text()


def read_text(path: Path) -> str:
    """A scenario file's text: a regular file, at most MAX_FILE_BYTES, UTF-8 (ScenarioError naming it if not)."""
    try:
        size = path.stat().st_size
        if size > MAX_FILE_BYTES:
            raise ScenarioError("scenario", f"{path} is {size:,} bytes; a scenario file is at most "
                                            f"{MAX_FILE_BYTES:,} bytes (docs/limits.md)")
        with path.open("rb") as fh:
            data = fh.read(MAX_FILE_BYTES + 1)
    except OSError as exc:
        raise ScenarioError("scenario", f"cannot read {path}: {exc.strerror or exc}") from None
    if len(data) > MAX_FILE_BYTES:
        raise ScenarioError("scenario", f"{path} is over {MAX_FILE_BYTES:,} bytes; a scenario file is at most that")
    if data[:4] in (b"\xff\xfe\x00\x00", b"\x00\x00\xfe\xff"):
        raise ScenarioError("scenario", f"{path} is UTF-32 text; save it as UTF-8")
    if data[:2] in (b"\xff\xfe", b"\xfe\xff"):
        raise ScenarioError("scenario", f"{path} is UTF-16 text; save it as UTF-8")
    if b"\x00" in data:
        raise ScenarioError("scenario", f"{path} is a binary file (it holds NUL bytes), not a TOML scenario")
    try:
        return data.decode("utf-8-sig")             # a byte-order mark, which some editors write, is dropped
    except UnicodeDecodeError as exc:
        raise ScenarioError("scenario", f"{path} is not UTF-8 text (byte 0x{data[exc.start]:02x} at offset "
                                        f"{exc.start}); save it as UTF-8") from None


def _depth(node) -> int:
    """Nesting depth of parsed TOML (iterative: a deep file cannot exhaust the stack here)."""
    deepest, stack = 0, [(node, 1)]
    while stack:
        item, level = stack.pop()
        if isinstance(item, (dict, list)):
            deepest = max(deepest, level)
            if deepest > MAX_DEPTH:
                return deepest
            stack.extend((child, level + 1) for child in (item.values() if isinstance(item, dict) else item))
    return deepest


def parse_toml(text: str, source: str) -> dict:
    """tomllib, with every failure (syntax, nesting that exhausts the parser, huge integers) one ScenarioError."""
    try:
        raw = tomllib.loads(text)
    except tomllib.TOMLDecodeError as exc:
        raise ScenarioError("scenario", f"malformed TOML in {source}: {exc}") from None
    except RecursionError:
        raise ScenarioError("scenario", f"{source} nests tables or arrays too deeply (at most {MAX_DEPTH})") from None
    except ValueError as exc:
        raise ScenarioError("scenario", f"unreadable value in {source}: {str(exc).splitlines()[0][:120]}") from None
    if _depth(raw) > MAX_DEPTH:
        raise ScenarioError("scenario", f"{source} nests tables or arrays more than {MAX_DEPTH} deep")
    return raw


def _is_path(name_or_path: str) -> bool:
    """Whether a scenario argument names a file: a .toml name, a name with a folder separator ("./name" forces a
    path), or an existing file; otherwise a built-in name wins over a folder of the same name (an output folder
    `mechsim run NAME --out NAME` wrote), and anything else that exists is a path (refused below if a folder)."""
    path = Path(name_or_path)
    if path.suffix == ".toml" or "/" in name_or_path or os.sep in name_or_path or path.is_file():
        return True
    return path.exists() and name_or_path not in builtin_names()


def read_raw(name_or_path: str) -> tuple[dict, str]:
    """Parse a scenario file or built-in by name (`_is_path` says which)."""
    path = Path(name_or_path)
    if _is_path(name_or_path):
        if not path.exists():
            raise ScenarioError("scenario", f"file not found: {name_or_path}")
        if not path.is_file():
            what = "a folder" if path.is_dir() else "not a regular file (a pipe, device or socket)"
            raise ScenarioError("scenario", f"{name_or_path} is {what}, not a scenario file")
        text, source = read_text(path), str(path)
    else:
        text, source = builtin_text(name_or_path), f"built-in:{name_or_path}"
    return parse_toml(text, source), source


def parse_override(text: str) -> tuple[list[str], object]:
    """'section.key=value' -> (path, value); the value is read as TOML when it can be, else as a string."""
    if "=" not in text:
        raise ScenarioError("--set", f"expected section.key=value, got {text!r}")
    path, value = text.split("=", 1)
    keys = [k.strip() for k in path.strip().split(".") if k.strip()]
    if not keys:
        raise ScenarioError("--set", f"missing key in {text!r}")
    return keys, copy.deepcopy(_override_value(value.strip()))


@functools.lru_cache(maxsize=4096)
def _override_value(text: str):
    """An override's value read as TOML when it can be, else the text (cached: a sweep repeats its values; the
    caller copies it, as a value may be a table or array)."""
    try:
        value = tomllib.loads(f"v = {text}")["v"]
    except tomllib.TOMLDecodeError:
        return text
    except RecursionError:
        value = None
    if value is None or _depth(value) > MAX_DEPTH:
        raise ScenarioError("--set", f"the value nests tables or arrays more than {MAX_DEPTH} deep")
    return value


def apply_overrides(raw: dict, overrides: list[str]) -> dict:
    """The scenario with `overrides` ("section.key=value") set, and without the file's values they replace or leave
    without meaning (`drop_replaced`): what every override of a scenario goes through (--set, a sweep's case, a
    sizing's design, a comparison's side)."""
    return drop_replaced(_with_values(raw, overrides), raw, overrides)


def _with_values(raw: dict, overrides: list[str]) -> dict:
    out = copy.deepcopy(raw)
    for text in overrides:
        keys, value = parse_override(text)
        node = out
        for k in keys[:-1]:
            node = node.setdefault(k, {})
            if not isinstance(node, dict):
                raise ScenarioError(".".join(keys), "is not inside a table")
        node[keys[-1]] = value
    return out


def drop_replaced(raw: dict, given: dict, overrides: list[str]) -> dict:
    """The overridden scenario without the file's values of keys an override gives in place of (`Field.replaces`):
    setting wheel_torque_profile on a scenario that gives wheel_torque replaces it, unless both are overridden; and
    without the file's values of a variant's keys (`Field.only_if`) that the overridden variant leaves without
    meaning: `--set drive.type=motor` on a prescribed-speed scenario drops its drive.speed, unless that is
    overridden too (then `check_section` refuses it, as it refuses such a key given with its variant)."""
    paths = {tuple(parse_override(text)[0]) for text in overrides}
    mtype = raw.get("mechanism", {}).get("type") if isinstance(raw.get("mechanism"), dict) else None
    if not isinstance(mtype, str) or mtype not in MECHANISMS:
        return raw                                          # validate() says what is wrong with the type
    sections = sections_for(mtype)
    for path in paths:
        if len(path) != 2 or not isinstance(sections.get(path[0]), dict) or path[1] not in sections[path[0]]:
            continue
        node, before = raw.get(path[0]), given.get(path[0])
        if not isinstance(node, dict) or not isinstance(before, dict):
            continue
        for other in sections[path[0]][path[1]].replaces:
            if (path[0], other) not in paths and other in before:
                node.pop(other, None)
        for other, spec in sections[path[0]].items():
            if (spec.only_if and spec.only_if[0] == path[1] and not spec.applies_with(node.get(path[1]))
                    and (path[0], other) not in paths and other in before):
                node.pop(other, None)
    # a prescribed speed overridden (its value, or the drive's type made 'speed') carries the drive from t = 0: the
    # file's initial speed, which it leaves unused (`validate`), goes with it unless that is overridden too
    speed_key = MECHANISMS[mtype].initial_keys[1]
    drive, initial, before = raw.get("drive"), raw.get("initial"), given.get("initial")
    if (paths & {("drive", "speed"), ("drive", "type")} and isinstance(drive, dict) and drive.get("type") == "speed"
            and isinstance(initial, dict) and isinstance(before, dict) and speed_key in before
            and ("initial", speed_key) not in paths):
        initial.pop(speed_key, None)
    return raw


def extra_sections(mech_cls: type[Mechanism]) -> dict:
    """Sections contributed by other packages (thermal), keyed by name, as schema dicts."""
    from mechsim.scenarios.thermal_schema import thermal_section  # local: keeps the import graph one-way and lazy
    return {"thermal": thermal_section(mech_cls)}


def sections_for(mtype: str) -> dict[str, dict[str, Field]]:
    """Every section's fields for a mechanism type (common + mechanism + thermal + initial)."""
    mech_cls = MECHANISMS[mtype]
    sections = dict(COMMON_SECTIONS)
    sections.update(mech_cls.schema)
    sections.update(extra_sections(mech_cls))
    sections["initial"] = {
        mech_cls.initial_keys[0]: Field("quantity", "rad", default=0.0, help="initial angle of the drive coordinate"),
        mech_cls.initial_keys[1]: Field("quantity", "rad/s", default=0.0, help="initial speed of the drive coordinate"),
    }
    return sections


def _as_text(spec: Field, value):
    if value is None or spec.kind not in ("quantity", "points", "list", "profile") or not spec.unit:
        return value
    if spec.kind == "quantity":
        return f"{value!r} {spec.unit}"
    if spec.kind == "points":
        return [[f"{c!r} {spec.unit}" for c in p] for p in value]
    if spec.kind == "profile":
        return {"t": [f"{c!r} s" for c in value["t"]],
                spec.profile_key: [f"{c!r} {spec.unit}" for c in value[spec.profile_key]]}
    return [f"{c!r} {spec.unit}" for c in value]


def resolved_raw(si: dict) -> dict:
    """The resolved scenario (SI) written back as scenario input: quantities as strings with SI units."""
    sections = sections_for(si["mechanism"]["type"])
    out = {k: _as_text(TOP[k], si[k]) for k in TOP}
    for name, fields in sections.items():
        out[name] = {k: _as_text(spec, si[name].get(k)) for k, spec in fields.items() if k in si.get(name, {})}
    out["mechanism"] = {"type": si["mechanism"]["type"], **out["mechanism"]}
    return out


def validate(raw: dict) -> dict:
    """Check every section and key; return the resolved scenario in SI."""
    if not isinstance(raw, dict):
        raise ScenarioError("scenario", "must be a TOML table")
    mech_raw = raw.get("mechanism")
    if not isinstance(mech_raw, dict):
        raise ScenarioError("mechanism", "missing (required table with at least `type`)")
    mtype = mech_raw.get("type")
    if "type" not in mech_raw:
        raise ScenarioError("mechanism.type", f"missing (required: one of {', '.join(MECHANISMS)})")
    if not isinstance(mtype, str) or mtype not in MECHANISMS:
        shown = repr(mtype) if isinstance(mtype, (str, int, float, bool, type(None))) else type(mtype).__name__
        hint = did_you_mean(mtype, MECHANISMS) if isinstance(mtype, str) else ""
        raise ScenarioError("mechanism.type", f"must be one of {', '.join(MECHANISMS)}; got {shown[:80]}{hint}")
    sections = sections_for(mtype)
    for name, value in raw.items():
        if name in sections and not isinstance(value, dict):
            raise ScenarioError(name, f"must be a table ([{name}]), got {type(value).__name__}")
        if isinstance(value, dict) and name not in sections:
            raise ScenarioError(name, f"unknown section (known: {', '.join(sorted(sections))})")
    top_raw = {k: v for k, v in raw.items() if not isinstance(v, dict)}
    for key in [k for k in top_raw if k not in TOP]:   # a section's key without its section (--set crank_radius=75mm)
        owners = [name for name, fields in sections.items() if key in fields]
        if owners:
            raise ScenarioError(key, f"not a top-level key: it belongs in [{owners[0]}] "
                                     f"({owners[0]}.{key} with --set)")
    si = check_section("", TOP, top_raw)
    for name, fields in sections.items():
        data = raw.get(name, {})
        if name == "mechanism":
            data = {k: v for k, v in data.items() if k != "type"}
        si[name] = check_section(name, fields, data)
    si["mechanism"]["type"] = mtype
    from mechsim.scenarios.thermal_schema import check_thermal  # local, like extra_sections
    check_thermal(si)
    drive = si["drive"]
    for key in REQUIRED_FOR_DRIVE[drive["type"]]:
        if drive.get(key) is None:
            raise ScenarioError(f"drive.{key}", f"missing (required for drive type '{drive['type']}')")
    if (drive.get("duty_on") is None) != (drive.get("duty_off") is None):
        missing = "duty_off" if drive.get("duty_off") is None else "duty_on"
        raise ScenarioError(f"drive.{missing}", "missing (a duty cycle needs both duty_on and duty_off)")
    speed_key = MECHANISMS[mtype].initial_keys[1]
    start = si["initial"][speed_key]
    if drive["type"] == "speed" and start != 0.0 and abs(start - drive["speed"]) > 1e-9 * abs(drive["speed"]):
        raise ScenarioError(f"initial.{speed_key}", f"{start!r} rad/s would be ignored: a prescribed drive turns at "
                                                    f"drive.speed = {drive['speed']!r} rad/s from t = 0 (remove it, "
                                                    "or give it the drive's speed)")
    if drive.get("duty_on") is not None and drive["type"] == "speed":
        raise ScenarioError("drive.duty_on", "a duty cycle needs drive.type 'torque' or 'motor' (a prescribed "
                                             "speed has no torque to switch off)")
    if si["output_step"] > si["duration"]:
        raise ScenarioError("output_step", "must not exceed duration")
    check_derived(si)
    return si


def build_mechanism(si: dict) -> Mechanism:
    """The mechanism model of a validated scenario (geometry errors become ScenarioError), with the derivation
    cache as the store of the functions it derives for itself (`Mechanism.function_store`)."""
    from mechsim.dynamics import derivation_cache
    cls = MECHANISMS[si["mechanism"]["type"]]
    try:
        if (si.get("contact") or {}).get("model") == "compliant":
            si = _with_contact_modulus(si)
        mech = cls.from_config(si)
        mech.function_store = derivation_cache.FunctionStore()
        return mech
    except ValueError as exc:
        if isinstance(exc, ScenarioError):
            raise
        named = re.match(r"^([a-z_]+\.[a-z_]+(?:\[\d+\])?): (.+)$", str(exc), re.S)  # 'section.key: problem'
        if named:
            raise ScenarioError(named.group(1), named.group(2)) from None
        raise ScenarioError("mechanism", str(exc)) from None
    except ArithmeticError as exc:                        # overflow/zero division in a degenerate geometry
        raise ScenarioError("mechanism", f"the geometry cannot be built ({type(exc).__name__}: {exc})") from None


def _with_contact_modulus(si: dict) -> dict:
    """si with contact.modulus, the contact modulus E* of the thermal section's material (its library values or
    overrides; thermal/hertz.py): a compliant contact's stiffness is made of it (mechanisms/ reads no thermal/)."""
    from mechsim.thermal.hertz import effective_modulus
    from mechsim.thermal.materials import material_with_overrides
    return {**si, "contact": {**si["contact"], "modulus": effective_modulus(material_with_overrides(
        si.get("thermal") or {}))}}


def load(name_or_path: str, overrides: list[str] | None = None) -> Scenario:
    """Read, override, validate. Raises ScenarioError (one line) on any user error."""
    return from_raw(*read_raw(name_or_path), overrides)


def from_raw(raw: dict, source: str, overrides: list[str] | None = None) -> Scenario:
    """Override and validate a parsed scenario (`read_raw`), e.g. once per sweep case."""
    raw = apply_overrides(raw, overrides or [])
    si = validate(raw)
    build_mechanism(si)  # geometry checks now, before anything runs
    return Scenario(si["name"], raw, si, source)


#: the column at which a key's comment starts (a longer line puts it two spaces after)
COMMENT_COLUMN = 40


def literal(value) -> str:
    """A value as a one-line TOML literal (arrays inline)."""
    if isinstance(value, (list, tuple)):
        return "[" + ", ".join(literal(v) for v in value) + "]"
    if isinstance(value, dict):
        return "{" + ", ".join(f"{key_name(k)} = {literal(v)}" for k, v in value.items()) + "}"
    return toml_literal(value)


def key_name(key: str) -> str:
    """A key as TOML writes it: bare where it can be, quoted otherwise."""
    return key if key and all(c.isalnum() or c in "_-" for c in key) and key.isascii() else literal(key)


def _default_text(spec: Field) -> str:
    """The default of a key as it would be written (SI with its unit), or why there is none."""
    if spec.default is None:
        return "(no default)"
    return literal(_as_text(spec, spec.default))


def key_comment(spec: Field, key: str, fields: dict[str, Field] | None = None) -> str:
    """A key's comment: its meaning, SI unit, choices and the variants it belongs to (`fields`: its section's, where
    a key read under every variant but one says "not with" that one)."""
    head = (spec.help or key.replace("_", " ")) + (f" [{spec.unit}]" if spec.unit else "")
    parts = [head]
    if spec.choices and len(spec.choices) > 1:
        parts.append("one of " + ", ".join(map(str, spec.choices)))
    if spec.only_if:
        sibling, wanted = spec.only_if[0], spec.only_if[1] if isinstance(spec.only_if[1], tuple) else (spec.only_if[1],)
        rest = [c for c in (fields[sibling].choices if fields and sibling in fields else ()) if c not in wanted]
        parts.append(f"not with {sibling} = {literal(rest[0])}" if len(rest) == 1 and len(wanted) > 1 else
                     f"only with {sibling} = {' or '.join(literal(w) for w in wanted)}")
    if spec.required:
        parts.append("required")
    return "; ".join(parts)


def _line(text: str, comment: str) -> str:
    return f"{text.ljust(COMMENT_COLUMN - 2)}  # {comment}".rstrip() if comment else text


def _source_comments(source: str) -> dict[tuple[str, str], tuple[str, object]]:
    """{(section, key): (the comment after the key's line, the value on that line)} of the scenario's own file
    (a built-in's or a file's; {} where it cannot be read): single-line keys with a trailing `# comment`."""
    try:
        text = builtin_text(source[len("built-in:"):]) if source.startswith("built-in:") else read_text(Path(source))
    except (OSError, ValueError):
        return {}
    out: dict = {}
    section = ""
    for line in text.splitlines():
        stripped = line.strip()
        if stripped.startswith("[") and not stripped.startswith("[["):
            section = stripped.split("]")[0].strip("[ ")
            continue
        if "=" not in stripped or stripped.startswith("#"):
            continue
        for i, c in enumerate(line):
            if c != "#":
                continue
            try:
                parsed = tomllib.loads(line[:i])
            except tomllib.TOMLDecodeError:
                continue
            if len(parsed) == 1:
                (key, value), = parsed.items()
                out[(section, key)] = (line[i + 1:].strip(), value)
            break
    return out


def annotated_toml(scenario: Scenario) -> str:
    """The scenario as commented TOML (`Scenario.to_toml(comments=True)`, `mechsim show`): every key the schema
    knows for its mechanism, each with its meaning, SI unit and choices as a comment; the keys the scenario sets as
    written, every optional key it leaves out as a commented line with its default, so the text is also the
    scenario's reference. The scenario file's own comments stay beside the keys whose value is still the file's.
    Loading the text back gives the same scenario."""
    raw = scenario.raw
    mtype = scenario.mechanism_type
    own = _source_comments(scenario.source)

    def lines_of(section: str, fields: dict[str, Field], values: dict, extra: dict[str, str]) -> list[str]:
        out = []
        for key, comment in extra.items():              # keys outside the schema's fields (mechanism.type)
            if key in values:
                out.append(_line(f"{key_name(key)} = {literal(values[key])}", comment))
        for key, spec in fields.items():
            comment = key_comment(spec, key, fields)
            if key in values:
                written, value = own.get((section, key), ("", None))
                if written and value == values[key]:
                    comment = f"{comment} -- {written}"
                out.append(_line(f"{key_name(key)} = {literal(values[key])}", comment))
            else:
                out.append(_line(f"# {key_name(key)} = {_default_text(spec)}", comment))
        return out

    text = [f"# {scenario.name} (from {scenario.source})",
            "# every key with its meaning and SI unit; a key the scenario leaves out is a comment with its default:",
            "# remove the '# ' in front to set it (any unit of the same dimension: \"75 mm\", \"3000 rpm\")"]
    text += lines_of("", TOP, raw, {})
    sections = sections_for(mtype)
    types = {"type": "mechanism type: one of " + ", ".join(MECHANISMS)}
    order = [s for s in raw if isinstance(raw[s], dict)] + [s for s in sections if s not in raw]
    for name in order:
        values = raw.get(name)
        body = lines_of(name, sections.get(name, {}), values or {}, types if name == "mechanism" else {})
        header = f"[{key_name(name)}]"
        text += [""] + ([header] + body if values is not None else [f"# {header}"] + body)
    return "\n".join(text) + "\n"
