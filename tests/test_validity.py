"""Validity monitors (scenarios/validity.py, docs/theory.md "Validity"): the conditions each model declares, read
on every output row. The rolling pair's reference runs leave theirs (the contact pulls, the friction demanded is
far beyond any coefficient), the Geneva's stay valid; summary, console and report.html say so, and
`output.on_invalid = "stop"` ends the run at the first violating row with exit 3, the table up to it written."""
import json

import numpy as np
import pandas as pd
import pytest
from cli_helpers import invoke

from mechsim.scenarios.loader import load
from mechsim.scenarios.runner import run

NO_PLOTS = ["output.plots=false"]
trapezoid = getattr(np, "trapezoid", None) or np.trapz


def _share(t, mask):
    """Share of the run's time where mask holds, the indicator integrated by the trapezoidal rule on the rows."""
    return float(trapezoid(mask.astype(float), t) / (t[-1] - t[0]))


def _condition(summary, name):
    return next(c for c in summary["validity"]["conditions"] if c["name"] == name)


@pytest.fixture(scope="module")
def rolling_a():
    return run(load("rolling-a-torque", NO_PLOTS))


def test_rolling_a_torque_pulls_on_its_contact_and_needs_impossible_friction(rolling_a):
    """The numbers located on the continuous solution (`validity.located`): the contact's worst pull is the
    extremum of the normal force, at or below the rows' least and equal to the located peak; it starts pulling where N crosses zero (N read there
    is zero to round-off of its scale); the share of time it pulls counts each crossing's instant, so it lies within
    half an output step a crossing of the rows' trapezoidal share; the friction demand |F_t|/|N| has a pole where N
    passes zero: unbounded, not the largest row's value."""
    df, s = rolling_a.timeseries, rolling_a.summary
    t, N, demand = (df[c].to_numpy(float) for c in ("t_s", "contact_force_N", "friction_demand"))
    assert not s["validity"]["valid"]
    assert {"contact_in_compression", "rolling_without_slip"} <= set(s["validity"]["violated"])
    tension = _condition(s, "contact_in_compression")
    assert tension["how"] == "located"
    crossings = int(np.count_nonzero((N[1:] < 0) != (N[:-1] < 0)))
    step = float(np.diff(t).max())
    assert tension["violated_share"] == pytest.approx(_share(t, N < 0), abs=crossings * step / (t[-1] - t[0]))
    assert 0.4 < tension["violated_share"] < 0.5                   # the contact pulls on about 46 % of the run
    assert tension["worst"]["value"] <= N.min() < -200
    # the same extremum as the summary's located peak of the column, found by the peaks' own search
    assert tension["worst"]["value"] == pytest.approx(s["peaks"]["contact_force_N"]["min"]["value"], rel=1e-9)
    first_row = t[np.argmax(N < 0)]
    assert first_row - step < tension["first_violation_t_s"] <= first_row
    assert abs(tension["first_violation_value"]) <= 1e-9 * np.abs(N).max()
    slip = _condition(s, "rolling_without_slip")
    assert slip["bound"] == 0.3                                      # contact.friction's default
    np.testing.assert_allclose(demand, np.abs(df["traction_force_N"]) / np.abs(N), rtol=1e-12)
    assert slip["worst"]["unbounded"] and slip["worst"]["value"] is None and demand.max() > 200
    assert slip["violated_share"] == pytest.approx(_share(t, demand > 0.3), abs=0.01)


def test_the_located_validity_does_not_move_with_the_output_step():
    """rolling-crank-torque (a crank-driven rolling pair, a DAE): every evaluated number the same at 0.37 and 2.3 ms
    rows, to the readings' tolerance; on the rows before, the dead-point distance's worst was 1.8e-5 and 5.5e-4
    (its true least 0: the transmission passes zero), the shares 3e-4 apart, the first violations a row's time."""
    runs = [run(load("rolling-crank-torque", NO_PLOTS + [f"output_step='{step}'"])).summary["validity"]
            for step in ("0.37 ms", "2.3 ms")]
    for a, b in zip(*(r["conditions"] for r in runs)):
        assert a["how"] == b["how"] == "located"
        assert a["violated_share"] == pytest.approx(b["violated_share"], abs=1e-9)
        if a["first_violation_t_s"] is not None:
            assert a["first_violation_t_s"] == pytest.approx(b["first_violation_t_s"], abs=1e-9)
        scale = max(abs(a["bound"]), 1.0)
        assert a["worst"]["value"] == pytest.approx(b["worst"]["value"], abs=1e-9 * scale)
    dead = next(c for c in runs[0]["conditions"] if c["name"] == "dead_point_distance")
    assert dead["worst"]["value"] < 1e-9


