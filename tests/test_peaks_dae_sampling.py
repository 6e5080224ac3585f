"""A DAE run's columns are sampled between its rows at a fixed drive-angle step before their candidates are ranked
(`peaks._rows_finest`, `TrajectoryReader.sampler`): its states interpolated between the rows (cubic Hermite on the
integrator's own y and y'), or its dense output where it keeps one (docs/theory.md §K5). Every located value is
still read by re-integration (or the dense output), so the samples only decide which peak is refined.

- geneva-torque, the start-up's contact-force minimum: each engagement of the start-up dips (-79.33 N in one,
  -79.836 N in the last), about 8 ms wide. At 2.3 ms rows the parabola through the three rows around the deeper dip
  underestimated it, the bound left it out, and -79.33 N (the other engagement's) was reported: 0.6 % off.
- chain-mech2-detuned, the coupler force's maximum: 0.15 % low at 23 ms rows.

Both runs' located values carry the re-integration's error from different rows' states (the run's rtol 1e-7, at a
tenth of it): measured 1.3e-7 of the column's largest magnitude between 1, 0.37 and 2.3 ms rows for geneva-torque,
3e-11 for the chain. 1e-6 is the margin, far below the errors this closes.
"""
import functools

import numpy as np
import pytest

import mechsim
from mechsim.dynamics.trajectory_reader import TrajectoryReader
from mechsim.scenarios import runner
from mechsim.scenarios.peaks import DAE_STEP_RAD, HOW_DAE, HOW_DAE_SAMPLED, _rows_finest


@functools.cache
def _peaks(name, step=None):
    """(located peaks, table) of the scenario at output_step `step` (None: its own), run once for the module: the
    reference runs are read by several tests (only read, never changed)."""
    sets = ["output.plots=false"] + ([f'output_step="{step}"'] if step is not None else [])
    r = mechsim.run(mechsim.load(name, set=sets))
    assert r.success
    return r.summary["peaks"], r.timeseries


def _scale(peaks, column):
    return max(abs(peaks[column]["max"]["value"]), abs(peaks[column]["min"]["value"]))


@pytest.mark.parametrize("step", ["2.3 ms", "0.37 ms"])
def test_the_start_up_contact_force_minimum_at_any_step(step):
    own, _ = _peaks("geneva-torque", "1 ms")
    other, _ = _peaks("geneva-torque", step)
    want, got = own["contact_force_N"]["startup"]["min"], other["contact_force_N"]["startup"]["min"]
    assert got["value"] == pytest.approx(want["value"], abs=1e-6 * _scale(own, "contact_force_N"))
    assert got["t_s"] == pytest.approx(want["t_s"], abs=1e-5)
    assert other["contact_force_N"]["how"] == HOW_DAE_SAMPLED
    if step == "2.3 ms":      # what the start-up's rows alone show: the other engagement's dip, 0.5 N above
        assert got["best_row_value"] > want["value"] + 0.4


@pytest.mark.parametrize("step", ["23 ms", "73 ms"])
def test_the_chains_coupler_force_maximum_at_coarse_rows(step):
    """At 73 ms rows the coupler force's maximum (0.324261 N, a spike about 1.5 degrees of drive wide) fell between
    samples 1 degree apart and another cycle's peak, 1.4e-3 lower, was reported; the samples are 0.5 degree apart,
    as a closed form's."""
    own, _ = _peaks("chain-mech2-detuned", "10 ms")
    other, _ = _peaks("chain-mech2-detuned", step)
    for name in ("max", "min"):
        assert other["coupler_force_N"][name]["value"] == pytest.approx(
            own["coupler_force_N"][name]["value"], abs=1e-6 * _scale(own, "coupler_force_N"))


