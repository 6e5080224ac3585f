"""Design sensitivities (scenarios/studies/sensitivity.py on dynamics/sensitivity.py) against central finite
differences of the IDA path at a tight tolerance, Richardson-extrapolated (docs/sensitivity.md, 'How it is checked').

The finite differences re-run the scenario (IDA, index-2, rtol 1e-12; the sensitivities run at 1e-10) with one value
moved by +-h and +-h/2 (relative) and read each quantity the way the sensitivity defines it: a peak at the nominal
arg-max row (the output times are fixed), event times from the events table, the drive's work at an event by cubic
Hermite interpolation of the output rows before it (work' = drive torque x crank speed). Step: the IDA solution
moves by about rtol relative in a way that is not smooth in the values (adaptive steps), so a central difference has
noise ~ rtol/h (2e-9 at h = 5e-4), and Richardson-extrapolated, truncation ~ h^4 times the fourth derivative. That
one is large for geneva-torque's peak contact force (just after an entry, two flank switches later in the same
engagement): the plain central difference in the drive torque is off by 6e-3 at h = 1e-3 and by 6e-5 at 1e-4
(measured), so h = 5e-4 with h/2. The derivatives must agree to 1e-4 relative, each entry on its own (see
ELASTICITY_FLOOR for the ones that are zero).
"""
from __future__ import annotations

import numpy as np
import pytest

import mechsim
from conftest import assert_matches_finite_differences, located_peak, richardson_central, run_locating
from mechsim.scenarios.studies.sensitivity import PEAKS, sensitivity

BASE = ["duration=1.45 s", "solver.rtol=1e-10", "solver.atol=1e-12"]
#: the finite differences run tighter than the sensitivities, so that they are the more accurate side
FD_RTOL = 1e-12
FD = ["duration=1.45 s", f"solver.rtol={FD_RTOL}", f"solver.atol={FD_RTOL / 100}"]
WRT = ["load.wheel_torque", "contact.friction", "mechanism.crank_radius", "mechanism.wheel_inertia"]
H = 5e-4
#: a derivative that is zero (the energy of a constant-torque cycle, 2 pi T, does not depend on an inertia) is
#: compared absolutely: both sides are then integration noise, elasticities ~1e-8 here (the derivative is assembled
#: from S at rtol 1e-10 over ~1e3 steps and several events); 1e-6 is far below anything a design reads
ELASTICITY_FLOOR = 1e-6


def _run(name, sets, columns):
    """The run the finite differences read, the located peaks of only the mechanism's `columns` (`run_locating`)."""
    r = run_locating(mechsim.load(name, set=sets), columns)
    assert r.failure is None, r.failure.message()
    return r


def _work_at(df, t_event, name="drive"):
    """A work column at t_event: cubic Hermite on the two output rows before it (work' = the power: drive torque x
    crank speed, or minus the friction power)."""
    t = df["t_s"].to_numpy(float)
    w = df[f"work_{name}_J"].to_numpy(float)
    pw = ((df["drive_torque_N_m"] * df["crank_speed_rad_s"]).to_numpy(float) if name == "drive"
          else -df["friction_power_W"].to_numpy(float))
    i = int(np.searchsorted(t, t_event)) - 1          # the last row before the event
    t0, h = t[i - 1], t[i] - t[i - 1]
    s = (t_event - t0) / h
    h00, h10, h01, h11 = 2 * s**3 - 3 * s**2 + 1, s**3 - 2 * s**2 + s, -2 * s**3 + 3 * s**2, s**3 - s**2
    return h00 * w[i - 1] + h10 * h * pw[i - 1] + h01 * w[i] + h11 * h * pw[i]


