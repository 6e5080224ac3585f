"""The scenario schema: the common sections, plus each mechanism's own fields (declared in mechanisms/).

Validation is generic: every key is declared as a `Field`; unknown sections and keys are rejected; each
problem is reported as one `ScenarioError` naming `section.key`. Every number must be finite and inside a
physical range: the field's own (Field.minimum/maximum with its reason) and its unit's (UNIT_RANGES); derived
sizes (output rows) are bounded before anything runs. The limits and their reasons: docs/limits.md.
"""
from __future__ import annotations

import difflib
import math
import os

from mechsim.dynamics.settings import BACKENDS
from mechsim.mechanisms.base import Field

from mechsim.scenarios.units import ScenarioError, to_si

TOP = {
    "name": Field("str", required=True, help="scenario label (the default output folder is results/<its slug>)"),
    "description": Field("str", default="", help="free text"),
    "duration": Field("quantity", "s", required=True, positive=True, help="simulated time"),
    "output_step": Field("quantity", "s", default=1e-3, positive=True, help="spacing of output rows"),
}

COMMON_SECTIONS: dict[str, dict[str, Field]] = {
    "drive": {
        "type": Field("str", required=True, choices=("speed", "torque", "motor"), help="drive model"),
        "speed": Field("quantity", "rad/s", default=None, positive=True, help="prescribed speed",
                       only_if=("type", "speed")),
        "torque": Field("quantity", "N*m", default=None, help="constant torque", only_if=("type", "torque")),
        "stall_torque": Field("quantity", "N*m", default=None, positive=True, help="motor stall torque",
                              only_if=("type", "motor")),
        "no_load_speed": Field("quantity", "rad/s", default=None, positive=True, help="motor no-load speed",
                               only_if=("type", "motor")),
        "duty_on": Field("quantity", "s", default=None, positive=True, help=(
            "duty cycle (torque or motor drive): on for duty_on, then off for duty_off, repeated from t = 0; off "
            "is no torque at all (the drive coasts), not a brake")),
        "duty_off": Field("quantity", "s", default=None, positive=True, help="duty cycle: time off per period"),
    },
    "solver": {
        "backend": Field("str", default="auto", choices=BACKENDS,
                         help="integrator; auto: ida-compiled once compiled, else ida (docs/architecture.md)"),
        "formulation": Field("str", default="index2", choices=("index1", "index2", "index3"),
                             help="DAE index formulation (docs/stability.md)"),
        "method": Field("str", default="auto", choices=("auto", "dae", "closed-form"),
                        help="auto: closed form where the drive is prescribed and the model allows it"),
        "rtol": Field("float", default=1e-8, positive=True, minimum=1e-15, maximum=0.1, help="relative tolerance",
                      why="float64 carries about 16 digits; above 0.1 there is no accuracy left"),
        "atol": Field("float", default=1e-10, positive=True, minimum=1e-30, maximum=1.0,
                      help="absolute tolerance (SI: m, rad)",
                      why="an absolute error in SI units (m, rad): 1e-30 is far below round-off, 1 is no accuracy"),
        "multiplier_atol": Field("float", default=None, positive=True, minimum=1e-30, maximum=1e6,
                                 help="IDA's absolute tolerance on the constraint forces (default 1e6 for index2 and "
                                      "index3, 1e3 for index1: kept out of the error test)",
                                 why="an absolute error on constraint forces (N)"),
        "baumgarte_alpha": Field("float", default=10.0, nonnegative=True, maximum=1e8,
                                 help="index1: Baumgarte stabilisation parameter (1/s; docs/stability.md)",
                                 why="stabilisation rates (1/s) beyond 1e8 are stiffer than any mechanism's dynamics"),
        "baumgarte_beta": Field("float", default=10.0, nonnegative=True, maximum=1e8,
                                help="index1: Baumgarte stabilisation parameter (1/s; docs/stability.md)",
                                why="stabilisation rates (1/s) beyond 1e8 are stiffer than any mechanism's dynamics"),
        "max_steps": Field("int", default=20000, minimum=1, maximum=10_000_000,
                           help="most solver steps between two output rows (IDA), per segment (diffrax)",
                           why="ten million steps is hours of solver time and gigabytes of history"),
        "events": Field("bool", default=True, help="locate the mode changes (false only for the stability study)"),
        "diffrax_solver": Field("str", default="Tsit5", help="diffrax solver class (docs/diffrax.md)"),
        "diffrax_compiled_run": Field("bool", default=True, help=(
            "diffrax, explicit solvers: the whole run as one compiled call where the mechanism has a transition "
            "table (docs/diffrax.md 'The compiled run'); false: one compiled solve per segment, as `sweep --batch`")),
        "jacobian": Field("str", default="exact", choices=("exact", "fd"),
                          help="IDA Jacobian: exact (generated) or fd (finite differences, only when asked)"),
    },
    "output": {
        "plots": Field("bool", default=True, help="write PNG plots"),
        "drawing_instants": Field("int", default=4, minimum=0, maximum=24, help="mechanism drawings at this many "
                                  "instants", why="each drawing is one more figure panel; 24 still fit one page"),
        "animation": Field("bool", default=False, help="write an animation of the mechanism beside its force trace"),
        "animation_format": Field("str", default="gif", choices=("gif", "mp4"),
                                  help="gif (Pillow) or mp4 (needs ffmpeg)"),
        "csv": Field("str", default="always", choices=("always", "auto", "never"), help=(
            "timeseries.csv beside timeseries.parquet: always, never, or auto (left out of a large output, "
            "scenarios/output/size.py LARGE_OUTPUT_BYTES; the console says so)")),
        "on_invalid": Field("str", default="warn", choices=("warn", "stop"), help=(
            "where the model leaves its validity (summary.json 'validity'): warn (run on, list each violation) or "
            "stop (exit 3 at the first output row that violates a condition, what ran written)")),
    },
}