def test_rolling_crank_torque_is_in_tension_throughout():
    result = run(load("rolling-crank-torque", NO_PLOTS))
    N = result.timeseries["contact_force_N"].to_numpy(float)
    tension = _condition(result.summary, "contact_in_compression")
    assert N.max() < 0 and tension["violated_share"] == 1.0
    assert "rolling_without_slip" in result.summary["validity"]["violated"]


def test_stop_keeps_the_run_up_to_its_first_violation():
    """A Geneva pin of 0.05 mm: the Hertz band outgrows 0.1 R mid-engagement (b/R peaks at 0.113). With
    on_invalid = 'stop' the run is the full run's table up to and including the first violating row, its
    failure code model_invalid, its events and warnings those until then."""
    base = NO_PLOTS + ["duration='1.5 s'", "mechanism.pin_radius='0.05 mm'"]
    full = run(load("geneva-lc1", base))
    assert full.summary["validity"]["violated"] == ["hertz_half_width"]
    t_v = _condition(full.summary, "hertz_half_width")["first_violation_t_s"]      # located between rows
    stopped = run(load("geneva-lc1", base + ["output.on_invalid='stop'"]))
    t_stop = stopped.failure.time                                                  # its first violating row
    assert stopped.failure.code.value == "model_invalid" and t_v <= t_stop
    assert t_stop - t_v < full.scenario["output_step"]                  # the row after the located crossing
    assert stopped.summary["failure_code"] == "model_invalid" and stopped.failure.mode == "engaged"
    expected = full.timeseries[full.timeseries["t_s"] <= t_stop].reset_index(drop=True)
    assert len(expected) > 100 and stopped.timeseries["t_s"].iloc[-1] == t_stop
    pd.testing.assert_frame_equal(stopped.timeseries, expected)
    ratio = stopped.timeseries["hertz_half_width_m"].to_numpy(float) / 0.05e-3
    assert ratio[-1] > 0.1 >= np.nanmax(ratio[:-1])
    assert (stopped.events["t_s"] <= t_stop).all() and len(stopped.events) == (full.events["t_s"] <= t_stop).sum()


def test_console_and_report_show_the_violations(tmp_path):
    out = tmp_path / "run"
    result = invoke("run", "rolling-a-torque", "--out", out, "--set", "output.plots=false")
    assert result.exit_code == 0, result.output
    lines = [line for line in result.stderr.splitlines() if "leaves its validity" in line]
    assert [line.split(" violated ")[0] for line in lines] == [
        "warning: the model leaves its validity: contact_in_compression",
        "warning: the model leaves its validity: rolling_without_slip"]
    assert "45.6 % of the time" in lines[0] and "unbounded near t = " in lines[1]
    page = (out / "report.html").read_text()
    section = page[page.index("<h2>Validity</h2>"):page.index("<h2>Energy")]
    for name in ("contact_in_compression", "rolling_without_slip"):
        assert f"<td>{name}</td><td>VIOLATED</td>" in section
    assert "<td>dead_point_distance</td><td>holds</td>" in section
    assert json.loads((out / "summary.json").read_text())["validity"]["valid"] is False


@pytest.mark.parametrize("name", ["rolling-a-torque", "rolling-crank-torque"])
def test_on_invalid_stop_exits_3_with_the_results_written(tmp_path, name):
    out = tmp_path / "run"
    result = invoke("run", name, "--out", out, "--set", "output.plots=false", "--set", "output.on_invalid=stop")
    assert result.exit_code == 3, result.output
    last = result.stderr.strip().splitlines()[-1]
    assert last.startswith("failed: stopped at t = 0 s") and "the model leaves its validity" in last
    summary = json.loads((out / "summary.json").read_text())
    assert summary["failure_code"] == "model_invalid" and not summary["success"]
    table = pd.read_parquet(out / "timeseries.parquet")
    assert len(table) >= 1 and table["t_s"].iloc[-1] <= 0.0
    assert (out / "report.html").exists() and (out / "events.csv").exists()