def test_rows_closer_than_the_step_are_not_sampled():
    """Rows at most DAE_STEP_RAD of drive angle apart: no samples (the located peaks as before, at no cost); wider
    gaps: the spacing that keeps the angle that far apart at the rows' pace there."""
    t = np.linspace(0.0, 1.0, 11)
    assert _rows_finest(t, 0.9 * DAE_STEP_RAD * np.arange(11)) is None
    angles = np.r_[0.0, np.cumsum([0.5, 3.0, 0.5, 0.5, 0.5, 0.5, 0.5, 0.5, 0.5, 0.5])] * DAE_STEP_RAD
    spacing = _rows_finest(t, angles)
    gaps = spacing(t)
    assert gaps[1] == pytest.approx(0.1 / 3.0)
    assert gaps[0] == pytest.approx(0.2)
    _, table = _peaks("geneva-motor", "1 ms")      # 0.34 deg a row at most: the located peaks not sampled
    assert _rows_finest(table["t_s"].to_numpy(), table["crank_angle_rad"].to_numpy()) is None
    assert mechsim.run(mechsim.load("geneva-motor", set=["output.plots=false", "duration=1 s"])).summary[
        "peaks"]["contact_force_N"]["how"] == HOW_DAE


def test_a_gap_is_sampled_at_the_drive_speed_its_ends_show():
    """Two rows at one angle a second apart, the drive turning at 2 rad/s at either end (a swing out and back in
    between): the net turn says nothing, the speed at the ends gives the spacing DAE_STEP_RAD / 2 rad/s; where the
    ends are slower than the net turn, the net turn's pace stands."""
    t = np.array([0.0, 1.0, 2.0])
    spacing = _rows_finest(t, np.array([0.0, 0.0, 1.0]), np.array([2.0, -2.0, 0.5]))
    gaps = spacing(t)
    assert gaps[0] == pytest.approx(DAE_STEP_RAD / 2.0)
    assert gaps[1] == pytest.approx(DAE_STEP_RAD / 2.0)       # the faster end (|-2|) over the net turn (1 rad/s)
    assert _rows_finest(t, np.array([0.0, 0.0, 0.0]), None) is None
    slow = _rows_finest(t, np.array([0.0, 0.5, 1.0]), np.array([0.1, 0.1, 0.1]))
    assert slow(t)[0] == pytest.approx(DAE_STEP_RAD / 0.5)


def test_interpolated_states_are_the_rows_at_the_rows_and_near_the_solution_between():
    """The sampler at a row's instant reads that row's own state (the cubic Hermite's end), and between rows at
    2.3 ms agrees with a run at 0.1 ms rows to the interpolant's error, h^4 |y''''| / 384 (about 1e-4 of the
    contact force's scale at this step; measured 9e-5); away from the events, where the rows of the fine run
    straddle no event."""
    plan = runner.plan(mechsim.load("geneva-torque", set=["output.plots=false", 'output_step="2.3 ms"']))
    df, events, *_, traj = runner._mechanics(plan, plan.scenario.si["duration"], None, None)
    sampler = TrajectoryReader(traj, plan.mechanism.angle_coordinates, plan.settings).sampler()
    t = df["t_s"].to_numpy()
    inner = t[(t > 0.01) & (t < t[-1] - 0.01)]
    inner = inner[np.min(np.abs(inner[:, None] - events["t_s"].to_numpy()[None, :]), axis=1) > 1e-6]
    at_rows = np.asarray(sampler.read_at(inner, [])["contact_force_N"])
    rows = df.set_index("t_s").loc[inner, "contact_force_N"].to_numpy()
    scale = np.abs(df["contact_force_N"].to_numpy()).max()
    assert np.max(np.abs(at_rows - rows)) <= 1e-12 * scale
    fine = runner._mechanics(runner.plan(mechsim.load("geneva-torque", set=['output_step="0.1 ms"'])),
                             plan.scenario.si["duration"], None, None)[0]
    tf = fine["t_s"].to_numpy()
    ev = events["t_s"].to_numpy()
    far = np.min(np.abs(tf[:, None] - ev[None, :]), axis=1) > 3e-3
    got = np.asarray(sampler.read_at(tf[far], [])["contact_force_N"])
    assert np.max(np.abs(got - fine["contact_force_N"].to_numpy()[far])) <= 5e-4 * scale


