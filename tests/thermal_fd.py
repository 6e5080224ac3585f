"""Finite differences of the thermal quantities of a run against a sensitivity table, shared by the lumped
(tests/test_sensitivity_thermal.py) and 1-D wall (tests/test_sensitivity_wall.py) checks: the peaks are read at
the sensitivity's own rows, the heat per index as tests/test_sensitivity.py reads it, the differences as
`conftest.richardson_central`, compared by `conftest.assert_matches_finite_differences`."""
from __future__ import annotations

from typing import Callable

import numpy as np
import pytest

from conftest import assert_matches_finite_differences, richardson_central
from mechsim.scenarios.studies.sensitivity import THERMAL_PEAKS
from test_sensitivity import _work_at


def thermal_quantities(result, rows: dict) -> dict:
    """The thermal peaks at the given rows, and the heat of the last complete engagement (the friction work from
    entry to exit, as tests/test_sensitivity.py reads it)."""
    df, ev = result.timeseries, result.events
    out = {q: float(df[THERMAL_PEAKS[q]].iloc[i]) for q, i in rows.items()}
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
    Richardson): values to 1e-7, elasticities as `assert_matches_finite_differences` with `floor`. The peaks'
    rows are the nominal run's arg-max rows, and must be the table's (the same row is differentiated).
    Returns the nominal run."""
    nominal = run([])
    df = nominal.timeseries
    rows = {q: int(np.nanargmax(np.abs(df[c].to_numpy(float)))) for q, c in THERMAL_PEAKS.items()}
    for q, i in rows.items():       # the sensitivity's peak is the run's (same row)
        assert table.loc[table["quantity"] == q, "t_s"].iloc[0] == pytest.approx(float(df["t_s"].iloc[i]))
    ref0 = thermal_quantities(nominal, rows)
    worst = {}
    for key in keys:
        part = table[table["wrt"] == key].set_index("quantity")
        p, unit = float(part["parameter"].iloc[0]), part["wrt_unit"].iloc[0]
        fd = richardson_central(
            lambda value: thermal_quantities(run([f"{key}={scenario_literal(value, unit)}"]), rows), p, h)
        mine = {}
        assert_matches_finite_differences(part, ref0, fd, p, key, 1e-7, floor, mine)
        print(label, key, {q: f"{e:.1e}" for q, e in mine.items()})
        worst.update({q: max(e, worst.get(q, 0.0)) for q, e in mine.items()})
    print(label, "largest relative deviation from the finite differences:", {q: f"{e:.1e}" for q, e in worst.items()})
    return nominal
