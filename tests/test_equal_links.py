"""Equal links are not degenerate by themselves (docs/limits.md, "Geometry that cannot assemble"): a dyad with
crank = coupler is an isosceles triangle, unique on its branch while the driven point stays off the crank pivot;
its folded configuration shrinks to that one point, where the crank angle is undefined. So a chain with
coupler_length = crank_radius runs and closes its loop exactly, and is refused (one line, nothing written)
when its chain passes through the crank pivot."""
import numpy as np
import pandas as pd
from cli_helpers import invoke, one_line_error

EQUAL = ["--set", "mechanism.coupler_length=5 cm"]          # crank_radius = 5 cm in chain-mech1-kinematic


def test_chain_with_coupler_equal_to_crank_runs_and_closes_its_loop(tmp_path):
    r = invoke("run", "chain-mech1-kinematic", *EQUAL, "--out", tmp_path / "o", "--quiet", "--set",
               "output.plots=false")
    assert r.exit_code == 0, r.output
    df = pd.read_parquet(tmp_path / "o" / "timeseries.parquet")
    R = L = 0.05
    phi, theta = df["crank_angle_rad"].to_numpy(), df["coupler_angle_rad"].to_numpy()
    tip = np.column_stack([df["crank_tip_x_m"], df["crank_tip_y_m"]])
    B = np.column_stack([df["joint_B_x_m"], df["joint_B_y_m"]])
    # loop R e(phi) + L e(theta) = B - Q (Q = pivot at the origin), to round-off of lengths ~0.1 m
    np.testing.assert_allclose(tip, R * np.column_stack([np.cos(phi), np.sin(phi)]), rtol=0, atol=1e-12)
    np.testing.assert_allclose(B - tip, L * np.column_stack([np.cos(theta), np.sin(theta)]), rtol=0, atol=1e-12)
    # the chain stays >= 2 cm from the pivot (sprockets 5 cm out, 3 cm radius), so the dyad never folds to a point
    assert np.hypot(B[:, 0], B[:, 1]).min() > 0.019
    # and the dyad's own speeds stay those of a well-posed triangle: nothing near the fold's infinite ratio
    assert df["crank_speed_rad_s"].abs().max() < 2.0 and df["coupler_speed_rad_s"].abs().max() < 2.0


def test_chain_passing_through_the_pivot_of_equal_links_is_refused(tmp_path):
    # pivot on the chain (the wrap of sprocket 1 at (5, 0) cm, radius 3 cm): |QB| reaches |R - L| = 0 there
    r = invoke("run", "chain-mech1-kinematic", *EQUAL, "--set", 'mechanism.pivot=["8 cm", "0 cm"]',
               "--out", tmp_path / "o", "--quiet")
    assert r.exit_code == 2
    line = one_line_error(r)
    assert "mechanism.coupler_length" in line and "[0, 0.1] m" in line
    assert not (tmp_path / "o").exists()