def quantities(result, rows: dict) -> dict:
    """The table's quantities read off an IDA result (the located peaks of the quantities in rows)."""
    df, ev = result.timeseries, result.events
    out = {q: located_peak(result, PEAKS[q]) for q in rows}
    entries = ev.loc[ev["kind"] == "entry", "t_s"].to_numpy(float)
    exits = ev.loc[ev["kind"] == "exit", "t_s"].to_numpy(float)
    last_exit = exits[-1]
    out["index_time_s"] = last_exit - entries[entries < last_exit][-1]
    out["heat_per_index_J"] = (_work_at(df, entries[entries < last_exit][-1], "friction")
                               - _work_at(df, last_exit, "friction"))
    out["cycle_time_s"] = entries[-1] - entries[-2]
    out["energy_per_cycle_J"] = _work_at(df, entries[-1]) - _work_at(df, entries[-2])
    return out


def _literal(si_value, unit):
    return f"{si_value!r} {unit}" if unit else repr(si_value)


CASES = {
    # motor drive from its running speed: two entries, friction 0.15 with slip reversals
    "geneva-motor": (["duration=1.45 s"], WRT),
    # constant torque, frictionless, viscous crank damping: running up, four entries in 0.75 s
    "geneva-torque": (["duration=0.75 s"], ["drive.torque", "mechanism.crank_inertia", "mechanism.crank_damping",
                                            "initial.crank_speed"]),
}


@pytest.fixture(scope="module")
def tables():
    return {name: sensitivity(mechsim.load(name, set=sets + BASE[1:]), wrt) for name, (sets, wrt) in CASES.items()}


@pytest.fixture(scope="module")
def motor_table(tables):
    return tables["geneva-motor"], None


@pytest.mark.parametrize("name", CASES)
def test_geneva_matches_finite_differences(tables, name):
    sets, wrt = CASES[name]
    table = tables[name]
    fd_sets = sets + FD[1:]
    columns = [c for q, c in PEAKS.items() if q in set(table["quantity"])]
    nominal = _run(name, fd_sets, columns)
    df = nominal.timeseries
    rows = {q: int(np.nanargmax(np.abs(df[c].to_numpy(float)))) for q, c in PEAKS.items()
            if q in set(table["quantity"])}
    ref0 = quantities(nominal, rows)
    worst = {}
    for key in wrt:
        part = table[table["wrt"] == key].set_index("quantity")
        p, unit = float(part["parameter"].iloc[0]), part["wrt_unit"].iloc[0]
        fd = richardson_central(
            lambda value: quantities(_run(name, fd_sets + [f"{key}={_literal(value, unit)}"], columns), rows), p, H)
        assert_matches_finite_differences(part, ref0, fd, p, key, 1e-7, ELASTICITY_FLOOR, worst)
    print(name, "largest relative deviation from the finite differences:", {q: f"{e:.1e}" for q, e in worst.items()})


def test_cli_prints_and_writes_the_table(tmp_path, motor_table):
    import json

    import pandas as pd
    from cli_helpers import durations, invoke
    out = tmp_path / "s"
    r = invoke("sensitivity", "geneva-motor", "--wrt", ",".join(WRT), *sum((["--set", s] for s in BASE), []),
               "--out", out)
    assert r.exit_code == 0, r.output
    assert "peak_contact_force_N" in r.stdout and "elasticity" in r.stdout
    # the whole command's wall time, with the run's and the sensitivities' shares beside it: the summary's own
    line = next(x for x in r.stdout.splitlines() if x.startswith("time: "))
    _, run_s, sens_s, _ = durations(line)
    cost = json.loads((out / "summary.json").read_text())["sensitivity"]["cost"]
    for shown, value in ((run_s, cost["run_wall_time_s"]), (sens_s, cost["sensitivity_wall_time_s"])):
        assert shown == pytest.approx(value, abs=0.5e-4 if value < 0.1 else 0.5e-2)     # to the last digit shown
    written = pd.read_csv(out / "sensitivity.csv")
    table, _ = motor_table
    assert list(written["quantity"]) == list(table["quantity"])
    assert written["derivative"].to_numpy() == pytest.approx(table["derivative"].to_numpy(), rel=1e-12)
    summary = json.loads((out / "summary.json").read_text())
    assert len(summary["sensitivity"]["rows"]) == len(table)
    cost = summary["sensitivity"]["cost"]      # the cost record: what was differentiated and how it is stated
    assert cost["values"] == len(WRT) and cost["sensitivity_steps"] > 0
    assert cost["sensitivity_per_run"] == pytest.approx(
        (cost["sensitivity_wall_time_s"] - cost["sensitivity_compile_time_s"]) / cost["run_wall_time_s"], rel=1e-9)
    assert (out / "tornado.png").stat().st_size > 10_000


