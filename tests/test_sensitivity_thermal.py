"""Sensitivities of the temperatures (docs/sensitivity.md, 'Temperatures'): the peak contact temperature, the peak
flash rise and the heat per index of a Geneva with the lumped thermal model, against central finite differences of
the IDA path (rtol 1e-12, Richardson-extrapolated, as tests/test_sensitivity.py; on IDA's compiled callbacks, which
cost one compilation of the model and then a fifth to a tenth of scikit-sundae's Python callbacks a run: the file
155 -> 109 s on a fresh cache), and three exact identities of the thermal model; the refusals of what is not
traced.

geneva-motor for 0.7 s (motor drive, friction 0.15: one engagement with a slip reversal) and geneva-torque with
friction 0.15 for 0.5 s (constant torque with crank damping, running up: two engagements with slip reversals). Both request the same quantities, so the compiled pass
(the model with its thermal states, the same for both drives) serves both cases. The cycle-averaged temperatures
(the seed's load case 1 with a motor, 60 s; last section) reuse it too.
"""
from __future__ import annotations

import dataclasses

import numpy as np
import pytest

import mechsim
from conftest import assert_matches_finite_differences, locating, richardson_central, run_locating
from mechsim.scenarios.units import ScenarioError
from mechsim.scenarios import runner
from mechsim.scenarios.studies.sensitivity import THERMAL_PEAKS, cycle_temperatures, cycle_window, sensitivity
from thermal_fd import assert_thermal_matches_fd, located_peak

THERMAL = ["thermal.model=lumped", "thermal.averaging=resolved"]
SENS = ["solver.rtol=1e-10", "solver.atol=1e-12"]
#: the finite differences' runs: IDA at rtol 1e-12 on the compiled callbacks (the same IDA algorithm as `ida`)
FD = ["solver.rtol=1e-12", "solver.atol=1e-14", 'solver.backend="ida-compiled"']
OF = list(THERMAL_PEAKS) + ["heat_per_index_J"]
H = 5e-4
#: an elasticity that is zero (a thermal value cannot move the heat per index; the convection barely moves a
#: temperature over one engagement: its elasticity is ~1e-6) is compared absolutely, as in test_sensitivity.py
ELASTICITY_FLOOR = 1e-6
#: name: (settings, values traced, values also checked by finite differences); the motor case traces three more
#: for the exact identities (test_exact_identities), which check them without re-running
CASES = {
    "geneva-motor": (["duration=0.7 s"],
                     ["load.wheel_torque", "contact.friction", "mechanism.crank_radius", "thermal.conductivity",
                      "thermal.convection_pin", "thermal.density", "thermal.specific_heat",
                      "thermal.ambient_temperature"], 5),
    # the output step is fine here because the finite differences read the heat per index by interpolating the
    # friction work between output rows (tests/test_sensitivity.py `_work_at`), and the friction power changes fast
    # near this run's exits: at 1 ms that reading's own derivative is off by 2e-3, at 0.1 ms by < 1e-6
    "geneva-torque": (["duration=0.5 s", "output_step=0.1 ms", "contact.friction=0.15"],
                      ["drive.torque", "mechanism.pin_radius", "mechanism.thickness", "thermal.E",
                       "mechanism.wheel_inertia", "initial.crank_speed", "thermal.convection_wheel"], 4),
}


def _run(name, sets):
    """The run the finite differences read: its thermal peaks located (`run_locating`: the mechanics' are not read).
    No segment is restarted after a failure: at rtol 1e-12 IDA's own first step after an entry is below the
    round-off of t (dynamics/backends/ida.py `resolving_first_step`)."""
    r = run_locating(mechsim.load(name, set=THERMAL + sets))
    assert r.failure is None, r.failure.message()
    assert r.summary["solver"]["recoveries"] == 0
    return r


@pytest.fixture(scope="module")
def tables():
    return {name: sensitivity(mechsim.load(name, set=THERMAL + sets + SENS), wrt, OF)
            for name, (sets, wrt, _) in CASES.items()}


@pytest.mark.parametrize("name", CASES)
def test_temperatures_match_finite_differences(tables, name):
    sets, wrt, checked = CASES[name]
    assert_thermal_matches_fd(tables[name], lambda extra: _run(name, sets + FD + extra), wrt[:checked], H,
                              ELASTICITY_FLOOR, name)