REQUIRED_FOR_DRIVE = {"speed": ("speed",), "torque": ("torque",), "motor": ("stall_torque", "no_load_speed")}

#: physical range of every quantity by its SI unit: (smallest magnitude of a positive field, largest magnitude,
#: why). A typo of a few orders of magnitude, or an overflow, is refused before any work (docs/limits.md).
UNIT_RANGES: dict[str, tuple[float, float, str]] = {
    "m": (1e-9, 1e3, "machine parts lie between 1 nm and 1 km"),
    "m^2": (1e-18, 1e6, "areas of parts between 1 nm^2 and 1 km^2"),
    "m^3": (1e-27, 1e9, "volumes of parts between 1 nm^3 and 1 km^3"),
    "rad": (1e-12, 1e6, "angles beyond 1e6 rad (160,000 turns) lose float64 resolution"),
    "rad/s": (1e-9, 1e5, "1e5 rad/s (about a million rpm) is beyond any machine shaft"),
    "s": (1e-9, 1e6, "simulated times between 1 ns and 1e6 s (11.6 days)"),
    "N*m": (1e-12, 1e7, "1e7 N*m is the torque of the largest ship propeller shafts"),
    "kg": (1e-9, 1e6, "masses between 1 microgram and 1000 t"),
    "kg*m^2": (1e-15, 1e6, "inertias between a 1 mm steel pin's (about 1e-14 kg*m^2) and a large flywheel's"),
    "N*m*s/rad": (1e-15, 1e6, "viscous damping up to 1e6 N*m*s/rad (a locked shaft)"),
    "N/m": (1.0, 1e13, "stiffnesses up to 1e13 N/m (a steel line contact 10 cm long is about 1e10 N/m)"),
    "m/s^2": (1e-9, 1e4, "accelerations of gravity up to 1000 g"),
    "K": (1.0, 3000.0, "temperatures between 1 K and 3000 K (above the melting point of steel)"),
    "Pa": (1e5, 2e12, "Young's moduli between soft foams and diamond (1.2e12 Pa)"),
    "kg/m^3": (1.0, 1e5, "densities between light foams and osmium (22,600 kg/m^3)"),
    "J/(kg*K)": (10.0, 1e5, "specific heats of solids lie between 10 and 1e5 J/(kg*K)"),
    "W/(m*K)": (1e-3, 1e4, "conductivities between aerogels and diamond (2,200 W/(m*K))"),
    "W/(m^2*K)": (1e-6, 1e6, "heat-transfer coefficients up to 1e6 W/(m^2*K) (boiling water)"),
    "W/K": (1e-12, 1e6, "thermal conductances up to 1e6 W/K"),
}
#: at most this many output steps on the requested grid (duration / output_step): a fully resolved table of
#: about 40 float64 columns is then about 3 GB (a cycle-averaged thermal run keeps only its mechanics window)
MAX_OUTPUT_ROWS = 10_000_000
#: bytes of memory a run needs per output row at its peak (tables, their copies while writing Parquet and CSV):
#: what a Geneva run's columns need, with a margin (docs/limits.md has the figures)
BYTES_PER_ROW = 2048
#: the share of the machine's physical memory one run may plan to use
MEMORY_SHARE = 0.5
#: at most this many entries in a list field (sprockets, points): no mechanism here has more than a few
MAX_LIST = 64
#: longest string value (names, descriptions, choices)
MAX_STRING = 10_000


