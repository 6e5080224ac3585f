"""Sweep definitions: list/range/log SPECs with units, grid and zip sizes, sweep files, one-line errors."""
import numpy as np
import pytest
import tomli_w

from mechsim.scenarios.studies.sweep.spec import SweepSpec, build_spec, parse_vary, read_sweep_file
from mechsim.scenarios.units import ScenarioError


def test_list_with_one_unit_applies_it_to_every_item():
    a = parse_vary("load.wheel_torque=5,7,14 N*m")
    assert a.key == "load.wheel_torque" and a.values == ("5 N*m", "7 N*m", "14 N*m")
    assert a.override(2) == 'load.wheel_torque="14 N*m"'
    assert parse_vary("load.wheel_torque=5 N*m, 7 N*m").values == ("5 N*m", "7 N*m")


def test_list_of_numbers_words_and_booleans():
    assert parse_vary("contact.friction=0.1, 0.2").values == (0.1, 0.2)
    assert parse_vary("solver.method=dae,closed-form").values == ("dae", "closed-form")
    assert parse_vary("solver.events=true,false").values == (True, False)
    assert parse_vary("mechanism.slots=3,4,6").override(0) == "mechanism.slots=3"


def test_range_is_inclusive_linspace_with_optional_unit():
    a = parse_vary("contact.friction=0.1:0.4:7")
    assert a.kind == "range"
    np.testing.assert_allclose(a.values, np.linspace(0.1, 0.4, 7), rtol=1e-12)
    assert parse_vary("load.wheel_torque=0:10:3 N*m").values == ("0 N*m", "5 N*m", "10 N*m")
    assert parse_vary("mechanism.slots=3:6:4").values == (3, 4, 5, 6)   # integer ends, integer points
    assert parse_vary("contact.friction=0.2:0.2:1").values == (0.2,)
    assert parse_vary("mechanism.crank_radius=60mm:90mm:4").values == ("60 mm", "70 mm", "80 mm", "90 mm")
    assert parse_vary("drive.speed=log:1 rad/s:100 rad/s:3").values == ("1 rad/s", "10 rad/s", "100 rad/s")


def test_log_range_is_geometric():
    a = parse_vary("solver.rtol=log:1e-3:1e-1:5")
    assert a.kind == "log"
    np.testing.assert_allclose(a.values, [1e-3, 10 ** -2.5, 1e-2, 10 ** -1.5, 1e-1], rtol=1e-11)
    b = parse_vary("drive.speed=log:1:100:3 rad/s")
    assert b.values == ("1 rad/s", "10 rad/s", "100 rad/s")


@pytest.mark.parametrize("text, fragment", [
    ("contact.friction", "expected section.key=SPEC"),
    ("contact.friction=", "empty SPEC"),
    ("contact.friction=0.1:0.4", "as a range"),
    ("contact.friction=0.1:0.4:x", "whole number"),
    ("contact.friction=0.1:0.4:0", "at least 1"),
    ("solver.rtol=log:0:1:3", "positive ends"),
    ("load.wheel_torque=5 N*m,7", "unit once"),
    ("mechanism.crank_radius=60 mm:0.09 m:4", "same on both ends"),
    ("mechanism.crank_radius=60 mm:90:4", "same on both ends"),
    ("contact.friction=0.1,,0.2", "empty item"),
    (".friction=0.1", "section.key"),
])
def test_bad_specs_name_the_option(text, fragment):
    with pytest.raises(ScenarioError) as info:
        parse_vary(text)
    assert fragment in str(info.value) and "\n" not in str(info.value)


def test_grid_and_zip_sizes_and_order():
    axes = (parse_vary("contact.friction=0.1,0.2,0.3"), parse_vary("load.wheel_torque=5,7 N*m"))
    grid = SweepSpec("geneva-lc1", axes)
    assert len(grid) == 6 and len(grid.case_overrides()) == 6
    assert grid.case_overrides()[1] == ["contact.friction=0.1", 'load.wheel_torque="7 N*m"']   # last axis fastest
    with pytest.raises(ScenarioError, match="equal lengths"):
        SweepSpec("geneva-lc1", axes, mode="zip")
    zipped = SweepSpec("geneva-lc1", (axes[0], parse_vary("load.wheel_torque=5,7,9 N*m")), mode="zip",
                       base=("duration=0.5 s",))
    assert len(zipped) == 3
    assert zipped.case_overrides()[2] == ["duration=0.5 s", "contact.friction=0.3", 'load.wheel_torque="9 N*m"']


def test_duplicate_and_conflicting_keys_are_refused():
    a = parse_vary("contact.friction=0.1,0.2")
    with pytest.raises(ScenarioError, match="varied twice"):
        SweepSpec("geneva-lc1", (a, a))
    with pytest.raises(ScenarioError, match="also fixed by --set"):
        SweepSpec("geneva-lc1", (a,), base=("contact.friction=0.3",))
    with pytest.raises(ScenarioError, match="nothing to sweep"):
        SweepSpec("geneva-lc1", ())


def test_sweep_file_round_trips_its_own_definition(tmp_path):
    path = tmp_path / "s.toml"
    path.write_text("""
[sweep]
scenario = "geneva-lc1"
mode = "zip"
[sweep.set]
duration = "0.5 s"
solver.method = "dae"
[sweep.vary]
contact.friction = "0.1:0.2:2"
"load.wheel_torque" = ["5 N*m", "7 N*m"]
""")
    spec = build_spec(str(path), ["drive.speed=5,6 rad/s"], [], False)
    assert spec.mode == "zip" and spec.keys == ["contact.friction", "load.wheel_torque", "drive.speed"]
    assert spec.base == ('duration="0.5 s"', 'solver.method="dae"')
    again = tmp_path / "again.toml"
    again.write_text(tomli_w.dumps(spec.describe()))
    scenario, mode, base, axes = read_sweep_file(again)
    assert (scenario, mode, base) == ("geneva-lc1", "zip", list(spec.base))
    assert [a.values for a in axes] == [a.values for a in spec.axes]


def test_sweep_file_errors(tmp_path):
    path = tmp_path / "s.toml"
    path.write_text(tomli_w.dumps({"sweep": {"scenario": "geneva-lc1", "grid": True}}))
    with pytest.raises(ScenarioError, match="sweep.grid: unknown key"):
        read_sweep_file(path)
    path.write_text(tomli_w.dumps({"sweep": {"vary": {"contact.friction": "0.1,0.2"}}}))
    with pytest.raises(ScenarioError, match="sweep.scenario: missing"):
        read_sweep_file(path)