def test_geneva_stays_valid_its_hertz_band_narrow_against_the_pin():
    result = run(load("geneva-lc1", NO_PLOTS + ["duration='1.5 s'", "output.on_invalid='stop'"]))
    assert result.success and result.summary["validity"] == {**result.summary["validity"], "valid": True,
                                                              "violated": []}
    band = _condition(result.summary, "hertz_half_width")
    df, m = result.timeseries, result.scenario["mechanism"]
    R, length, E_star = m["pin_radius"], m["thickness"], 113.74e9      # steel on steel (docs/theory.md §G3)
    b = np.sqrt(4 * df["contact_force_N"].abs().to_numpy(float) * R / (np.pi * length * E_star))   # Hertz
    assert band["worst"]["value"] == pytest.approx(b.max() / R, rel=1e-4) and band["worst"]["value"] < 0.1
    assert band["violated_share"] == 0.0 and 0 < band["applies_share"] < 1      # evaluated in contact only


def test_the_seed_flash_formula_is_checked_against_its_peclet_range():
    """thermal.flash = 'seed-blok' (seed S(13)) holds for 0.1 < L < 5, L = b omega1 r/(2 chi) as the seed evaluates
    it: load case 1 stays inside. At constant crank speed L grows as b, i.e. as sqrt(N): the seed's 0.583 at
    93.33 N (docs/theory.md §G7 row 11, U = 0.4005 m/s) scales to the run's extremes of the contact force."""
    result = run(load("geneva-lc1", NO_PLOTS + ["duration='1.5 s'", "thermal.flash='seed-blok'"]))
    low, high = (_condition(result.summary, n) for n in ("flash_peclet_low", "flash_peclet_high"))
    assert result.summary["validity"]["valid"]
    N = result.timeseries["contact_force_N"].abs().to_numpy(float)
    N = N[N > 0]
    peak = result.summary["peaks"]["contact_force_N"]["max"]["value"]         # located, as the worst L is
    assert high["worst"]["value"] == pytest.approx(0.583 * np.sqrt(peak / 93.33), rel=1e-3)
    # the least L located where a contact starts or ends, below the rows' least (0.15 % here)
    assert low["worst"]["value"] <= 0.583 * np.sqrt(N.min() / 93.33) * (1 + 1e-3)
    assert 0.1 < low["worst"]["value"] < high["worst"]["value"] < 5


@pytest.mark.parametrize("step", ["1 ms", "2.3 ms"])
def test_a_pole_is_unbounded_at_any_output_step(step):
    """rolling-a-torque's friction demand |F_t|/|N| has a pole where N passes zero: unbounded at any output step
    (on the rows it read 9574, 3777 and 812 at 0.37, 1 and 2.3 ms), its instant where N crosses zero."""
    r = run(load("rolling-a-torque", NO_PLOTS + [f"output_step='{step}'"]))
    worst = _condition(r.summary, "rolling_without_slip")["worst"]
    assert worst["unbounded"] and worst["value"] is None
    t, N = (r.timeseries[c].to_numpy(float) for c in ("t_s", "contact_force_N"))
    # N there is zero: within the linear interpolation's reach of the rows around it (a row step of N's change)
    j = int(np.searchsorted(t, worst["t_s"]))
    assert N[j - 1] * N[j] <= 0 or abs(np.interp(worst["t_s"], t, N)) <= abs(N[j] - N[j - 1])


def test_the_thermal_conditions_are_located_too():
    """The thermal model's conditions (the Hertz band, the seed's Peclet range) are read between rows as its columns
    are (`peaks.thermal_point_reader`, the thermal reader of the located peaks): each worst value the same at 1, 2.3
    and 10 ms rows to 1e-9 (on the rows: 0.05 %, 0.08 % and 0.5 % below the located at 10 ms), the band's the Hertz
    width at the located peak of the contact force, b growing as sqrt(N) (thermal/hertz.py `half_width`)."""
    got = {}
    for step in ("1 ms", "2.3 ms", "10 ms"):
        r = run(load("geneva-seed-lc3-mu030", NO_PLOTS + ["thermal.flash='seed-blok'", f"output_step='{step}'",
                                                          "duration='1.5 s'"]))
        rows = r.summary["validity"]["conditions"]
        assert [c["how"] for c in rows] == ["located"] * 3
        got[step] = {c["name"]: c["worst"]["value"] for c in rows}
        df, R = r.timeseries, r.scenario["mechanism"]["pin_radius"]
        N, b = df["contact_force_N"].abs().to_numpy(float), df["hertz_half_width_m"].to_numpy(float)
        i = int(np.nanargmax(N))
        peak = r.summary["peaks"]["contact_force_N"]["max"]["value"]
        assert got[step]["hertz_half_width"] == pytest.approx(b[i] * np.sqrt(peak / N[i]) / R, rel=1e-9)
        assert got[step]["hertz_half_width"] >= np.nanmax(b) / R
    for step in ("2.3 ms", "10 ms"):
        for name, value in got["1 ms"].items():
            assert got[step][name] == pytest.approx(value, rel=1e-9), (step, name)


