"""dynamics/backends/xla_options.py: mechsim sets its two XLA options before JAX starts its backend, keeps what the user
set, and says when it came too late. Each case runs in a fresh interpreter (XLA reads XLA_FLAGS once per
process). What the options buy is measured in docs/benchmarks.md and docs/diffrax.md, not here (no timed tests);
that they leave the results alone is what every diffrax test of the suite checks, all run with them on; the
batched sweep that hung without the scheduler option is tests/test_sweep_batch.py."""
from __future__ import annotations

import json
import os
import subprocess
import sys
import textwrap

from mechsim.dynamics.backends.xla_options import LOOP_BYTES, LOOP_OPTION, SCHEDULER_FLAG, with_options

LOOP = f"--xla_backend_extra_options={LOOP_OPTION}={LOOP_BYTES}"
NO_SCHEDULER = f"{SCHEDULER_FLAG}=false"


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
    from mechsim.dynamics.backends import xla_options
    print(json.dumps({"state": xla_options.state(), "flags": os.environ.get("XLA_FLAGS")}))
"""


def test_flags_merge_into_the_users_own():
    assert with_options("") == f"{LOOP} {NO_SCHEDULER}"
    assert with_options("--xla_dump_to=/tmp/d") == f"--xla_dump_to=/tmp/d {LOOP} {NO_SCHEDULER}"
    merged = with_options("--xla_cpu_enable_fast_math=false --xla_backend_extra_options=a=1,b=2")
    assert merged == (f"--xla_cpu_enable_fast_math=false --xla_backend_extra_options=a=1,b=2,{LOOP_OPTION}="
                      f"{LOOP_BYTES} {NO_SCHEDULER}")
    assert merged.count("--xla_backend_extra_options") == 1
    mine = f"--xla_backend_extra_options={LOOP_OPTION}=4096 {SCHEDULER_FLAG}=true"
    assert with_options(mine) == mine


def test_a_fresh_process_gets_the_options_before_jax_starts():
    assert run_fresh(IMPORT_MECHSIM, None) == {"state": "on", "flags": f"{LOOP} {NO_SCHEDULER}"}
    got = run_fresh(IMPORT_MECHSIM, "--xla_backend_extra_options=a=1")
    assert got == {"state": "on",
                   "flags": f"--xla_backend_extra_options=a=1,{LOOP_OPTION}={LOOP_BYTES} {NO_SCHEDULER}"}


def test_the_users_values_are_kept():
    mine = f"--xla_backend_extra_options={LOOP_OPTION}=4096"
    got = run_fresh(IMPORT_MECHSIM, mine)
    assert got == {"state": f"on ({LOOP_OPTION} as XLA_FLAGS set it)", "flags": f"{mine} {NO_SCHEDULER}"}


def test_a_backend_started_first_is_reported_and_left_alone():
    """Reported in the state the summaries carry, and once as a warning the user sees (a notebook that ran JAX code
    before it imported mechsim)."""
    got = run_fresh("import jax, warnings; jax.devices(); warnings.simplefilter('always')\n"
                    "with warnings.catch_warnings(record=True) as caught:\n"
                    "    import mechsim.dynamics.jax_model\n"
                    "    from mechsim.dynamics.backends import xla_options\n"
                    "    xla_options.request()\n"
                    "import json, os\n"
                    "print(json.dumps({'state': xla_options.state(), 'flags': os.environ.get('XLA_FLAGS'),\n"
                    "                  'warned': [str(w.message) for w in caught if w.category is RuntimeWarning]}))",
                    None)
    assert got["flags"] is None
    assert got["state"].startswith("off: JAX's CPU backend was started before mechsim")
    assert got["warned"] == [f"mechsim: XLA options {got['state']}"]
