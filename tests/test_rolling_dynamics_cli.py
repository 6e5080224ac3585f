"""The rolling-pair 4-bar through the command line, in-process: every built-in rolling scenario runs, user errors
are one line with exit 2, a prescribed crank speed stopped by a dead point exits 3, and `mechsim curves` writes
the coupler-curve atlas (numbers from docs/theory.md §K2.2-2.4 and §3)."""
import json

import numpy as np
import pandas as pd
import pytest
from cli_helpers import invoke, one_line_error


def run_ok(tmp_path, name, *extra, plots=False):
    out = tmp_path / name
    r = invoke("run", name, "--out", out, "--quiet", *([] if plots else ["--set", "output.plots=false"]), *extra)
    assert r.exit_code == 0, r.output
    return (json.loads((out / "summary.json").read_text()), pd.read_parquet(out / "timeseries.parquet"),
            pd.read_csv(out / "events.csv"), r)


def test_list_shows_the_rolling_scenarios():
    r = invoke("list")
    names = {"rolling-a-torque", "rolling-a-speed", "rolling-b-components", "rolling-c-cusp", "rolling-d-line",
             "rolling-crank-torque"}
    assert r.exit_code == 0 and all(n in r.stdout for n in names)


def test_torque_on_rolling_link_reference(tmp_path):
    """docs/theory.md §K3, branch +1: phi(4 s) = 32.268 rad, W = 484.0 J; energy closes with the gravity work."""
    s, df, ev, _ = run_ok(tmp_path, "rolling-a-torque", plots=True)
    assert s["mechanism"] == "rolling_pair" and s["model"]["method"] == "dae"
    assert df["rolling_angle_rad"].iloc[-1] == pytest.approx(32.268, abs=1e-3)
    assert s["energy"]["work_J"]["drive"] == pytest.approx(484.0, abs=0.05)
    assert abs(s["energy"]["closure_error_relative"]) <= 1e-7
    assert df["rolling_speed_rad_s"].max() == pytest.approx(32.77, abs=0.01)   # on the reference's 0.01 s grid
    assert len(ev) == 0 and s["max_constraint_residual_m"] <= 1e-9
    for col in ("contact_force_N", "coupler_force_N", "potential_energy_J", "coupler_point_x_m", "branch"):
        assert col in df
    assert (tmp_path / "rolling-a-torque" / "mechanism.png").is_file()


def test_prescribed_rolling_speed_is_closed_form_over_one_period(tmp_path):
    """Set A, branch -1, 0.3 turn/s for one trochoid period (6 pi in 10 s): no DAE; the motion is periodic, so the crank
    makes one net turn and the drive work over the period is the (zero) change of kinetic + potential energy."""
    s, df, _, _ = run_ok(tmp_path, "rolling-a-speed")
    assert s["model"]["method"] == "closed-form"
    assert df["rolling_angle_rad"].iloc[-1] == pytest.approx(6 * np.pi, abs=1e-7)
    assert df["crank_angle_rad"].iloc[-1] - df["crank_angle_rad"].iloc[0] == pytest.approx(2 * np.pi, abs=1e-6)
    assert df["kinetic_energy_J"].iloc[-1] == pytest.approx(df["kinetic_energy_J"].iloc[0], rel=1e-6)
    drive = df["work_drive_J"].iloc[-1]
    assert abs(drive) <= 1e-3 * np.trapezoid(np.abs(df["drive_torque_N_m"] * 0.6 * np.pi), df["t_s"])


def test_multi_component_dead_points(tmp_path):
    """Set B under a torque on the rolling link: the run reaches the stretched end of the closure interval
    [2.081243, 5.781935] twice, the events table says so, and the run completes."""
    s, df, ev, r = run_ok(tmp_path, "rolling-b-components")
    assert list(ev["kind"]) == ["dead point", "dead point"]
    np.testing.assert_allclose(ev["rolling_q"], 5.781935, atol=1e-6)
    assert s["events"] == {"dead point": 2} and len(s["warnings"]) == 2
    assert all("stretched dyad" in w for w in s["warnings"]) and r.stderr == ""   # --quiet: errors only
    assert df["t_s"].iloc[-1] == pytest.approx(6.0)
    assert df["rolling_angle_rad"].max() <= 5.781935 + 1e-6


def test_cusp_scenario_coupler_point_stops(tmp_path):
    """Set C (l4 = r): the coupler point's speed (finite differences of its path) drops to ~0 at each cusp
    phi_k = 3.522124, 11.899704, 20.277284 (docs/theory.md §K2.3) and is O(1) elsewhere."""
    s, df, _, _ = run_ok(tmp_path, "rolling-c-cusp")
    assert s["model"]["method"] == "closed-form"
    t = df["t_s"].to_numpy()
    speed = np.hypot(np.gradient(df["coupler_point_x_m"], t), np.gradient(df["coupler_point_y_m"], t))
    phi = df["rolling_angle_rad"].to_numpy()
    for phi_k in (3.522124, 11.899704, 20.277284):
        near = np.abs(phi - phi_k) <= 0.011
        assert speed[near].min() <= 0.02
    assert np.median(speed) > 0.3


def test_line_scenario(tmp_path):
    """Set D, disc on the line y = -2: the contact stays on the line, moving -r dphi along it."""
    s, df, _, _ = run_ok(tmp_path, "rolling-d-line")
    assert s["model"]["method"] == "closed-form"
    np.testing.assert_allclose(df["contact_y_m"], -2.0, atol=1e-12)
    np.testing.assert_allclose(df["contact_x_m"], -6.0 - df["rolling_angle_rad"], atol=1e-12)


