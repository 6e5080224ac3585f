"""The thermal model alongside the Geneva mechanics (issue 3 parts 2-6): heat balance of the states integrated with
the mechanics, cycle-averaged vs resolved bulk, the flash columns against docs/theory.md §G4.7, DAE vs closed form,
the exact Jacobian of the thermal rows, and the 1-D track mesh against the exact (Duhamel) surface solution."""
import math

import numpy as np
import pytest

from mechsim.dynamics.drives import Drive
from mechsim.dynamics.model import derive
from mechsim.scenarios.loader import load
from mechsim.scenarios.runner import build_mechanism, make_drive, run
from mechsim.thermal.cycle import CycleMeans, bulk_response
from mechsim.thermal.lumped import ambient_temperatures
from mechsim.thermal.exact import (ModalNetwork, closed_form_columns, input_function, states_between_rows,
                                   states_between_rows_many, switch_times)
from mechsim.thermal.plan import plan
from mechsim.thermal import duhamel_surface, get_material, integrate_mean_heat

STEEL = get_material("aisi1045")
E_STAR = 113.74e9              # docs/theory.md §G3: steel on steel, Johnson's convention
R_PIN, LENGTH = 4e-3, 4e-3


def scenario_run(name, *overrides):
    return run(load(name, list(overrides)))


def closure(result):
    hb = result.summary["thermal"]["heat_balance"]
    return hb["closure_error_relative"], hb


@pytest.fixture(scope="module")
def lumped_pair():
    """geneva-lc1 (lumped) at prescribed speed over 3 cycles: the closed-form path and the DAE path."""
    common = ["duration=3.6 s"]
    return scenario_run("geneva-lc1", *common), scenario_run("geneva-lc1", *common, "solver.method=dae")


@pytest.fixture(scope="module")
def one_d_pair():
    common = ["duration=3.6 s", "thermal.model=1d"]
    return scenario_run("geneva-lc1", *common), scenario_run("geneva-lc1", *common, "solver.method=dae")


# ------------------------------------------------------------------------------------------------ heat balance
def test_heat_balance_lumped_dae_motor():
    """Motor drive (speed from the dynamics), 5 cycles: generated = stored + convected to 1e-6 of generated; the
    generated heat is the friction work of the mechanics (an independent state) and grows with each engagement."""
    r = scenario_run("geneva-motor", "thermal.model=lumped", "duration=5 s")
    assert r.success
    rel, hb = closure(r)
    assert abs(rel) <= 1e-6
    assert hb["convected_J"] > 0 and hb["stored_J"] > 0.9 * hb["generated_J"]
    df = r.timeseries
    assert hb["generated_J"] == pytest.approx(-df["work_friction_J"].iloc[-1], rel=1e-6)
    assert (df["crank_angle_rad"].iloc[-1] - df["crank_angle_rad"].iloc[0]) / (2 * math.pi) >= 5


@pytest.mark.parametrize("path", [0, 1], ids=["closed-form", "dae"])
def test_heat_balance_lumped_and_1d(lumped_pair, one_d_pair, path):
    for result in (lumped_pair[path], one_d_pair[path]):
        assert result.success
        rel, hb = closure(result)
        assert abs(rel) <= 1e-6, hb
        assert hb["generated_J"] > 3 * 1.8          # three engagements of ~1.87 J (docs/theory.md §G7 row 18)


# ------------------------------------------------------------------------------------------------ DAE vs closed form
def test_dae_and_closed_form_give_the_same_temperatures(lumped_pair, one_d_pair):
    for cf, dae in (lumped_pair, one_d_pair):
        assert len(cf.timeseries) == len(dae.timeseries)
        for col, tol in [("temp_bulk_pin_C", 1e-5), ("temp_bulk_crank_C", 1e-5), ("temp_bulk_wheel_C", 1e-6),
                         ("temp_contact_C", 2e-3), ("temp_flash_rise_K", 2e-3)]:
            a, b = cf.timeseries[col].to_numpy(), dae.timeseries[col].to_numpy()
            np.testing.assert_array_equal(np.isnan(a), np.isnan(b))
            assert np.nanmax(np.abs(a - b)) <= tol, col
    cf, dae = one_d_pair
    a, b = cf.timeseries["temp_wall_surface_C"], dae.timeseries["temp_wall_surface_C"]
    assert np.max(np.abs(a - b)) <= 1e-4
    assert "same IDA run" in dae.summary["thermal"]["why"] and "no DAE" in cf.summary["thermal"]["why"]