def test_tornado_panels_share_one_scale_and_fit_with_one_value():
    """Ten quantities by one value (a study of one design value): every panel has room for its title and bar
    (constrained layout applies: no warning), and the panels share the elasticity scale, so an elasticity of 1e-9
    draws a bar too short to see, not one as long as an elasticity of 1."""
    import io
    import warnings

    import pandas as pd

    from mechsim.scenarios.studies.sensitivity import tornado_figure
    e = [1.0, 0.38, 4e-3, -2.4e-4, -4.5e-9, 0.0, 0.13, 7e-3, 5e-3, 0.985]
    table = pd.DataFrame({"quantity": [f"q{i}" for i in range(10)], "wrt": "contact.friction", "value": 1.0,
                          "derivative": e, "elasticity": e})
    fig = tornado_figure(table)
    with warnings.catch_warnings():
        warnings.simplefilter("error")
        fig.savefig(io.BytesIO(), format="png", dpi=50)
    limits = {ax.get_xlim() for ax in fig.axes}
    assert len(limits) == 1 and limits.pop()[1] == pytest.approx(1.2)
    widths = [abs(patch.get_width()) for ax in fig.axes for patch in ax.patches]
    assert sorted(widths) == sorted(abs(x) for x in e)


@pytest.mark.parametrize("args, field", [
    (["--wrt", "mechanism.slots"], "mechanism.slots"),                      # an integer: no derivative
    (["--wrt", "load.wheel_torque", "--of", "peak_temp_contact_C"], "--of"),   # no thermal model here
    (["--wrt", "load.wheel_torque", "--of", "no_such_quantity"], "--of"),
    # no index completes in 0.1 s: an empty table is refused, not written (tornado.png had no panel to draw)
    # (the values of the tables above: the same traced program)
    (["--wrt", ",".join(WRT), "--of", "index_time_s", "--set", "duration=0.1 s"], "--of"),
    # the 1-D wall-track model is traced (tests/test_sensitivity_wall.py), its mesh settings are not (a choice)
    (["--wrt", "thermal.mesh_depth", "--set", "thermal.model=1d", "--set", "thermal.mesh_depth=10 mm"],
     "thermal.mesh_depth"),
])
def test_cli_refuses_what_is_not_traced_in_one_line(tmp_path, args, field):
    from cli_helpers import invoke, one_line_error
    out = tmp_path / "s"
    r = invoke("sensitivity", "geneva-motor", *args, "--out", out)
    assert r.exit_code == 2, r.output
    assert one_line_error(r).startswith(f"error: {field}:")
    assert not out.exists()


def test_an_untraced_value_is_refused_not_guessed():
    # a tuned chain's crank alone would detune its dwells (no derivative exists), a rolling pair on a circle has no
    # line angle, and a value the map does not know is not guessed: each refused by name
    with pytest.raises(mechsim.ScenarioError, match="^mechanism.crank_radius: .*tuned"):
        mechsim.sensitivity("chain-mech1-torque", wrt="mechanism.crank_radius")
    with pytest.raises(mechsim.ScenarioError, match="^mechanism.line_angle:"):
        mechsim.sensitivity("rolling-a-torque", wrt="mechanism.line_angle")
    with pytest.raises(mechsim.ScenarioError, match="^mechanism.start_rolling_angle:"):
        mechsim.sensitivity("rolling-a-torque", wrt="mechanism.start_rolling_angle")
    with pytest.raises(mechsim.ScenarioError, match=r"\(did you mean mechanism\.crank_radius\?\)"):   # misspelt
        mechsim.sensitivity("geneva-motor", wrt="mechanism.crank_radus")