def test_exact_identities(tables):
    """(1) rho and c_p enter only as rho c_p: equal elasticities. (2) The flash rise is (Q/l) R_p R_w/(R_p + R_w),
    R_i = theta(L_i)/(2k) with L_i = U_i b/(2 chi), chi = k/(rho c_p) (docs/theory.md §G4.2-§G4.6): scaling k and
    rho c_p together keeps every L_i and scales the rise by 1/k, so its elasticities in k and rho add up to -1.
    (3) The bulk network is linear, C T' = -K T + h A T_amb + B u, and starts at T_amb (docs/theory.md §G5): T - T_amb
    does not depend on T_amb, so d(contact temperature)/d T_amb = 1 and the flash rise does not depend on it."""
    assert_exact_identities(tables["geneva-motor"], ["thermal.conductivity"])


def assert_exact_identities(table, mechanics_only):
    """The identities above on a sensitivity table; `mechanics_only`: thermal values the heat per index must not
    depend on (exactly zero derivative)."""
    t = table.set_index(["quantity", "wrt"])
    for q in OF:
        assert t.loc[(q, "thermal.density"), "elasticity"] == pytest.approx(
            t.loc[(q, "thermal.specific_heat"), "elasticity"], rel=1e-12, abs=1e-15)
    flash = "peak_temp_flash_rise_K"
    assert (t.loc[(flash, "thermal.conductivity"), "elasticity"] + t.loc[(flash, "thermal.density"), "elasticity"]
            == pytest.approx(-1.0, abs=1e-10))
    assert t.loc[("peak_temp_contact_C", "thermal.ambient_temperature"), "derivative"] == pytest.approx(1.0, abs=1e-9)
    assert t.loc[(flash, "thermal.ambient_temperature"), "derivative"] == 0.0
    for key in mechanics_only:
        assert t.loc[("heat_per_index_J", key), "derivative"] == 0.0


@pytest.mark.parametrize("sets, field", [
    (["thermal.model=1d", "thermal.mesh_depth=2 mm"], "thermal.mesh_depth"),  # a discretisation choice
    (["thermal.flash=seed-blok"], "thermal.flash"),                        # the seed's formula: not traced
])
def test_refused_thermal_options(sets, field):
    sc = mechsim.load("geneva-motor", set=["thermal.model=lumped"] + sets)
    with pytest.raises(ScenarioError) as err:
        sensitivity(sc, [field] if field == "thermal.mesh_depth" else ["load.wheel_torque"], OF)
    assert err.value.field == field


def test_unset_thermal_geometry_is_refused():
    sc = mechsim.load("geneva-motor", set=["thermal.model=lumped"])
    with pytest.raises(ScenarioError) as err:
        sensitivity(sc, ["thermal.wheel_radius"], OF)
    assert err.value.field == "thermal.wheel_radius"


def test_band_table_in_jax_is_the_table():
    """The band rise the flash derivatives go through (`band_theta_table_xp` in jax) is the run's table, values and
    slope, inside the table and on both asymptotes (docs/theory.md §G4.3). In jax as the pass runs it: jitted (one
    program each; op by op, jax compiles every operation on its own, seconds of compilation)."""
    import jax
    import jax.numpy as jnp
    import mechsim.dynamics.jax_model  # noqa: F401 (jax in float64, as the pass runs it; on its own the test had float32)
    from mechsim.thermal.band_source import band_theta_table, band_theta_table_xp
    L = np.logspace(-5, 5, 301)
    np.testing.assert_array_equal(band_theta_table_xp(L), band_theta_table(L))
    np.testing.assert_allclose(np.asarray(jax.jit(lambda x: band_theta_table_xp(x, xp=jnp))(jnp.asarray(L))),
                               band_theta_table(L), rtol=1e-15)
    slope = np.asarray(jax.jit(jax.vmap(jax.grad(lambda x: band_theta_table_xp(x, xp=jnp))))(jnp.asarray(L)))
    h = 1e-6
    fd = (band_theta_table(L * (1 + h)) - band_theta_table(L * (1 - h))) / (2 * h * L)
    inside = (L > 1.1e-4) & (L < 0.9e4)        # away from the table's ends, where the pieces meet the asymptotes
    np.testing.assert_allclose(slope[inside], fd[inside], rtol=1e-7)