def _closed_form_lc1():
    """geneva-lc1 over 1.2 s at its prescribed speed: (its thermal plan, the closed form's columns, the heat input)."""
    sc = load("geneva-lc1", ["duration=1.2 s"])
    mech = build_mechanism(sc.si)
    pl = plan(sc.si, mech, make_drive(sc.si), "closed-form")
    columns = closed_form_columns(mech, -math.pi, 5.34)
    return pl, columns, input_function(pl.setup.extension, mech, columns)


def test_closed_form_path_equals_the_thermal_package_integrator():
    """The modal exponential integrator of the closed-form path against LinearThermalSystem.integrate (Radau)."""
    pl, columns, inputs = _closed_form_lc1()
    ext = pl.setup.extension
    t = np.linspace(0.0, 1.2, 1201)
    breaks = switch_times(columns, t)
    assert len(breaks) == 3                       # entry, slip reversal, exit
    modal = ModalNetwork(ext.system, ext.loss).integrate(inputs, t, pl.setup.initial, breaks)
    n_in = ext.system.input_matrix.shape[1]
    y = pl.setup.initial[:ext.system.size]
    rows = [y]
    for a, b in zip([0.0] + breaks, breaks + [1.2]):
        keep = t[(t > a) & (t <= b)]
        t_eval = np.unique(np.r_[keep, b])
        sol = ext.system.integrate((a, b), y, lambda s: inputs(np.array([s]))[:n_in, 0], t_eval=t_eval,
                                   method="Radau", rtol=1e-11, atol=1e-12)
        rows += list(sol.y.T[np.searchsorted(t_eval, keep)])
        y = sol.y[:, -1]
    bdf = np.array(rows)[:len(t)]
    np.testing.assert_allclose(modal[:, :ext.system.size], bdf, rtol=0, atol=1e-7)


def test_readings_between_rows_together_equal_each_alone():
    """The network's states read between output rows for several readings at once (`states_between_rows_many`:
    one evaluation of the heat input for all their integrations) equal each reading's own, to the bit; and a state
    read between rows is the one integrating through that instant gives (to round-off: both are exact in the modes
    and the quadrature's error on 10 ms pieces is below it; ~100 steps on 293 K carry about 1e-12 K)."""
    pl, columns, inputs = _closed_form_lc1()
    ext = pl.setup.extension
    t = np.linspace(0.0, 1.2, 121)
    breaks = switch_times(columns, t)
    network = ModalNetwork(ext.system, ext.loss)
    rows = network.integrate(inputs, t, pl.setup.initial, breaks)
    rng = np.random.default_rng(3)
    readings = [np.sort(rng.uniform(a, a + 0.05, 5)) for a in rng.uniform(0.0, 1.1, 6)]
    readings += [t[[3, 40, 41]], np.array([breaks[0]]), np.r_[breaks[1] - 1e-4, breaks[1] + 1e-4]]
    together = states_between_rows_many(network, inputs, breaks, t, rows, readings)
    for times, got in zip(readings, together):
        assert np.array_equal(got, states_between_rows(network, inputs, breaks, t, rows, times))
    np.testing.assert_array_equal(together[6], rows[[3, 40, 41]])            # at a row: the row itself
    through = network.integrate(inputs, np.unique(np.r_[t, np.concatenate(readings)]), pl.setup.initial, breaks)
    at = np.unique(np.r_[t, np.concatenate(readings)])
    for times, got in zip(readings, together):
        np.testing.assert_allclose(got[:, :ext.system.size], through[np.searchsorted(at, times), :ext.system.size],
                                   rtol=0, atol=1e-11)