def test_constant_torque_cycle_energy_is_exact(tables):
    """Over one drive revolution a constant torque T does the work 2 pi T whatever else changes: the derivative is
    exactly 2 pi in T and zero in every other value (docs/sensitivity.md, 'How it is checked'). The sensitivities,
    integrated at rtol 1e-10, accumulate ~1e-7 relative over the run's four cycles (measured 7e-8): 1e-6."""
    table = tables["geneva-torque"].set_index(["quantity", "wrt"])
    energy = table.xs("energy_per_cycle_J")
    assert energy["value"].iloc[0] == pytest.approx(2 * np.pi * 6.0, rel=1e-9)
    assert energy.loc["drive.torque", "derivative"] == pytest.approx(2 * np.pi, rel=1e-6)
    others = energy.drop(index="drive.torque")
    assert np.all(np.abs(others["elasticity"]) <= 1e-7), others["elasticity"]


def test_prescribed_speed_against_the_closed_form():
    """At a prescribed crank speed w the Geneva's motion is known in closed form (docs/theory.md §G1): wheel speed
    w G(alpha) and acceleration w^2 G'(alpha) at alpha = -pi + w t (start at -180 deg), index time 2 alpha0 / w,
    cycle time 2 pi / w, none of them depending on the crank radius; the normal force N = (J2 a2 + T_L) / (x - mu
    sigma R) (docs/theory.md §G2) is linear in the load and the wheel inertia at a fixed row. Their derivatives,
    at the table's own rows (a fixed t: d alpha / dw = t), against the sensitivities of the DAE with the speed as a
    constraint. The start angle theta0 moves alpha by as much at every row (the drive's angle0 moves with it): the
    wheel speed by w G'(alpha), the acceleration by w^2 G''(alpha) per radian, the index and cycle times not at all.
    The sensitivities carry ~1e-7 relative from their integration at rtol 1e-10 (see above): 1e-6."""
    import mechsim.mechanisms.geneva.kinematics as gk
    w = np.pi                                         # mid-engagement (alpha = 0) falls on the row t = 1 s
    sets = ["thermal.model=none", "duration=2.8 s", f"drive.speed={w!r} rad/s", "solver.rtol=1e-10",
            "solver.atol=1e-12", "mechanism.wheel_damping=0 N*m*s/rad"]
    wrt = ["drive.speed", "mechanism.crank_radius", "load.wheel_torque", "mechanism.wheel_inertia",
           "initial.crank_angle"]
    sc = mechsim.load("geneva-lc1", set=sets)
    table = sensitivity(sc, wrt).set_index(["quantity", "wrt"])
    m, si = sc.si["mechanism"], sc.si
    geom = gk.GenevaGeometry(m["crank_radius"], m["slots"], m["pin_radius"], m["thickness"])
    lam, a0 = geom.ratio, geom.engagement_half_angle

    def at(q):
        t = float(table.loc[(q, "drive.speed"), "t_s"])
        alpha = (-np.pi + w * t + np.pi) % (2 * np.pi) - np.pi
        return t, alpha

    seen = {}

    def check(q, key, expected, scale):
        got = table.loc[(q, key), "derivative"]
        seen[(q, key)] = f"{abs(got - expected) / scale:.1e}"
        assert abs(got - expected) <= 1e-6 * scale, (q, key, got, expected)

    t, al = at("peak_wheel_speed_rad_s")
    g, g1, g2 = (f(lam, al) for f in (gk.speed_ratio, gk.speed_ratio_derivative, gk.speed_ratio_second_derivative))
    check("peak_wheel_speed_rad_s", "drive.speed", g + w * g1 * t, abs(g))
    check("peak_wheel_speed_rad_s", "mechanism.crank_radius", 0.0, abs(g) * w / m["crank_radius"])
    check("peak_wheel_speed_rad_s", "initial.crank_angle", w * g1, abs(g) * w)
    t, al = at("peak_wheel_accel_rad_s2")
    g1, g2 = gk.speed_ratio_derivative(lam, al), gk.speed_ratio_second_derivative(lam, al)
    check("peak_wheel_accel_rad_s2", "drive.speed", 2 * w * g1 + w**2 * g2 * t, abs(2 * w * g1))
    check("peak_wheel_accel_rad_s2", "mechanism.crank_radius", 0.0, abs(w**2 * g1) / m["crank_radius"])
    check("peak_wheel_accel_rad_s2", "initial.crank_angle", w**2 * g2, abs(w**2 * g1))
    check("index_time_s", "drive.speed", -2 * a0 / w**2, 2 * a0 / w**2)
    check("cycle_time_s", "drive.speed", -2 * np.pi / w**2, 2 * np.pi / w**2)
    check("index_time_s", "mechanism.crank_radius", 0.0, 2 * a0 / w / m["crank_radius"])
    check("index_time_s", "initial.crank_angle", 0.0, 2 * a0 / w)
    check("cycle_time_s", "initial.crank_angle", 0.0, 2 * np.pi / w)
    # the normal force at its row: d/dT_L = 1 / (x - mu sigma R), d/dJ2 = a2 / (x - mu sigma R)
    t, al = at("peak_contact_force_N")
    a2 = w**2 * gk.speed_ratio_derivative(lam, al)
    w2 = w * gk.speed_ratio(lam, al)
    x = float(gk.pin_distance(geom, al))
    beta = gk.wheel_angle(lam, al)
    u = m["crank_radius"] * w * np.sin(al + beta) + m["pin_radius"] * (w + w2)      # driving flank
    arm = x - si["contact"]["friction"] * np.sign(u) * m["pin_radius"]
    check("peak_contact_force_N", "load.wheel_torque", 1 / arm, 1 / arm)
    check("peak_contact_force_N", "mechanism.wheel_inertia", a2 / arm, abs(a2 / arm))
    assert table.loc[("peak_contact_force_N", "drive.speed"), "value"] == pytest.approx(
        (m["wheel_inertia"] * a2 + si["load"]["wheel_torque"]) / arm, rel=1e-8)
    print("deviation from the closed form (relative to the scale):", seen)


