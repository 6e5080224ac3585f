"""One owner of the process's compiled programs (dynamics/programs.py): kept under the model's structure, so a
model derived again, an equal structure, finds what was built for the first; never under an object's id."""
from __future__ import annotations

import mechsim
from mechsim.dynamics import model as model_module
from mechsim.dynamics import programs
from mechsim.dynamics.jax_model import jax_model
from mechsim.dynamics.model import derive
from mechsim.scenarios.runner import plan


def _derived():
    p = plan(mechsim.load("geneva-torque"))
    return derive(p.mechanism, p.settings.formulation, p.drive.is_prescribed)


def test_a_model_derived_again_finds_the_programs_of_its_structure():
    first = _derived()
    built = jax_model(first)
    model_module._derive_cached.cache_clear()        # the same structure, derived (or loaded) into a new object
    again = _derived()
    assert again is not first and again.key == first.key
    assert jax_model(again) is built
    assert programs.structure(again) == programs.structure(first) == ("key", first.key)
    mode = next(iter(again.modes.values()))
    assert programs.structure(mode) == ("key", mode.cache_key)


def test_a_program_is_built_once_per_key_and_an_unkeyed_object_is_its_own_structure():
    class Bare:
        key = ()

    a, b = Bare(), Bare()
    calls = []
    one, fresh_one = programs.program("probe", a, ("opt",), lambda: calls.append(1) or object())
    same, fresh_same = programs.program("probe", a, ("opt",), lambda: calls.append(1) or object())
    other, fresh_other = programs.program("probe", b, ("opt",), lambda: calls.append(1) or object())
    assert (fresh_one, fresh_same, fresh_other) == (True, False, True) and len(calls) == 2
    assert same is one and other is not one
    assert one in programs.programs("probe") and other in programs.programs("probe")
