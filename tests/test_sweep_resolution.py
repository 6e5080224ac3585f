"""Sweep figures compare cases only as finely as their runs resolve them: a quantity that is the same in every case
but for integration noise is drawn as one value (its panel not stretched over the noise, its heat map one colour)
and says so, while one that changes between cases keeps its range; failed cases are marked and the mark named.

The case: internal-geneva-motor over the wheel load and the friction. In every dwell the wheel is locked and the
crank runs free, settling (time constant J / (Ts/w0 + c), 4 ms, against a dwell of about 0.27 s) where the motor
curve meets the crank damping: the least drive torque is T* = c Ts / (Ts/w0 + c) whatever the load and friction
(docs/internal_geneva.md, the motor drive of docs/theory.md). Its located values differ between cases by the
integration's error of the crank speed near the no-load speed, times Ts/w0, about 1e-8 of the drive torque's peak.
"""
import numpy as np
import pytest

import mechsim
from mechsim.scenarios.studies.resolution import TOLERANCES_RESOLVED
from mechsim.scenarios.studies.sweep.plots import heatmap, plot_against, resolution

AXES = {"load.wheel_torque": "4,10 N*m", "contact.friction": "0.1,0.3"}
LOAD, FRICTION = "load.wheel_torque_N_m", "contact.friction"
RTOL = 1e-8                                    # the scenario's own (solver.rtol)


@pytest.fixture(scope="module")
def table():
    return mechsim.sweep("internal-geneva-motor", AXES, set=["duration=1 s", "thermal.model=none"])


def test_the_least_drive_torque_is_the_motors_equilibrium_in_every_case(table):
    sc = mechsim.load("internal-geneva-motor")
    stall, free = sc.si["drive"]["stall_torque"], sc.si["drive"]["no_load_speed"]
    c = sc.si["mechanism"]["crank_damping"]
    equilibrium = c * stall / (stall / free + c)
    least = table["peak_min_drive_torque_N_m"].to_numpy(float)
    assert table["success"].all() and len(least) == 4
    # to the integration's tolerance of the torque's scale (the stall torque reached at start-up)
    np.testing.assert_allclose(least, equilibrium, rtol=0, atol=10 * RTOL * stall)
    spread = np.ptp(least)
    assert 0 < spread <= resolution(table, "peak_min_drive_torque_N_m", RTOL)
    # ... while the contact force's peak changes with the load by far more than the runs resolve
    assert np.ptp(table["peak_max_contact_force_N"]) > 1e3 * resolution(table, "peak_max_contact_force_N", RTOL)


def test_resolution_is_the_tolerance_of_the_columns_scale(table):
    scale = np.abs(table[["peak_max_drive_torque_N_m", "peak_min_drive_torque_N_m"]].to_numpy(float)).max()
    assert resolution(table, "peak_min_drive_torque_N_m", RTOL) == pytest.approx(TOLERANCES_RESOLVED * RTOL * scale)
    assert resolution(table, "impacts_per_turn_max", RTOL) == 0.0          # a count: every difference is real


def _panel(fig, figure):
    return next(ax for ax in fig.axes if ax.get_ylabel().startswith(figure.removesuffix("_N_m").removesuffix("_N")))


def test_an_unresolved_quantity_is_one_line_and_says_so(table):
    fig = plot_against(table, LOAD, [FRICTION], ["peak_min_drive_torque_N_m", "peak_max_contact_force_N"],
                       tolerance=RTOL)
    flat = _panel(fig, "peak_min_drive_torque")
    low, high = flat.get_ylim()
    middle = float(np.median(table["peak_min_drive_torque_N_m"]))
    assert high - low >= 0.05 * middle        # not stretched over the 1e-7 N m between cases
    assert any("equal in every case within the runs' tolerance" in t.get_text() for t in flat.texts)
    ranged = _panel(fig, "peak_max_contact_force")
    low, high = ranged.get_ylim()
    forces = table["peak_max_contact_force_N"]
    assert high - low < 1.5 * np.ptp(forces) and not ranged.texts


def test_an_unresolved_heat_map_is_one_colour_and_says_so(table):
    fig = heatmap(table, FRICTION, LOAD, "peak_min_drive_torque_N_m", tolerance=RTOL)
    assert "equal in every case within the runs' tolerance" in fig.get_suptitle()
    image = next(ax.images[0] for ax in fig.axes if ax.images)
    low, high = image.get_clim()
    assert high - low >= 1.0 and np.ptp(np.asarray(image.get_array(), float)) == 0       # every cell one colour
    cells = [t.get_text() for ax in fig.axes for t in ax.texts]        # each cell still reads its own value
    assert len(cells) == 4 and set(cells) == {f"{v:.4g}" for v in table["peak_min_drive_torque_N_m"]}
    fig = heatmap(table, FRICTION, LOAD, "peak_max_contact_force_N", tolerance=RTOL)
    assert "tolerance" not in fig.get_suptitle()
    image = next(ax.images[0] for ax in fig.axes if ax.images)
    np.testing.assert_allclose(image.get_clim(), [table["peak_max_contact_force_N"].min(),
                                                  table["peak_max_contact_force_N"].max()])


def test_failed_cases_are_marked_and_the_mark_is_named():
    """A one-parameter sweep with failed cases (too little torque: the crank stalls in the engagement) marks them
    with a red x on the parameter axis, and the legend says what the mark is, though there is only one line."""
    import pandas as pd
    table = pd.DataFrame({"drive.torque_N_m": [1.0, 2.0, 6.0, 9.0], "success": [False, False, True, True],
                          "peak_max_contact_force_N": [np.nan, np.nan, 560.0, 1170.0]})
    fig = plot_against(table, "drive.torque_N_m", [], ["peak_max_contact_force_N"])
    (marks,) = [line for line in fig.axes[0].get_lines() if line.get_marker() == "x"]
    np.testing.assert_array_equal(marks.get_xdata(), [1.0, 2.0])
    assert [t.get_text() for legend in fig.legends for t in legend.get_texts()] == ["failed case"]
