"""The two XLA options mechsim sets, before JAX starts its CPU backend (docs/diffrax.md, 'XLA on the CPU').

1. **While loops as one kernel.** Since JAX 0.4.32 XLA's CPU runtime executes a program as a sequence of
   "thunks" (one per fused kernel, copy, conditional, loop), and a `lax.while_loop` runs its body thunk by thunk
   on every iteration. A step of the compiled diffrax run (`dynamics/backends/diffrax_run.py`) is a few hundred small
   kernels - seven KKT solves, the guards, the step-size controller - so the dispatch between them, not the
   arithmetic, was most of a step's time. XLA's small-while-loop pass compiles a loop whose state is below a byte
   threshold into ONE kernel instead; its default (about 1 kB) excludes every loop mechsim writes (the step
   buffer alone is megabytes), so mechsim raises it (`xla_cpu_small_while_loop_byte_threshold`, an entry of
   `--xla_backend_extra_options`; not settable per compilation). The run call of case A is several times faster,
   the crank angle the same to round-off (docs/benchmarks.md).
2. **No concurrency-optimised scheduling** (`--xla_cpu_enable_concurrency_optimized_scheduler=false`). With it,
   the vmapped segment solve of `sweep --batch` (`dynamics/backends/diffrax_batch.py`, 64 lanes) hung in about one
   call in five, from the first call of a process to the fourth: the calling thread waits for the program's completion
   while every XLA worker thread waits for work (native stacks, gdb), with or without option 1, with
   async dispatch, multi-threaded Eigen, XNNPACK or equinox's host callbacks switched off. With this scheduler
   off, 52 calls in five processes all returned, in the same time.

XLA reads XLA_FLAGS once, when JAX starts its CPU backend. `request` is called where mechsim first imports JAX
(`dynamics/jax_model.py`), so in mechsim's CLI and in any process that imports mechsim before it runs JAX code
the options are in force; a process that started JAX first keeps XLA's defaults (the same results; compiled
runs about three times slower, and batched sweeps exposed to the hang), and `state()` says so. A value the user
sets in XLA_FLAGS for either option is kept. They apply to every JAX program of the process: they change how
loops are lowered and in which order independent kernels are scheduled, not what is computed.
"""
from __future__ import annotations

import os
import warnings
from contextlib import contextmanager

LOOP_OPTION = "xla_cpu_small_while_loop_byte_threshold"
#: loops whose state (buffers included) is below this many bytes become one kernel: mechsim's largest, the
#: compiled run with the lumped thermal states, carries ~4 MB; 100 MB keeps a batched sweep's loops in too
LOOP_BYTES = 100_000_000
EXTRA = "--xla_backend_extra_options="
SCHEDULER_FLAG = "--xla_cpu_enable_concurrency_optimized_scheduler"

_state: str | None = None


def _backend_started() -> bool:
    try:
        from jax._src import xla_bridge
        return bool(xla_bridge.backends_are_initialized())
    except (ImportError, AttributeError):       # a JAX without that function: assume not started
        return False


def with_options(flags: str) -> str:
    """XLA_FLAGS with mechsim's two options added where the user has not set them: the loop threshold into the
    user's own --xla_backend_extra_options if there is one (the flag holds one map, a second would replace the
    first), else as a flag of its own; the scheduler switched off."""
    tokens = flags.split()
    if LOOP_OPTION not in flags:
        entry = f"{LOOP_OPTION}={LOOP_BYTES}"
        for i, token in enumerate(tokens):
            if token.startswith(EXTRA):
                value = token[len(EXTRA):]
                tokens[i] = EXTRA + (f"{value},{entry}" if value else entry)
                break
        else:
            tokens.append(EXTRA + entry)
    if SCHEDULER_FLAG not in flags:
        tokens.append(f"{SCHEDULER_FLAG}=false")
    return " ".join(tokens)


