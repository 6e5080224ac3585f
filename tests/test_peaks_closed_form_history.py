"""The closed-form reader of a closed form that follows the motion's history (the chain's apex law, the rolling pair's
unwrapped angles: `scenarios/peaks.py` `_closed_form_reader`): many readings evaluated together must give what each
reading gives alone and what the table holds at its own rows, and a shortened history that would count the turns
wrongly must be caught by its check against the table."""
from __future__ import annotations

import numpy as np
import pytest

import mechsim
from mechsim.dynamics.extrema import Interval
from mechsim.scenarios import peaks

#: the columns compared (angles unwrapped from the run's start, a rate, a force from the inverse dynamics)
COLUMNS = {"chain-mech2-kinematic": ("crank_angle_rad", "coupler_angle_rad", "coupler_accel_rad_s2",
                                     "drive_torque_N_m"),
           "rolling-c-cusp": ("coupler_angle_rad", "rolling_angle_rad", "rolling_speed_rad_s", "contact_force_N")}


def _reader_and_table(name: str, monkeypatch, arguments: list | None = None):
    """The reader a run of `name` located its peaks with, and the run's table (arguments: filled with the reader's)."""
    made = []
    real = peaks._closed_form_reader

    def keep(*args):
        made.append(real(*args))
        if arguments is not None and not arguments:         # the located peaks' (the validity reads with another)
            arguments.extend(args)
        return made[-1]
    monkeypatch.setattr(peaks, "_closed_form_reader", keep)
    result = mechsim.run(mechsim.load(name, set=["output.plots=false"]))
    assert made, "the run located no peak on the closed form"
    return made[0], result.timeseries


def _evaluations(monkeypatch) -> list[int]:
    """The number of instants of each closed-form evaluation from now on."""
    sizes = []
    real = peaks._closed_form_at

    def count(mech, at, angle0, speed):
        sizes.append(len(at))
        return real(mech, at, angle0, speed)
    monkeypatch.setattr(peaks, "_closed_form_at", count)
    return sizes


@pytest.mark.parametrize("name", sorted(COLUMNS))
def test_readings_together_equal_the_table_and_each_reading_alone(name, monkeypatch):
    read, df = _reader_and_table(name, monkeypatch)
    t = df["t_s"].to_numpy(float)
    n = len(t)
    columns = [c for c in COLUMNS[name] if c in df]
    assert len(columns) >= 2
    # requests on stretches all over the run (early, middle, late: a late one's history skips most rows), each
    # asking for three of its rows and the midpoints between them
    requests = []
    for k in np.linspace(5, n - 10, 9).astype(int):
        rows = np.arange(k - 2, k + 3)
        iv = Interval(float(t[k - 3]), float(t[k + 3]), "start", "end", np.arange(k - 3, k + 4))
        times = np.sort(np.concatenate([t[rows[::2]], 0.5 * (t[rows[:-1]] + t[rows[1:]])]))
        requests.append((iv, 0, times))
    sizes = _evaluations(monkeypatch)
    together = read.read_many(requests)
    evaluations_together = len(sizes)
    alone = [read(*r) for r in requests]
    assert evaluations_together == 1 and len(sizes) - evaluations_together >= len(requests)
    assert sizes[0] < n // 4                          # the history shortened to what the readings depend on
    for (iv, _, times), a, b in zip(requests, together, alone):
        np.testing.assert_array_equal(a["t_s"], times)
        on_rows = np.isin(times, t)
        rows = t.searchsorted(times[on_rows])
        for c in columns:
            # together and alone: the same evaluation but for the rows around, so the same values to round-off
            np.testing.assert_allclose(a[c], b[c], rtol=1e-12, atol=1e-12 * np.abs(df[c]).max())
            # at the table's own instants, the table's values (counted from the run's first instant: the turns)
            np.testing.assert_allclose(a[c][on_rows], df[c].to_numpy(float)[rows], rtol=1e-10,
                                       atol=1e-10 * np.abs(df[c]).max())


def test_a_late_reading_counts_the_turns_from_a_short_history(monkeypatch):
    """The rolling pair's rolling angle turns four times: a reading late in the run is evaluated from a history of a
    few rows (the first instant's, those where an angle crosses a quarter turn, the row before each instant), not from
    every row before it, and counts the turns as the table does."""
    read, df = _reader_and_table("rolling-c-cusp", monkeypatch)
    t, angle = df["t_s"].to_numpy(float), df["rolling_angle_rad"].to_numpy(float)
    assert angle.max() - angle.min() > 6 * np.pi              # several turns: a miscount would show
    k = len(t) - 20
    iv = Interval(float(t[k - 3]), float(t[k + 3]), "start", "end", np.arange(k - 3, k + 4))
    sizes = _evaluations(monkeypatch)
    got = read(iv, 0, t[k - 1:k + 2])
    np.testing.assert_allclose(got["rolling_angle_rad"], angle[k - 1:k + 2], rtol=1e-12)
    assert len(sizes) == 1 and sizes[0] < k // 10


@pytest.mark.parametrize("change", ["a turn off from the middle on", "a located column off next to the reading"])
def test_a_history_that_does_not_reproduce_the_table_is_not_used(change, monkeypatch):
    """Where the shortened history's rows do not give the table's own values (a table whose rolling angle is a turn
    off from the middle of the run on; one whose located column is off by 1e-6 on the rows around the reading), the
    check rejects it and the reading is taken from every row up to it."""
    arguments: list = []
    _reader_and_table("rolling-c-cusp", monkeypatch, arguments)
    source, angle0, t, table, check = arguments
    k = len(t) - 20
    if change.startswith("a turn"):
        name = "rolling_angle_rad"
        off = np.where(t > t[len(t) // 2], table[name] + 2 * np.pi, table[name])
    else:
        name = next(c for c in check if not c.endswith("_angle_rad"))
        off = table[name].copy()
        off[k - 2:k + 3] *= 1 + 1e-6
    assert name in check
    read = peaks._closed_form_reader(source, angle0, t, dict(table, **{name: off}), check)
    iv = Interval(float(t[k - 3]), float(t[k + 3]), "start", "end", np.arange(k - 3, k + 4))
    sizes = _evaluations(monkeypatch)
    got = read(iv, 0, t[k - 1:k + 2])
    assert len(sizes) == 2 and sizes[0] < k // 10 and sizes[1] >= k
    # from every row: the closed form's own values (the true table's), not the changed ones
    np.testing.assert_allclose(got[name], table[name][k - 1:k + 2], rtol=1e-12)


def test_a_request_without_instants_is_read_alone(monkeypatch):
    """A request without instants is evaluated alone: the requests around it are read as without it, and it comes
    back with no rows."""
    read, df = _reader_and_table("chain-mech2-kinematic", monkeypatch)
    t = df["t_s"].to_numpy(float)

    def request(k, times):
        return Interval(float(t[k - 3]), float(t[k + 3]), "start", "end", np.arange(k - 3, k + 4)), 0, times
    plain = [request(100, t[100:101]), request(120, t[120:122])]
    without = read.read_many(plain)
    with_empty = read.read_many([plain[0], request(110, np.zeros(0)), plain[1]])
    for a, b in zip(without, [with_empty[0], with_empty[2]]):
        for c in ("coupler_angle_rad", "drive_torque_N_m"):
            np.testing.assert_array_equal(a[c], b[c])
    assert len(with_empty[1]["t_s"]) == 0 and len(with_empty[1]["drive_torque_N_m"]) == 0