def test_lengths_scale_out():
    """Scaling every length of the Geneva (r and R; c = r / sin(pi/n) follows) by s with the inertias, torques and
    friction kept leaves the motion in angle and time unchanged and every force times 1/s (the moment arms grow by
    s): the elasticities in crank and pin radius add up to -1 for the contact force and to 0 for the angular,
    time, torque and energy quantities, exactly (dimensional analysis); to the integration's ~1e-7 here."""
    sc = mechsim.load("geneva-motor", set=BASE)
    table = sensitivity(sc, ["mechanism.crank_radius", "mechanism.pin_radius"])
    total = table.groupby("quantity")["elasticity"].sum()
    assert total.pop("peak_contact_force_N") == pytest.approx(-1.0, abs=1e-7)
    assert np.all(np.abs(total.to_numpy()) <= 1e-7), total
    # and the single elasticities are not trivially zero
    assert np.all(np.abs(table["elasticity"]) > 1e-4)


def test_a_map_out_of_step_with_the_mechanism_is_caught(monkeypatch):
    """The scenario-to-parameter map is checked against the mechanism rebuilt with each value moved: a map that
    forgets the centre distance c = r / sin(pi/n) (it moves with the crank radius) is refused, not used."""
    import dataclasses

    import mechsim.mechanisms.geneva.sensitivity as geneva_map
    right = geneva_map.MAP

    def forgets_c(x, si, mech):
        out = right.parameters(x, si, mech)
        out.pop("c")
        return out
    monkeypatch.setattr(geneva_map, "MAP", dataclasses.replace(right, parameters=forgets_c))
    with pytest.raises(RuntimeError, match="'c' moves by"):
        sensitivity(mechsim.load("geneva-motor", set=["duration=0.2 s"]), ["mechanism.crank_radius"])
