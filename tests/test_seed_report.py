"""`mechsim report seed --small`: the seed-as-printed columns reproduce docs/theory.md §G7 rows 7, 11, 12 and the §4.7
S(13) column, the corrected model reproduces the §4.7 table, mechsim's normal force is the wheel balance of §2,
and the conclusions written are those of the tables. Expected numbers: docs/theory.md (Part G)."""
import math

import numpy as np
import pandas as pd
import pytest
from typer.testing import CliRunner

from mechsim.scenarios.cli import app

# docs/theory.md §G0 / §1 / §2: seed geometry, wheel inertia, loads
R_CRANK, N_SLOTS, R_PIN, LENGTH, J2 = 0.075, 4, 0.004, 0.004, 1.5626e-3
LAM = math.sin(math.pi / N_SLOTS)
C = R_CRANK / LAM
ALPHA0 = math.pi / 2 - math.pi / N_SLOTS
CASES = {(lc, mu): f"geneva-seed-lc{lc}-mu{code}" for lc in (1, 2, 3) for mu, code in ((0.15, "015"), (0.3, "030"))}
TORQUE = {1: 7.0, 2: 14.0, 3: 7.0}
SPEED = {1: 5.34, 2: 5.34, 3: 10.68}
# docs/theory.md §G4.7 corrected-model table: phi, N, b (um), |u|, dT_flash (mu = 0.15; x2 at mu = 0.3), seed S(13) mu = 0.15
TABLE_47 = [(5, 103.1, 34.0, 0.375, 14.8, 3.4), (15, 127.7, 37.8, 0.352, 17.1, 5.9), (30, 186.2, 45.7, 0.233, 16.0, 6.7),
            (45, 225.3, 50.2, 0.073, 7.6, 0.0), (60, 174.5, 44.2, 0.334, 21.7, 6.7),
            (75, 123.9, 37.2, 0.412, 19.5, 5.9), (85, 101.4, 33.7, 0.422, 17.0, 3.4)]
FIGURES = ("normal_load", "half_width", "pressure", "peclet", "heat", "flash_rise", "contact_temperature",
           "conclusions")


@pytest.fixture(scope="module")
def report(tmp_path_factory):
    out = tmp_path_factory.mktemp("seed-report") / "report"
    result = CliRunner().invoke(app, ["report", "seed", "--small", "--out", str(out)])
    assert result.exit_code == 0, result.output
    return out


def table(report, lc, mu):
    return pd.read_csv(report / f"case_{CASES[(lc, mu)]}.csv")


def at(t, phi):
    rows = t.loc[np.isclose(t["phi_deg"], phi)]
    assert len(rows) == 1, phi
    return rows.iloc[0]


def test_outputs_and_user_errors(report):
    for name in CASES.values():
        assert (report / f"case_{name}.csv").is_file()
    for name in ("comparison.csv", "peak_location.csv", "speed_vs_torque.csv", "report.md"):
        assert (report / name).is_file(), name
    text = (report / "report.md").read_text()
    for stem in FIGURES:
        assert (report / f"{stem}.png").stat().st_size > 1000
        assert f"({stem}.png)" in text
    # an existing folder needs --force; an unknown report is a user error: one line, exit 2
    for args in (["report", "seed", "--small", "--out", str(report)], ["report", "nonsense", "--out", str(report)]):
        r = CliRunner().invoke(app, args)
        assert r.exit_code == 2
        lines = [line for line in r.stderr.splitlines() if line.strip()]
        assert len(lines) == 1 and lines[0].startswith("error: ")


