"""dynamics/xla_options.py: mechsim asks XLA to compile while loops into one CPU kernel, before JAX starts its
backend, keeps what the user set, and says when it came too late. Each case runs in a fresh interpreter (XLA reads
XLA_FLAGS once per process). What the option buys is measured in docs/benchmarks.md, not here (no timed tests);
that it leaves the results alone is what every diffrax test of the suite checks, all of them run with it on."""
from __future__ import annotations

import json
import os
import subprocess
import sys
import textwrap

from mechsim.dynamics.xla_options import LOOP_BYTES, OPTION, with_loop_option

ON = f"--xla_backend_extra_options={OPTION}={LOOP_BYTES}"


def run_fresh(code: str, xla_flags: str | None) -> dict:
    """Run `code` in a new interpreter (XLA_FLAGS as given, unset if None); it prints one JSON object."""
    env = {k: v for k, v in os.environ.items() if k != "XLA_FLAGS"}
    if xla_flags is not None:
        env["XLA_FLAGS"] = xla_flags
    out = subprocess.run([sys.executable, "-c", textwrap.dedent(code)], env=env, capture_output=True, text=True,
                         timeout=300, check=True)
    return json.loads(out.stdout.strip().splitlines()[-1])


IMPORT_MECHSIM = """
    import json, os
    import mechsim.dynamics.jax_model
    from mechsim.dynamics import xla_options
    print(json.dumps({"state": xla_options.loop_kernels(), "flags": os.environ.get("XLA_FLAGS")}))
"""


def test_flags_merge_into_the_users_extra_options():
    assert with_loop_option("") == ON
    assert with_loop_option("--xla_dump_to=/tmp/d") == f"--xla_dump_to=/tmp/d {ON}"
    merged = with_loop_option("--xla_cpu_enable_fast_math=false --xla_backend_extra_options=a=1,b=2")
    assert merged == f"--xla_cpu_enable_fast_math=false --xla_backend_extra_options=a=1,b=2,{OPTION}={LOOP_BYTES}"
    assert merged.count("--xla_backend_extra_options") == 1


def test_a_fresh_process_gets_the_option_before_jax_starts():
    got = run_fresh(IMPORT_MECHSIM, None)
    assert got == {"state": "on", "flags": ON}
    got = run_fresh(IMPORT_MECHSIM, "--xla_backend_extra_options=a=1")
    assert got == {"state": "on", "flags": f"--xla_backend_extra_options=a=1,{OPTION}={LOOP_BYTES}"}


def test_the_users_threshold_is_kept():
    mine = f"--xla_backend_extra_options={OPTION}=4096"
    assert run_fresh(IMPORT_MECHSIM, mine) == {"state": "as XLA_FLAGS sets it", "flags": mine}


def test_a_backend_started_first_is_reported_and_left_alone():
    got = run_fresh("import jax; jax.devices()\n" + textwrap.dedent(IMPORT_MECHSIM), None)
    assert got["flags"] is None
    assert got["state"].startswith("off: JAX's CPU backend was started before mechsim")