# ------------------------------------------------------------------------------------------------ cycle averaging
# Sensitivities of the cycle-averaged temperatures (`thermal.averaging = "cycle"`, docs/sensitivity.md "Cycle
# averaging"): the periodic turn's peak contact temperature and flash rise at their last time in the run, against
# central finite differences of the IDA path, exact identities, and the closed-form cycle bulk (thermal/cycle_exact.py)
# against the run's own (thermal/cycle.py `bulk_response`). The seed's load case 1 with a motor drive for 60 s: the
# mechanics runs six turns and the bulk is the cycle-averaged solution at a minute, so every piece of the cycle model
# is in the derivative (the turn's ends, its mean heat and share, the network's modes, the periodic ripple of the
# input read on the window's solution, the time t_w + m P) at a fraction of an hour's cost. Here, after the resolved
# cases, its pass reuses their compiled model (same network, same read-outs): only the cycle bulk's jvp compiles.
CYCLE_NAME = "geneva-seed-lc1-mu015"
CYCLE_SETS = ["duration=60 s", "drive.type=motor", "drive.stall_torque=40 N*m", "drive.no_load_speed=8 rad/s",
              "thermal.averaging=cycle"]
CYCLE_COLUMNS = {"peak_temp_contact_C": "temp_contact_C", "peak_temp_flash_rise_K": "temp_flash_rise_K"}
#: the first two are checked by finite differences (the geometry, which moves the mechanics, the network's areas
#: and volumes and the flash; the motor, and with it the period, the turn's ends and the phases); the others serve
#: the exact identities (which tie the material values to each other)
CYCLE_WRT = ["mechanism.crank_radius", "drive.no_load_speed", "thermal.conductivity", "thermal.density",
             "thermal.specific_heat", "thermal.ambient_temperature", "thermal.convection_pin", "drive.stall_torque"]
CYCLE_CHECKED = 2
#: relative steps 1e-5 and 5e-6: small enough that the peak's last repetition stays in the run, large against rtol
#: 1e-12 (measured: the elasticities 5e-6 (crank radius) and 1e-8 (no-load speed) from the Richardson differences)
CYCLE_H = 1e-5


#: the stated change of the cycle table: large enough that the last repetition's crossing of the run's end is
#: warned for the motor's no-load speed (test_last_repetition_crossing_the_end_is_warned); it sets only the warnings'
#: threshold and the table's first-order changes, which the other checks do not read
CYCLE_CHANGE = 0.5


@pytest.fixture(scope="module")
def cycle_table():
    return sensitivity(mechsim.load(CYCLE_NAME, set=CYCLE_SETS + SENS), CYCLE_WRT, OF, change=CYCLE_CHANGE)


_WINDOW: list = []
_WINDOWS: dict = {}


def _cycle_window(sets):
    """The plan and its mechanics window's run (the run cycle averaging averages), and the turn's temperatures. The
    window is the one the sensitivity's run settles on (runner.settled), the same for every design compared: its
    length is a discrete choice, not differentiated. Kept per settings for the module (the nominal FD window is
    read by two tests; only read, never changed)."""
    if tuple(sets) not in _WINDOWS:
        _WINDOWS[tuple(sets)] = _read_cycle_window(sets)
    return _WINDOWS[tuple(sets)]


def _read_cycle_window(sets):
    plan = runner.plan(mechsim.load(CYCLE_NAME, set=CYCLE_SETS + sets))
    if not _WINDOW:
        _WINDOW.append(runner.settled(runner.plan(mechsim.load(CYCLE_NAME, set=CYCLE_SETS + SENS)))
                       .thermal.mechanics_duration)
    plan = dataclasses.replace(plan, thermal=dataclasses.replace(plan.thermal, mechanics_duration=_WINDOW[0]))
    result = runner.execute(locating(cycle_window(plan)))       # its rows are read, no peak (`locating`)
    assert result.failure is None
    return plan, result, cycle_temperatures(plan, result.timeseries)


def _cycle_run(sets):
    """The whole cycle-averaged run (its window the sensitivity's, `_cycle_window`), for its located thermal peaks
    (`locating`: the mechanics' are not read)."""
    plan = runner.plan(mechsim.load(CYCLE_NAME, set=CYCLE_SETS + sets))
    if not _WINDOW:
        _cycle_window([])
    plan = dataclasses.replace(plan, thermal=dataclasses.replace(plan.thermal, mechanics_duration=_WINDOW[0]))
    result = runner.execute(locating(plan))
    assert result.failure is None
    return result


