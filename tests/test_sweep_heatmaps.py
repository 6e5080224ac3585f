"""Sweep heat maps say what a cell holds: a four-parameter grid through `mechsim.sweep` draws the first two
parameters, a panel per value of the third (small multiples on one colour scale), and reduces the fourth by the
aggregate the title names (the max of a peak_max_*, the min of a peak_min_*), checked against the table."""
import numpy as np
import pytest
from PIL import Image

import mechsim
from mechsim.scenarios.studies.sweep.plots import heatmap

AXES = {"contact.friction": "0.1,0.3", "load.wheel_torque": "5,9 N*m", "drive.speed": "4,6 rad/s",
        "mechanism.pin_radius": "3,5 mm"}
A, B, FACET, HIDDEN = "contact.friction", "load.wheel_torque_N_m", "drive.speed_rad_s", "mechanism.pin_radius_m"
# closed form (prescribed speed), no thermal model: one index per case, a fraction of a second each
BASE = ["duration=0.8 s", "output_step=5 ms", "thermal.model=none"]


@pytest.fixture(scope="module")
def swept(tmp_path_factory):
    out = tmp_path_factory.mktemp("heat") / "sweep"
    table = mechsim.sweep("geneva-lc1", AXES, set=BASE, out=out, plots=True)
    return table, out / "plots"


def _cells(fig):
    """Each panel's title and its image (rows: parameter B, columns: parameter A)."""
    return {ax.get_title(): np.asarray(ax.images[0].get_array(), float) for ax in fig.axes if ax.images}


def test_peaks_are_the_max_over_the_hidden_parameter_in_small_multiples(swept):
    table, plots = swept
    assert len(table) == 16 and table["success"].all()
    for value, how in (("peak_max_contact_force_N", "max"), ("peak_max_wheel_accel_rad_s2", "max"),
                       ("peak_min_wheel_accel_rad_s2", "min")):
        fig = heatmap(table, A, B, value, FACET, [HIDDEN])
        title = fig.get_suptitle()
        assert f"{how} over mechanism.pin_radius (m) (2 cases per cell)" in title, title
        panels = _cells(fig)
        assert sorted(panels) == ["drive.speed (rad/s) = 4", "drive.speed (rad/s) = 6"]
        expected = table.groupby([FACET, B, A])[value].agg(how)
        for speed in (4.0, 6.0):
            grid = panels[f"drive.speed (rad/s) = {speed:g}"]
            want = expected.loc[speed].unstack(A).sort_index().sort_index(axis=1).to_numpy()
            np.testing.assert_array_equal(grid, want)
            if value == "peak_max_contact_force_N":   # the pin radius moves the force (not the kinematic accel)
                thin = table[(table[FACET] == speed) & (table[HIDDEN] == 3e-3)]
                assert (grid > thin.pivot_table(index=B, columns=A, values=value).to_numpy()).all()
        limits = {im.get_clim() for ax in fig.axes for im in ax.images}
        assert len(limits) == 1                     # one colour scale across the panels
    # the files the sweep wrote: two panels side by side, wider than tall
    with Image.open(plots / "heatmap_peak_max_contact_force_N.png") as im:
        assert im.width > 1.5 * im.height
    assert (plots / "heatmap_success.png").is_file()


def test_the_aggregate_can_be_chosen_and_a_failed_cell_is_named(swept):
    table, _ = swept
    fig = heatmap(table, A, B, "peak_max_contact_force_N", FACET, [HIDDEN], aggregate="mean")
    assert "mean over mechanism.pin_radius (m)" in fig.get_suptitle()
    grid = _cells(fig)["drive.speed (rad/s) = 4"]
    want = table[table[FACET] == 4.0].pivot_table(index=B, columns=A, values="peak_max_contact_force_N",
                                                 aggfunc="mean").to_numpy()
    np.testing.assert_allclose(grid, want, rtol=1e-15)
    broken = table.copy()
    broken.loc[(broken[A] == 0.1) & (broken[B] == 5.0), "success"] = False
    fig = heatmap(broken, A, B, "peak_max_contact_force_N", FACET, [HIDDEN])
    grid = _cells(fig)["drive.speed (rad/s) = 4"]
    assert np.isnan(grid[0, 0]) and np.isfinite(grid).sum() == 3
    assert "all failed" in [t.get_text() for ax in fig.axes for t in ax.texts]
    share = _cells(heatmap(broken, A, B, "success", FACET, [HIDDEN]))["drive.speed (rad/s) = 4"]
    np.testing.assert_array_equal(share, [[0.0, 1.0], [1.0, 1.0]])


def test_a_bad_aggregate_is_one_error_naming_it_before_any_case_runs(tmp_path):
    with pytest.raises(mechsim.ScenarioError, match=r"heatmap_aggregate: must be one of auto, max, min, mean; "
                                                   r"got 'median'"):
        mechsim.sweep("geneva-lc1", AXES, set=BASE, out=tmp_path / "s", plots=True, heatmap_aggregate="median")
    assert not (tmp_path / "s").exists()


def test_the_cli_takes_the_aggregate_and_refuses_a_bad_one_in_one_line(tmp_path):
    from cli_helpers import invoke, one_line_error
    bad = invoke("sweep", "geneva-lc1", "--vary", "contact.friction=0.1,0.3", *sum((["--set", s] for s in BASE), []),
                 "--out", tmp_path / "bad", "--heatmap-aggregate", "median", "--workers", "0")
    assert bad.exit_code == 2 and "heatmap_aggregate: must be one of" in one_line_error(bad)
    assert not (tmp_path / "bad").exists()
    good = invoke("sweep", "geneva-lc1", "--vary", "contact.friction=0.1,0.3", "--vary", "load.wheel_torque=5,9 N*m",
                  "--vary", "mechanism.pin_radius=3,5 mm", *sum((["--set", s] for s in BASE), []),
                  "--out", tmp_path / "good", "--heatmap-aggregate", "min", "--workers", "0", "--quiet")
    assert good.exit_code == 0, good.output
    with Image.open(tmp_path / "good" / "plots" / "heatmap_peak_max_contact_force_N.png") as im:
        assert im.size[0] > 0
