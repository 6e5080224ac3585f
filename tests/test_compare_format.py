"""`mechsim compare --format`: csv and json parse back to the same numbers at full precision; piped text keeps
every digit; the bounds scale with rtol relative to the column's peak."""
import io
import json

import numpy as np
import pandas as pd
import pytest
from typer.testing import CliRunner

import mechsim.scenarios.studies.compare as cmp
from mechsim.scenarios.cli import app


@pytest.fixture()
def table():
    t = np.linspace(0.0, 4.0, 41)
    ida = pd.DataFrame({"t_s": t, "mode": ["engaged"] * 41, "rolling_angle_rad": 8 * t, "crank_speed_rad_s": np.cos(t),
                        "contact_force_N": 10 + np.sin(t), "drive_torque_N_m": np.ones(41)})
    other = ida.copy()
    other["rolling_angle_rad"] += 1.5017542764894642e-07 * t / 4       # rolling-a-torque's IDA error: 1.5e-7 rad
    other["crank_speed_rad_s"] += 1.2345678901234567e-9
    table = cmp.column_table(ida, other, "rolling_angle_rad", rtol=1e-10)
    table.attrs.update(passed=bool(table["passed"].dropna().all()), scenario="synthetic", rtol=1e-10, atol=1e-12,
                       diffrax_solver="Tsit5", rows={"ida": 41, "diffrax": 41}, events={"ida": 0, "diffrax": 0},
                       event_time_max_diff_s=0.0, failures={}, solver={"ida": {}, "diffrax": {}})
    return table


def test_angle_bound_is_relative_to_the_peak_and_scales_with_rtol(table):
    row = table.set_index("column").loc["rolling_angle_rad"]
    assert row["max_abs_diff"] > 1e-7 and row["passed"]           # 1.5e-7 rad of 32 rad: 4.7e-9 relative
    assert row["tolerance"] == "rel <= 1e-07"
    assert cmp.tolerance_for("rolling_angle_rad", 1e-12).value == pytest.approx(1e-9)
    assert cmp.tolerance_for("contact_force_N", 1e-10).value == pytest.approx(1e-5)


def _invoke(monkeypatch, table, *args):
    monkeypatch.setattr(cmp, "compare", lambda *a, **k: table)
    return CliRunner().invoke(app, ["compare", "synthetic", "--backends", *args])


def test_csv_parses_with_pandas_at_full_precision(monkeypatch, table):
    r = _invoke(monkeypatch, table, "--format", "csv")
    assert r.exit_code == 0, r.output
    back = pd.read_csv(io.StringIO(r.stdout))
    assert list(back["column"]) == list(table["column"])
    np.testing.assert_array_equal(back["max_abs_diff"].to_numpy(), table["max_abs_diff"].to_numpy())
    assert "rows {" in r.stderr and "rows {" not in r.stdout       # the notes stay off the data


def test_json_holds_the_run_facts_and_every_row(monkeypatch, table):
    r = _invoke(monkeypatch, table, "--format", "json")
    assert r.exit_code == 0, r.output
    doc = json.loads(r.stdout)
    assert doc["passed"] is True and doc["scenario"] == "synthetic" and len(doc["columns"]) == len(table)
    speed = next(c for c in doc["columns"] if c["column"] == "crank_speed_rad_s")
    assert speed["max_abs_diff"] == table.set_index("column").loc["crank_speed_rad_s", "max_abs_diff"]


def test_piped_table_is_plain_text_with_every_digit(monkeypatch, table):
    r = _invoke(monkeypatch, table)
    assert r.exit_code == 0, r.output
    assert "…" not in r.stdout and "┃" not in r.stdout
    exact = table.set_index("column").loc["crank_speed_rad_s", "max_abs_diff"]
    line = next(line for line in r.stdout.splitlines() if line.startswith("crank_speed_rad_s"))
    assert float(line.split()[1]) == exact


def test_unknown_format_is_one_line(monkeypatch, table):
    r = _invoke(monkeypatch, table, "--format", "xml")
    assert r.exit_code == 2 and len(r.stderr.strip().splitlines()) == 1