def test_cycle_temperatures_match_finite_differences(cycle_table):
    """The located peaks of the cycle-averaged run (scenarios/thermal_peaks.py: the periodic turn's mechanics at
    the phase, the cycle-averaged bulk at the instant) against central differences of the runs' own located peaks."""
    nominal = _cycle_run(FD)
    period = nominal.summary["thermal"]["cycle"]["period_s"]
    for q, c in CYCLE_COLUMNS.items():
        # the sensitivity's peak is the run's, at its instant; the flash rise repeats every turn of the periodic
        # regime, equal to the solver's tolerance, so its instant is one of those turns' (the tolerance decides)
        gap = cycle_table.loc[cycle_table["quantity"] == q, "t_s"].iloc[0] - located_peak(nominal, c)["t_s"]
        turns = 0 if q == "peak_temp_contact_C" else round(gap / period)
        assert gap == pytest.approx(turns * period, abs=1e-6 + 1e-6 * abs(turns)), q

    def quantities(sets, result=None):
        result = result if result is not None else _cycle_run(FD + sets)
        return {q: float(located_peak(result, c)["value"]) for q, c in CYCLE_COLUMNS.items()}

    ref0 = quantities([], nominal)          # the nominal run above: the same scenario
    worst = {}
    for key in CYCLE_WRT[:CYCLE_CHECKED]:
        part = cycle_table[cycle_table["wrt"] == key].set_index("quantity")
        p, unit = float(part["parameter"].iloc[0]), part["wrt_unit"].iloc[0]
        fd = richardson_central(lambda v: quantities([f"{key}={v!r} {unit}".strip()]), p, CYCLE_H)
        mine = {}
        assert_matches_finite_differences(part, ref0, fd, p, key, 1e-7, ELASTICITY_FLOOR, mine)
        print(key, {q: f"{e:.1e}" for q, e in mine.items()})
        worst.update({q: max(e, worst.get(q, 0.0)) for q, e in mine.items()})
    print("largest relative deviation from the finite differences:", {q: f"{e:.1e}" for q, e in worst.items()})


def test_cycle_exact_identities(cycle_table):
    """(1) The network is linear and starts at the ambient, and the cycle model keeps that (the mean response from
    ambient, a zero-mean ripple): the contact temperature's derivative in T_amb is 1, the flash rise's 0.
    (2) rho and c_p enter only as rho c_p (capacities C = rho c_p V, diffusivity k/(rho c_p)): equal elasticities.
    (3) The flash rise depends on k and rho c_p only through k and the Peclet numbers U b/(2 chi): scaling both keeps
    every Peclet number and scales the rise by 1/k, so its elasticities in k and rho add up to -1
    (docs/theory.md §G4.2-§G4.6). (4) The heat per index is mechanics: no thermal value moves it."""
    assert_exact_identities(cycle_table, ["thermal.conductivity", "thermal.convection_pin",
                                          "thermal.ambient_temperature"])


def test_closed_form_cycle_bulk_is_the_runs():
    """The cycle bulk of a turn read on its rows (thermal/cycle_exact.py `turn_bulk`: exact for the input linear
    between the rows, as a closed-form cycle's derivatives trace it) equals thermal/cycle.py `bulk_response` for that
    input (Gauss-Legendre on pieces between the turn's rows, exact for it to its quadrature error) at the rows' last
    times in the run. (A DAE run reads its turn on the solution: tests/test_cycle_peaks_dense.py.)"""
    from mechsim.thermal import cycle as cyc
    plan, result, turn = _cycle_window([])
    df = result.timeseries
    t, angle = df["t_s"].to_numpy(float), df["crank_angle_rad"].to_numpy(float)
    bounds = cyc.turn_boundaries(t, angle, angle[0])
    means = cyc.cycle_means_from_energies(t, bounds, df["heat_generated_J"].to_numpy(float),
                                          df["heat_pin_J"].to_numpy(float))
    setup = plan.thermal.setup
    means.start = np.array([np.interp(means.t_start, t, df[name[:-2] + "_C"].to_numpy(float)) + 273.15
                            for name in setup.system.state_names])
    u = setup.extension.inputs_numeric(plan.mechanism.contact_state(df))[0]
    a, P = means.t_start, means.period
    rows = [float(x) - a for x in t[(t > a) & (t < a + P)]]
    _, bulk = cyc.bulk_response(setup.system, means, lambda s: np.array([np.interp(a + s, t, ui) for ui in u]),
                                rows, turn["t_s"])
    assert turn["period"] == pytest.approx(P, rel=1e-14)
    np.testing.assert_allclose(turn["bulk"], bulk, rtol=0, atol=1e-9)
    ripple = bulk - bulk.mean(axis=0)
    assert np.ptp(ripple[:, 0]) > 0.1          # the pin's ripple over the turn is in it (K)