def test_violations_narrower_than_a_row_count_at_any_output_step():
    """A Geneva pin of 0.06338 mm: the Hertz band exceeds 0.1 R by 3e-5 of it at each engagement's force peak, for
    about 1.4 ms, so most output steps put no row inside one. Each such dip between rows that hold is located
    (the worst's and every other row minimum's that may reach the bound), and a crossing next to an event is
    searched in each smooth interval between the rows: the violated share and the first violation the same at 1,
    2.3, 3.7 and 7.3 ms rows to 1e-9 (before: a share of 3, 2, 1 and 6 such dips' time, whichever rows fell inside)."""
    got = []
    for step in ("1 ms", "2.3 ms", "3.7 ms", "7.3 ms"):
        r = run(load("geneva-lc1", NO_PLOTS + ["duration='3 s'", "mechanism.pin_radius='0.06338 mm'",
                                                f"output_step='{step}'"]))
        band = _condition(r.summary, "hertz_half_width")
        assert band["how"] == "located" and 0.1 < band["worst"]["value"] < 0.1 * (1 + 1e-4)
        got.append((band["violated_share"], band["first_violation_t_s"]))
    assert _condition(r.summary, "hertz_half_width").get("violated_between_rows")
    for share, first in got[1:]:
        assert share == pytest.approx(got[0][0], abs=1e-9) and first == pytest.approx(got[0][1], abs=1e-9)
    assert got[0][0] > 0


@pytest.mark.parametrize("case", ["a violation inside holding", "a return to holding inside a violation"])
def test_a_crossing_pair_narrower_than_a_row_is_located_against_the_closed_form(case):
    """q(t) = c + s 0.1003 exp(-((t - 0.4137 s) / 5 ms)^2) against q <= 0.9, read exactly between rows (a closed form):
    with c = 0.8, s = 1 the condition is violated for 2 w sqrt(ln 1.003) = 0.547 ms around the peak, with c = 1,
    s = -1 it holds for that long inside a violation; no row falls inside that stretch at any of these output steps,
    while the rows show the peak's approach. The violated share is the closed form's (0.547 ms of the 1 s run, or
    all of it but those) to 1e-9 at 1, 2.3, 3.7 and 7.3 ms rows; before the return to holding was located, its share
    was 1 (every row violates)."""
    from mechsim.mechanisms.base import ValidityCondition
    from mechsim.scenarios import validity
    centre, width, height, bound = 0.4137, 5e-3, 0.1003, 0.9
    base, sign = (0.8, 1.0) if case.startswith("a violation") else (1.0, -1.0)

    def q(columns):
        return base + sign * height * np.exp(-((np.asarray(columns["t_s"], float) - centre) / width) ** 2)

    condition = ValidityCondition("q", "a closed form", q, bound, "max", "", "closed form", ("t_s",))
    stretch = 2 * width * np.sqrt(np.log(height / (bound - 0.8)))       # where q crosses 0.9 (either case)
    exact = stretch if sign > 0 else 1.0 - stretch
    for step in (1e-3, 2.3e-3, 3.7e-3, 7.3e-3):
        t = np.r_[np.arange(0.0, 1.0, step), 1.0]
        inside = np.abs(t - centre) < 0.5 * stretch
        assert not inside.any()             # no row sees it
        section = validity.evaluate([condition], {"t_s": t})
        validity.located(section, [condition], {"t_s": t},
                         (lambda grids, groups=True: [{"t_s": np.asarray(g, float)} for g in grids],
                          np.array([0.0, 1.0])), {"t_s"})
        row = section["conditions"][0]
        assert row["how"] == "located"
        assert row["violated_share"] == pytest.approx(exact, abs=1e-9), step
        assert row.get("violated_between_rows" if sign > 0 else "held_between_rows")
        if sign > 0:
            assert row["worst"]["value"] == pytest.approx(0.8 + height, rel=1e-12)
            assert row["first_violation_t_s"] == pytest.approx(centre - 0.5 * stretch, abs=1e-9)


