"""The process pool sends cases in chunks (scenarios/studies/sweep/execute.py, ChunkSizer): fewer pool calls for
cheap cases, the same rows, every case delivered once, and an interruption keeps every case of a finished chunk.

No timing is asserted: the chunk sizes are computed from given case times.
"""
import json

import pytest

from mechsim.scenarios.studies.sweep import execute
from mechsim.scenarios.studies.sweep.execute import (CHUNK_MAX, CHUNK_SECONDS, CaseTask, ChunkSizer, PoolRunner,
                                                     SerialRunner, SweepInterrupted)
from mechsim.scenarios.studies.sweep.run import plan
from mechsim.scenarios.studies.sweep.spec import build_spec

#: columns that time the work (every path's solver statistics time the solve, the closed form's too)
TIMING = ("case_wall_time_s", "case_cpu_time_s", "solver_wall_time_s", "solver_derive_time_s", "solver_solve_time_s",
          "solver_tables_time_s",
          "solver_compile_time_s", "solver_compile_cpu_time_s", "worker")


def test_chunk_sizes_follow_the_case_time_and_shrink_towards_the_end():
    sizer = ChunkSizer(2)
    assert sizer.next(1000) == 1                      # nothing timed yet: one case a call
    sizer.observe(0.010)
    assert sizer.next(1000) == min(CHUNK_MAX, int(CHUNK_SECONDS / 0.010))
    assert sizer.next(9) == 3                         # 9 left for 2 workers: at most ceil(9 / 4) a call
    assert sizer.next(1) == 1
    slow = ChunkSizer(2)
    slow.observe(2.0)                                 # a DAE case: always alone
    assert slow.next(1000) == 1
    fast = ChunkSizer(2)
    fast.observe(1e-5)
    assert fast.next(1000) == CHUNK_MAX
    sizer.observe(0.060)                              # the estimate follows the recent cases (0.8 / 0.2 average)
    assert sizer.estimate == pytest.approx(0.8 * 0.010 + 0.2 * 0.060)


def _tasks(n):
    spec = build_spec("geneva-lc1", [f"contact.friction=0.05:0.3:{n}"],
                      ["duration=0.1 s", "output_step=5 ms", "thermal.model=none"], False)
    return [CaseTask(c.key, c.scenario) for c in plan(spec).cases]


@pytest.fixture
def recorded_sizes(monkeypatch):
    """The chunk sizes the pool used, in submission order (chunks are consecutive slices of the task list)."""
    sizes = []
    real = ChunkSizer.next

    def next_(self, remaining):
        k = real(self, remaining)
        sizes.append(k)
        return k

    monkeypatch.setattr(ChunkSizer, "next", next_)
    monkeypatch.setattr(execute, "CHUNK_SECONDS", 10.0)       # chunks as large as the end-of-sweep share allows
    return sizes


def test_chunked_pool_delivers_every_case_once_with_the_serial_rows(recorded_sizes):
    tasks = _tasks(24)
    pooled, serial = [], []
    PoolRunner(2).run(tasks, pooled.append)
    SerialRunner().run(tasks, serial.append)
    assert max(recorded_sizes) > 1 and sum(recorded_sizes) == 24
    assert sorted(o.key for o in pooled) == sorted(t.key for t in tasks)
    by_key = {o.key: o.row for o in pooled}
    for o in serial:
        a = {k: v for k, v in by_key[o.key].items() if k not in TIMING}
        b = {k: v for k, v in o.row.items() if k not in TIMING}
        assert json.dumps(a, sort_keys=True) == json.dumps(b, sort_keys=True)      # NaN where no turn completed


def test_interruption_inside_a_chunk_delivers_the_rest_of_every_finished_chunk(recorded_sizes):
    tasks = _tasks(24)
    calls = []

    def on_result(outcome):
        calls.append(outcome.key)
        if len(calls) == 6:                 # the first chunks hold one case each: the 6th lies in a larger one
            raise KeyboardInterrupt

    with pytest.raises(SweepInterrupted, match="Ctrl-C"):
        PoolRunner(2).run(tasks, on_result)
    delivered = set(calls)
    assert len(delivered) >= 6
    assert [k for k in calls if calls.count(k) > 1] in ([], [calls[5]] * 2)   # only the interrupted one again
    start = 0
    for k in recorded_sizes:                 # a chunk is delivered whole or not at all
        keys = {t.key for t in tasks[start:start + k]}
        assert keys <= delivered or not keys & delivered, (start, k)
        start += k
