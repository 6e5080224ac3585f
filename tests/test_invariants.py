"""Physical invariants on every output row (issue 17 item 3): a broken one is a failure with its time.

The forced violations are the real symptom: a friction force pointing along the slip (the sign of the Geneva's
`slide` flipped on one segment, as a missed stall did), which makes friction power negative - energy created -
while the work states stay consistent; and a jump in a work column that the kinetic energy does not follow.
"""
from __future__ import annotations

import numpy as np
import pytest

import mechsim
from mechsim.dynamics.hybrid import simulate
from mechsim.dynamics.result import FailureCode
from mechsim.dynamics.invariants import QUADRATURE_FACTOR, energy_closure, first_violation, trapezoid_error_estimate
from mechsim.scenarios.runner import run

TORQUE = ["duration=0.6 s", "contact.friction=0.15"]


def flipped_slide(piece_index: int):
    """A backend call whose trajectory has the friction direction of one segment reversed."""
    def integrate(*args, **kwargs):
        traj = simulate(*args, **kwargs)
        piece = traj.pieces[piece_index]
        k = traj.model.parameter_names.index("slide")
        params = list(piece.params)
        params[k] = -params[k]
        piece.params = tuple(params)
        integrate.first_time = float(piece.t[0])
        return traj
    return integrate


def test_friction_along_the_slip_is_a_failure_at_its_first_row():
    sc = mechsim.load("geneva-torque", set=TORQUE)
    good = run(sc)
    assert good.success and first_violation(good.timeseries, good.events, 1e-8, 1e-10) is None
    engaged = good.timeseries[(good.timeseries["mode"] == "engaged") & (good.timeseries["friction_power_W"] > 1.0)]
    assert len(engaged), "the scenario must slide with friction"
    # the first engaged segment is piece 2 (piece 0: the initial state, piece 1: the first dwell)
    integrate = flipped_slide(2)
    bad = run(sc, integrate=integrate)
    assert not bad.success
    assert "friction power" in bad.failure.reason and "invariant" in bad.failure.reason
    assert bad.failure.code is FailureCode.INVARIANT_VIOLATED
    ts = good.timeseries.set_index("t_s")
    first_bad = ts.index[(ts.index >= integrate.first_time) & (ts["friction_power_W"] > 0)][0]
    assert bad.failure.time == pytest.approx(first_bad, abs=1e-12)
    # nothing from the violating row on is written; everything before it is the good run's
    assert bad.timeseries["t_s"].max() < first_bad
    n = len(bad.timeseries)
    assert np.array_equal(bad.timeseries["crank_angle_rad"].to_numpy(), good.timeseries["crank_angle_rad"][:n])


def test_energy_created_in_a_work_column_is_caught_at_its_row():
    r = run(mechsim.load("geneva-torque", set=TORQUE))
    df = r.timeseries.copy()
    closure = energy_closure(df, r.events)
    scale = df["work_drive_J"].abs().max()
    assert np.max(np.abs(closure)) < 1e-6 * scale       # closes to the integrator's tolerance (rtol 1e-8)
    i = len(df) // 3
    df.loc[i:, "work_drive_J"] += 1e-3 * scale          # 0.1 % of the drive work appears from nowhere
    v = first_violation(df, r.events, 1e-8, 1e-10)
    assert v is not None and v.invariant.startswith("energy") and v.time == df["t_s"].iloc[i]


def test_heat_that_decreases_is_caught():
    r = run(mechsim.load("geneva-lc1", set=["duration=0.5 s", "thermal.model=lumped"]))
    df = r.timeseries
    assert "heat_generated_J" in df and first_violation(df, r.events, 1e-8, 1e-10, exact=True) is None
    bad = df[["t_s", "mode", "heat_generated_J"]].copy()
    i = len(bad) // 2
    bad.loc[i:, "heat_generated_J"] -= bad["heat_generated_J"].iloc[i] + 1e-3   # below its start
    v = first_violation(bad, None, 1e-8, 1e-10)
    assert v is not None and v.invariant.startswith("heat generated") and v.time == bad["t_s"].iloc[i]


@pytest.mark.parametrize("name", mechsim.builtins())
def test_every_builtin_keeps_its_invariants(name):
    r = run(mechsim.load(name, set=["duration=0.3 s"]))
    assert r.failure is None or r.failure.kind == "physics", r.failure and r.failure.message()
    exact = r.summary["model"]["method"] == "closed-form"
    assert first_violation(r.timeseries, r.events, r.summary["model"]["rtol"], r.summary["model"]["atol"],
                           exact) is None


