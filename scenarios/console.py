"""A calm console for the CLI: warnings grouped by kind, and what C libraries print captured instead of shown.

A run's warnings are strings "t = <time> s: <message>" (or a plain message); their kind is the message up to
its first colon with the numbers taken out, so 52 flank switches make one line with the count and the first
and last time (the line keeps the numbers every message shares, such as a formula's "= 0", and shows each number
that differs as the range its messages span, "5.9 .. 20.6"). SUNDIALS (and other native code) print straight to
file descriptors 1 and 2; `native_output` points those at a temporary file for the length of a run while Python's
own streams keep the terminal. A run's headline lines (its peaks, its impacts) are written from its summary here,
numbers within round-off of zero shown as 0 (`as_shown`, also the report's).
"""
from __future__ import annotations

import io
import math
import os
import re
import sys
import tempfile
import warnings as py_warnings
from contextlib import contextmanager
from typing import Iterator

_TIME = re.compile(r"^t = ([-+0-9.eE]+) s: ")
_NUMBER = re.compile(r"[-+]?\d+(?:\.\d*)?(?:[eE][-+]?\d+)?")


def warning_kind(message: str) -> str:
    """The kind of a warning: its text without the time prefix, up to the first ': ' that ends at least four
    words, numbers as '#'."""
    return _NUMBER.sub("#", _head(message)).strip()


def _head(message: str) -> str:
    """A warning's text without the time prefix, up to the first ': ' that ends at least four words."""
    parts = _TIME.sub("", message).split(": ")
    head = parts[0]
    for part in parts[1:]:          # a short tag ("thermal: ...") is no kind of its own: take the next clause
        if len(head.split()) >= 4:
            break
        head += ": " + part
    return head


def warning_time(message: str) -> float | None:
    """The time (s) a warning "t = <time> s: ..." carries, or None."""
    m = _TIME.match(message)
    return float(m.group(1)) if m else None


def group_warnings(messages: list[str]) -> list[dict]:
    """One dict per kind, in order of first appearance: kind, count, first and last time (s, None if the
    warnings carry none) and the first message in full. The kind shown keeps the numbers that are the same in
    every message of the group (a formula's "= 0", a limit) and writes each that differs as the range of its
    values over the group, "least .. largest" (each as its message wrote it), as the console's peaks line does."""
    groups: dict[str, dict] = {}
    numbers: dict[str, tuple[str, list[list[str]]]] = {}     # key -> (first head, each number's least and largest)
    for message in messages:
        key = warning_kind(message)
        t = warning_time(message)
        g = groups.setdefault(key, dict(kind=key, count=0, first_t_s=t, last_t_s=t, first=message))
        head = _head(message)
        found = _NUMBER.findall(head)
        if key not in numbers:
            numbers[key] = (head, [[value, value] for value in found])
        else:
            for span, value in zip(numbers[key][1], found):
                if float(value) < float(span[0]):
                    span[0] = value
                elif float(value) > float(span[1]):
                    span[1] = value
        g["count"] += 1
        if t is not None:
            g["first_t_s"] = t if g["first_t_s"] is None else min(g["first_t_s"], t)
            g["last_t_s"] = t if g["last_t_s"] is None else max(g["last_t_s"], t)
    for key, (head, spans) in numbers.items():
        shown = iter(a if float(a) == float(b) else f"{a} .. {b}" for a, b in spans)
        groups[key]["kind"] = _NUMBER.sub(lambda m: next(shown), head).strip()
    return list(groups.values())


def group_line(group: dict) -> str:
    """One console line for a group of warnings."""
    if group["count"] == 1:
        return f"warning: {group['first']}"
    when = ""
    if group["first_t_s"] is not None:
        when = f" between t = {group['first_t_s']:.4g} s and {group['last_t_s']:.4g} s"
    first = _TIME.sub("", group["first"])
    return f"warning: {group['count']} x {group['kind']}{when} (first: {first}); all in summary.json"