def test_cycle_peak_is_the_runs_reported_peak(cycle_table):
    """The sensitivity's value of the peak contact temperature is the run's reported (located) peak itself, in the
    run's last turn, and it is never below the run's rows there."""
    run = mechsim.run(mechsim.load(CYCLE_NAME, set=CYCLE_SETS + SENS))
    assert run.failure is None
    peak = run.summary["peaks"]["temp_contact_C"]["max"]
    assert run.summary["peaks"]["temp_contact_C"]["how"].startswith("located")
    row = cycle_table[cycle_table["quantity"] == "peak_temp_contact_C"].iloc[0]
    assert row["value"] == peak["value"] and row["t_s"] == peak["t_s"]
    assert peak["value"] >= np.nanmax(run.timeseries["temp_contact_C"].to_numpy(float)) - 1e-9
    assert peak["t_s"] > 60.0 - run.summary["thermal"]["cycle"]["period_s"]       # in the last turn of the run


def test_last_repetition_crossing_the_end_is_warned(cycle_table):
    """The peak's row is read at its last repetition t_k + m_k P <= duration; a value that changes the period moves
    it by m_k dP (t_k is a fixed output row), and where that reaches the run's end within the stated change the row's
    last repetition leaves the run (or one more enters) and the value jumps by one period's rise of the bulk. The
    warning states the change that gets there: min(gap to the end / m_k, gap to the next repetition / (m_k + 1)) / |dP|,
    here checked with dP from central differences of the window's period (step 1e-4 relative: truncation ~1e-8,
    round-off ~ rtol 1e-12 / 1e-4, both far below the two digits stated). The table is the module's (stated change
    CYCLE_CHANGE = 0.5; the warning names each value's change on its own, so the other values do not alter it)."""
    from mechsim.thermal import cycle as cyc
    key = "drive.no_load_speed"
    table = cycle_table[cycle_table["quantity"] == "peak_temp_contact_C"]
    notes = [w for w in cycle_table.attrs["warnings"] if "last repetition" in w]
    assert len(notes) == 1 and "\n" not in notes[0]

    def period(v, result=None):
        if result is None:
            _, result, _ = _cycle_window(FD + [f"{key}={v!r} rad/s"])
        df = result.timeseries
        b = cyc.turn_boundaries(df["t_s"].to_numpy(float), df["crank_angle_rad"].to_numpy(float),
                                float(df["crank_angle_rad"].iloc[0]))
        return b[-1] - b[-2]
    p, h = 8.0, 1e-4
    dP = (period(p * (1 + h)) - period(p * (1 - h))) / (2 * h)         # per relative change of the value
    _, nominal, turn = _cycle_window(FD)      # the scenario's own no_load_speed is p
    P, at = period(p, nominal), float(table["t_s"].iloc[0])
    m_k = int(turn["layout"].periods[int(np.argmin(np.abs(turn["t_s"] - at)))])
    leave, enter = 60.0 - at, at + P - 60.0
    need = min(leave / (m_k * abs(dP)), enter / ((m_k + 1) * abs(dP)))
    assert need < CYCLE_CHANGE and f"{key} {need * 100:.2g}%" in notes[0], (need, notes[0])


