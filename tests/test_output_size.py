"""Output size: estimated before the run (an upper estimate, the rows exact), measured from the table before it is
written (the CSV to a few per cent), announced by the console above a threshold with a coarser output_step that
brings it under, and [output] csv = "auto" writing Parquet only there; the tables' writing is reported as it goes."""
import os

import pandas as pd
import pytest

import mechsim
from mechsim.scenarios.output import size
from cli_helpers import invoke, one_line_error

# closed form with the lumped thermal model: 38 columns, 30,001 rows (about 11 MB of CSV) in a second
BASE = ["duration=3 s", "output_step=0.1 ms"]


@pytest.fixture(scope="module")
def saved(tmp_path_factory):
    calls = []
    r = mechsim.run("geneva-lc1", set=BASE)
    out = r.save(tmp_path_factory.mktemp("size") / "run", plots=False, progress=lambda f, what: calls.append((f, what)))
    return r, out, calls


def test_the_estimate_before_the_run_bounds_the_files_and_the_measure_after_it_is_close(saved):
    r, out, _ = saved
    before = mechsim.output_size("geneva-lc1", set=BASE)
    csv, parquet = (os.path.getsize(out / f) for f in ("timeseries.csv", "timeseries.parquet"))
    assert before.rows == len(r.timeseries) == 30001 and not before.measured
    assert csv <= before.csv_bytes <= 2.5 * csv and parquet <= before.parquet_bytes <= 3 * parquet
    after = r.output_size()
    assert after.measured and after.columns == r.timeseries.shape[1]
    assert abs(after.csv_bytes - csv) <= 0.03 * csv            # an even sample of 500 rows, scaled
    assert after.parquet_bytes >= parquet


def test_writing_the_tables_reports_as_it_goes(saved):
    _, out, calls = saved
    fractions = [f for f, _ in calls]
    assert fractions[0] == 0.0 and fractions[-1] == 1.0 and fractions == sorted(fractions)
    what = [w for _, w in calls]
    assert what[-1] == "figures" and {"timeseries.parquet", "timeseries.csv"} <= set(what)
    # 30,001 rows x 38 columns in pieces of 500,000 values: three pieces each, the bar moves inside both files
    assert sum(w == "timeseries.csv" and 0 < f < 1 for f, w in calls) >= 3
    assert sum(w == "timeseries.parquet" and 0 < f < 1 for f, w in calls) >= 2
    back = mechsim.open(out)
    pd.testing.assert_frame_equal(back.timeseries, pd.read_csv(out / "timeseries.csv"), check_dtype=False)


def test_auto_writes_parquet_only_above_the_threshold_and_the_console_says_so(tmp_path, monkeypatch):
    monkeypatch.setattr(size, "LARGE_OUTPUT_BYTES", 4e6)        # 11 MB of CSV passes it
    sc = mechsim.load("geneva-lc1", set=BASE + ["output.csv='auto'"])
    est = mechsim.output_size(sc)
    assert est.large
    step = size.coarser_step(sc.si, est)
    coarser = mechsim.output_size("geneva-lc1", set=BASE[:1] + [f"output_step={step} s"])
    assert not coarser.large and step in (2e-4, 5e-4, 1e-3, 2e-3, 5e-3)
    r = mechsim.run(sc)
    out = r.save(tmp_path / "auto", plots=False)
    assert not (out / "timeseries.csv").exists() and (out / "timeseries.parquet").exists()
    pd.testing.assert_frame_equal(mechsim.open(out).timeseries, r.timeseries)
    for setting, written in (("always", True), ("never", False)):
        r.scenario["output"]["csv"] = setting
        assert (r.save(tmp_path / setting, plots=False) / "timeseries.csv").exists() == written
    res = invoke("run", "geneva-lc1", *sum((["--set", s] for s in BASE + ["output.csv='auto'", "output.plots=false"]),
                                           []), "--out", tmp_path / "cli")
    assert res.exit_code == 0, res.output
    notes = [line for line in res.stderr.splitlines() if line.startswith("note:")]
    assert notes[0].startswith("note: a large output: 30,001 rows x about 40 columns")
    assert f"output_step = {step:g} s writes" in notes[0] and 'csv = "auto" leaves timeseries.csv out' in notes[0]
    assert notes[1].startswith("note: timeseries.csv not written") and "timeseries.parquet holds" in notes[1]
    assert not (tmp_path / "cli" / "timeseries.csv").exists()
    quiet = invoke("run", "geneva-lc1", *sum((["--set", s] for s in BASE + ["output.plots=false"]), []),
                   "--out", tmp_path / "quiet", "--quiet")
    assert quiet.exit_code == 0 and "note:" not in quiet.stderr


def test_a_small_run_says_nothing(tmp_path):
    res = invoke("run", "geneva-lc1", "--set", "duration=0.2 s", "--set", "output.plots=false", "--out", tmp_path / "o")
    assert res.exit_code == 0 and "note: a large output" not in res.stderr
    assert (tmp_path / "o" / "timeseries.csv").exists()


@pytest.mark.parametrize("value, problem", [("'yes'", "must be one of always, auto, never; got 'yes'"),
                                            ("true", "expected a string, got True")])
def test_a_bad_csv_setting_is_one_line_naming_the_field(value, problem, tmp_path):
    res = invoke("run", "geneva-lc1", "--set", f"output.csv={value}", "--out", tmp_path / "bad")
    assert res.exit_code == 2
    assert one_line_error(res) == f"error: output.csv: {problem}"
    with pytest.raises(mechsim.ScenarioError, match="output.csv"):
        mechsim.output_size("geneva-lc1", set=[f"output.csv={value}"])