@contextmanager
def native_output() -> Iterator[list[str]]:
    """Capture what the solver libraries print while the block runs: native code writing to file descriptors 1
    and 2 (SUNDIALS, XLA), Python-level prints to sys.stdout (scikit-sundae's error handler) and Python warnings
    ('python: <category>: <text>'). The yielded list receives the captured lines (blank ones dropped) when the
    block ends. sys.stderr, where it is descriptor 2, stays on the terminal (the progress bar draws there)."""
    lines: list[str] = []
    for stream in (sys.stdout, sys.stderr):
        try:
            stream.flush()
        except (AttributeError, ValueError):
            pass
    saved = {fd: os.dup(fd) for fd in (1, 2)}
    printed, stdout, stderr = io.StringIO(), sys.stdout, sys.stderr
    with tempfile.TemporaryFile(mode="w+b") as sink, py_warnings.catch_warnings(record=True) as caught:
        py_warnings.simplefilter("default")
        sys.stdout = printed
        if _fileno(stderr) == 2:
            sys.stderr = os.fdopen(os.dup(saved[2]), "w", buffering=1, encoding=getattr(stderr, "encoding", None),
                                   errors="replace")
        for fd in (1, 2):
            os.dup2(sink.fileno(), fd)
        try:
            yield lines
        finally:
            _flush_c_stdio()                  # C's stdout is block-buffered into a file: empty it into the sink
            sys.stdout = stdout
            if sys.stderr is not stderr:
                sys.stderr.close()
                sys.stderr = stderr
            for fd, copy in saved.items():
                os.dup2(copy, fd)
                os.close(copy)
            sink.seek(0)
            text = sink.read().decode(errors="replace") + "\n" + printed.getvalue()
            lines += [line.strip() for line in text.splitlines() if line.strip()]
            lines += [f"python: {w.category.__name__}: {w.message}" for w in caught]


def _flush_c_stdio() -> None:
    try:
        import ctypes
        ctypes.CDLL(None).fflush(None)
    except (OSError, AttributeError):
        pass


def _fileno(stream) -> int | None:
    try:
        return stream.fileno()
    except (AttributeError, ValueError, OSError):
        return None


class RunProgress:
    """The progress bar of `mechsim run` on stderr: the simulated time while the run advances (`simulated(t)`),
    then the share of the tables written while the files are written (`writing(fraction, what)`), so that the bar
    keeps moving while a long run's tables are written. Transient: it leaves no line behind. Disabled (`--quiet`)
    it only keeps the time (rich is not imported)."""

    def __init__(self, console, name: str, duration: float, disable: bool = False):
        self.name, self.duration, self.time, self.phase = name, duration, 0.0, "run"
        self.bar = None
        if disable:
            return
        from rich.progress import BarColumn, Progress, TextColumn, TimeElapsedColumn, TimeRemainingColumn
        self.bar = Progress(TextColumn("[bold]{task.description}"), BarColumn(), TextColumn("{task.fields[where]}"),
                            TimeElapsedColumn(), TimeRemainingColumn(), console=console, transient=True)
        self.task = self.bar.add_task(name, total=duration, where="t = 0.000 s")

    def __enter__(self) -> "RunProgress":
        if self.bar is not None:
            self.bar.__enter__()
        return self

    def __exit__(self, *exc) -> None:
        if self.bar is not None:
            self.bar.__exit__(*exc)

    def simulated(self, t: float) -> None:
        """The run has reached simulated time t (s)."""
        self.time = t
        if self.bar is not None:
            self.bar.update(self.task, completed=t, where=f"t = {t:.3f} s")

    def writing(self, fraction: float, what: str = "files") -> None:
        """A share `fraction` of the tables is written; `what` is being written now."""
        if self.bar is None:
            return
        if self.phase != "write":
            self.phase = "write"
            self.bar.reset(self.task, total=1.0)
        self.bar.update(self.task, completed=fraction, description=f"{self.name}: writing {what}",
                        where=f"{100 * fraction:.0f} %")


#: the columns the console's peaks line names, where the run has them
CONSOLE_COLUMNS = ("contact_force_N", "coupler_force_N", "drive_torque_N_m", "temp_contact_C")


def console_lines(summary: dict) -> list[str]:
    """The console's peaks: the headline line, and where the run reaches a periodic regime, when and how many
    start-up turns (the headline is the periodic regime's; the start-up's is beside it in summary.json)."""
    from mechsim.scenarios.peaks import PERIODIC_RTOL
    out = []
    line = console_line(summary.get("peaks", {}))
    regime = summary.get("regime")
    if regime:
        out.append(f"periodic from t = {regime['from_t_s']:.6g} s after {regime['startup_turns']} start-up turn(s) "
                   f"(period {regime['period_s']:.6g} s; every turn since equals the last in duration and start speed to "
                   f"{PERIODIC_RTOL:g}, the durations to {regime['turn_spread']:.1g}); the peaks are the periodic regime's, "
                   "the start-up's are beside them in summary.json")
    return ([line] if line else []) + out