def test_peak_is_smooth_across_event_rows(cycle_table):
    """The run reads its turn's heat input on the window's solution, on pieces fixed by the turn and its events (not
    linear between output rows), and so does the traced turn: where the entry and exit move past output rows the
    located peak moves smoothly (with the rows' input it had teeth of a row's heat, 7e-4 K). Central differences of
    the run's located peak in the stall torque, steps +-2 % (the entry moves past about 28 output rows in all, while
    the peak keeps its repetition in the run, asserted), equal the derivative within their truncation (h^2/6 of the
    third derivative: 1e-3 of the value allowed, measured 2.8e-4). The trend `mechsim size` uses (table attrs
    "trend") is the derivative plus the repetitions' term alone (`repetition_trend`, -dT_P m dP/P: the peak's last
    repetition crossing the run's end), which these differences, holding the repetition, do not see: the trend less
    that term (m and dT_P, one period's rise of the bulk, from the nominal turn's rows; dP from the same runs'
    periods: 1e-2 of the term allowed, 2e-4 of the derivative) is the derivative."""
    key, p, h = "drive.stall_torque", 40.0, 2e-2
    part = cycle_table[(cycle_table["quantity"] == "peak_temp_contact_C") & (cycle_table["wrt"] == key)].iloc[0]
    trend = cycle_table.attrs["trend"]["peak_temp_contact_C"][key]
    runs = {s: _cycle_run(FD + [f"{key}={p * (1 + s * h)!r} N*m"]) for s in (1, -1)}
    peaks = {s: located_peak(r, "temp_contact_C") for s, r in runs.items()}
    periods = {s: r.summary["thermal"]["cycle"]["period_s"] for s, r in runs.items()}

    def entry(result):
        ev, until = result.events, result.summary["thermal"]["cycle"]["mechanics_simulated_until_s"]
        return float(ev.loc[(ev["kind"] == "entry") & (ev["t_s"] <= until), "t_s"].iloc[-1])
    assert abs(entry(runs[1]) - entry(runs[-1])) > 25 * 1e-3        # many rows crossed (output step 1 ms)
    for s in (1, -1):        # the peak in the last turn, moved smoothly: its last repetition stays in the run
        assert 60.0 - periods[s] < peaks[s]["t_s"] <= 60.0
        assert abs(peaks[s]["t_s"] - part["t_s"]) < 0.25 * periods[s]
    fd = (peaks[1]["value"] - peaks[-1]["value"]) / (2 * h * p)
    print(f"derivative {part['derivative']:.7g}, trend {trend:.7g}, differences {fd:.7g}")
    assert part["derivative"] == pytest.approx(fd, rel=1e-3)
    _, _, turn = _cycle_window(FD)
    k = int(np.argmin(np.abs(turn["t_s"] - part["t_s"])))
    m, jump = turn["layout"].periods[k], turn["temp_contact_C"][k] - turn["temp_contact_previous_C"][k]
    repetitions = -jump * m * (periods[1] - periods[-1]) / (2 * h * p) / turn["period"]
    assert trend - part["derivative"] == pytest.approx(repetitions, rel=1e-2)


def test_shipped_lc1_design_is_a_kkt_point():
    """The seed's load case 1 design as `mechsim size` wrote it (docs/lc1_sizing_design.toml, docs/sensitivity.md "A
    thermal sizing"): minimise the crank radius r over (r, stall torque) subject to the peak contact temperature
    after the hour <= 60 °C and the index time <= 0.3 s. At the optimum both limits are active (within the sizing's
    activity threshold ACTIVE below and its feasibility tolerance FEASIBLE above), their gradients are independent
    (two limits fix two values), and stationarity, grad r = -(mu_T grad T + mu_t grad t), holds with both
    multipliers positive (Nocedal & Wright Theorem 12.1): with two active limits in two values the multipliers are
    the solution of that 2x2 system, and their signs are the physics: a higher temperature or a longer index allowed
    would each let the crank shrink. The gradients are the exact sensitivities at the design (the hour's window
    only; the module's compiled pass is reused: the cycle cases' model and quantities, and the two values the
    sizing moves, which the pass pads to its compiled seed width as it does the cycle cases' eight)."""
    from pathlib import Path

    from mechsim.scenarios.studies.sizing import ACTIVE, FEASIBLE
    from mechsim.scenarios.keys import lookup
    design = mechsim.load(Path(__file__).resolve().parent.parent / "docs" / "lc1_sizing_design.toml")
    keys = ["mechanism.crank_radius", "drive.stall_torque"]
    table = sensitivity(design, keys, OF + ["index_time_s"])
    values, grads = {}, {}
    for q, limit in (("peak_temp_contact_C", 60.0), ("index_time_s", 0.3)):
        part = table[table["quantity"] == q].set_index("wrt")
        values[q] = float(part["value"].iloc[0])
        grads[q] = part.loc[keys, "derivative"].to_numpy(float)
        assert limit * (1 - ACTIVE) <= values[q] <= limit * (1 + FEASIBLE), (q, values[q])
    G = np.column_stack([grads["peak_temp_contact_C"], grads["index_time_s"]])        # per SI unit of r, T
    # independent: the elasticity matrix (per relative change of each value, relative to each limit) is well
    # conditioned; the multipliers' relative error is about cond x the gradients' (1e-6 at most in this module's
    # finite-difference checks), so cond < 1e4 fixes them to 1 %, their signs with room to spare
    x = np.array([float(lookup(design.si, k)) for k in keys])
    assert np.linalg.cond(G * x[:, None] / np.array([60.0, 0.3])[None, :]) < 1e4
    mu = np.linalg.solve(G, -np.array([1.0, 0.0]))
    assert mu[0] > 0 and mu[1] > 0, mu