def test_a_sign_change_between_rows_finds_a_return_to_holding_no_row_hints_at():
    """|x| <= 0.05 with x(t) = tanh((t - 0.4137 s) / 0.1 ms): every row violates (|x| = 1 to round-off), the condition
    holds for 2 w atanh(0.05) = 10 us around the zero of x, and the rows show no sign of it but x's sign, which
    changes between two rows (`ValidityCondition.signed`, as the rolling pair's friction demand declares its
    traction): the violated share is the closed form's to 1e-9 at four output steps; without `signed` it is 1."""
    from mechsim.mechanisms.base import ValidityCondition
    from mechsim.scenarios import validity
    centre, width, bound = 0.4137, 1e-4, 0.05

    def x(columns):
        return np.tanh((np.asarray(columns["t_s"], float) - centre) / width)

    def magnitude(columns):
        return np.abs(x(columns))

    exact = 1.0 - 2 * width * np.arctanh(bound)
    for signed in (x, None):
        condition = ValidityCondition("x", "a closed form", magnitude, bound, "max", "", "closed form", ("t_s",),
                                      signed)
        for step in (1e-3, 2.3e-3, 3.7e-3, 7.3e-3):
            t = np.r_[np.arange(0.0, 1.0, step), 1.0]
            section = validity.evaluate([condition], {"t_s": t})
            validity.located(section, [condition], {"t_s": t},
                             (lambda grids, groups=True: [{"t_s": np.asarray(g, float)} for g in grids],
                              np.array([0.0, 1.0])), {"t_s"})
            row = section["conditions"][0]
            assert row["violated_rows"] == len(t)
            if signed is None:
                assert row["violated_share"] == 1.0
            else:
                assert row["violated_share"] == pytest.approx(exact, abs=1e-9), step
                assert row["held_between_rows"]


def test_a_violation_across_an_event_between_rows_counts_on_both_sides():
    """|t - t_e| / tau >= 0.5 with an event at t_e = 0.4137 s (a dead point: the quantity's least, zero, is the event's
    one-sided limit) and tau = 1 ms: violated for tau around the event, between two rows that hold at these output
    steps. The stretch after the event is searched in the next smooth interval: the share is tau / 1 s to 1e-9 (before,
    the half before the event alone: rolling-b-components' dead points at 7 ms rows, 5.0e-4 against 1.0e-3)."""
    from mechsim.mechanisms.base import ValidityCondition
    from mechsim.scenarios import validity
    event, tau = 0.4137, 1e-3

    def distance(columns):
        return np.abs(np.asarray(columns["t_s"], float) - event) / tau

    condition = ValidityCondition("d", "a closed form", distance, 0.5, "min", "", "closed form", ("t_s",))
    for step in (1.7e-3, 2.9e-3, 3.7e-3, 7.3e-3):
        t = np.r_[np.arange(0.0, 1.0, step), 1.0]
        section = validity.evaluate([condition], {"t_s": t})
        assert section["conditions"][0]["violated_rows"] == 0
        validity.located(section, [condition], {"t_s": t},
                         (lambda grids, groups=True: [{"t_s": np.asarray(g, float)} for g in grids],
                          np.array([0.0, event, 1.0])), {"t_s"})
        row = section["conditions"][0]
        assert row["violated_share"] == pytest.approx(tau, abs=1e-9), step
        assert row["first_violation_t_s"] == pytest.approx(event - 0.5 * tau, abs=1e-9)


def test_where_a_condition_starts_and_stops_applying_is_located_at_the_events():
    """A condition that applies on two contacts only (NaN elsewhere), each begun and ended by an event: [0.3, 0.6] s
    with q = 100 (t - 0.3) + 0.05 >= 0.1, violated from the contact's start for 0.5 ms, and [0.7003, 0.7008] s, a
    contact no row falls in, with q = 0.01 + 100 (t - 0.7005)^2, violated throughout, its least 0.01 at 0.7005 s.
    The share it applies is 0.3005 and the violated share 0.001 of the 1 s run, to 1e-12, at five output steps (one of
    them with rows at the events themselves); the first violation is the first contact's start, q = 0.05 there, and
    the worst value the second contact's least. On the rows the applying share was within half a row of each event
    (0.2987 to 0.3066) and the second contact unseen."""
    from mechsim.mechanisms.base import ValidityCondition
    from mechsim.scenarios import validity

    def q(columns):
        t = np.asarray(columns["t_s"], float)
        return np.where((t >= 0.3) & (t <= 0.6), 100 * (t - 0.3) + 0.05,
                        np.where((t >= 0.7003) & (t <= 0.7008), 0.01 + 100 * (t - 0.7005) ** 2, np.nan))

    condition = ValidityCondition("q", "a closed form", q, 0.1, "min", "", "closed form", ("t_s",))
    ends = np.array([0.0, 0.3, 0.6, 0.7003, 0.7008, 1.0])
    for step in (1e-3, 1.7e-3, 2.9e-3, 3.7e-3, 7.3e-3):
        t = np.r_[np.arange(0.0, 1.0, step), 1.0]
        section = validity.evaluate([condition], {"t_s": t})
        validity.located(section, [condition], {"t_s": t},
                         (lambda grids, groups=True: [{"t_s": np.asarray(g, float)} for g in grids], ends), {"t_s"})
        row = section["conditions"][0]
        assert row["applies_share"] == pytest.approx(0.3005, abs=1e-12), step
        assert row["violated_share"] == pytest.approx(0.001, abs=1e-12), step
        assert row["first_violation_t_s"] == pytest.approx(0.3, abs=1e-12)
        assert row["first_violation_value"] == pytest.approx(0.05, rel=1e-9)
        assert row["worst"]["value"] == pytest.approx(0.01, rel=1e-9)
        assert row["worst"]["t_s"] == pytest.approx(0.7005, abs=1e-9)


