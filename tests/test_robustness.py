"""The robustness tier of issue 12: valid Geneva torque/motor scenarios spread over the robustness grid, with
zero numerical failures, and every physical stop where the independent one-coordinate model puts it.

The cases are the grid's own (benchmarks/robustness_grid.py, every 7th: 30 cases over slots 3-12, torque
2-20 N*m and motor curves, load 0-20 N*m, friction 0/0.15/0.3, rtol 1e-4 ... 1e-10 with atol = rtol/100), run
for 1 s on IDA index1 and index2; diffrax (whose compiled solve is specific to the tolerance) runs every
third of them at rtol 1e-8. The grid itself (210 cases x 3 solvers, 5 s) is a benchmark: docs/stability.md.

What each run must show:
- it completes, or stops for physics (a stall or a creeping rest): no integrator failure, no max_steps, no
  broken row invariant (friction power >= 0, energy balance: dynamics/invariants.py, checked by every run);
- it stops if and only if the reference does (benchmarks/stall_reference.py, DOP853 at rtol 1e-12), and at the
  reference's time to within 1e4 rtol (s): the stall time's error is the speed's global error over the
  deceleration (|d omega| ~ rtol |omega| over a run, |omega'| >= 1 rad/s^2 near a stall here), with a factor
  for the global-vs-local error; a creeping rest threshold (speed + 1 s |accel| < 1e-5 rad/s) is crossed
  where the speed changes slowly, so its time is looser: 0.05 s.
"""
from __future__ import annotations

import numpy as np
import pytest

from mechsim.benchmarks import robustness_grid as grid

pytestmark = pytest.mark.hybrid

DURATION = 1.0
TIER = grid.cases(grid.N_CASES)[::7]
DIFFRAX_RTOL = 1e-8
RUNS = ([(c, "ida", f) for c in TIER for f in ("index1", "index2")]
        + [(grid.with_rtol(c, DIFFRAX_RTOL), "diffrax", "index1") for c in TIER[::3]])


def test_the_tier_spans_the_grid():
    assert len(TIER) >= 30
    for factor, levels in (("slots", grid.SLOTS), ("load", grid.LOADS), ("friction", grid.FRICTION),
                           ("rtol", grid.RTOLS)):
        assert {getattr(c, factor) for c in TIER} == set(levels), factor
    kinds = {c.drive[0] for c in TIER}
    assert kinds == {"torque", "motor"}


@pytest.mark.parametrize("case,backend,formulation", RUNS,
                         ids=[f"{c.name}-{b}-{f}" for c, b, f in RUNS])
def test_no_numerical_failure_and_stops_where_the_reference_stops(case, backend, formulation):
    row = grid.run_case(case, backend, formulation, DURATION)
    assert row["outcome"] in ("completed", "stop:stall", "stop:rest"), row["detail"]
    if row["reduced_outcome"] == "running":
        assert row["outcome"] == "completed", row["detail"]
        return
    assert row["outcome"] == f"stop:{row['reduced_outcome']}", row["detail"]
    tol = 1e4 * case.rtol if row["reduced_outcome"] == "stall" else 0.05
    assert abs(row["stop_time_s"] - row["reduced_stop_time_s"]) <= tol
    assert np.isnan(row["min_friction_power_W"]) or row["min_friction_power_W"] >= -1e-9
