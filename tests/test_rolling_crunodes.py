"""Crunodes of the trochoid and of the coupler curve, set A (docs/theory.md §K2.4)."""
import numpy as np
import pytest

from mechsim.mechanisms.rolling.atlas import crunodes_table, trochoid_crunodes_table
from mechsim.mechanisms.rolling.sets import make

TROCHOID = [((2.585419, 5.939359), (0.905415, 2.982469)), ((12.010197, 15.364137), (0.094585, -2.382469))]
BRANCH_P = [((2.585419, 5.939359), (1.048915, 0.636241), True),
            ((12.010197, 15.364137), (-0.963456, -0.283439), True),
            ((3.506135, 5.207815), (0.987099, -0.205780), False),
            ((12.208300, 15.320223), (-0.976823, -0.219344), False)]
BRANCH_M = [((2.585419, 5.939359), (-1.379432, 3.534600), True),
            ((12.010197, 15.364137), (2.444407, -2.321539), True)]


@pytest.fixture(scope="module")
def set_a():
    m = make("A")
    tro = trochoid_crunodes_table(m)
    return m, tro, crunodes_table(m, trochoid=tro)


def _match(rows, ref_phi, ref_xy):
    hit = rows[np.isclose(rows.rolling_angle_1_rad, ref_phi[0], atol=2e-6)
               & np.isclose(rows.rolling_angle_2_rad, ref_phi[1], atol=2e-6)]
    assert len(hit) == 1, (ref_phi, rows)
    row = hit.iloc[0]
    assert (row.x_m, row.y_m) == pytest.approx(ref_xy, abs=2e-6)
    return row


def test_trochoid_crunodes(set_a):
    m, tro, _ = set_a
    assert len(tro) == 2
    for phis, xy in TROCHOID:
        row = _match(tro, phis, xy)
        B1, B2 = m.trochoid(np.array([row.rolling_angle_1_rad, row.rolling_angle_2_rad]))["B"]
        assert abs(B1 - B2) <= 1e-9  # located to 1e-9


@pytest.mark.parametrize("branch,ref", [(1, BRANCH_P), (-1, BRANCH_M)])
def test_coupler_crunodes(set_a, branch, ref):
    """Branch +1: 4 crunodes (2 induced by the trochoid's, 2 not); branch −1: 2, both induced."""
    m, _, cr = set_a
    rows = cr[(cr.branch_1 == branch) & (cr.branch_2 == branch)]
    assert len(rows) == len(ref)
    for phis, xy, induced in ref:
        row = _match(rows, phis, xy)
        assert bool(row.induced) is induced and bool(row.converged)
        C1 = m.coupler(np.array(row.rolling_angle_1_rad), branch)
        C2 = m.coupler(np.array(row.rolling_angle_2_rad), branch)
        assert abs(C1 - C2) <= 1e-9  # located to 1e-9
        assert abs(C1 - (row.x_m + 1j * row.y_m)) <= 1e-9
        # a genuine crossing: the tangents are not parallel
        d1 = m.solve(np.array(row.rolling_angle_1_rad), branch).dC
        d2 = m.solve(np.array(row.rolling_angle_2_rad), branch).dC
        assert abs((np.conj(d1) * d2).imag) > 1e-3 * abs(d1) * abs(d2)


def test_crunodes_converge_with_sampling():
    """The refined crunodes do not depend on the sampling density of the search polyline."""
    m = make("A")
    coarse = crunodes_table(m, samples_per_turn=360)
    fine = crunodes_table(m, samples_per_turn=1440)
    assert len(coarse) == len(fine) == 6
    np.testing.assert_allclose(coarse[["x_m", "y_m"]].to_numpy(), fine[["x_m", "y_m"]].to_numpy(), atol=1e-12)