# ------------------------------------------------------------------------------------------------ cycle averaging
def _compare_cycle(name, duration, *extra, mean_only=False):
    common = [f"duration={duration} s", "output_step=5 ms", "thermal.model=lumped", *extra]
    resolved = scenario_run(name, *common, "thermal.averaging=resolved")
    cycle = scenario_run(name, *common, "thermal.averaging=cycle")
    assert resolved.success and cycle.success
    assert cycle.summary["thermal"]["averaging"] == "cycle"
    history = cycle.extra_tables["thermal_history"]
    ts = resolved.timeseries
    worst = {}
    for col in ("temp_bulk_pin_C", "temp_bulk_crank_C", "temp_bulk_wheel_C"):
        res = np.interp(history["t_s"], ts["t_s"], ts[col])
        rise = ts[col].max() - ts[col].iloc[0]
        worst[col] = np.max(np.abs(res - history[col])) / rise
        # over a minute the mean curve alone is already within 1 % for the slow bodies (tau >> cycle)
        if mean_only and col != "temp_bulk_pin_C":
            assert np.max(np.abs(res - history[col.replace("_C", "_mean_C")])) <= 0.01 * rise
    assert max(worst.values()) <= 0.01, worst
    # the shifted last turn: the bulk there is the resolved bulk at the same instants
    w = cycle.timeseries
    assert w["t_s"].iloc[-1] <= duration and w["t_s"].iloc[-1] > duration - 2 * cycle.summary["thermal"]["cycle"][
        "period_s"]
    for col in ("temp_bulk_crank_C", "temp_bulk_wheel_C"):
        res = np.interp(w["t_s"], ts["t_s"], ts[col])
        assert np.max(np.abs(res - w[col])) <= 0.01 * (ts[col].max() - ts[col].iloc[0])
    return worst, cycle


def test_cycle_averaged_matches_resolved_prescribed_speed():
    worst, cycle = _compare_cycle("geneva-lc1", 60.0, mean_only=True)
    assert max(worst.values()) <= 1e-4            # exact superposition: only the integrators differ
    assert abs(cycle.summary["thermal"]["heat_balance"]["closure_error_relative"]) <= 1e-9


def test_cycle_averaged_matches_resolved_motor():
    """Motor drive: the mechanics settles over the first turns, resolved; the cycle model continues from there."""
    worst, cycle = _compare_cycle("geneva-motor", 30.0)
    assert cycle.summary["thermal"]["cycle"]["periodicity_of_mean_heat"] < 1e-3


def test_mean_response_is_integrate_mean_heat_and_auto_picks_cycle():
    sc = load("geneva-lc1", ["duration=1 h"])
    mech = build_mechanism(sc.si)
    pl = plan(sc.si, mech, make_drive(sc.si), "closed-form")
    assert pl.averaging == "cycle" and "3060 cycles" in pl.averaging_why
    assert pl.mechanics_duration < 3.0
    sysm = pl.setup.system
    times = np.array([0.0, 10.0, 600.0, 3600.0])
    # from ambient at t = 0 under a constant input (no ripple): the mean curve is the mean-heat solution
    means = CycleMeans(0.0, 1.1766, 1.59, 0.35, None, start=ambient_temperatures(sysm))
    mean, _ = bulk_response(sysm, means, lambda s: np.zeros((2, np.size(s))) + np.array([[0.5565], [1.0335]]),
                            [], times)
    # integrate_mean_heat propagates with scipy's expm of the augmented matrix A = [[-C^-1 K, f], [0, 0]]; the
    # squaring phase of scaling-and-squaring amplifies round-off about like ||A t|| (Higham 2005), so its forward
    # error is ~ ||A t||_1 u |T| (measured against a 40-digit mpmath expm: 1.3-2.7x that, 1.3e-9 K at 1 h,
    # while the modal form is within 2.3e-13 K). The bound below allows 10x that growth, per row.
    expected = integrate_mean_heat(sysm, 1.59, 0.35, times)
    n = sysm.size
    A = np.zeros((n + 1, n + 1))
    J = sysm.jacobian()
    A[:n, :n] = J.toarray() if hasattr(J, "toarray") else J
    A[:n, n] = sysm.rhs(np.zeros(n), np.array([0.35 * 1.59, 0.65 * 1.59]))
    bound = 10 * np.linalg.norm(A, 1) * times * np.finfo(float).eps * np.abs(expected).max()
    assert np.all(np.abs(mean - expected) <= bound[:, None] + 4 * np.spacing(expected))
    short = plan(load("geneva-lc1", []).si, mech, make_drive(sc.si), "closed-form")
    assert short.averaging == "resolved" and "auto" in short.averaging_why


# ------------------------------------------------------------------------------------------------ flash columns
# docs/theory.md §G4.7 corrected-model table: phi (deg), L_wall, L_pin, Q at mu = 0.15 (W), dT_flash at mu = 0.15 (K)
TABLE47 = [(5, 0.61, 0.06, 5.80, 14.8), (15, 0.65, 0.05, 6.73, 17.1), (30, 0.58, 0.10, 6.50, 16.0),
           (45, 0.13, 0.17, 2.46, 7.6), (60, 0.56, 0.10, 8.73, 21.7), (75, 0.64, 0.05, 7.65, 19.5),
           (85, 0.61, 0.04, 6.42, 17.0)]


