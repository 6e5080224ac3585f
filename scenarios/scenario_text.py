"""A scenario as commented TOML (`mechsim show`, `Scenario.to_toml(comments=True)`): every key the schema knows for its
mechanism, each with its meaning, SI unit and choices as a comment; the keys the scenario sets as written, every
optional key it leaves out as a commented line with its default, so the file is also the scenario's reference.
Comments of the scenario's own file stay beside the keys whose value is still the file's. Loading the text back
gives the same scenario (tests/test_show.py).
"""
from __future__ import annotations

import tomllib

from mechsim.mechanisms import MECHANISMS
from mechsim.mechanisms.base import Field

#: the column at which a key's comment starts (a longer line puts it two spaces after)
COMMENT_COLUMN = 40


def literal(value) -> str:
    """A value as a one-line TOML literal (arrays inline)."""
    from mechsim.scenarios.loader import toml_literal
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
    from mechsim.scenarios.loader import _as_text
    return literal(_as_text(spec, spec.default))


def describe(spec: Field, key: str) -> str:
    """A key's comment: its meaning, SI unit, choices and the variant it belongs to."""
    head = (spec.help or key.replace("_", " ")) + (f" [{spec.unit}]" if spec.unit else "")
    parts = [head]
    if spec.choices and len(spec.choices) > 1:
        parts.append("one of " + ", ".join(map(str, spec.choices)))
    if spec.only_if:
        parts.append(f"only with {spec.only_if[0]} = {literal(spec.only_if[1])}")
    if spec.required:
        parts.append("required")
    return "; ".join(parts)


def _line(text: str, comment: str) -> str:
    return f"{text.ljust(COMMENT_COLUMN - 2)}  # {comment}".rstrip() if comment else text


def _source_comments(source: str) -> dict[tuple[str, str], tuple[str, object]]:
    """{(section, key): (the comment after the key's line, the value on that line)} of the scenario's own file
    (a built-in's or a file's; {} where it cannot be read): single-line keys with a trailing `# comment`."""
    from pathlib import Path

    from mechsim.scenarios.loader import builtin_text, read_text
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


def annotated_toml(scenario) -> str:
    """The scenario as commented TOML (module docstring)."""
    from mechsim.scenarios.loader import sections_for
    from mechsim.scenarios.schema import TOP
    raw = scenario.raw
    mtype = scenario.mechanism_type
    own = _source_comments(scenario.source)

    def lines_of(section: str, fields: dict[str, Field], values: dict, extra: dict[str, str]) -> list[str]:
        out = []
        for key, comment in extra.items():              # keys outside the schema's fields (mechanism.type)
            if key in values:
                out.append(_line(f"{key_name(key)} = {literal(values[key])}", comment))
        for key, spec in fields.items():
            comment = describe(spec, key)
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
