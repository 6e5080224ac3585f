"""Events of a prescribed-speed (closed-form) Geneva run: every entry and exit at its exact time."""
import numpy as np
import pytest

from mechsim.mechanisms.geneva.kinematics import speed_ratio
from mechsim.scenarios.loader import load
from mechsim.scenarios.runner import run


@pytest.fixture(scope="module")
def lc1():
    return run(load("geneva-lc1", ["thermal.model='none'"]))


def test_entries_and_exits_at_the_closed_form_crank_angles(lc1):
    si = lc1.scenario
    n, w, theta0 = si["mechanism"]["slots"], si["drive"]["speed"], si["initial"]["crank_angle"]
    a0 = np.pi / 2 - np.pi / n                     # docs/theory.md §G1: engagement half angle
    ev = lc1.events
    assert lc1.summary["model"]["method"] == "closed-form"
    theta_end = theta0 + w * si["duration"]
    expected = sorted([(2 * np.pi * k - a0, "entry") for k in range(-2, 10)] +
                      [(2 * np.pi * k + a0, "exit") for k in range(-2, 10)])
    expected = [(a, kind) for a, kind in expected if theta0 < a <= theta_end]
    assert list(ev["kind"]) == [kind for _, kind in expected]
    np.testing.assert_allclose(ev["t_s"], [(a - theta0) / w for a, _ in expected], rtol=1e-13, atol=1e-13)
    # entries end a dwell, exits start one; the wheel speed ratio is zero there (shock-free entry, §G1)
    assert set(zip(ev["kind"], ev["from_mode"], ev["to_mode"])) == {("entry", "dwell", "engaged"),
                                                                     ("exit", "engaged", "dwell")}
    alpha = ev["crank_q"].to_numpy() - 2 * np.pi * np.round(ev["crank_q"].to_numpy() / (2 * np.pi))
    np.testing.assert_allclose(speed_ratio(np.sin(np.pi / n), alpha), 0.0, atol=1e-15)


def test_event_times_bracket_the_table_modes(lc1):
    """The mode column changes between the two output rows around every event, and nowhere else."""
    df, ev = lc1.timeseries, lc1.events
    t = df["t_s"].to_numpy()
    changes = np.flatnonzero(df["mode"].to_numpy()[1:] != df["mode"].to_numpy()[:-1])
    assert len(changes) == len(ev)
    for i, te in zip(changes, ev["t_s"]):
        assert t[i] < te <= t[i + 1] + 1e-12
