"""The process's compiled programs, in one place, each kept under the structure of the model it was built from.

A program (the diffrax segment solve, the compiled whole run, the vmapped batch solve, the sensitivity pass's
solve and tools, a mode's jax functions, a mode's numba callbacks for ida-compiled) depends only on the model's structure, the
derivation key of `dynamics/model.py` (mechanism structure, formulation, drive kind, state extension), and on the
options that shape it; parameter values, tolerances and initial states are its arguments. So it is kept under
(kind, structure, options), never under an object's id: a model derived again, or loaded from the derivation
cache, finds the program built for an equal one. A model without a derivation key (built by hand) is its own
structure, kept alive beside its program so its id cannot be reused. What outlives the process is elsewhere:
the derived source in the derivation cache, numba's and JAX's compiled code in the user's cache folder
(`dynamics/user_cache.py`).
"""
from __future__ import annotations

import os
import threading
from typing import Callable, TypeVar

T = TypeVar("T")

_LOCK = threading.Lock()
#: (kind, structure, options) -> (the object the structure stands for, when keyed by identity; the program)
_PROGRAMS: dict[tuple, tuple[object, object]] = {}
#: key -> look-ups in this process (which programs a piece of work used: tests/xdist_schedule.py groups by them)
_USES: dict[tuple, int] = {}
#: one lock per key while its program is built: threads wait for the program they need, not for others
_BUILDING: dict[tuple, threading.Lock] = {}


def _after_fork_in_child() -> None:
    """A lock another thread held at a fork would never be released in the child (compiled_model's background
    compilation forks): the child starts with its own."""
    global _LOCK
    _LOCK = threading.Lock()
    _BUILDING.clear()


os.register_at_fork(after_in_child=_after_fork_in_child)


def structure(obj) -> tuple:
    """The structure a derived model or mode stands for: its derivation key (`DerivedModel.key`,
    `ModeFunctions.cache_key`), or its identity where it has none."""
    key = getattr(obj, "cache_key", None) or getattr(obj, "key", None)
    return ("key", key) if key else ("object", id(obj))


def kept_key(of, options: tuple) -> tuple | None:
    """The key a program of `of`'s structure under `options` is kept under across processes (dynamics/traced.py):
    None for a structure by identity, which another process cannot name."""
    s = structure(of)
    return None if s[0] == "object" else (s, options)


def program(kind: str, of, options: tuple, build: Callable[[], T]) -> tuple[T, bool]:
    """The program `kind` of `of`'s structure under `options`, built by `build()` on its first use in this process;
    True when this call built it."""
    key = (kind, structure(of), options)
    with _LOCK:
        _USES[key] = _USES.get(key, 0) + 1
        hit = _PROGRAMS.get(key)
        if hit is not None:
            return hit[1], False
        building = _BUILDING.setdefault(key, threading.Lock())
    with building:
        with _LOCK:
            hit = _PROGRAMS.get(key)
        if hit is not None:             # built by another thread meanwhile
            return hit[1], False
        made = build()
        with _LOCK:
            _PROGRAMS[key] = (of if key[1][0] == "object" else None, made)
            _BUILDING.pop(key, None)
        return made, True


def built(kind: str, of, options: tuple) -> bool:
    """Whether the program `kind` of `of`'s structure under `options` is built in this process already."""
    with _LOCK:
        return (kind, structure(of), options) in _PROGRAMS


def programs(kind: str) -> list:
    """Every program of this kind built in this process so far."""
    with _LOCK:
        return [entry for (k, _, _), (_, entry) in _PROGRAMS.items() if k == kind]


def uses() -> dict[tuple, int]:
    """(kind, structure, options) -> how often it was looked up in this process so far."""
    with _LOCK:
        return dict(_USES)