@pytest.fixture(scope="module")
def lumped_runs():
    sets = ["output.plots=false", "thermal.model='lumped'", "contact.friction=0.15"]
    return {step: mechsim.run(mechsim.load("geneva-torque", set=sets + [f'output_step="{step}"']))
            for step in ("1 ms", "3.1 ms", "7.3 ms", "31 ms")}


def test_the_contact_temperature_maximum_at_coarse_rows(lumped_runs):
    """The thermal columns of a DAE run sampled as its mechanical ones (`ThermalReader.sampler`: the mechanics and
    the lumped temperatures, DAE states of the run, interpolated between its rows; the thermal formulas there).
    geneva-torque with friction 0.15 and lumped temperatures: the contact temperature's maximum, a flash a few ms
    wide in the run's last engagement, was 134.855 C at 3.1 ms rows against 134.985 C at 1 ms; now the same to
    3e-6 C (measured), within the re-integration's error."""
    own, other = (lumped_runs[s].summary["peaks"]["temp_contact_C"]["max"] for s in ("1 ms", "3.1 ms"))
    assert other["value"] == pytest.approx(own["value"], abs=1e-6 * abs(own["value"]))
    assert other["t_s"] == pytest.approx(own["t_s"], abs=1e-5)
    assert other["best_row_value"] < own["value"] - 0.5       # the rows at 3.1 ms miss the flash's top


@pytest.mark.parametrize("step", ["7.3 ms", "31 ms"])
def test_the_thermal_columns_where_a_contact_holds_no_row_and_a_gap_cannot_be_interpolated(lumped_runs, step):
    """The same run at 7.3 ms rows stopped with a traceback (a contact episode between two rows: the thermal
    sampler asked for a row to start from inside it); at 31 ms the interpolated mechanics ranked another flash first
    and put the contact temperature's maximum at 134.855 C (1e-3 low). The sampler now reads such an episode from
    the states around it, and re-integrates a gap the interpolation cannot be trusted in, as the mechanical
    columns' (`_RowInterpolation.gap_errors`): every thermal maximum as at 1 ms rows, to the re-integration's error
    (measured 4e-8 of the value; 1e-6 is the margin)."""
    own, other = lumped_runs["1 ms"].summary["peaks"], lumped_runs[step].summary["peaks"]
    assert lumped_runs[step].success
    for column in ("temp_contact_C", "temp_flash_rise_K", "temp_bulk_pin_C", "temp_bulk_wheel_C"):
        want = own[column]["max"]["value"]
        assert other[column]["max"]["value"] == pytest.approx(want, abs=1e-6 * abs(want)), column


@pytest.mark.parametrize("step", ["73 ms", "0.5 s"])
def test_far_apart_rows_are_re_integrated_where_the_interpolation_cannot_rank(step):
    """rolling-a-torque (rtol 1e-10): the crank reverses within ~30 ms at 3.06 s, where the contact force peaks at
    798.04 N and the coupler force at 1322.7 N. Rows 73 ms or 0.5 s apart put that reversal inside one gap, where
    the cubic Hermite through the rows' states is off by far more than the integration's error, and the samples
    ranked it below other stretches: 667 N and 929 N were reported at 80 ms rows; the crank speed's maximum,
    11.6385 rad/s, was 9.93 rad/s at 73 ms. Such a gap (`_RowInterpolation.gap_errors` above TRUSTED_RAD) is
    re-integrated: every column's maximum and minimum as at 10 ms rows, to the re-integration's error from rows that
    far apart (measured 1e-8 of each column's scale; 1e-6 is the margin), and never below the rows' own (the run's end,
    a row, read again from the row 73 ms before it: 3e-9 of the crank speed's scale apart)."""
    ref, _ = _peaks("rolling-a-torque", "10 ms")
    got, df = _peaks("rolling-a-torque", step)
    assert got["contact_force_N"]["how"] == HOW_DAE_SAMPLED
    for column, entry in ref.items():
        if not isinstance(entry.get("max"), dict) or entry["max"].get("value") is None:
            continue
        for name, sense in (("max", 1.0), ("min", -1.0)):
            want, have = entry[name]["value"], got[column][name]["value"]
            assert have == pytest.approx(want, abs=1e-6 * _scale(ref, column)), (column, name)
            assert sense * (have - df[column].agg(name)) >= -1e-6 * _scale(ref, column), (column, name)


