"""The [thermal] section on the command line: bad input exits 2 with one line naming the field; a thermal run writes
its columns, the heat balance and (cycle-averaged) the bulk history."""
import json

import pandas as pd
import pytest
from cli_helpers import invoke, one_line_error


BAD = [
    ("unknown model", "thermal.model=2d", "thermal.model"),
    ("unknown flash", "thermal.flash=blok", "thermal.flash"),
    ("unknown distribution", "thermal.distribution=triangular", "thermal.distribution"),
    ("unknown material", "thermal.material=unobtanium", "thermal.material"),
    ("unknown key", "thermal.emissivity=0.3", "thermal.emissivity"),
    ("Poisson ratio", "thermal.nu=0.7", "thermal.nu"),
    ("negative conductivity", 'thermal.conductivity="-40 W/(m*K)"', "thermal.conductivity"),
    ("wrong unit", 'thermal.convection_pin="15 W/m^2"', "thermal.convection_pin"),
    ("missing unit", "thermal.density=7800", "thermal.density"),
    ("below absolute zero", 'thermal.ambient_temperature="-300 degC"', "thermal.ambient_temperature"),
    ("bad averaging", "thermal.averaging=sometimes", "thermal.averaging"),
    ("cycle with 1d", "thermal.model=1d --set thermal.averaging=cycle", "thermal.averaging"),
    ("growth below 1", "thermal.mesh_growth=0.9", "thermal.mesh_growth"),
    ("first cell over depth", 'thermal.model=1d --set thermal.mesh_first_cell="5 mm" --set thermal.mesh_depth="1 mm"',
     "thermal.mesh_first_cell"),
    ("a mesh without the 1-D model", 'thermal.mesh_depth="1 mm"', "thermal.mesh_depth"),
    ("a bulk key on the flash model", 'thermal.model=flash --set thermal.convection_pin="25 W/(m^2*K)"',
     "thermal.convection_pin"),
    ("crank volume alone", 'thermal.crank_volume="1 cm^3"', "thermal.crank_area"),
    ("direction", "thermal.mesh_direction=track", "thermal.mesh_direction"),
]


@pytest.mark.parametrize("label,setting,field", BAD, ids=[b[0] for b in BAD])
def test_bad_thermal_input_exits_2_with_one_line(tmp_path, label, setting, field):
    sets = []
    for part in setting.split(" --set "):
        sets += ["--set", part]
    r = invoke("run", "geneva-lc1", "--out", tmp_path / "out", "--quiet", *sets)
    assert r.exit_code == 2, r.output
    line = one_line_error(r)
    assert field in line
    assert not (tmp_path / "out").exists()


def test_mechanism_without_sliding_contact_accepts_only_none(tmp_path):
    r = invoke("run", "rolling-a-speed", "--out", tmp_path / "out", "--quiet", "--set", "thermal.model=lumped")
    assert r.exit_code == 2 and "thermal.model" in one_line_error(r)


def test_thermal_run_writes_columns_balance_and_history(tmp_path):
    # 90 s = 76 cycles of 1.18 s: over thermal.plan.AUTO_CYCLES (50), so 'auto' averages per cycle
    out, duration = tmp_path / "long", 90.0
    r = invoke("run", "geneva-seed-lc2-mu030", "--out", out, "--quiet", "--set", f"duration={duration} s",
               "--set", "output.plots=false")
    assert r.exit_code == 0, r.output
    summary = json.loads((out / "summary.json").read_text())
    th = summary["thermal"]
    assert th["model"] == "lumped" and th["averaging"] == "cycle" and "auto" in th["averaging_why"]
    assert abs(th["heat_balance"]["closure_error_relative"]) < 1e-9
    for col in ("temp_contact_C", "temp_flash_rise_K", "heat_rate_W", "temp_bulk_pin_C", "temp_bulk_wheel_C"):
        assert col in summary["peaks"]
        assert -180 <= summary["peaks"][col]["max"]["drive_angle_wrapped_deg"] <= 180
    df = pd.read_parquet(out / "timeseries.parquet")
    # the whole history, not the last turn: the continued rows are on the output grid, the last at the end
    # (docs/thermal.md, "Cycle averaging")
    import mechsim
    step = mechsim.load("geneva-seed-lc2-mu030").si["output_step"]
    assert df["t_s"].iloc[-1] == duration and len(df) == round(duration / step) + 1
    pd.testing.assert_frame_equal(df, pd.read_csv(out / "timeseries.csv"), check_dtype=False, check_exact=True)
    history = pd.read_csv(out / "thermal_history.csv")
    assert history["t_s"].iloc[-1] == pytest.approx(duration)
    # the cycle-mean bulk of a linear network heated from ambient by a constant mean heat rate rises monotonically
    # (its rate obeys the same Metzler system, starting from B q >= 0); the sampled bulk carries the per-cycle ripple
    assert history["heat_generated_J"].is_monotonic_increasing
    # (the mean curve is that of the continuation: NaN over the resolved start-up before it)
    mean = history["temp_bulk_wheel_mean_C"].dropna()
    assert mean.is_monotonic_increasing and mean.index[0] < 0.1 * len(history)
    assert mean.iloc[-1] > history["temp_bulk_wheel_C"].iloc[0] + 1.0
    # the resolved scenario (with its thermal section) is valid input again
    r2 = invoke("run", out / "scenario.toml", "--out", tmp_path / "again", "--quiet", "--set", "duration=0.5 s",
                "--set", "output.plots=false")
    assert r2.exit_code == 0, r2.output
