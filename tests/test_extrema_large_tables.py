"""A large table's candidates are found one column at a time (`extrema.JOINT_VALUES`): each series' candidates,
brackets and bounds must be exactly those of all columns at once, for one window and for several found together,
whatever the values hold (NaN, infinities, ties, constant stretches, signed zeros)."""
import numpy as np
import pytest

from mechsim.dynamics import extrema
from mechsim.dynamics.extrema import _candidates_bounds, intervals_of


def _table(rng, n_rows: int, n_columns: int) -> np.ndarray:
    """Smooth bumps with the troubles a table can hold written over random stretches."""
    t = np.linspace(0.0, 10.0, n_rows)
    F = np.array([np.sin((c + 1.3) * t + c) * (1 + 0.1 * c) for c in range(n_columns)])
    for c in range(n_columns):
        for value in (np.nan, np.inf, -np.inf, 0.0, -0.0, 1.0):
            a = int(rng.integers(0, n_rows - 5))
            F[c, a:a + int(rng.integers(1, 6))] = value
        ties = rng.integers(0, n_rows, 4)
        F[c, ties] = F[c].max() if np.isfinite(F[c]).any() else 0.0
    return t, F


@pytest.mark.parametrize("seed", range(12))
@pytest.mark.parametrize("windows", [1, 2, 3])
def test_per_column_candidates_equal_the_joint_ones(seed, windows, monkeypatch):
    rng = np.random.default_rng(seed)
    t, F = _table(rng, int(rng.integers(40, 400)), int(rng.integers(2, 6)))
    if seed % 3 == 0:
        F[:, :] = np.where(np.isfinite(F), F, 0.0)          # every value finite: the finite path
    cuts = np.sort(rng.uniform(0.5, 9.5, windows - 1))
    edges = [0.0, *cuts.tolist(), 10.0]
    breaks = [(float(b), f"event 'e{k}'") for k, b in enumerate(np.sort(rng.uniform(0.0, 10.0, 6)))]
    spans = [intervals_of(t, breaks, a, b) for a, b in zip(edges[:-1], edges[1:])]
    intervals = [iv for s in spans for iv in s]
    groups = [len(s) for s in spans]
    ties = np.abs(rng.normal(size=len(F))) * 1e-3
    ties[0] = 0.0
    monkeypatch.setattr(extrema, "JOINT_VALUES", 10 ** 9)
    joint = _candidates_bounds(t, F, ties, intervals, groups=groups)
    monkeypatch.setattr(extrema, "JOINT_VALUES", 0)
    split = _candidates_bounds(t, F, ties, intervals, groups=groups)
    assert split[0] == joint[0]
    np.testing.assert_array_equal(split[1], joint[1])