def _shown(value) -> str:
    """repr of a value, short (a 5000-digit integer or a long string stays one readable line)."""
    if isinstance(value, int) and not isinstance(value, bool) and value.bit_length() > 64:
        return f"an integer of about {int(value.bit_length() * 0.30103)} digits"
    text = repr(value)
    return text if len(text) <= 80 else text[:60] + "...'"


def _as_float(where: str, value) -> float:
    try:
        return float(value)
    except OverflowError:
        raise ScenarioError(where, f"{_shown(value)} is too large for a float (at most about 1.8e308)") from None


def check_range(where: str, spec: Field, out: float, value) -> None:
    """Finite, signs, the field's own range and its unit's range (ScenarioError with the reason)."""
    if not math.isfinite(out):
        raise ScenarioError(where, f"must be a finite number, got {_shown(value)}")
    unit = f" {spec.unit}" if spec.unit else ""
    if spec.positive and not out > 0:
        raise ScenarioError(where, f"must be positive, got {_shown(value)}")
    if spec.nonnegative and out < 0:
        raise ScenarioError(where, f"must not be negative, got {_shown(value)}")
    why = f" ({spec.why})" if spec.why else ""
    if spec.minimum is not None and out < spec.minimum:
        raise ScenarioError(where, f"must be at least {spec.minimum:g}{unit}{why}, got {_shown(value)}")
    if spec.maximum is not None and out > spec.maximum:
        raise ScenarioError(where, f"must be at most {spec.maximum:g}{unit}{why}, got {_shown(value)}")
    if spec.unit in UNIT_RANGES:
        tiny, huge, reason = UNIT_RANGES[spec.unit]
        if abs(out) > huge:
            raise ScenarioError(where, f"must be at most {huge:g}{unit} in magnitude ({reason}), got {_shown(value)}")
        if spec.positive and out < tiny:
            raise ScenarioError(where, f"must be at least {tiny:g}{unit} ({reason}), got {_shown(value)}")
        if spec.nonnegative and 0.0 < out < tiny:
            raise ScenarioError(where, f"must be 0 or at least {tiny:g}{unit} ({reason}), got {_shown(value)}")