@pytest.fixture(scope="module", params=[0.15, 0.3], ids=["mu015", "mu030"])
def flash_run(request):
    r = scenario_run("geneva-lc1", "duration=1.2 s", "output_step=0.1 ms", "thermal.model=flash",
                     f"contact.friction={request.param}")
    return request.param, r.timeseries


def _at_phi(df, col, phi_deg):
    """Column value at seed angle phi = alpha + 45 deg in the first engagement (interpolated in phi)."""
    eng = df[df["mode"] == "engaged"]
    alpha = (eng["crank_angle_rad"] + math.pi) % (2 * math.pi) - math.pi
    phi = np.degrees(alpha.to_numpy()) + 45.0
    first = eng["t_s"].to_numpy() < 0.9
    return float(np.interp(phi_deg, phi[first], eng[col].to_numpy()[first]))


@pytest.mark.parametrize("phi,L_wall,L_pin,Q,dT", TABLE47)
def test_flash_columns_reproduce_table_47(flash_run, phi, L_wall, L_pin, Q, dT):
    mu, df = flash_run
    scale = mu / 0.15
    assert _at_phi(df, "temp_flash_rise_K", phi) == pytest.approx(scale * dT, rel=0.15)
    # the table's N omits the friction arm: N = (T_L + J2 alpha2)/(x - sigma mu R) is up to mu R/x_min = 4 % larger
    assert _at_phi(df, "heat_rate_W", phi) == pytest.approx(scale * Q, rel=0.05)
    # the table lists the effective pin Peclet number, floored by the time since entry (docs/theory.md §G4.6-4.7);
    # b (so L) grows as sqrt(N): up to 2 % above the table at mu = 0.3
    floor = 0.749 * _at_phi(df, "hertz_half_width_m", phi) / math.sqrt(STEEL.diffusivity * math.radians(phi) / 5.34)
    assert max(_at_phi(df, "peclet_pin", phi), floor) == pytest.approx(L_pin, rel=0.03, abs=0.011)
    if phi != 45:                                    # the table's 0.13 at 45 deg is the floored value
        assert _at_phi(df, "peclet_wheel", phi) == pytest.approx(L_wall, rel=0.03, abs=0.011)
    assert 0.28 <= _at_phi(df, "heat_share_pin", phi) <= 0.55
    # contact temperature with the flash model = ambient + flash rise
    assert _at_phi(df, "temp_contact_C", phi) == pytest.approx(20.0 + _at_phi(df, "temp_flash_rise_K", phi),
                                                               abs=1e-9)


def test_row20_flash_phi60(flash_run):
    mu, df = flash_run
    assert _at_phi(df, "temp_flash_rise_K", 60) == pytest.approx(21.7 * mu / 0.15, rel=0.15)


def test_hertz_columns(flash_run):
    """docs/theory.md §G3/§7 row 10: b = sqrt(4 N R/(pi l E*)), p0 b = 2 N/(pi l); 225.33 N -> 50.22 um, 714.0 MPa."""
    _, df = flash_run
    eng = df[df["mode"] == "engaged"]
    N = eng["contact_force_N"].to_numpy()
    b = eng["hertz_half_width_m"].to_numpy()
    p0 = eng["hertz_pressure_max_Pa"].to_numpy()
    np.testing.assert_allclose(b, np.sqrt(4 * N * R_PIN / (math.pi * LENGTH * E_STAR)), rtol=1e-3)
    np.testing.assert_allclose(p0 * b, 2 * N / (math.pi * LENGTH), rtol=1e-12)
    scale = np.sqrt(225.33 / N.max())
    assert b.max() * scale == pytest.approx(50.22e-6, rel=1e-3)
    assert p0.max() * scale == pytest.approx(714.0e6, rel=1e-3)
    dwell = df[df["mode"] == "dwell"]
    assert (dwell["hertz_half_width_m"] == 0).all() and dwell["temp_contact_C"].isna().all()


def test_seed_blok_flash_is_the_seed_formula():
    r = scenario_run("geneva-lc1", "duration=1.2 s", "thermal.model=flash", "thermal.flash=seed-blok")
    df = r.timeseries
    eng = df[df["mode"] == "engaged"]
    U = 5.34 * 0.075                                # the seed's source speed: the crank-pin speed
    expected = 0.159 * 2.5 * eng["heat_rate_W"] / (STEEL.conductivity * LENGTH) * STEEL.diffusivity / (
        U * eng["hertz_half_width_m"])
    np.testing.assert_allclose(eng["temp_flash_rise_K"], expected, rtol=1e-9)