def test_seed_as_printed_reproduces_rows_7_11_12_and_s13(report):
    for mu in (0.15, 0.3):
        t = table(report, 1, mu)
        # row 7: S(8) 66.00 N at phi = 30, 93.33 N at 45 (T = 7 N m)
        assert at(t, 30)["seed_normal_load_N"] == pytest.approx(66.00, abs=0.01)
        assert at(t, 45)["seed_normal_load_N"] == pytest.approx(93.33, abs=0.01)
        # row 11: Peclet with U = omega1 r and the Hertz (E*) half-width: 0.357 at 35 N, 0.583 at 93.33 N
        assert at(t, 45)["seed_peclet_pin"] == pytest.approx(0.583, rel=5e-3)
        first = t[t["phi_deg"] <= 45]
        assert np.interp(35.0, first["seed_normal_load_N"], first["seed_peclet_pin"]) == pytest.approx(0.357, rel=5e-3)
        np.testing.assert_allclose(t["seed_peclet_wheel"], t["seed_peclet_pin"])
        # §3: S(9) as printed (E' = 2E*) at 93.33 N: b 22.86 um, p 324.9 MPa; the seed's effective W/(pi b l) 229.8 MPa
        assert at(t, 45)["seed_half_width_printed_m"] == pytest.approx(22.86e-6, rel=1e-3)
        assert at(t, 45)["seed_pressure_max_printed_Pa"] == pytest.approx(324.9e6, rel=1e-3)
        assert at(t, 45)["seed_pressure_max_Pa"] == pytest.approx(229.8e6, rel=1e-3)
        # §4.7 column "seed S(13)": 3.4 / 5.9 / 6.7 / 0 K at mu = 0.15, doubled at 0.3
        scale = mu / 0.15
        for phi, *_, s13 in TABLE_47:
            assert at(t, phi)["seed_temp_flash_rise_K"] == pytest.approx(scale * s13, abs=0.051 * scale)
        # row 12: heat maximum 1/2 mu T omega1 at phi = 30 deg (5.607 W for mu = 0.3)
        i = int(t["seed_heat_rate_W"].idxmax())
        assert t.loc[i, "seed_heat_rate_W"] == pytest.approx(0.5 * mu * 7.0 * 5.34, rel=1e-6)
        assert t.loc[i, "phi_deg"] == pytest.approx(30.0)
        if mu == 0.3:
            assert t.loc[i, "seed_heat_rate_W"] == pytest.approx(5.607, rel=1e-3)
    # S(8) scales with the torque; S(13) ~ Q/U does not depend on the speed (Q and U = omega1 r both double)
    t1, t2, t3 = (table(report, lc, 0.15) for lc in (1, 2, 3))
    np.testing.assert_allclose(t2["seed_normal_load_N"], 2 * t1["seed_normal_load_N"], rtol=1e-9)
    np.testing.assert_allclose(t3["seed_temp_flash_rise_K"], t1["seed_temp_flash_rise_K"], rtol=1e-9)
    np.testing.assert_allclose(t2["seed_temp_flash_rise_K"], math.sqrt(2) * t1["seed_temp_flash_rise_K"], rtol=1e-9)


def test_corrected_model_reproduces_table_47(report):
    for mu in (0.15, 0.3):
        t = table(report, 1, mu)
        for phi, N, b, u, dT, _ in TABLE_47:
            r = at(t, phi)
            assert r["corrected_normal_load_N"] == pytest.approx(N, rel=0.15)
            assert r["corrected_half_width_m"] == pytest.approx(b * 1e-6, rel=0.15)
            assert abs(r["corrected_slip_speed_m_s"]) == pytest.approx(u, rel=0.15)
            assert r["corrected_temp_flash_rise_K"] == pytest.approx(dT * mu / 0.15, rel=0.15)
        # rows 8/9: N = T_L/x at the centre, 225.33 N; row 10: Hertz p0 714.0 MPa there
        assert at(t, 45)["corrected_normal_load_N"] == pytest.approx(225.33, abs=0.01)
        assert at(t, 45)["corrected_pressure_max_Pa"] == pytest.approx(714.0e6, rel=1e-3)
    c = pd.read_csv(report / "comparison.csv").set_index(["case", "model"])
    # row 18: heat per index 1.868 J (mu = 0.15); §4.7: the seed's S(8) model 0.49 J
    assert c.loc[(CASES[(1, 0.15)], "corrected"), "energy_per_index_J"] == pytest.approx(1.868, rel=5e-3)
    assert c.loc[(CASES[(1, 0.15)], "seed"), "energy_per_index_J"] == pytest.approx(0.49, rel=1e-2)


def test_mechsim_normal_force_is_the_wheel_balance(report):
    for (lc, mu), name in CASES.items():
        t = table(report, lc, mu)
        w1, T_L = SPEED[lc], TORQUE[lc]
        alpha = np.radians(t["phi_deg"].to_numpy()) - ALPHA0
        D = 1 - 2 * LAM * np.cos(alpha) + LAM**2
        # docs/theory.md §G1 closed forms for the columns the balance uses
        np.testing.assert_allclose(t["mechsim_pin_distance_m"], C * np.sqrt(D), rtol=1e-9)
        np.testing.assert_allclose(t["mechsim_wheel_accel_rad_s2"], -w1**2 * LAM * (1 - LAM**2) * np.sin(alpha) / D**2,
                                   rtol=1e-9, atol=1e-9)
        sigma = np.sign(t["mechsim_slip_speed_m_s"])
        N = (J2 * t["mechsim_wheel_accel_rad_s2"] + T_L) / (t["mechsim_pin_distance_m"] - sigma * mu * R_PIN)
        np.testing.assert_allclose(t["mechsim_normal_load_N"], N, rtol=1e-9)
        assert (t["mechsim_flank"] == 1).all()          # J2 alpha2 < T_L: no flank switch (§2)
        # heat = mu |N| |u|; the flash is not zero at mid-stroke (pin spin; §4.7: 7.6 K at mu = 0.15)
        np.testing.assert_allclose(t["mechsim_heat_rate_W"],
                                   mu * t["mechsim_normal_load_N"].abs() * t["mechsim_slip_speed_m_s"].abs(), rtol=1e-9)
        if lc == 1:
            assert at(t, 45)["mechsim_temp_flash_rise_K"] == pytest.approx(7.6 * mu / 0.15, rel=0.15)


