"""Batched diffrax sweeps (dynamics.backends.diffrax_batch, `mechsim sweep --batch`): every lane equals its own run.

Three geneva-motor cases (friction x wheel torque) over 1.5 s, about two engagements each, with their slip
reversals at case-dependent times (0.39 s to 0.45 s): a lock-step vmap would be wrong here. One batch
compilation (3 lanes) and one single-case compilation serve the whole module.
"""
import json
from dataclasses import replace

import numpy as np
import pandas as pd
import pytest

from cli_helpers import invoke
import mechsim.dynamics.backends.diffrax_backend as diffrax_backend
from mechsim.dynamics.backends.diffrax_batch import last_batch, simulate_batch
from mechsim.dynamics.hybrid import simulate
from mechsim.scenarios.loader import build_mechanism, load
from mechsim.scenarios.runner import make_drive, solver_settings
from mechsim.scenarios.studies.sweep.execute import CaseTask, SerialRunner, _batch_reason
from mechsim.scenarios.studies.sweep.run import run_sweep
from mechsim.scenarios.studies.sweep.spec import build_spec

CASES = [(0.15, 7.0), (0.05, 2.0), (0.3, 12.0)]
# the batch vmaps the segment loop; the serial sweep runs on it too (solver.diffrax_compiled_run = false), so that
# both are the same computation (the compiled whole-run loop agrees with it to the integration error only)
BASE = ["solver.backend=diffrax", "solver.diffrax_compiled_run=false", "duration=1.5 s"]
VARY = ["contact.friction=0.15,0.05,0.3", "load.wheel_torque=7,2,12 N*m"]
TIMING = ("case_wall_time_s", "case_cpu_time_s", "solver_wall_time_s", "solver_derive_time_s", "solver_solve_time_s",
          "solver_tables_time_s",
          "solver_compile_time_s", "solver_compile_cpu_time_s", "solver_compilations", "solver_wall_time_backend_s",
          "worker", "run_id")


def _call(friction, torque):
    si = load("geneva-motor", ["solver.backend='diffrax'", f"contact.friction={friction}",
                               f'load.wheel_torque="{torque} N*m"', 'duration="1.5 s"']).si
    mech = build_mechanism(si)
    angle_key, speed_key = mech.initial_keys
    return (mech, make_drive(si), solver_settings(si), si["duration"], si["output_step"], si["initial"][angle_key],
            si["initial"][speed_key])


def _rows(traj):
    return np.concatenate([p.t for p in traj.pieces]), np.vstack([p.y for p in traj.pieces])


def test_each_lane_equals_its_own_run():
    calls = [_call(*c) for c in CASES]
    batch = simulate_batch(*[[c[i] for c in calls] if i != 2 and i != 4 else calls[0][i] for i in range(7)])
    slips = []
    for call, tb in zip(calls, batch):
        # the batch vmaps the segment loop: each lane equals its own run on that loop (the default single run
        # is the compiled whole-run loop, docs/diffrax.md, equal to it only to the integration error)
        segments = replace(diffrax_backend.default_options(call[2]), compiled_run=False)
        ts = simulate(*call, backend=diffrax_backend.DiffraxBackend(call[2], segments))
        assert tb.failure is None and ts.failure is None
        (t_b, y_b), (t_s, y_s) = _rows(tb), _rows(ts)
        assert np.array_equal(t_b, t_s)
        crank = ts.model.modes[ts.pieces[0].mode].index["q"].start
        assert np.abs(y_b[:, crank] - y_s[:, crank]).max() < 1e-9
        assert [(e["kind"], e["from_mode"], e["to_mode"]) for e in tb.events] == \
               [(e["kind"], e["from_mode"], e["to_mode"]) for e in ts.events]
        assert np.allclose([e["t_s"] for e in tb.events], [e["t_s"] for e in ts.events], rtol=0, atol=1e-9)
        assert tb.stats["segments"] == ts.stats["segments"] and set(tb.stats) == set(ts.stats)
        slips.append([e["t_s"] for e in tb.events if "slip" in e["kind"]][0])
    assert last_batch["lanes"] == 3 and last_batch["rounds"] == max(t.stats["segments"] for t in batch)
    assert 0.0 < last_batch["calls_time_s"] <= last_batch["solve_time_s"]     # the vmapped calls: a part of the solve
    assert max(slips) - min(slips) > 0.03          # events at case-dependent times: not lock-step


