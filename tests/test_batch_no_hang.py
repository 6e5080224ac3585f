"""A batched sweep of 64 lanes returns (dynamics/backends/xla_options.py, option 2).

With XLA's concurrency-optimised scheduler (its default), the vmapped segment solve of 64 geneva-lc1 lanes hung
in about one call in five (the calling thread waiting for the program, every XLA worker waiting for work), from
the first call of a process to the fourth; 16 lanes never did. mechsim switches that scheduler off before JAX
starts. Here six batched calls (3 s of geneva-lc1 in each lane, 10 rounds) run in a fresh process (the option is
read once per process) under a time limit far above their cost (about 12 s with the compilation), and every lane
must come back finished. A hang fails the test at the limit instead of stalling the suite. Without the option,
processes of four such calls hung in about half the tries (a race: this test catches it often, not always)."""
from __future__ import annotations

import json
import os
import subprocess
import sys
import textwrap

SCRIPT = """
    import itertools, json
    import numpy as np
    from mechsim.scenarios.loader import build_mechanism, load
    from mechsim.scenarios.runner import make_drive, solver_settings
    from mechsim.dynamics.backends.diffrax_batch import last_batch, simulate_batch
    from mechsim.dynamics.backends import xla_options
    calls = []
    for mu, torque in itertools.product(np.linspace(0.05, 0.3, 8), np.linspace(2, 12, 8)):
        si = load("geneva-lc1", ["solver.backend='diffrax'", "solver.method='dae'", f"contact.friction={mu}",
                                 f'load.wheel_torque="{torque} N*m"', 'output_step="5 ms"']).si
        mech = build_mechanism(si)
        angle, speed = mech.initial_keys
        calls.append((mech, make_drive(si), solver_settings(si), si["duration"], si["output_step"],
                      si["initial"][angle], si["initial"][speed]))
    args = [[c[i] for c in calls] if i not in (2, 4) else calls[0][i] for i in range(7)]
    done = []
    for _ in range(6):
        results = simulate_batch(*args)
        done.append(int(sum(r.failure is None and r.pieces[-1].t[-1] >= si["duration"] - 1e-9 for r in results)))
    print(json.dumps({"finished": done, "lanes": last_batch["lanes"], "rounds": last_batch["rounds"],
                      "options": xla_options.state()}))
"""


def test_64_lanes_come_back():
    env = {k: v for k, v in os.environ.items() if k != "XLA_FLAGS"}   # as a user's process starts (the test
    try:                                                              # process may have set mechsim's already)
        out = subprocess.run([sys.executable, "-c", textwrap.dedent(SCRIPT)], env=env, capture_output=True,
                             text=True, timeout=240, check=True)
    except subprocess.TimeoutExpired:
        raise AssertionError("a batched call of 64 lanes did not return within 240 s (XLA hang)") from None
    got = json.loads(out.stdout.strip().splitlines()[-1])
    assert got["options"] == "on"
    assert got["lanes"] == 64 and got["rounds"] >= 2          # several segments: the dwell and the engagement
    assert got["finished"] == [64] * 6                        # every lane reached its end, in every call