def test_crank_torque_dead_points(tmp_path):
    s, df, ev, r = run_ok(tmp_path, "rolling-crank-torque")
    assert s["model"]["method"] == "dae" and s["success"]
    assert list(ev["kind"]) == ["dead point", "dead point"]
    assert all("dead point of the crank input" in w for w in s["warnings"]) and r.stderr == ""
    np.testing.assert_allclose(df["transmission_crank"].iloc[0], 0.5425, atol=1e-4)


def test_prescribed_crank_speed_dead_point_exits_3(tmp_path):
    out = tmp_path / "crank-speed"
    r = invoke("run", "rolling-crank-torque", "--out", out, "--quiet", "--set", "output.plots=false",
               "--set", "drive.type=speed", "--set", "drive.speed=1 rad/s", "--set", "initial.drive_speed=1 rad/s")
    assert r.exit_code == 3, r.output
    assert "dead point" in r.stderr and "prescribed crank speed" in r.stderr
    summary = json.loads((out / "summary.json").read_text())
    assert summary["success"] is False and summary["events"] == {"dead point": 1}
    assert 0.6 < pd.read_csv(out / "timeseries.csv")["t_s"].iloc[-1] < 0.65


USER_ERRORS = [
    ("thermal model", "rolling-a-torque", ["thermal.model=flash"], "thermal.model"),
    ("speed past a stretched dyad", "rolling-b-components",
     ["drive.type=speed", "drive.speed=1 rad/s", "duration=4 s"], "drive.speed"),
    ("dyad cannot close", "rolling-a-torque", ["mechanism.crank_length=0.5 m"], "initial.drive_angle"),
    ("circle without radius", "rolling-d-line", ["mechanism.profile=circle", "mechanism.line_point=[\"0 m\", \"0 m\"]",
                                                 "mechanism.line_angle=0 deg"], "mechanism.fixed_radius"),
    ("a line's key on a circle", "rolling-d-line", ["mechanism.profile=circle", "mechanism.fixed_radius=2 m",
                                                     "mechanism.line_angle=10 deg"], "mechanism.line_angle"),
    # switching the profile drops the file's line keys: what the circle still needs is named
    ("switched to a circle", "rolling-d-line", ["mechanism.profile=circle"], "mechanism.fixed_radius"),
    ("bad branch", "rolling-a-torque", ["mechanism.branch=2"], "mechanism.branch"),
    ("bad driven link", "rolling-a-torque", ["mechanism.driven_link=coupler"], "mechanism.driven_link"),
    ("crank cannot assemble", "rolling-crank-torque", ["mechanism.crank_length=20 m"], "initial.drive_angle"),
]


@pytest.mark.parametrize("label,name,sets,field", USER_ERRORS, ids=[u[0] for u in USER_ERRORS])
def test_user_errors_exit_2_with_one_line(tmp_path, label, name, sets, field):
    args = [a for s in sets for a in ("--set", s)]
    r = invoke("run", name, "--out", tmp_path / "out", "--quiet", *args)
    assert r.exit_code == 2, r.output
    assert field in one_line_error(r)
    assert not (tmp_path / "out").exists()


def test_curves_set_a(tmp_path):
    """Set A: bicursal (two closed monochromatic components), crunodes 4 on branch +1 and 2 on branch -1 with
    4 of them induced by the trochoid's 2 (docs/theory.md §K2.4)."""
    out = tmp_path / "A"
    r = invoke("curves", "A", "--out", out)
    assert r.exit_code == 0, r.output
    for name in ("components", "closure", "nonclosure", "curve", "trochoid", "cusps", "crunodes",
                 "trochoid_crunodes"):
        assert (out / f"{name}.csv").is_file(), name
    assert (out / "atlas.png").is_file()
    comps = pd.read_csv(out / "components.csv")
    assert list(comps["kind"]) == ["monochromatic", "monochromatic"] and comps["closed"].all()
    cr = pd.read_csv(out / "crunodes.csv")
    assert (cr["branch_1"] == 1).sum() == 4 and (cr["branch_1"] == -1).sum() == 2 and cr["induced"].sum() == 4
    assert len(pd.read_csv(out / "trochoid_crunodes.csv")) == 2
    r = invoke("curves", "A", "--out", out)
    assert r.exit_code == 2 and "--force" in one_line_error(r)


def test_curves_from_scenarios(tmp_path):
    """A built-in scenario (set D on a line, with its atlas span) and a scenario file (set B): closure intervals of
    docs/theory.md §K2.2."""
    r = invoke("curves", "rolling-d-line", "--out", tmp_path / "d")
    assert r.exit_code == 0, r.output
    cl = pd.read_csv(tmp_path / "d" / "closure.csv")
    np.testing.assert_allclose(cl[["rolling_angle_start_rad", "rolling_angle_end_rad"]].to_numpy(),
                               [[-12.878132, -6.739964], [-6.245489, -0.082021]], atol=1e-6)
    assert len(pd.read_csv(tmp_path / "d" / "cusps.csv")) == 4   # phi = -10.124778, -3.841593 on both branches
    from mechsim.scenarios.loader import builtin_text
    path = tmp_path / "b.toml"
    path.write_text(builtin_text("rolling-b-components"))
    r = invoke("curves", path, "--out", tmp_path / "b")
    assert r.exit_code == 0, r.output
    comps = pd.read_csv(tmp_path / "b" / "components.csv")
    assert list(comps["kind"]) == ["dichromatic"] * 4
    np.testing.assert_allclose(comps["rolling_angle_end_rad"], [5.781935, 11.498952, 17.022659, 22.773735],
                               atol=1e-6)


@pytest.mark.parametrize("name,field", [("no-such-set", "curves"), ("geneva-lc1", "mechanism.type")])
def test_curves_user_errors(tmp_path, name, field):
    r = invoke("curves", name, "--out", tmp_path / "x")
    assert r.exit_code == 2 and field in one_line_error(r)