#: the console and the report show a number this small against its column's largest as 0 (`as_shown`)
ROUNDOFF_SHOWN = 1e-12


def column_scale(entry: dict) -> float:
    """The largest finite magnitude a column's entry shows: its max, min, start-up max and min and turn mean."""
    turn = entry.get("periodic") or entry.get("cycle") or {}
    shown = [entry.get("max", {}).get("value"), entry.get("min", {}).get("value"), turn.get("mean")]
    shown += [x.get("value") for x in (entry.get("startup") or {}).values() if isinstance(x, dict)]
    return max((abs(v) for v in shown if v is not None and math.isfinite(v)), default=0.0)


def as_shown(value: float, scale: float) -> float:
    """A peak or mean as a designer reads it: 0 where it is within ROUNDOFF_SHOWN of its column's `scale`
    (`column_scale`; a closed form's zero is round-off of the terms it is computed from, a chain's drive torque in a
    dwell -3.3e-19 N m), else the value itself; summary.json keeps every number as computed."""
    return 0.0 if abs(value) <= ROUNDOFF_SHOWN * scale else value


def console_line(peaks: dict) -> str | None:
    """One line of the headline peaks for the console: each column's minimum and maximum with the maximum's
    instant and drive angle within its turn (what a periodic regime's turns share: its instant may be any of
    them), its mean over the last turn (the periodic regime's, else the last drive cycle) where it has one, and
    whether they are located or the rows' (the full entries are in summary.json); a round-off zero as 0
    (`as_shown`)."""
    parts = []
    for col in CONSOLE_COLUMNS:
        e = peaks.get(col)
        if not e:
            continue
        hi, lo = e["max"], e["min"]
        tag = "" if e["how"].startswith("located") else " (rows)"
        start = e.get("startup", {}).get("max")
        turn = e.get("periodic") or e.get("cycle") or {}
        scale = column_scale(e)

        def number(v: float) -> str:
            return f"{as_shown(v, scale):.5g}"

        def shown(x):
            return "unbounded" if x["value"] is None else number(x["value"])
        beside = f", start-up max {shown(start)}" if start else ""
        if turn.get("mean") is not None or turn.get("unbounded"):
            mean = "unbounded" if turn.get("unbounded") else number(turn["mean"])
            beside += f", mean {mean} over the last turn"
        angle = hi.get("drive_angle_wrapped_deg")
        at = f", drive angle {as_shown(angle, 360.0):.4g}°" if angle is not None and math.isfinite(angle) else ""
        parts.append(f"{col} {shown(lo)} .. {shown(hi)} (max at t = {hi['t_s']:.6g} s{at}{beside}){tag}")
    return "peaks, min .. max: " + "; ".join(parts) if parts else None


def impacts_line(summary: dict) -> str | None:
    """The console's line on a run's impacts (summary["impacts"], a mechanism with clearance): how many, per turn,
    the largest impulse with where it struck, the energy lost, and the largest impact flash where a thermal model
    ran (docs/theory.md §G2.1-G2.2)."""
    imp = summary.get("impacts")
    if not imp or not imp.get("count"):
        return None
    text = (f"impacts: {imp['count']} ({imp['impacts_per_turn_max']} per turn at most); largest impulse "
            f"{imp['peak_impulse_N_s'] * 1e3:.4g} mN*s on the {imp['peak_impulse_flank']} flank at t = "
            f"{imp['peak_impulse_at_t_s']:.6g} s (crank {imp['peak_impulse_at_crank_angle_deg']:.2f} deg); "
            f"energy lost {imp['energy_lost_J'] * 1e3:.4g} mJ")
    if imp.get("peak_force_N") is not None:           # the compliant contact: its located peak force
        text += (f"; peak contact force {imp['peak_force_N']:.4g} N at t = {imp['peak_force_at_t_s']:.6g} s, "
                 f"lasting {imp['duration_at_peak_force_s'] * 1e6:.3g} us")
    flash = ((summary.get("thermal") or {}).get("impacts") or {})
    rise = flash.get("flash_rise_max_K")
    lock = summary.get("lock_impacts") or {}
    return text + (f"; largest impact flash +{rise:.3g} K (estimate)" if rise is not None else "") + (
        f"; lock impacts {lock['count']} (largest {lock['peak_impulse_N_s'] * 1e3:.4g} mN*s at the crank radius, "
        f"energy lost {lock['energy_lost_J'] * 1e3:.4g} mJ)" if lock.get("count") else "")