def test_the_interpolations_error_estimate_is_the_cubics_error():
    """`gap_errors` on a known solution, q = sin(w t) held h apart with v and a exact: the estimate is at least the
    cubic Hermite's true error at mid-gap, less the quintic's own remainder (h^6 q^(6)/46080 against h^4 q^(4)/384:
    a relative (h w)^2/120), at most that plus the integrated v's error, and scales as h^4."""
    from types import SimpleNamespace

    from mechsim.dynamics.trajectory_reader import _RowInterpolation

    w, largest = 7.0, {}
    for h in (0.02, 0.04):
        t = np.arange(0.0, 1.0, h)
        y = np.stack([np.sin(w * t), w * np.cos(w * t)], axis=1)
        yp = np.stack([w * np.cos(w * t), -w * w * np.sin(w * t)], axis=1)
        sampler = object.__new__(_RowInterpolation)
        sampler.t, sampler.y, sampler.yp = t, y, yp
        sampler.reader = SimpleNamespace(traj=SimpleNamespace(model=SimpleNamespace(coordinates=("q",))),
                                         angle_coordinates=(0,))         # an angle: the error in its radians
        j = np.arange(len(t) - 1)
        got = sampler.gap_errors(j)
        mid = t[j] + h / 2
        cubic = (y[j, 0] + y[j + 1, 0]) / 2 + h * (yp[j, 0] - yp[j + 1, 0]) / 8
        true = np.abs(np.sin(w * mid) - cubic)
        bound = h ** 4 * w ** 4 / 384
        remainder = 2 * (h * w) ** 2 / 120 * bound           # the quintic's, twice over
        assert np.all(got >= true - remainder), h
        # the other estimate, the integrated v's h^5 q^(5)/720, leads where q^(4) vanishes
        assert np.all(got <= true + h ** 5 * w ** 5 / 720 + remainder), h
        largest[h] = np.max(got)
    assert largest[0.04] / largest[0.02] == pytest.approx(16.0, rel=0.05)


def test_a_swing_between_rows_at_nearly_one_angle_is_sampled():
    """rolling-b-components' crank rocks between dead points; its speed peaks (4.1466 rad/s) 8 ms after the dead point
    at 1.8988 s. At 0.75 s rows the gap from that event to the next row showed little net turning, so few samples
    were placed there, and the limit at the dead point (4.0855 rad/s) was reported. The samples' pace is now the
    faster of the net turn and the drive's speed at either end of a gap: the peak as at 10 ms rows, to the
    re-integration's error (1e-6 of the scale is the margin)."""
    own, _ = _peaks("rolling-b-components", "10 ms")
    other, _ = _peaks("rolling-b-components", "0.75 s")
    for name in ("max", "min"):
        assert other["crank_speed_rad_s"][name]["value"] == pytest.approx(
            own["crank_speed_rad_s"][name]["value"], abs=1e-6 * _scale(own, "crank_speed_rad_s"))
        assert other["crank_speed_rad_s"][name]["t_s"] == pytest.approx(own["crank_speed_rad_s"][name]["t_s"],
                                                                         abs=1e-6)


def test_the_thermal_validity_between_far_apart_rows(lumped_runs):
    """The Hertz band's condition on the same run, read on the thermal reader: at 31 ms rows many engagements hold
    no row, and without samples between the rows it applied 0.157 of the run against 0.2708 at 1 ms. The thermal
    reader's samples join the rows as the mechanical ones do: the same share and worst value to the crossings' and
    the extremum's location (measured 1e-9 and 3e-8 relative; 1e-7 is the margin)."""
    def band(step):
        return next(c for c in lumped_runs[step].summary["validity"]["conditions"] if c["name"] == "hertz_half_width")
    own, other = band("1 ms"), band("31 ms")
    assert other["applies_share"] == pytest.approx(own["applies_share"], rel=1e-7)
    assert other["worst"]["value"] == pytest.approx(own["worst"]["value"], rel=1e-7)