def check_field(where: str, spec: Field, value):
    """Validate and convert one value to SI."""
    if spec.kind == "quantity":
        out = to_si(where, value, spec.unit)
    elif spec.kind == "int":
        if isinstance(value, bool) or not isinstance(value, int):
            raise ScenarioError(where, f"expected an integer, got {_shown(value)}")
        if value.bit_length() > 64:  # compared as an integer: a huge one cannot even become a float
            raise ScenarioError(where, f"{_shown(value)} is out of range"
                                + (f"; at most {spec.maximum:g}" if spec.maximum is not None else ""))
        out = value
    elif spec.kind == "float":
        if isinstance(value, bool) or not isinstance(value, (int, float)):
            raise ScenarioError(where, f"expected a number, got {_shown(value)}")
        out = _as_float(where, value)
    elif spec.kind == "bool":
        if not isinstance(value, bool):
            raise ScenarioError(where, f"expected true or false, got {_shown(value)}")
        out = value
    elif spec.kind == "str":
        if not isinstance(value, str):
            raise ScenarioError(where, f"expected a string, got {_shown(value)}")
        if len(value) > MAX_STRING:
            raise ScenarioError(where, f"a string of {len(value)} characters; at most {MAX_STRING}")
        out = value
    elif spec.kind == "points":
        if not isinstance(value, list) or not all(isinstance(p, list) and len(p) == 2 for p in value):
            raise ScenarioError(where, "expected a list of [x, y] pairs")
        _check_length(where, value)
        out = [[_element(f"{where}[{i}]", spec, c) for c in p] for i, p in enumerate(value)]
    elif spec.kind == "profile":
        out = _profile(where, spec, value)
    elif spec.kind == "list":
        if not isinstance(value, list):
            raise ScenarioError(where, "expected a list")
        _check_length(where, value)
        out = [_element(f"{where}[{i}]", spec, c) if spec.unit else c for i, c in enumerate(value)]
    else:  # pragma: no cover - a schema bug, not a user error
        raise AssertionError(spec.kind)
    if spec.choices:
        try:
            known = out in spec.choices
        except TypeError:
            known = False
        if not known:
            why = f" ({spec.help})" if len(spec.choices) == 1 and spec.help else ""
            hint = did_you_mean(out, map(str, spec.choices)) if isinstance(out, str) else ""
            raise ScenarioError(where, f"must be one of {', '.join(map(str, spec.choices))}; got {_shown(out)}"
                                       f"{hint}{why}")
    if isinstance(out, (int, float)) and not isinstance(out, bool):
        check_range(where, spec, out, value)
    return out


def _profile(where: str, spec: Field, value) -> dict:
    """A piecewise-linear profile {t = [times], <profile_key> = [values]}: both lists of one length (1 to MAX_LIST),
    times in s, not negative and strictly increasing, values in the field's unit."""
    name = spec.profile_key
    if not isinstance(value, dict) or set(value) != {"t", name}:
        raise ScenarioError(where, f"expected a table {{ t = [times], {name} = [values] }}")
    times, values = value["t"], value[name]
    for key, items in (("t", times), (name, values)):
        if not isinstance(items, list) or not items:
            raise ScenarioError(f"{where}.{key}", "expected a non-empty list")
        _check_length(f"{where}.{key}", items)
    if len(times) != len(values):
        raise ScenarioError(f"{where}.{name}", f"{len(values)} values for {len(times)} times; give one per time")
    t = [_element(f"{where}.t[{i}]", Field("list", "s"), x) for i, x in enumerate(times)]
    for i, x in enumerate(t):
        if x < 0:
            raise ScenarioError(f"{where}.t[{i}]", f"must not be negative, got {_shown(times[i])}")
        if i and not x > t[i - 1]:
            raise ScenarioError(f"{where}.t[{i}]", f"times must be strictly increasing: {_shown(times[i])} after "
                                                   f"{_shown(times[i - 1])}")
    return {"t": t, name: [_element(f"{where}.{name}[{i}]", spec, x) for i, x in enumerate(values)]}


def _check_length(where: str, value: list) -> None:
    if len(value) > MAX_LIST:
        raise ScenarioError(where, f"a list of {len(value)} entries; at most {MAX_LIST} (no mechanism here has more)")


def _element(where: str, spec: Field, value) -> float:
    """One entry of a list/points field: a quantity in the field's unit, finite and inside the unit's range."""
    out = to_si(where, value, spec.unit)
    check_range(where, Field("quantity", spec.unit), out, value)
    return out


#: at most this many duty-cycle switches in one run (each is a restart of the integrator)
MAX_SWITCHES = 100_000
#: the drive turns at most this far in one run (prescribed speed x duration)
MAX_DRIVE_ANGLE = 1e6


