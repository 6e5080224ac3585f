"""`mechsim compare --backends` on every built-in model (SAME_PATH_AS: the built-ins another case stands for): IDA and
diffrax integrate the same DAE (solver.method = 'dae', also for a prescribed speed) and agree within the bounds compare
states (scenarios/studies/compare.py: angles 1e3 rtol, speeds 1e4 rtol, contact force 1e5 rtol of the column's peak).
A short run (0.3 s) keeps this cheap: each model structure is compiled once per process, and the bounds are per step,
so the start covers every mode the formulation has to hold; the whole default runs were checked by hand
(docs/diffrax.md)."""
import numpy as np
import pytest

import mechsim
from mechsim.scenarios.studies.compare import tolerance_for

RTOL = 1e-10

#: Built-ins left out here, each with the case that checks its code path. The six seed load cases are one model (the
#: seed Geneva at a prescribed speed, friction, lumped + Jaeger flash thermal: one compiled program) with other values
#: of the speed and the friction; geneva-seed-lc3-mu030 stands for them all: at 10.68 rad/s its 0.3 s from -180 deg
#: cross the entry at -45 deg and the slip reversal at 0 deg, while lc1 and lc2 (5.34 rad/s, to -88 deg) stay in the
#: dwell. internal-geneva-motor is compared by tests/test_internal_geneva.py (test_ida_and_diffrax_agree: the same
#: `compare_backends` at the same rtol over 2.5 s, through entries, slip reversals and exits), so its compilation is
#: not paid twice.
SAME_PATH_AS = {**{f"geneva-seed-lc{lc}-mu{mu}": "geneva-seed-lc3-mu030"
                   for lc, mu in (("1", "015"), ("1", "030"), ("2", "015"), ("2", "030"), ("3", "015"))},
                "internal-geneva-motor": "tests/test_internal_geneva.py::test_ida_and_diffrax_agree"}
CASES = [name for name in mechsim.builtins() if name not in SAME_PATH_AS]


def test_the_cases_leave_out_only_same_path_builtins():
    assert set(SAME_PATH_AS) <= set(mechsim.builtins())
    assert {case for case in SAME_PATH_AS.values() if "::" not in case} <= set(CASES)


@pytest.mark.parametrize("name", CASES)
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
