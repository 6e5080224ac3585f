"""Finite differences of the thermal quantities of a run against a sensitivity table, shared by the lumped
(tests/test_sensitivity_thermal.py) and 1-D wall (tests/test_sensitivity_wall.py) checks: the peaks are the runs'
located ones (summary.json peaks), the heat per index as tests/test_sensitivity.py reads it, the differences as
`conftest.richardson_central`, compared by `conftest.assert_matches_finite_differences`."""
from __future__ import annotations

from typing import Callable

import numpy as np
import pytest

from conftest import assert_matches_finite_differences, richardson_central
from mechsim.scenarios.studies.sensitivity import THERMAL_PEAKS
from test_sensitivity import _work_at


def located_peak(result, column: str) -> dict:
    """The run's located extremum of largest magnitude of a thermal column (summary.json peaks, `abs_max`'s side,
    the signed value): what the sensitivity differentiates."""
    entry = result.summary["peaks"][column]
    assert entry["how"].startswith("located"), entry["how"]
    return entry[entry["abs_max"]["side"]]


def thermal_quantities(result) -> dict:
    """The located thermal peaks, and the heat of the last complete engagement (the friction work from entry to
    exit, as tests/test_sensitivity.py reads it)."""
    df, ev = result.timeseries, result.events
    out = {q: float(located_peak(result, c)["value"]) for q, c in THERMAL_PEAKS.items()}
    entries = ev.loc[ev["kind"] == "entry", "t_s"].to_numpy(float)
    last_exit = ev.loc[ev["kind"] == "exit", "t_s"].to_numpy(float)[-1]
    out["heat_per_index_J"] = (_work_at(df, entries[entries < last_exit][-1], "friction")
                               - _work_at(df, last_exit, "friction"))
    return out


def scenario_literal(si_value: float, unit: str) -> str:
    """A --set value in the table's unit (the literal repr, so no digit is lost)."""
    return f"{si_value!r} {unit}" if unit else repr(si_value)


def assert_thermal_matches_fd(table, run: Callable[[list[str]], object], keys: list[str], h: float, floor: float,
                              label: str = ""):
    """Each of `keys` against central differences of `run(extra --set values)` (relative steps h, h/2,
    Richardson): values to 1e-7, elasticities as `assert_matches_finite_differences` with `floor`. The peaks are
    the runs' located ones (each run's own instant: the derivative of the located extremum), the nominal one at the
    table's instant. Returns the nominal run."""
    nominal = run([])
    for q, c in THERMAL_PEAKS.items():       # the sensitivity's peak is the run's
        assert table.loc[table["quantity"] == q, "t_s"].iloc[0] == pytest.approx(located_peak(nominal, c)["t_s"],
                                                                                  abs=1e-6)
    ref0 = thermal_quantities(nominal)
    worst = {}
    for key in keys:
        part = table[table["wrt"] == key].set_index("quantity")
        p, unit = float(part["parameter"].iloc[0]), part["wrt_unit"].iloc[0]
        fd = richardson_central(
            lambda value: thermal_quantities(run([f"{key}={scenario_literal(value, unit)}"])), p, h)
        mine = {}
        assert_matches_finite_differences(part, ref0, fd, p, key, 1e-7, floor, mine)
        print(label, key, {q: f"{e:.1e}" for q, e in mine.items()})
        worst.update({q: max(e, worst.get(q, 0.0)) for q, e in mine.items()})
    print(label, "largest relative deviation from the finite differences:", {q: f"{e:.1e}" for q, e in worst.items()})
    return nominal