def check_derived(si: dict) -> None:
    """Derived sizes before any work: output rows (memory and disk) and the prescribed drive angle are bounded."""
    drive = si["drive"]
    speed = drive.get("speed") if drive["type"] == "speed" else drive.get("no_load_speed")
    if speed is not None and speed * si["duration"] > MAX_DRIVE_ANGLE:
        field = "drive.speed" if drive["type"] == "speed" else "drive.no_load_speed"
        raise ScenarioError(field, f"{speed:g} rad/s for {si['duration']:g} s turns the drive {speed * si['duration']:.3g}"
                                   f" rad; at most {MAX_DRIVE_ANGLE:g} rad (160,000 turns) in one run: shorten "
                                   "duration")
    if drive.get("duty_on") is not None:
        switches = 2 * si["duration"] / (drive["duty_on"] + drive["duty_off"])
        if switches > MAX_SWITCHES:
            raise ScenarioError("drive.duty_on", f"{switches:.3g} switches over the duration; at most "
                                                 f"{MAX_SWITCHES:,} (each one stops and restarts the integrator)")
    problem = rows_problem(si["duration"] / si["output_step"])
    if problem:
        raise ScenarioError("output_step", f"{si['output_step']:g} s over a duration of {si['duration']:g} s gives "
                                           f"{problem}: raise output_step or shorten duration")


def rows_problem(rows: float) -> str | None:
    """What is wrong with a table of `rows` rows (more than MAX_OUTPUT_ROWS, or more memory than `memory_budget`),
    or None."""
    if rows > MAX_OUTPUT_ROWS:
        return f"{rows:.3g} output steps; at most {MAX_OUTPUT_ROWS:,}"
    need, budget = rows * BYTES_PER_ROW, memory_budget()
    if need > budget:
        return (f"{rows:.3g} rows, about {need / 2**30:.1f} GiB of memory; this machine allows {budget / 2**30:.1f} "
                f"GiB ({MEMORY_SHARE:.0%} of its memory)")
    return None


def memory_budget() -> float:
    """Bytes one run may plan to use: MEMORY_SHARE of the machine's physical memory (2 GiB where it is unknown)."""
    try:
        return MEMORY_SHARE * os.sysconf("SC_PHYS_PAGES") * os.sysconf("SC_PAGE_SIZE")
    except (AttributeError, ValueError, OSError):
        return 2.0 * 2**30


def did_you_mean(word: str, choices) -> str:
    """' (did you mean X?)' for the closest of `choices` to a misspelt `word` (difflib's ratio at least 0.75),
    else ''."""
    close = difflib.get_close_matches(word, list(choices), n=1, cutoff=0.75)
    return f" (did you mean {close[0]}?)" if close else ""


def check_section(name: str, fields: dict[str, Field], data) -> dict:
    """Validate one table: unknown keys rejected, required keys present, defaults filled."""
    if not isinstance(data, dict):
        raise ScenarioError(name, "must be a table")
    for key in data:
        if key not in fields:
            known = ", ".join(sorted(fields))
            raise ScenarioError(f"{name}.{key}" if name else key,
                                f"unknown key{did_you_mean(str(key), fields)} (known keys: {known})")
    out = {}
    for key, spec in fields.items():
        where = f"{name}.{key}" if name else key
        if key in data:
            out[key] = check_field(where, spec, data[key])
        elif spec.required:
            raise ScenarioError(where, "missing (required)")
        else:
            out[key] = spec.default
    for key, spec in fields.items():
        if spec.only_if and key in data and out[key] != spec.default and not spec.applies_with(out[spec.only_if[0]]):
            sibling, wanted = spec.only_if
            named = f"{name}.{sibling}" if name else sibling
            values = " or ".join(repr(w) for w in (wanted if isinstance(wanted, tuple) else (wanted,)))
            raise ScenarioError(f"{name}.{key}" if name else key,
                                f"applies only with {named} = {values}; with {named} = {out[sibling]!r} it "
                                f"would be ignored (remove it, or set {named} as well)")
    return out
