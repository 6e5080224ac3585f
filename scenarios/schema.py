"""The scenario schema: the common sections, plus each mechanism's own fields (declared in mechanisms/).

Validation is generic: every key is declared as a `Field`; unknown sections and keys are rejected; each
problem is reported as one `ScenarioError` naming `section.key`.
"""
from __future__ import annotations

from mechsim.mechanisms.base import Field

from mechsim.scenarios.units import ScenarioError, to_si

TOP = {
    "name": Field("str", required=True, help="scenario name (also the default output folder)"),
    "description": Field("str", default="", help="free text"),
    "duration": Field("quantity", "s", required=True, positive=True, help="simulated time"),
    "output_step": Field("quantity", "s", default=1e-3, positive=True, help="spacing of output rows"),
}

COMMON_SECTIONS: dict[str, dict[str, Field]] = {
    "drive": {
        "type": Field("str", required=True, choices=("speed", "torque", "motor"), help="drive model"),
        "speed": Field("quantity", "rad/s", default=None, positive=True, help="prescribed speed (type = speed)"),
        "torque": Field("quantity", "N*m", default=None, help="constant torque (type = torque)"),
        "stall_torque": Field("quantity", "N*m", default=None, positive=True, help="motor stall torque"),
        "no_load_speed": Field("quantity", "rad/s", default=None, positive=True, help="motor no-load speed"),
    },
    "solver": {
        "backend": Field("str", default="ida", choices=("ida", "diffrax")),
        "formulation": Field("str", default="index2", choices=("index1", "index2", "index3")),
        "method": Field("str", default="auto", choices=("auto", "dae", "closed-form"),
                        help="auto: closed form where the drive is prescribed and the model allows it"),
        "rtol": Field("float", default=1e-8, positive=True),
        "atol": Field("float", default=1e-10, positive=True),
        "multiplier_atol": Field("float", default=None, positive=True),
        "baumgarte_alpha": Field("float", default=10.0, nonnegative=True),
        "baumgarte_beta": Field("float", default=10.0, nonnegative=True),
        "max_steps": Field("int", default=20000, minimum=1),
        "events": Field("bool", default=True),
        "diffrax_solver": Field("str", default="Tsit5"),
        "jacobian": Field("str", default="exact", choices=("exact", "fd"),
                          help="IDA Jacobian: exact (generated) or fd (finite differences, only when asked)"),
    },
    "output": {
        "plots": Field("bool", default=True, help="write PNG plots"),
        "drawing_instants": Field("int", default=4, minimum=0, help="mechanism drawings at this many instants"),
        "animation": Field("bool", default=False, help="write an animation of the mechanism beside its force trace"),
        "animation_format": Field("str", default="gif", choices=("gif", "mp4"),
                                  help="gif (Pillow) or mp4 (needs ffmpeg)"),
    },
}

REQUIRED_FOR_DRIVE = {"speed": ("speed",), "torque": ("torque",), "motor": ("stall_torque", "no_load_speed")}


def check_field(where: str, spec: Field, value):
    """Validate and convert one value to SI."""
    if spec.kind == "quantity":
        out = to_si(where, value, spec.unit)
    elif spec.kind == "int":
        if isinstance(value, bool) or not isinstance(value, int):
            raise ScenarioError(where, f"expected an integer, got {value!r}")
        out = value
    elif spec.kind == "float":
        if isinstance(value, bool) or not isinstance(value, (int, float)):
            raise ScenarioError(where, f"expected a number, got {value!r}")
        out = float(value)
    elif spec.kind == "bool":
        if not isinstance(value, bool):
            raise ScenarioError(where, f"expected true or false, got {value!r}")
        out = value
    elif spec.kind == "str":
        if not isinstance(value, str):
            raise ScenarioError(where, f"expected a string, got {value!r}")
        out = value
    elif spec.kind == "points":
        if not isinstance(value, list) or not all(isinstance(p, list) and len(p) == 2 for p in value):
            raise ScenarioError(where, "expected a list of [x, y] pairs")
        out = [[to_si(f"{where}[{i}]", c, spec.unit) for c in p] for i, p in enumerate(value)]
    elif spec.kind == "list":
        if not isinstance(value, list):
            raise ScenarioError(where, "expected a list")
        out = [to_si(f"{where}[{i}]", c, spec.unit) if spec.unit else c for i, c in enumerate(value)]
    else:  # pragma: no cover - a schema bug, not a user error
        raise AssertionError(spec.kind)
    if spec.choices and out not in spec.choices:
        why = f" ({spec.help})" if len(spec.choices) == 1 and spec.help else ""
        raise ScenarioError(where, f"must be one of {', '.join(map(str, spec.choices))}; got {out!r}{why}")
    if isinstance(out, (int, float)) and not isinstance(out, bool):
        if spec.positive and not out > 0:
            raise ScenarioError(where, f"must be positive, got {value!r}")
        if spec.nonnegative and out < 0:
            raise ScenarioError(where, f"must not be negative, got {value!r}")
        if spec.minimum is not None and out < spec.minimum:
            raise ScenarioError(where, f"must be at least {spec.minimum}, got {value!r}")
    return out


def check_section(name: str, fields: dict[str, Field], data) -> dict:
    """Validate one table: unknown keys rejected, required keys present, defaults filled."""
    if not isinstance(data, dict):
        raise ScenarioError(name, "must be a table")
    for key in data:
        if key not in fields:
            known = ", ".join(sorted(fields))
            raise ScenarioError(f"{name}.{key}" if name else key, f"unknown key (known keys: {known})")
    out = {}
    for key, spec in fields.items():
        where = f"{name}.{key}" if name else key
        if key in data:
            out[key] = check_field(where, spec, data[key])
        elif spec.required:
            raise ScenarioError(where, "missing (required)")
        else:
            out[key] = spec.default
    return out
