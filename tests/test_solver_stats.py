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


#: the keys the runner adds to a backend's statistics in summary['solver']
RUNNER_KEYS = {"tables_time_s", "wall_time_s", "output_rows"}


def test_every_path_reports_the_same_statistics_keys():
    """IDA, compiled IDA, diffrax's compiled whole run, diffrax segment by segment and the closed form (no DAE):
    one statistics dict shape (dynamics/stats.py), whose counters are numbers or None with the reason."""
    paths = {
        "ida": {"solver.backend": "ida"},
        "ida-compiled": {"solver.backend": "ida-compiled"},
        "diffrax": {"solver.backend": "diffrax"},
        "diffrax segments": {"solver.backend": "diffrax", "solver.diffrax_compiled_run": False},
    }
    seen = {name: _solver_summary_with(setting) for name, setting in paths.items()}
    closed = mechsim.run(mechsim.load("geneva-lc1", set={**SHORT, "thermal.model": "none"}))
    assert closed.success and closed.summary["model"]["method"] == "closed-form"
    seen["closed form"] = closed.summary["solver"]
    for name, s in seen.items():
        assert set(s) == set(STAT_KEYS) | RUNNER_KEYS, name
        assert all(key in s["notes"] for key in STAT_KEYS if s[key] is None), name
    # the closed form integrated nothing but lists the same events as a DAE of that motion
    assert seen["closed form"]["steps"] == seen["closed form"]["residual_evaluations"] == 0
    assert seen["closed form"]["events"] == len(closed.events) > 0
    # the Geneva's events are the same on every integrator
    assert len({s["events"] for name, s in seen.items() if name != "closed form"}) == 1


def _solver_summary_with(setting: dict) -> dict:
    result = mechsim.run(mechsim.load("geneva-motor", set={**SHORT, **setting}))
    assert result.success, result.failure
    return result.summary["solver"]


def test_the_compiled_run_maps_every_device_code_to_the_public_vocabulary():
    """The compiled diffrax run keeps integer codes on the device; one table maps each finished call's code to
    how it ended (`End`, as a loop segment ends) and, for a failure, to the one `FailureCode`."""
    from mechsim.dynamics.backend import End
    from mechsim.dynamics.backends.diffrax_run import OUTCOME, Code
    from mechsim.dynamics.result import FailureCode

    assert set(OUTCOME) == set(Code) - {Code.RUNNING}
    for code, (end, failure) in OUTCOME.items():
        assert isinstance(end, End), code
        assert (end is End.FAILED) == isinstance(failure, FailureCode), code
    assert {f for _, f in OUTCOME.values() if f} <= set(FailureCode)
    assert {e for e, _ in OUTCOME.values()} == set(End)
