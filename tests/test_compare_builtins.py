"""`mechsim compare --backends` on every built-in: IDA and diffrax integrate the same DAE (solver.method = 'dae', also
for a prescribed speed) and agree within the bounds compare states (scenarios/studies/compare.py: angles 1e3 rtol,
speeds 1e4 rtol, contact force 1e5 rtol of the column's peak). A short run (0.3 s) keeps this cheap: each model
structure is compiled once per process, and the bounds are per step, so the start covers every mode the
formulation has to hold; the whole default runs were checked by hand (docs/diffrax.md)."""
import numpy as np
import pytest

import mechsim
from mechsim.scenarios.studies.compare import tolerance_for

RTOL = 1e-10


@pytest.mark.parametrize("name", mechsim.builtins())
def test_every_builtin_agrees_on_both_backends(name):
    table = mechsim.compare_backends(name, set={"duration": "0.3 s"}, rtol=RTOL)
    rows = table.set_index("column")
    assert table.attrs["passed"], table[table["passed"] == False]  # noqa: E712 (object column)
    assert rows.loc["mode (rows differing)", "max_abs_diff"] == 0       # same mode on every output row
    checked = rows[rows["passed"].notna()]
    # every angle and speed column is held to its stated bound, and at least one of each kind is there
    assert any(c.endswith("_angle_rad") for c in checked.index) and any("_speed_" in c for c in checked.index)
    for column, row in checked.iterrows():
        bound = tolerance_for(column, RTOL)
        assert row["tolerance"] == f"{bound.kind} <= {bound.value:g}"
        assert np.isfinite(row["max_rel_diff"]) and row["max_rel_diff"] <= bound.value, column