# ------------------------------------------------------------------------------------------------ exact Jacobian
@pytest.mark.parametrize("model", ["lumped", "1d"])
def test_thermal_rows_jacobian_matches_finite_differences(model):
    sc = load("geneva-lc1", [f"thermal.model={model}", "solver.method=dae"])
    mech = build_mechanism(sc.si)
    pl = plan(sc.si, mech, make_drive(sc.si), "dae")
    ext = pl.extension
    derived = derive(mech, "index2", False, ext)
    mf = derived.modes["engaged"]
    values = {**mech.parameter_values(), **Drive("motor", stall_torque=30, no_load_speed=9).parameter_values(0.0),
              "baumgarte_alpha": 10.0, "baumgarte_beta": 10.0, **ext.parameter_values(), "mu": 0.2}
    p = tuple(values[n] for n in derived.parameter_names)
    rng = np.random.default_rng(3)
    y, yp = rng.normal(size=mf.ny), rng.normal(size=mf.ny)
    y[0], y[1], y[2], y[3], y[4] = -0.3, -0.25, 5.0, 3.0, 150.0
    y[mf.index["ext"]] = 293.15 + rng.normal(size=len(ext.names))
    J = np.zeros((mf.ny, mf.ny))
    cj = 21.0
    mf.jacobian(0.1, y, yp, None, cj, J, p)
    assert np.all(np.isfinite(J))
    rows = np.r_[mf.index["ext"]]
    for j in range(mf.ny):
        h = 1e-6 * max(1.0, abs(y[j]))
        e = np.zeros(mf.ny)
        e[j] = h
        r = [np.zeros(mf.ny) for _ in range(4)]
        mf.residual(0.1, y + e, yp, r[0], p)
        mf.residual(0.1, y - e, yp, r[1], p)
        mf.residual(0.1, y, yp + e, r[2], p)
        mf.residual(0.1, y, yp - e, r[3], p)
        fd = (r[0] - r[1]) / (2 * h) + cj * (r[2] - r[3]) / (2 * h)
        np.testing.assert_allclose(J[rows, j], fd[rows], rtol=1e-5, atol=1e-6 * (1 + np.abs(fd[rows]).max()))
    # N = 0 (flank switch) and zero source speeds (centre of the slot) keep every derivative finite
    y[4], y[2], y[3] = 0.0, 0.0, 0.0
    mf.jacobian(0.1, y, yp, None, cj, J, p)
    assert np.all(np.isfinite(J))


# ------------------------------------------------------------------------------------------------ 1-D track mesh
def test_wall_track_surface_matches_duhamel(one_d_pair):
    """During the first engagement the wall track is a semi-infinite solid under the flux q(t) = (1-gamma) Q / A:
    its surface rise is the exact Duhamel integral (docs/theory.md §G6) while the penetration is << the mesh depth."""
    cf, _ = one_d_pair
    df = cf.timeseries
    th = cf.summary["thermal"]
    area = th["mesh"]["track_area_m2"]
    eng = df[(df["mode"] == "engaged") & (df["t_s"] < 0.9)]
    t = df["t_s"].to_numpy()
    flux = (df["heat_rate_W"] * (1 - df["heat_share_pin_bulk"].fillna(0.0))).to_numpy() / area
    t0 = eng["t_s"].iloc[0] - 1e-3
    for ti in eng["t_s"].to_numpy()[::40][1:]:
        kinks = t[(t > t0) & (t < ti)] - t0                     # the interpolated flux is piecewise linear
        exact = duhamel_surface(ti - t0, lambda s: float(np.interp(t0 + s, t, flux)), STEEL, breakpoints=kinks)
        rise = float(np.interp(ti, t, df["temp_wall_surface_C"])) - float(np.interp(ti, t, df["temp_bulk_wheel_C"]))
        assert rise == pytest.approx(exact, rel=0.03, abs=1e-3)
    # and the validity of the 1-D model is reported: not a flash model at the Geneva's Peclet numbers, the flash
    # rise taken from the moving band instead; no advice names a module as if it were a scenario key
    assert any("would neglect lateral conduction" in w and "exact moving-band solution" in w
               for w in cf.summary["warnings"])
    assert not any("thermal.band_source" in w for w in cf.summary["warnings"])
    assert th["track_peclet"] > 5
