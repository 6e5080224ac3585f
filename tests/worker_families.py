"""Files that compile the same jax models run in one xdist worker (`--dist loadfile`, as .ci/run).

mechsim keeps each compiled model for the life of a process, keyed by the model's structure (the diffrax segment
solve: dynamics/diffrax_backend.py `compiled_solve`; the sensitivity pass: dynamics/sensitivity.py `_tools`), so a
second file that needs a model another file compiled pays nothing for it if it runs in the same worker, and the
whole compilation again if loadfile sends it to the other one. The families below were checked to share: in one
process the second file's call compiled nothing (measured 2026-11-27 on the shared machine):

- the sensitivity pass of geneva-motor (tests/test_sensitivity.py, tests/test_sensitivity_initial.py) and of
  rolling-a-torque (tests/test_sensitivity_rolling.py, tests/test_sensitivity_initial.py): 7.3 s and 8.9 s of
  compilation each, 0.0 s for the second caller;
- the diffrax (Tsit5) solve of the Geneva with a drive (geneva-motor and geneva-torque share it, at any slot
  count), used by tests/test_compare_builtins.py, tests/test_diffrax_compare.py, tests/test_diffrax_backend.py,
  tests/test_solver_stats.py, tests/test_restart_perturbation.py and tests/test_stalls.py: 5.7-6.1 s, then 0.0 s;
- the same with formulation = index1 (tests/test_robustness.py's diffrax cases, tests/test_stability.py's
  Baumgarte case): 4.2 s, then the stability case 3.3 s in all (8.4 s alone within the hour: ~7 s compiling).

The second pass of .ci/run (the hybrid-loop files) groups the same way: test_restart_perturbation, test_stalls and
test_diffrax_compare there are one unit.

Nothing else changes: every file still runs whole in one worker, in its own order, with its own module fixtures.
A family is one work unit for the scheduler, so it should stay well below half of the suite's time (the
largest here, the diffrax Geneva, is an estimated 100-130 s from the idle durations, of ~10 minutes of CPU; xdist
starts the units with the most tests first, and the families are among the first five). Without pytest-xdist, or with another --dist, this does nothing.
"""
from __future__ import annotations

import pytest

#: file -> the work unit it joins (the first file of its family)
FAMILIES = {
    "tests/test_sensitivity_initial.py": "tests/test_sensitivity.py",
    "tests/test_sensitivity_rolling.py": "tests/test_sensitivity.py",
    "tests/test_diffrax_compare.py": "tests/test_compare_builtins.py",
    "tests/test_diffrax_backend.py": "tests/test_compare_builtins.py",
    "tests/test_solver_stats.py": "tests/test_compare_builtins.py",
    "tests/test_restart_perturbation.py": "tests/test_compare_builtins.py",
    "tests/test_stalls.py": "tests/test_compare_builtins.py",
    "tests/test_stability.py": "tests/test_robustness.py",
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

    return FamilyScheduling(config, log)
