"""Columns located on intervals of their own over one table (the thermal columns, each on the intervals that may
hold its extremum) are planned together (`extrema.column_plans`: one pass of the candidates, a series per span):
every plan must be exactly the plan of that column alone on its intervals (`extrema.plan`), whatever the values
hold (NaN, infinities, ties, constant stretches, signed zeros) and however the spans share intervals."""
import math

import numpy as np
import pytest

from mechsim.dynamics.extrema import _candidates_bounds, _ties, column_plans, intervals_of, plan


def _table(rng, n_rows: int, n_columns: int):
    """Smooth bumps with the troubles a table can hold written over random stretches, the columns of magnitudes
    1e4 apart, each with stretches flat to within its own round-off tie (far beyond a smaller column's: the columns'
    ties must not be mixed up)."""
    t = np.linspace(0.0, 10.0, n_rows)
    values = {}
    for c in range(n_columns):
        scale = 10.0 ** (4 * c)
        f = np.sin((c + 1.3) * t + c) * scale
        for value in (np.nan, np.inf, -np.inf, 0.0, -0.0, scale):
            a = int(rng.integers(0, n_rows - 5))
            f[a:a + int(rng.integers(1, 6))] = value
        for _ in range(3):                           # nearly constant stretches: equal to round-off of the column
            a = int(rng.integers(0, n_rows - 12))
            f[a:a + 12] = 0.5 * scale + rng.uniform(-0.4, 0.4, 12) * 1e-13 * scale
        f[rng.integers(0, n_rows, 4)] = np.nanmax(np.where(np.isfinite(f), f, np.nan))     # ties of the largest
        for i in rng.choice(np.arange(1, n_rows - 1, 3), 4, replace=False):
            # peaks within the column's tie of each other (each exactly its row: symmetric neighbours), the best
            # of the column: which of them are kept hinges on the column's own tie
            f[i - 1:i + 2] = 2.0 * scale * np.array([1.0 - 1e-3, 1.0 - rng.uniform(0.0, 5e-14), 1.0 - 1e-3])
        values[f"c{c}"] = f
    return t, values


def _plain(x):
    """A value as comparable data: NaN equal to NaN, arrays and mappings by their items."""
    if isinstance(x, float) and math.isnan(x):
        return "nan"
    if isinstance(x, np.ndarray):
        return ("array", x.dtype.str, x.shape, tuple(_plain(v) for v in x.ravel().tolist()))
    if isinstance(x, dict):
        return tuple((k, _plain(v)) for k, v in x.items())
    if isinstance(x, (list, tuple)):
        return tuple(_plain(v) for v in x)
    if isinstance(x, (np.floating, np.integer)):
        return _plain(x.item())
    return x


def _described(p, intervals):
    """Everything a plan hands on, with intervals by their position in `intervals`."""
    at = {id(iv): k for k, iv in enumerate(intervals)}
    jobs = [_plain(tuple(vars(j).values())) for j in p.jobs]
    clusters = [[p.jobs.index(j) for j in group] for group in p.clusters]
    starts = {k: [p.jobs.index(j) for j in group] for k, group in p.starts.items()}
    requests = [(at[id(iv)], position, _plain(times)) for iv, position, times in p.requests]
    return (jobs, clusters, starts, [_plain(g) for g in p.grids], requests, _plain(p.ties), _plain(p.bounds),
            list(p.values), [at[id(iv)] for iv in p.intervals])


def _spans(rng, t, values):
    """Two windows' intervals, and per window and column a random subset of them (empty, all, or some; the
    columns sharing intervals), in order."""
    cut = float(rng.uniform(2.0, 8.0))
    breaks = [(float(b), f"event 'e{k}'") for k, b in enumerate(np.sort(rng.uniform(0.0, 10.0, 7)))]
    windows = [intervals_of(t, breaks, 0.0, cut), intervals_of(t, breaks, cut, 10.0)]
    spans = []
    for intervals in windows:
        for c in values:
            kind = rng.integers(0, 4)
            keep = ([] if kind == 0 else intervals if kind == 1 else
                    [iv for iv in intervals if rng.random() < 0.5])
            spans.append((c, keep))
    return windows, spans


@pytest.mark.parametrize("seed", range(16))
def test_plans_made_together_equal_each_columns_own(seed):
    rng = np.random.default_rng(seed)
    t, values = _table(rng, int(rng.integers(40, 300)), int(rng.integers(1, 5)))
    if seed % 4 == 0:
        values = {c: np.where(np.isfinite(f), f, 0.0) for c, f in values.items()}     # every value finite
    windows, spans = _spans(rng, t, values)
    every = [iv for w in windows for iv in w]
    together = column_plans(t, values, spans)
    assert len(together) == len(spans)
    for (c, intervals), joint in zip(spans, together):
        alone = plan(t, {c: values[c]}, intervals)
        assert _described(joint, every) == _described(alone, every)


@pytest.mark.parametrize("seed", range(8))
def test_a_series_per_window_finds_each_windows_candidates_as_alone(seed):
    """`_candidates_bounds` with a series per window: each window's candidates and bounds are those of its
    series found on its own (the differences across windows, whose rows are other series', never read)."""
    rng = np.random.default_rng(100 + seed)
    t, values = _table(rng, int(rng.integers(40, 300)), 3)
    F = np.array(list(values.values()))
    ties = _ties(F)
    windows, _ = _spans(rng, t, values)
    spans = [(int(rng.integers(0, 3)), w) for w in windows for _ in range(2)]
    spans = [(s, w) for s, w in spans if any(len(iv.rows) for iv in w)]
    got, bounds = _candidates_bounds(t, F, ties, [iv for _, w in spans for iv in w],
                                     groups=[len(w) for _, w in spans], series=[s for s, _ in spans])
    for q, (s, w) in enumerate(spans):
        own, own_bounds = _candidates_bounds(t, F[s:s + 1], ties[s:s + 1], w)
        assert got[2 * q:2 * q + 2] == own
        np.testing.assert_array_equal(bounds[2 * q:2 * q + 2], own_bounds)


@pytest.mark.parametrize("seed", range(8))
def test_each_columns_promising_intervals_are_its_own(seed):
    """The thermal columns' intervals worth refining (`thermal_peaks._promising`), found for all columns in one
    pass: each column's are those it gets alone (its own tie and slopes, not another column's)."""
    from mechsim.scenarios.thermal_peaks import _promising
    rng = np.random.default_rng(200 + seed)
    t, values = _table(rng, int(rng.integers(40, 300)), 4)
    F = np.array(list(values.values()))
    windows, _ = _spans(rng, t, values)
    for intervals in windows:
        together = _promising(F, intervals)
        for c in range(len(F)):
            assert [id(iv) for iv in together[c]] == [id(iv) for iv in _promising(F[c:c + 1], intervals)[0]]
        assert any(together)