@pytest.mark.parametrize("step", ["0.7 s", "1.3 s", "2.3 s", "10 s"])
def test_an_unbounded_approach_between_far_apart_rows(step):
    """chain-mech1-torque's coupler force grows like 1/distance toward each stop impact (exponent 1.000). At its own
    10 ms rows the maximum is unbounded toward the first, at 3.15176 s. Rows 0.7-2.3 s apart leave no two rows
    between a stop and the event before it, and the growth was judged on the rows only: the stops' one-sided
    limits, values of round-off at a pole, were reported, a maximum of +2.4e7 N and a minimum of -2.4e10 N. The
    growth is now judged on the rows with the samples between them (the plan's table, without its rows at the
    events themselves): the maximum is unbounded toward the same stop at every step. The minimum was then a stop's
    limit from the same side, no value either: it is the best of that table without those limits (the coupler
    carries nothing in the dwell: 0 N). At 10 s rows (three a run) no row lies in a dwell, and the rows alone gave
    0.0213 N; the readings between them hold the dwell's 0."""
    own = _peaks("chain-mech1-torque")[0]
    got = _peaks("chain-mech1-torque", step)[0]["coupler_force_N"]
    first = own["coupler_force_N"]["max"]
    assert first["value"] is None and got["max"]["value"] is None
    assert got["max"]["t_s"] == pytest.approx(first["t_s"], abs=1e-9)
    assert got["max"]["growth_exponent"] == pytest.approx(1.0, abs=1e-2)
    assert abs(got["min"]["value"]) <= 1e-9


@pytest.fixture(scope="module")
def internal_motor_own():
    return _peaks("internal-geneva-motor", "1 ms")[0]["temp_contact_C"]


@pytest.mark.parametrize("step", ["0.68 s", "1.6667 s"])
def test_the_contact_temperature_between_rows_a_turn_apart(internal_motor_own, step):
    """internal-geneva-motor's contact temperature is defined in contact only (NaN between engagements). At 0.68 s
    rows most engagements hold no row: the thermal reader refused to read a smooth stretch without a row of its own,
    so the located maximum fell back to a sample 1.1 ms before the exit (32.6914 against 32.7328 C). At 1.6667 s
    rows (three a run) no row holds a value at all, and the column had no entry. The reader now starts such a
    stretch from the state the run's segment started from, as the mechanics' reader does; the maximum is the limit
    at an exit, the minimum at a slip reversal, as at 1 ms rows. Readings from other starting states carry the
    run's own error (rtol 1e-7; measured 7.5e-10 of the value): 1e-7 is the margin."""
    got = _peaks("internal-geneva-motor", step)[0]["temp_contact_C"]
    for name in ("max", "min"):
        assert got[name]["value"] == pytest.approx(internal_motor_own[name]["value"], rel=1e-7)
        assert got[name]["t_s"] == pytest.approx(internal_motor_own[name]["t_s"], abs=1e-6)