def test_friction_direction_follows_the_slip_across_a_flank_switch():
    """The case the invariant found on the robustness grid: at a flank switch the slip's spin term changes sign,
    so the slip can change sign with it; the friction direction must be re-chosen there (before, friction
    pushed along the slip for the rest of the engagement: -0.94 W at t = 0.561 s on all three solvers)."""
    r = run(mechsim.load("geneva-torque", set=["mechanism.slots=5", "drive.torque=12 N*m", "load.wheel_torque=5 N*m",
                                               "contact.friction=0.15", "duration=0.6 s"]))
    assert r.success, r.failure and r.failure.message()
    assert (r.events["kind"] == "flank switch").sum() >= 8
    df = r.timeseries
    engaged = df[df["mode"] == "engaged"]
    # friction opposes the slip on every row where the slip is resolved (|u| above the integrator's 1e-6 m/s)
    resolved = engaged[engaged["slip_speed_m_s"].abs() > 1e-6]
    assert (np.sign(resolved["friction_force_N"]) == np.sign(resolved["slip_speed_m_s"])).all()


def _trapezoid_work(p, t):
    return np.concatenate([[0.0], np.cumsum(0.5 * (p[1:] + p[:-1]) * np.diff(t))])


def test_trapezoid_estimate_matches_the_error_where_the_power_is_smooth():
    """p = e^t: every panel's error is h^3 e^t / 12 with one sign, so the estimate is the error itself (to O(h))."""
    t = np.linspace(0.0, 1.0, 201)
    work = _trapezoid_work(np.exp(t), t)
    error = work - (np.exp(t) - 1.0)
    ratio = error[1:] / trapezoid_error_estimate(work)[1:]
    assert np.all((ratio > 0.97) & (ratio < 1.0))


@pytest.mark.parametrize("offset", [0.01, 0.25, 0.5, 0.75, 0.97, 0.999])
def test_trapezoid_estimate_bounds_a_jump_or_kink_inside_a_panel(offset):
    """A power that jumps (by J) or kinks (slope by J') between two rows, as at the chain's arc entry: the trapezoid's
    error is J (s - h/2) or J' s (h - s) / 2 with s the jump's distance to the panel's end; the estimate, taking the
    largest of the three centred second differences around each panel, is J h / 8 (J' h^2 / 12) there, so the
    error stays within 4 (1.5) times it on every row: within QUADRATURE_FACTOR. Before, the row ending the jump's
    panel had only J h / 24 (1.7 ms-row chain runs stopped with 'energy balance closure error')."""
    h = 1e-3
    t = np.arange(0.0, 0.05 + h / 2, h)
    c = t[20] + offset * h
    jump = np.where(t >= c, 1.0, 0.0)
    kink = np.maximum(t - c, 0.0) * 1e3
    for power, exact, worst in [(jump, np.maximum(t - c, 0.0), 4.0),
                                (kink, 0.5e3 * np.maximum(t - c, 0.0) ** 2, 1.5)]:
        work = _trapezoid_work(power, t)
        error, estimate = np.abs(work - exact), trapezoid_error_estimate(work)
        seen = estimate > 0
        assert np.all(error[~seen] < 1e-15)              # before the jump the rule is exact, and so is its estimate
        assert np.max(error[seen] / estimate[seen]) <= worst * (1 + 1e-9) and worst <= QUADRATURE_FACTOR


@pytest.mark.parametrize("step", ["1 ms", "3.7 ms"])
def test_a_closed_form_chain_closes_its_energy_on_a_fine_grid(step):
    """The chain's power jumps at each arc entry, between two output rows: on these grids the energy check refused
    the run at t = 2.36 s (closure 4.21e-8 J against a bound of 4.15e-8 J); the closure stays well within it."""
    r = run(mechsim.load("chain-mech1-kinematic", set=["output.plots=false", f"output_step={step!r}".replace("'", '"'),
                                                      "duration=3 s"]))
    assert r.success, r.failure and r.failure.message()
    closure = energy_closure(r.timeseries, r.events)
    work = r.timeseries[[c for c in r.timeseries if c.startswith("work_")]].to_numpy().sum(axis=1)
    assert np.max(np.abs(closure)[1:] / trapezoid_error_estimate(work)[1:]) < QUADRATURE_FACTOR / 2


