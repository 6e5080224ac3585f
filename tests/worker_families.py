"""Files that compile the same jax models run in one xdist worker (`--dist loadfile`, as .ci/run).

mechsim keeps each compiled model for the life of a process, keyed by the model's structure (the diffrax segment solve:
dynamics/backends/diffrax_backend.py `compiled_solve`; the sensitivity pass: dynamics/sensitivity.py `_tools`), so a
second file that needs a model another file compiled pays nothing for it if it runs in the same worker, and the whole
compilation again if loadfile sends it to the other one. The families below were checked to share: in one process the
second file's call compiled nothing (measured 2026-11-27 on the shared machine):

- the sensitivity pass of geneva-motor (tests/test_sensitivity.py, tests/test_sensitivity_initial.py) and of
  rolling-a-torque (tests/test_sensitivity_rolling.py, tests/test_sensitivity_initial.py): 7.3 s and 8.9 s of
  compilation each, 0.0 s for the second caller; and of the Geneva at a prescribed speed without thermal states
  (tests/test_sensitivity.py's closed-form case, tests/test_sizing.py's problem: the friction is a parameter):
  7.7 s, then 0.0 s (2026-11-28: tests/test_sizing.py 23.8 s of CPU alone, 19.5 s after the sensitivity files);
- the diffrax (Tsit5) solve of the Geneva with a drive (geneva-motor and geneva-torque share it, at any slot
  count), used by tests/test_compare_builtins.py, tests/test_diffrax_compare.py, tests/test_diffrax_backend.py,
  tests/test_solver_stats.py, tests/test_restart_perturbation.py and tests/test_stalls.py: 5.7-6.1 s, then 0.0 s;
- the same with formulation = index1 (tests/test_robustness.py's diffrax cases, tests/test_stability.py's
  Baumgarte case): 4.2 s, then the stability case 3.3 s in all (8.4 s alone within the hour: ~7 s compiling).

The second pass of .ci/run (the hybrid-loop files) groups the same way: test_restart_perturbation, test_stalls and
test_diffrax_compare there are one unit.

Nothing else changes: every file still runs whole in one worker, in its own order, with its own module fixtures;
the units in `COST` start first, longest first.
A family is one work unit for the scheduler, so it should stay well below half of the suite's time (the
largest here, the diffrax Geneva, took ~450 s of one worker of ~1700 s in all in a full run at load 3.3-3.7 on
2026-11-27 23:00, after the compiled diffrax whole-run loop). Without pytest-xdist, or with another --dist, this does
nothing.
"""
from __future__ import annotations

import pytest

#: file -> the work unit it joins (the first file of its family)
FAMILIES = {
    "tests/test_sensitivity_initial.py": "tests/test_sensitivity.py",
    "tests/test_sensitivity_rolling.py": "tests/test_sensitivity.py",
    "tests/test_sizing.py": "tests/test_sensitivity.py",
    "tests/test_diffrax_compare.py": "tests/test_compare_builtins.py",
    "tests/test_diffrax_backend.py": "tests/test_compare_builtins.py",
    "tests/test_solver_stats.py": "tests/test_compare_builtins.py",
    "tests/test_restart_perturbation.py": "tests/test_compare_builtins.py",
    "tests/test_stalls.py": "tests/test_compare_builtins.py",
    "tests/test_stability.py": "tests/test_robustness.py",
}


#: work units known to take long, seconds of one worker in a full run (2026-11-27 23:00, `-n 2 --dist loadfile` on
#: the shared 2-core machine at load 3.3-3.7, families summed): started first, longest first. xdist orders the units
#: by their number of tests, which put these few-test files at the end of the run (the sensitivity files: 3-13 tests
#: each, a minute or two each), where one of them could keep a worker busy long after the other had finished.
#: Units not listed follow in xdist's order. Only the order matters; the numbers need not be exact.
COST = {
    "tests/test_compare_builtins.py": 450,
    "tests/test_sensitivity_chain.py": 147,
    "tests/test_sensitivity.py": 180,
    "tests/test_robustness.py": 117,
    "tests/test_sensitivity_thermal.py": 116,
    "tests/test_sensitivity_cycle_speed.py": 76,
    "tests/test_ida_compiled.py": 66,
    "tests/test_diffrax_run.py": 63,
    "tests/test_sensitivity_wall.py": 59,
    "tests/test_sweep_batch.py": 59,
    "tests/test_seed_report.py": 56,
}


@pytest.hookimpl(optionalhook=True)
def pytest_xdist_make_scheduler(config, log):
    if config.getvalue("dist") != "loadfile":
        return None
    try:
        from xdist.scheduler import LoadFileScheduling
    except ImportError:          # an xdist without it: its own scheduler
        return None

    class FamilyScheduling(LoadFileScheduling):
        """loadfile, with the files of a family in one work unit."""

        def _split_scope(self, nodeid: str) -> str:
            scope = super()._split_scope(nodeid)
            return FAMILIES.get(scope, scope)

        def _assign_work_unit(self, node) -> None:
            if not getattr(self, "_costly_first", False):     # once, before the first unit leaves the queue
                self._costly_first = True
                for scope in sorted((s for s in self.workqueue if s in COST), key=COST.get):
                    self.workqueue.move_to_end(scope, last=False)
            super()._assign_work_unit(node)

    return FamilyScheduling(config, log)
