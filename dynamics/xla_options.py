"""The one XLA option mechsim sets: while loops compiled into one CPU kernel (docs/diffrax.md, 'XLA's loop
lowering on the CPU').

Since JAX 0.4.32 XLA's CPU runtime executes a program as a sequence of "thunks" (one per fused kernel, copy,
conditional, loop), and a `lax.while_loop` runs its body thunk by thunk on every iteration. A step of the
compiled diffrax run (`dynamics/diffrax_run.py`) is a few hundred small kernels - seven KKT solves, the guards,
the step-size controller - so the dispatch between them, not the arithmetic, was most of its ~4.5 us. XLA's
small-while-loop pass compiles a loop whose state is below a byte threshold into ONE kernel instead; its default
threshold (about 1 kB) excludes every loop mechsim writes (the step buffer alone is megabytes), so mechsim raises
it through XLA_FLAGS' `--xla_backend_extra_options` (the only way: the option is not a per-compilation one).
Measured on case A (docs/benchmarks.md): the run call 3.2 -> 0.9 ms wall, 3.8 -> 1.4 ms CPU, the crank angle
the same to 3e-13 rad, the compilation no slower.

XLA reads XLA_FLAGS once, when JAX starts its CPU backend. `request_loop_kernels` is called where mechsim first
imports JAX (`dynamics/jax_model.py`), so in mechsim's CLI and in any process that imports mechsim before it
runs JAX code, the option is in force; a process that started JAX first keeps XLA's default (the same results,
about three times slower compiled runs), and `loop_kernels()` says so. A threshold the user sets in XLA_FLAGS is
kept. The option applies to every JAX program of the process: it only changes how loops are lowered (one kernel
instead of one thunk per operation), not what they compute.
"""
from __future__ import annotations

import os

OPTION = "xla_cpu_small_while_loop_byte_threshold"
#: loops whose state (buffers included) is below this many bytes become one kernel: mechsim's largest, the
#: compiled run with the lumped thermal states, carries ~4 MB; 100 MB keeps a batched sweep's loops in too
LOOP_BYTES = 100_000_000
EXTRA = "--xla_backend_extra_options="

_state: str | None = None


def _backend_started() -> bool:
    try:
        from jax._src import xla_bridge
        return bool(xla_bridge.backends_are_initialized())
    except (ImportError, AttributeError):       # a JAX without that function: assume not started
        return False


def with_loop_option(flags: str) -> str:
    """XLA_FLAGS with the loop threshold added: into the user's own --xla_backend_extra_options if there is one
    (XLA keeps one value of that flag), else as a flag of its own."""
    tokens = flags.split()
    for i, token in enumerate(tokens):
        if token.startswith(EXTRA):
            value = token[len(EXTRA):]
            tokens[i] = EXTRA + (f"{value},{OPTION}={LOOP_BYTES}" if value else f"{OPTION}={LOOP_BYTES}")
            return " ".join(tokens)
    return " ".join(tokens + [f"{EXTRA}{OPTION}={LOOP_BYTES}"])


def request_loop_kernels() -> str:
    """Put the loop threshold into XLA_FLAGS unless the user chose one or JAX's backend has started (then it
    would be ignored); returns `loop_kernels()`."""
    global _state
    if _state is None:
        flags = os.environ.get("XLA_FLAGS", "")
        if OPTION in flags:
            _state = "as XLA_FLAGS sets it"
        elif _backend_started():
            _state = ("off: JAX's CPU backend was started before mechsim was imported, so XLA keeps its default "
                      "loop lowering (same results, compiled runs about 3x slower); import mechsim first")
        else:
            os.environ["XLA_FLAGS"] = with_loop_option(flags)
            _state = "on"
    return _state


def loop_kernels() -> str:
    """'on', 'as XLA_FLAGS sets it', 'off: <why>', or 'not requested' (JAX not imported by mechsim yet)."""
    return _state or "not requested"