def request() -> str:
    """Put the options into XLA_FLAGS unless JAX's backend has started (then XLA would ignore them); returns
    `state()`."""
    global _state
    if _state is None:
        flags = os.environ.get("XLA_FLAGS", "")
        if _backend_started():
            _state = ("off: JAX's CPU backend was started before mechsim was imported, so XLA keeps its defaults "
                      "(same results; compiled runs several times slower, batched sweeps can hang); "
                      "import mechsim first")
            # once, where a user can see it (a notebook that ran JAX code first): the summaries say it too
            warnings.warn(f"mechsim: XLA options {_state}", RuntimeWarning, stacklevel=2)
        else:
            os.environ["XLA_FLAGS"] = with_options(flags)
            kept = [name for name in (LOOP_OPTION, SCHEDULER_FLAG.lstrip("-")) if name in flags]
            _state = "on" + (f" ({', '.join(kept)} as XLA_FLAGS set it)" if kept else "")
    return _state


def batching_hazard() -> str | None:
    """Why a batched (vmapped) diffrax solve may hang in this process (point 2 above), or None: XLA's concurrency-
    optimised scheduler left on because JAX's backend started before mechsim could switch it off."""
    if request().startswith("off"):
        return ("XLA's concurrency-optimised scheduler is on in this process (JAX ran before mechsim was "
                "imported), under which a batched solve can hang; import mechsim before running JAX code to batch")
    return None


def state() -> str:
    """'on', 'on (<option> as XLA_FLAGS set it)', 'off: <why>', or 'not requested' (JAX not imported by
    mechsim yet)."""
    return _state or "not requested"


#: equinox reads it once, when it is imported: what a failed runtime check (`eqx.error_if`) does
EQX_VARIABLE = "EQX_ON_ERROR"


def checks_mode() -> str:
    """The equinox error mode mechsim's programs are traced under: the user's EQX_ON_ERROR where set, else "nan"
    (the CLI sets it, `checks_without_callbacks`; a library process traces under it, `library_checks_without_callbacks`)."""
    return os.environ.get(EQX_VARIABLE) or "nan"


@contextmanager
def library_checks_without_callbacks():
    """While mechsim traces a program of its own in a process whose user chose no EQX_ON_ERROR (mechsim imported
    as a library, equinox at its default "raise"): equinox's checks NaN-returning, as in the CLI, so that the
    program holds no host callback and is kept for later processes (dynamics/traced.py); equinox's default again
    afterwards. The checks' one shared trace cache (`branched_error_if_impl_jit`, keyed by message and shapes) is
    emptied before and after, so that neither mechsim nor the user's own code reuses a check traced under the other's
    mode (JAX code the user traces in another thread during those seconds would see the NaN mode too). Where
    equinox's internals are not those this was written for, nothing is changed: the programs are compiled and not
    kept, as before (a notebook then pays the tracing and compilation in every process).

    Why it is safe: the only checks inside mechsim's programs are diffrax's checks of a solve's inputs, which mechsim
    makes on the host before each call (`diffrax_common.save_times`); none fires, so the results are the same."""
    errors = None
    if os.environ.get(EQX_VARIABLE) is None:
        try:
            from equinox import _errors as errors
            evict = errors.branched_error_if_impl_jit._cached.clear_cache
            if errors.EQX_ON_ERROR != "raise":
                errors = None
        except (ImportError, AttributeError):
            errors = None
    if errors is None:
        yield
        return
    evict()
    errors.EQX_ON_ERROR = "nan"
    try:
        yield
    finally:
        errors.EQX_ON_ERROR = "raise"
        evict()


def checks_without_callbacks() -> None:
    """Make equinox's runtime checks NaN-returning (EQX_ON_ERROR=nan) in a process mechsim starts (its CLI, the
    test session), unless the user set the variable; to be called before equinox is imported.

    Why: with equinox's default each check inside a compiled program is a host callback, and JAX's persistent
    compilation cache refuses programs with host callbacks, so the diffrax segment solve and the sensitivity
    pass's segment solve were compiled again in every process (docs/diffrax.md, 'Compilation'). Their only runtime
    checks are diffrax's checks of its inputs (save times ordered and inside [t0, t1], the first step heading to
    t1); mechsim checks those inputs before each call (`diffrax_common.save_times`), so no check of theirs fires
    and the results are the same. A process that imports mechsim as a library keeps equinox's default, but for the
    tracing of mechsim's own programs (`library_checks_without_callbacks`)."""
    os.environ.setdefault(EQX_VARIABLE, "nan")