def test_a_long_run_up_keeps_its_energy_balance_within_its_steps():
    """rolling-crank-torque run up for 40 s, ten times its own duration: the crank speeds up all the way, so IDA
    takes 1.7e5 steps, about 100 times the 4 s run's. Its energy closure error grows with them: 2.6e-4 J near 38 s,
    about 1100 tolerance units, past GLOBAL_FACTOR (1000). Until the bound counted the run's steps, the run stopped
    there with "physical invariant broken". The error is the integration's: it scales with rtol. It is within the
    sum of the steps' local errors (`invariants.global_factor`), so both runs complete."""
    closure = {}
    for rtol in (1e-9, 1e-10):
        r = run(mechsim.load("rolling-crank-torque", set=[
            "duration=40 s", "output.plots=false", 'solver.backend="ida-compiled"', f"solver.rtol={rtol}",
            f"solver.atol={rtol / 10}"]))
        assert r.failure is None, r.failure.message()
        df, steps = r.timeseries, r.summary["solver"]["accepted_steps"]
        works = df[[c for c in df if c.startswith("work_")]].to_numpy(float)
        scale = float(np.abs(works - works[0]).max(axis=0).sum() + df["kinetic_energy_J"].abs().max())
        closure[rtol] = abs(energy_closure(df, r.events)[-1])
        assert steps > 1e5 and closure[rtol] <= steps * (rtol + rtol / 10) * scale
    assert 3.0 < closure[1e-9] / closure[1e-10] < 30.0, closure


@pytest.mark.parametrize("name", ["rolling-a-speed", "rolling-c-cusp"])
def test_the_relative_closure_error_is_against_the_energy_the_run_exchanges(name):
    """Over whole periods of a prescribed motion against gravity (or none) the net works are round-off (1.5e-14 J
    on rolling-a-speed), though the drive and gravity exchange joules within the period: the summary's relative
    closure error is the closure over the largest energy a term of the balance reaches (a work or the kinetic
    energy's change from the first row), so a closed form closes to round-off of it, as its works are exact to
    the Gauss-Lobatto panels' tolerance (1e-10 of the powers' scale) and here cancel to round-off. Over the net
    drive work it read 4.6 on rolling-a-speed."""
    r = run(mechsim.load(name, set=["output.plots=false"]))
    df, energy = r.timeseries, r.summary["energy"]
    works = df[[c for c in df.columns if c.startswith("work_") and c.endswith("_J")]].to_numpy(float)
    ke = df["kinetic_energy_J"].to_numpy(float)
    exchanged = max(np.abs(works - works[0]).max(), np.abs(ke - ke[0]).max())
    assert exchanged > 1e-3 and abs(energy["work_J"]["drive"]) < 1e-9 * exchanged
    assert energy["closure_error_relative"] == pytest.approx(energy["closure_error_J"] / exchanged, rel=1e-12)
    assert energy["largest_term_J"] == pytest.approx(exchanged, rel=1e-12)
    assert abs(energy["closure_error_relative"]) < 1e-12


def test_the_report_shows_a_round_off_energy_term_as_zero():
    """internal-geneva-motor has no impacts: its pin enters and leaves the slot tangentially, so each restart's
    projection loses only round-off of kinetic energy (1.1e-16 J against the 52 J its drive does in 5 s).
    report.html shows that term as 0, within 1e-12 of the largest energy term (`console.as_shown`); summary.json
    keeps the number, and the terms above round-off and the closure error keep their digits."""
    from mechsim.scenarios.output.report_html import report_html
    from mechsim.scenarios.console import ROUNDOFF_SHOWN
    r = run(mechsim.load("internal-geneva-motor", set=["output.plots=false", "duration=2 s"]))
    energy = r.summary["energy"]
    assert 0.0 < abs(energy["impact_losses_J"]) <= ROUNDOFF_SHOWN * energy["largest_term_J"]
    html = report_html(r, {})
    assert f"{energy['impact_losses_J']:.6g}" not in html
    assert '<td>impact losses</td><td class="num">0</td>' in html
    for value in (energy["work_J"]["drive"], energy["kinetic_energy_change_J"], energy["closure_error_J"]):
        assert f"{value:.6g}" in html
