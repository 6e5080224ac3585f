"""Kinematic history / dwell DataFrames (SI columns) and the plot helpers."""
import math
import re

import numpy as np
import pytest

import mechsim.mechanisms.chain.plots as chain_plots
from mechsim.mechanisms.chain.dwell import MECH1, MECH2, ChainDwellMechanism, dwell_table, kinematic_history, kinematics_table

UNIT = re.compile(r"^[A-Za-z0-9_]+_(s|rad|rad_s|rad_s2|m|m_s)$")


@pytest.fixture(scope="module")
def hist():
    return kinematic_history(MECH2, "leading", cycles=1.0, n=721)


def test_timeseries_columns_and_units(hist):
    ts, dw = hist
    for col in ts.columns:
        assert UNIT.match(col) or col in ("segment", "segment_name", "branch", "closes", "dwell"), col
    for col in ("t_s", "drive_angle_rad", "chain_travel_m", "crank_angle_rad", "crank_speed_rad_s",
                "crank_accel_rad_s2", "coupler_angle_rad", "segment", "branch"):
        assert col in ts.columns
    # SI: chain speed v = r1 omega1 = 3 cm/s, chain travel in metres
    assert np.allclose(ts["chain_speed_m_s"], 0.03)
    assert ts["chain_travel_m"].iloc[-1] == pytest.approx(0.4713383, abs=5e-8)
    assert ts["t_s"].equals(ts["drive_angle_rad"] / 1.0)
    assert ts["drive_angle_rad"].is_monotonic_increasing
    assert set(ts["segment_name"]) == {"line 1-2", "arc 2", "line 2-3", "arc 3", "line 3-4", "arc 4", "line 4-1",
                                       "arc 1"}
    # continuous crank angle: one full turn per chain cycle for the leading branch
    phi = ts["crank_angle_rad"].to_numpy()
    assert np.abs(np.diff(phi)).max() < 0.05
    assert phi[-1] - phi[0] == pytest.approx(2 * math.pi, abs=1e-9)


def test_event_rows_carry_one_sided_limits(hist):
    ts, _ = hist
    apex = ts[np.isclose(ts["drive_angle_rad"], math.radians(180.047447), atol=1e-8)]
    assert list(apex["crank_speed_rad_s"].round(12)) == [0.75, 0.0]
    exit_ = ts[np.isclose(ts["drive_angle_rad"], math.radians(225.047447), atol=1e-8)]
    assert exit_["crank_accel_rad_s2"].round(6).tolist() == [0.0, 0.848528]


def test_dwell_frame_and_flags(hist):
    ts, dw = hist
    assert len(dw) == 4
    assert dw["duration_drive_angle_rad"].to_numpy() == pytest.approx([math.pi / 4] * 4, abs=1e-12)
    assert np.degrees(dw["crank_angle_rad"]).tolist() == pytest.approx([90, 180, 270, 0], abs=1e-9)
    for col in ("start_drive_angle_rad", "end_drive_angle_rad", "duration_drive_angle_rad", "crank_angle_rad",
                "start_t_s", "end_t_s"):
        assert col in dw.columns
    ang = ts["drive_angle_rad"].to_numpy()
    for d in dw.itertuples():
        core = ts[(ang > d.start_drive_angle_rad + 1e-9) & (ang < d.end_drive_angle_rad - 1e-9)]
        assert len(core) > 5 and core["dwell"].all()
        assert np.abs(np.angle(np.exp(1j * (core["crank_angle_rad"] - d.crank_angle_rad)))).max() < 1e-12
        assert core["crank_speed_rad_s"].abs().max() < 1e-12
    cyc = ChainDwellMechanism(MECH2).cycle_angle
    bounds = np.concatenate([dw["start_drive_angle_rad"], dw["end_drive_angle_rad"]])
    dist = np.abs((ang[:, None] - bounds[None, :] + cyc / 2) % cyc - cyc / 2).min(axis=1)
    moving = ts[~ts["dwell"].to_numpy() & (dist > 1e-9)]
    assert (moving["crank_speed_rad_s"].abs() > 1e-6).all()   # no dwell outside the reported ones


def test_detuned_table_marks_non_closing_rows():
    m = ChainDwellMechanism(MECH1.detuned(-1e-4))
    ts = kinematics_table(m, "leading", n=2001)
    gap = ts[~ts["closes"]]
    assert len(gap) > 0 and gap["crank_angle_rad"].isna().all()
    assert ts.loc[ts["closes"], "crank_angle_rad"].notna().all()


def test_smooth_history_two_cycles():
    ts = kinematics_table(MECH1, "smooth", cycles=2, n=1201)
    assert set(ts["branch"]) == {"leading", "lagging"}
    dw = dwell_table(MECH1, "smooth", cycles=2)
    assert dw["sprocket"].tolist() == [3, 2, 1]


def test_plots_write_pngs(tmp_path, hist):
    ts, dw = hist
    lag = kinematics_table(MECH2, "lagging", n=361)
    tables = {"leading": ts, "lagging": lag}
    out = [chain_plots.plot_displacement(tables, tmp_path / "disp.png", dw),
           chain_plots.plot_velocity(tables, tmp_path / "vel.png", dw),
           chain_plots.plot_acceleration(ts, tmp_path / "acc.png"),
           chain_plots.plot_kinematics(tables, tmp_path / "kin.png", dw, title="Mech 2"),
           chain_plots.plot_mechanism(ChainDwellMechanism(MECH2), ts, tmp_path / "mech.png")]
    for p in out:
        assert p.exists() and p.read_bytes()[:8] == b"\x89PNG\r\n\x1a\n"
    with pytest.raises(ValueError, match="which must be one of"):
        chain_plots.plot_quantity(ts, tmp_path / "x.png", "jerk")


def test_window_not_starting_at_zero_is_consistent():
    m = ChainDwellMechanism(MECH1)
    th = np.linspace(math.radians(900), math.radians(1700), 801)
    ts = kinematics_table(m, "smooth", drive_angle=th)
    dw = dwell_table(m, "smooth", cycles=(th[-1] - th[0]) / m.cycle_angle, start_angle=th[0])
    # the second-cycle smooth dwells (docs/theory.md §K1.3): sprocket 2 [956.128274, 1046.128274], sprocket 1 from 1507.16
    assert np.degrees(dw["start_drive_angle_rad"]).tolist() == pytest.approx([956.128274, 1507.161653], abs=1e-6)
    for d in dw.itertuples():
        core = ts[(ts.drive_angle_rad > d.start_drive_angle_rad + 1e-9) & (ts.drive_angle_rad < d.end_drive_angle_rad - 1e-9)]
        assert core["dwell"].all() and core["crank_speed_rad_s"].abs().max() < 1e-12