def test_a_stalled_tighter_try_is_not_repeated_from_the_same_start(capfd, monkeypatch):
    """rolling-a-torque on scikit-sundae's IDA (`ida`) at 3.3 s rows: the readings between the rows start from the
    few states the run holds, and the tighter try (a tenth of the run's tolerances, TIGHT_STEPS a step) stalls at
    the event the mode ends at. Every reading from that start reaching as far stalled again, each after its whole
    step budget: 80 failures at five instants, 4.7 s of CPU. A start's stall is kept (`TrajectoryReader._stalls`):
    each failure now happens once, and the readings that would have stalled are taken at the run's own tolerances,
    as they were after each stall. The binding's error handler printed each failure on the user's stdout; a tighter
    try's, which falls back, is no longer printed. The located peaks are its own 10 ms rows' to 1e-5 of each
    column's scale (the readings' tolerance, from starts seconds apart)."""
    from sksundae import ida
    failures, solve = [], ida.IDA.solve

    def counted(self, *args, **kwargs):
        sol = solve(self, *args, **kwargs)
        if not sol.success:             # where it stalled (the binding's printed "At t = ...")
            failures.append(float(np.asarray(sol.t)[-1]) if len(sol.t) else None)
        return sol
    monkeypatch.setattr(ida.IDA, "solve", counted)
    sets = ['solver.backend="ida"']
    capfd.readouterr()
    coarse = mechsim.run(mechsim.load("rolling-a-torque", set=["output.plots=false", 'output_step="3.3 s"', *sets]))
    assert "[IDASolve" not in capfd.readouterr().out
    assert failures and len(failures) == len(set(failures))
    own = mechsim.run(mechsim.load("rolling-a-torque", set=["output.plots=false", *sets])).summary["peaks"]
    for column, entry in own.items():
        for name in ("max", "min"):
            want, got = entry[name]["value"], coarse.summary["peaks"][column][name]["value"]
            if want is None or not np.isfinite(want):
                continue
            assert got == pytest.approx(want, abs=1e-5 * _scale(own, column)), (column, name)


def test_a_reading_that_fails_at_the_runs_own_tolerances_prints_nothing(capfd, monkeypatch):
    """geneva-torque with the lumped thermal model at rtol 1e-12 on scikit-sundae's IDA (`ida`, the default until a
    model's compiled callbacks are cached), friction 0.15, E 0.025 % above the library's: readings that reach the
    exit at 0.3663 s fail at every try, the run's own tolerances too (the peaks then read from another start or the
    rows). The binding's error handler printed each such failure on the user's stdout ("[IDASolve, Error: -22] At t
    = 0.366316491708924, mxstep steps taken before reaching tout.", four lines from one mechsim.run); the
    failure is the reading's ReadingFailed, and nothing is printed."""
    from mechsim.dynamics.extrema import ReadingFailed
    failed, integrate = [], TrajectoryReader._integrate

    def recorded(self, *args, **kwargs):
        try:
            return integrate(self, *args, **kwargs)
        except ReadingFailed as exc:
            failed.append(str(exc))
            raise
    monkeypatch.setattr(TrajectoryReader, "_integrate", recorded)
    capfd.readouterr()
    r = mechsim.run(mechsim.load("geneva-torque", set=[
        "output.plots=false", "thermal.model=lumped", "thermal.averaging=resolved", "duration=0.5 s",
        "output_step=0.1 ms", "contact.friction=0.15", "solver.rtol=1e-12", "solver.atol=1e-14",
        'solver.backend="ida"', f"thermal.E={207e9 * (1 + 2.5e-4)!r} Pa"]))
    out = capfd.readouterr().out
    assert r.success and failed, failed
    assert "IDASolve" not in out, out


def test_the_contact_temperatures_derivatives_between_rows_a_turn_apart():
    """`mechsim sensitivity internal-geneva-motor` at 1.6667 s rows (three a run) exited 3: the traced thermal
    formulas are checked against the run's own on the row in contact nearest the located peak, and no row is in
    contact there, so the row checked was a dwell's (no contact temperature: NaN against NaN). A run whose rows
    hold no contact is checked on none (the same formulas are checked on every run that has one). The located
    contact temperatures and their derivatives are its own 1 ms rows' to the run's error (the derivatives measured
    4e-9 and 2.7e-7 relative apart; 1e-5 is the margin)."""
    from mechsim.scenarios.studies.sensitivity import sensitivity
    wrt, of = ["contact.friction"], ["peak_temp_contact_C", "peak_temp_flash_rise_K"]
    tables = [sensitivity(mechsim.load("internal-geneva-motor", set=["output.plots=false", *sets]), wrt, of)
              .set_index("quantity") for sets in ([], ['output_step="1.6667 s"'])]
    own, coarse = tables
    for q in of:
        assert coarse.loc[q, "value"] == pytest.approx(own.loc[q, "value"], rel=1e-7), q
        assert coarse.loc[q, "derivative"] == pytest.approx(own.loc[q, "derivative"], rel=1e-5), q