def test_conclusions_agree_with_the_tables(report):
    c = pd.read_csv(report / "comparison.csv")
    s = pd.read_csv(report / "speed_vs_torque.csv")
    p = pd.read_csv(report / "peak_location.csv")
    for r in s.itertuples():
        sub = c[(c["model"] == r.model) & np.isclose(c["mu"], r.mu)].set_index("load_case")[r.metric]
        assert (r.lc1, r.lc2_double_torque, r.lc3_double_speed) == pytest.approx((sub[1], sub[2], sub[3]), rel=1e-7)
        assert r.ratio_lc3_lc2 == pytest.approx(sub[3] / sub[2], rel=1e-7)
        assert r.ratio_lc2_lc1 == pytest.approx(sub[2] / sub[1], rel=1e-7)
        assert r.speed_heats_more == (sub[3] > sub[2] * (1 + 1e-9))
    # the peak locations are the maxima of the case tables, and mechsim's lies in the outward half (§4.7)
    for r in p.itertuples():
        t = table(report, r.load_case, r.mu)
        col = t[f"{r.model}_temp_contact_C"]
        assert r.peak_contact_temp_C == pytest.approx(col.max(), rel=1e-7)
        if r.model in ("corrected", "mechsim"):
            assert r.phi_peak_contact_temp_deg == pytest.approx(t.loc[col.idxmax(), "phi_deg"])
            assert r.phi_peak_contact_temp_deg > 45 and r.stroke_half_peak_contact_temp.startswith("second half")
    # the seed's own S(13): LC3 = LC1 and LC3/LC2 = 1/sqrt(2), whatever mu
    seed = s[(s["model"] == "seed") & (s["metric"] == "peak_flash_rise_K")]
    np.testing.assert_allclose(seed["ratio_lc3_lc2"], 1 / math.sqrt(2), rtol=1e-9)
    # report.md states the answer the table gives
    mech = s[(s["model"] == "mechsim") & s["metric"].isin(["peak_flash_rise_K", "peak_contact_rise_K"])]
    text = (report / "report.md").read_text()
    if not mech["speed_heats_more"].any():
        assert "No: doubling the torque (LC2) heats more than doubling the speed (LC3)" in text
    ratios = mech[mech["metric"] == "peak_flash_rise_K"].sort_values("mu")
    assert f"×{'/'.join(f'{v:.3g}' for v in ratios['ratio_lc3_lc1'])} for 2× speed" in text


@pytest.mark.parametrize("gib, lc3_step", [(64, 1.0), (8, 3.0)])
def test_the_full_reports_runs_fit_the_machine(monkeypatch, gib, lc3_step):
    """Every run of `mechsim report seed` (full) passes the runner's memory bound: the hour's run of LC3 on the full
    report's 0.25 deg grid asked for 8.8 million rows (about 17 GiB by that bound) and was refused on most machines.
    The hour's rows are every 1 deg where the bound allows (LC1, LC2: 1.1 million rows, 2.1 GiB), else every 3 deg
    (LC3 on a machine with 8 GiB: 2.2 million rows, 4.2 GiB by the bound, would exceed its 4 GiB)."""
    from mechsim.benchmarks.seed_report import CASES, ReportConfig, _hour_run, _overrides, load_case
    from mechsim.scenarios import schema
    from mechsim.scenarios.loader import load
    monkeypatch.setattr(schema, "memory_budget", lambda: schema.MEMORY_SHARE * gib * 2**30)
    config = ReportConfig.make(small=False)
    for name in CASES:
        case = load_case(name)
        load(name, _overrides(case, config, False))             # a ScenarioError (exit 2) when refused
        step, scenario = _hour_run(case, config)
        assert step == (lc3_step if case.load_case == 3 else 1.0), name
        assert scenario.si["duration"] == 3600.0


def test_a_coarser_runs_rows_land_on_their_rows_of_a_finer_grid():
    """The hour's run (rows every 1 deg) on the full report's 0.25 deg grid: each of its rows on the grid row of its
    own angle, equal to the same instant of a run on the finer grid, and the rows between left empty."""
    from mechsim.benchmarks.seed_report import ReportConfig, _last_engagement, _overrides, load_case, phi_grid
    from mechsim.scenarios.loader import load
    from mechsim.scenarios.runner import run
    case = load_case("geneva-seed-lc1-mu015")
    phi = phi_grid(0.25)
    fine, coarse = (run(load(case.name, _overrides(case, ReportConfig(True, step, 0), False))).timeseries
                    for step in (0.25, 1.0))
    a, _ = _last_engagement(fine, case, phi, 0.25, "m")
    b, _ = _last_engagement(coarse, case, phi, 1.0, "m", 0.25)
    whole = np.isclose(phi, np.rint(phi), rtol=0, atol=1e-9)
    assert whole.sum() == 89 and list(a.columns) == list(b.columns)
    for col in a:
        x, y = a[col].to_numpy(float), b[col].to_numpy(float)
        if np.isnan(x).all():
            continue
        assert np.isnan(y[~whole]).all() and np.isfinite(y[whole]).all(), col
        np.testing.assert_allclose(y[whole], x[whole], rtol=1e-9, atol=1e-12 * np.nanmax(np.abs(x)), err_msg=col)