def test_sweep_batch_matches_serial_and_says_what_ran_how(tmp_path):
    spec = build_spec("geneva-motor", VARY, BASE, True)
    serial = run_sweep(spec, tmp_path / "serial", SerialRunner(), plots=False)
    res = invoke("sweep", "geneva-motor", *sum([["--vary", v] for v in VARY], []),
                 *sum([["--set", s] for s in BASE], []), "--zip", "--batch", "--workers", "0", "--no-plots",
                 "--quiet", "--out", tmp_path / "batch")
    assert res.exit_code == 0, res.output
    a = pd.read_parquet(tmp_path / "serial" / "sweep.parquet")
    b = pd.read_parquet(tmp_path / "batch" / "sweep.parquet")
    assert list(a.columns) == list(b.columns) and b["success"].all()
    means = [c for c in a.columns if c.startswith("cycle_mean_")]
    drop = [c for c in a.columns if c in TIMING] + means
    pd.testing.assert_frame_equal(a.drop(columns=drop), b.drop(columns=drop), check_exact=False, rtol=1e-7)
    for c in means:         # a mean near 0 (the wheel's acceleration over a turn) to 1e-7 of the column's own scale
        col = c[len("cycle_mean_"):]
        scale = np.maximum(a[f"peak_max_{col}"].abs(), a[f"peak_min_{col}"].abs()).to_numpy()
        assert (a[c].isna() == b[c].isna()).all(), c
        held = a[c].notna().to_numpy()
        assert (np.abs(b[c] - a[c]).to_numpy()[held] <= 1e-7 * scale[held]).all(), c
    note = json.loads((tmp_path / "batch" / "sweep_summary.json").read_text())["batching"]
    assert note.startswith("batched: 3 case(s) in 1 vmapped diffrax group(s) of [3]"), note
    assert "--batch" in json.loads((tmp_path / "serial" / "sweep_summary.json").read_text())["batching"]
    assert serial.failed == 0


@pytest.mark.parametrize("overrides, reason", [
    (["solver.backend='ida'", "solver.method='dae'"], "IDA backend"),
    (["solver.backend='diffrax'"], "closed-form"),
])
def test_cases_that_cannot_batch_say_why(overrides, reason):
    assert reason in _batch_reason(CaseTask("k", load("geneva-lc1", overrides)))
    assert _batch_reason(CaseTask("k", load("geneva-motor", ["solver.backend='diffrax'"]))) is None


def test_a_process_where_a_batch_can_hang_runs_the_cases_one_by_one(monkeypatch):
    """JAX's backend started before mechsim was imported (a notebook that ran JAX first): XLA's concurrency-optimised
    scheduler stays on, under which the vmapped solve hung in about one call in five (xla_options point 2). Every
    diffrax case then goes to the fallback runner, and the note says why."""
    from mechsim.dynamics.backends import xla_options
    from mechsim.scenarios.studies.sweep.execute import BatchRunner

    class Recording(SerialRunner):
        def run(self, tasks, on_result):
            self.got = list(tasks)
    monkeypatch.setattr(xla_options, "_state", "off: JAX's CPU backend was started before mechsim was imported")
    tasks = [CaseTask(f"k{n}", load("geneva-motor", ["solver.backend='diffrax'", f"contact.friction={f}"]))
             for n, f in enumerate((0.1, 0.2, 0.3))]
    runner = BatchRunner(Recording())
    runner.run(tasks, lambda outcome: None)
    assert runner.fallback.got == tasks
    assert runner.batching_note.startswith("batched: none; 3 case(s) ran one by one")
    assert "scheduler" in runner.batching_note and "import mechsim before running JAX code" in runner.batching_note
