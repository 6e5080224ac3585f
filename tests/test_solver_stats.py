"""Solver statistics: the same keys for IDA and diffrax, counts that agree where both count the same thing."""
from __future__ import annotations

import mechsim
from mechsim.dynamics.stats import STAT_KEYS

SHORT = {"duration": "1.2 s"}


def _solver_summary(backend: str) -> dict:
    result = mechsim.run(mechsim.load("geneva-motor", set={**SHORT, "solver.backend": backend}))
    assert result.success, result.failure
    return result.summary["solver"]


def test_ida_and_diffrax_report_the_same_statistics():
    ida, dfx = _solver_summary("ida"), _solver_summary("diffrax")
    backend_keys = set(STAT_KEYS)
    assert backend_keys <= set(ida) and backend_keys <= set(dfx)
    assert set(ida) == set(dfx)
    assert (ida["backend"], dfx["backend"]) == ("ida", "diffrax")
    # the same hybrid solution: the same events, each followed by one restart
    assert ida["events"] == dfx["events"] > 0
    assert ida["restarts"] == ida["events"] and dfx["restarts"] == dfx["events"]
    for s in (ida, dfx):
        assert s["residual_evaluations"] > 0 and s["segments"] >= s["events"] + 1
        assert s["solve_time_s"] > 0 and s["derive_time_s"] >= 0
        # a counter a backend cannot give is None, with the reason; never a silent zero
        assert all(key in s["notes"] for key in STAT_KEYS if s[key] is None)
    assert dfx["steps"] == dfx["accepted_steps"] + dfx["rejected_steps"] > 0
    assert ida["steps"] is None and "scikit-sundae" in ida["notes"]["steps"]
    assert ida["compilations"] == 0 and ida["compile_time_s"] == 0.0