def test_the_samples_between_far_apart_rows_find_what_the_rows_do_not_show():
    """rolling-a-torque's contact pulls for 24 ms at 3.013 s inside a stretch where it presses: at 31 ms rows no row
    shows it (nor a row minimum near it), and the violated share was 0.461858 against 0.4564866 at 10 ms rows. The
    run's states sampled between its rows (0.5 degree of drive angle, as its located peaks sample them) show it, and it
    is searched as any dip: the shares equal to 1e-9 at 10 and 31 ms rows."""
    shares = {}
    for step in ("10 ms", "31 ms"):
        r = run(load("rolling-a-torque", NO_PLOTS + [f"output_step='{step}'"]))
        shares[step] = {c["name"]: c["violated_share"] for c in r.summary["validity"]["conditions"]}
    for name, share in shares["10 ms"].items():
        assert shares["31 ms"][name] == pytest.approx(share, abs=1e-9), name


@pytest.mark.parametrize("step", ["50 ms", "0.31 s"])
def test_every_excursion_between_far_apart_rows_is_counted(rolling_a, step):
    """rolling-a-torque's friction demand leaves its bound and returns several times within one 50 ms gap (a 0.4 ms
    return to holding at 3.5542 s inside a violation that ends at 3.5924 s), and its contact pulls more than once
    within a 0.31 s gap. One excursion a gap was searched: the rolling-without-slip share was 9.5e-5 off at 50 ms
    rows; at 0.31 s the contact's share 1.3e-2 off and its worst pull -156.1 N against -205.58 N. The samples
    between rows (0.5 degree of drive angle) now join the rows, so that each excursion they show is searched as
    one between rows: the shares as at 10 ms rows to the crossings' location (measured 3e-10; 1e-8 is the margin)
    and the worst pull the located peak's."""
    r = run(load("rolling-a-torque", NO_PLOTS + [f"output_step='{step}'"]))
    for name in ("contact_in_compression", "rolling_without_slip", "dead_point_distance"):
        want, got = _condition(rolling_a.summary, name), _condition(r.summary, name)
        assert got["violated_share"] == pytest.approx(want["violated_share"], abs=1e-8), name
        assert got["applies_share"] == pytest.approx(want["applies_share"], abs=1e-8), name
    pull = _condition(r.summary, "contact_in_compression")["worst"]
    assert pull["value"] == pytest.approx(_condition(rolling_a.summary, "contact_in_compression")["worst"]["value"],
                                          rel=1e-6)


def test_a_closed_forms_thermal_condition_between_far_apart_rows():
    """geneva-seed-lc3-mu030 (a closed form with the seed's flash formula) at 0.155 s rows, 155 times its own: its
    Hertz band applied 0.1438 of the run against 0.2451, its worst 0.01270 against 0.01312 (a contact's force peak
    between rows). The thermal reader's samples (0.5 degree of drive angle) join the rows: both as at 1 ms rows
    (measured 1e-15 and 8e-10 relative; 1e-8 is the margin)."""
    def band(sets):
        return _condition(run(load("geneva-seed-lc3-mu030", NO_PLOTS + sets)).summary, "hertz_half_width")
    own, other = band([]), band(["output_step='0.155 s'"])
    assert other["applies_share"] == pytest.approx(own["applies_share"], rel=1e-8)
    assert other["worst"]["value"] == pytest.approx(own["worst"]["value"], rel=1e-8)
