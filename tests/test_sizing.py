"""`mechsim size` against a sizing problem with a closed-form optimum (docs/sensitivity.md, "Sizing").

A 4-slot Geneva at a prescribed crank speed w whose wheel is a pure inertia J2 (no load torque, damping or
friction): the contact force is N = J2 w^2 G'(alpha) / x(alpha) (docs/theory.md §G1-§G2), so its peak is
J2 w^2 Phi_n / r with Phi_n from the peak angle cos(alpha_N) = (-(1 + l^2) + sqrt((1 + l^2)^2 + 60 l^2)) / (6 l),
l = sin(pi/n); the index time is (pi - 2 pi/n) / w. The smallest crank radius with peak force <= N_max and index
time <= t_max is then w* = (pi - 2 pi/n) / t_max, r* = J2 w*^2 Phi_n / N_max, with both limits active and shadow
prices dr*/dN_max = -r*/N_max and dr*/dt_max = -2 r*/t_max. The run starts at the force peak, so that its first
output row is the peak for every design. The rows are 7 ms apart, not 10: at w* the crank period is 1.2 s, and on a
10 ms grid the second engagement's peak fell exactly on row 120, equal to row 0 to round-off; which row the table
took then depended on the BLAS kernel, and with it the derivative (row 120's carries 1.2 s of the DAE pass's
integration error, 1e-5 relative in the index-time shadow price). 1.2 s is no multiple of 7 ms, so row 0 is the
one peak.

One optimisation for the whole module (the sensitivity pass compiles once, ~15 s on the shared machine); the
refusals run nothing.
"""
import json
import math

import numpy as np
import pandas as pd
import pytest
from cli_helpers import invoke, one_line_error

import mechsim
from mechsim.scenarios.units import ScenarioError

N_MAX, T_MAX, J2, SLOTS = 8.0, 0.3, 1.5626e-3, 4


def closed_form(n: int = SLOTS):
    """(alpha_N, w*, r*) of the module's problem (derivation in docs/sensitivity.md, "Sizing")."""
    lam = math.sin(math.pi / n)
    cos_a = (-(1 + lam**2) + math.sqrt((1 + lam**2) ** 2 + 60 * lam**2)) / (6 * lam)
    alpha = math.acos(cos_a)
    d = 1 - 2 * lam * cos_a + lam**2
    phi = lam**2 * (1 - lam**2) * math.sin(alpha) / d**2.5
    w = (math.pi - 2 * math.pi / n) / T_MAX
    return alpha, w, J2 * w**2 * phi / N_MAX


def scenario_text() -> str:
    alpha, _, _ = closed_form()
    return f"""name = "geneva-sizing-inertia"
duration = "1.9 s"
output_step = "7 ms"

[mechanism]
type = "geneva"
slots = {SLOTS}
crank_radius = "75 mm"
pin_radius = "4 mm"
thickness = "4 mm"
crank_inertia = "0.02 kg*m^2"
wheel_inertia = "{J2!r} kg*m^2"

[initial]
crank_angle = "{-alpha!r} rad"
crank_speed = "6 rad/s"

[drive]
type = "speed"
speed = "6 rad/s"

[contact]
friction = 0.0

[solver]
backend = "ida"
method = "dae"
rtol = 1e-10
atol = 1e-12

[thermal]
model = "none"
"""


REQUEST = ["--vary", "mechanism.crank_radius=30:120 mm", "--vary", "drive.speed=4:10 rad/s",
           "--minimize", "mechanism.crank_radius",
           "--subject-to", f"peak_contact_force_N <= {N_MAX}", "--subject-to", f"index_time_s <= {T_MAX}"]


@pytest.fixture(scope="module")
def scenario_file(tmp_path_factory):
    path = tmp_path_factory.mktemp("sizing") / "inertia.toml"
    path.write_text(scenario_text())
    return path


@pytest.fixture(scope="module")
def sized(scenario_file, tmp_path_factory):
    out = tmp_path_factory.mktemp("sized") / "out"
    r = invoke("size", scenario_file, *REQUEST, "--out", out)
    assert r.exit_code == 0, r.output
    return out, json.loads((out / "summary.json").read_text())["sizing"]


def test_reproduces_the_closed_form_optimum(sized):
    """Both limits are active at the optimum, so it is the solution of two equations the run evaluates to its
    tolerance (rtol 1e-10): 1e-6 relative leaves four orders of magnitude for the optimiser's ftol (1e-9)."""
    _, s = sized
    _, w, r = closed_form()
    got = {d["key"]: d["value"] for d in s["design"]}
    assert s["success"]
    assert got["mechanism.crank_radius"] == pytest.approx(r, rel=1e-6)
    assert got["drive.speed"] == pytest.approx(w, rel=1e-6)
    assert s["objective"]["value"] == pytest.approx(r, rel=1e-6)


def test_kkt_conditions_hold_at_the_optimum(sized, scenario_file):
    """Activity and shadow prices as the closed form says, and stationarity checked with an independent
    sensitivity run at the design: grad r + sum_i mu_i grad q_i = 0 with mu_i = -shadow price_i >= 0."""
    import mechsim
    out, s = sized
    _, w, r = closed_form()
    limits = {c["quantity"]: c for c in s["constraints"]}
    assert all(c["active"] for c in limits.values())
    assert not any(b["active"] for b in s["bounds"])
    assert limits["peak_contact_force_N"]["shadow_price"] == pytest.approx(-r / N_MAX, rel=1e-6)
    assert limits["index_time_s"]["shadow_price"] == pytest.approx(-2 * r / T_MAX, rel=1e-6)
    assert s["kkt_residual_relative"] < 1e-6
    keys = ["mechanism.crank_radius", "drive.speed"]
    table = mechsim.sensitivity(out / "design.toml", wrt=keys, of=list(limits))
    grad = np.array([1.0, 0.0])
    for q, c in limits.items():
        part = table[table["quantity"] == q].set_index("wrt")
        grad += -c["shadow_price"] * part.loc[keys, "derivative"].to_numpy(float)
    scale = np.array([r, w])          # per relative change of each value
    assert np.max(np.abs(grad * scale)) < 1e-6 * r


def test_written_design_runs_and_meets_the_limits(sized):
    """design.toml is a scenario `mechsim run` accepts; re-run, its peak force and index time are at their limits
    (active) and within them to the feasibility tolerance (1e-8 relative)."""
    out, _ = sized
    r = invoke("run", out / "design.toml", "--out", out.parent / "rerun", "--quiet", "--set", "output.plots=false")
    assert r.exit_code == 0, r.output
    ts = pd.read_parquet(out.parent / "rerun" / "timeseries.parquet")
    ev = pd.read_csv(out.parent / "rerun" / "events.csv")
    peak = float(np.max(np.abs(ts["contact_force_N"])))
    exit_t = ev[ev["kind"] == "exit"]["t_s"].iloc[-1]
    entry_t = ev[(ev["kind"] == "entry") & (ev["t_s"] < exit_t)]["t_s"].iloc[-1]
    assert peak <= N_MAX * (1 + 1e-8) and peak == pytest.approx(N_MAX, rel=1e-6)
    assert exit_t - entry_t <= T_MAX * (1 + 1e-8) and exit_t - entry_t == pytest.approx(T_MAX, rel=1e-6)


def test_convergence_table_and_plot(sized):
    """One row per iteration with the design values in their units; the last row is the design, feasible."""
    out, s = sized
    h = pd.read_csv(out / "convergence.csv")
    assert list(h.columns) == ["iteration", "solve", "mechanism.crank_radius_m", "drive.speed_rad_s",
                               "objective_mechanism.crank_radius", "peak_contact_force_N", "index_time_s",
                               "max_violation", "evaluations", "peak_contact_force_N_limit", "peak_contact_force_N_run",
                               "index_time_s_limit", "index_time_s_run"]
    assert (h["solve"] == 0).all() and (h["peak_contact_force_N_limit"] == N_MAX).all()
    assert h["iteration"].tolist() == list(range(len(h)))
    assert h["mechanism.crank_radius_m"].iloc[-1] == pytest.approx(s["design"][0]["value"], rel=1e-12)
    assert h["max_violation"].iloc[0] > 0.05 and h["max_violation"].iloc[-1] <= 1e-8   # the start breaks a limit
    assert (out / "convergence.png").stat().st_size > 10_000


@pytest.mark.parametrize("args, field", [
    (["--vary", "mechanism.crank_radiu=30:120 mm", "--minimize", "peak_contact_force_N"], "--vary"),
    (["--vary", "mechanism.crank_radius=120:30 mm", "--minimize", "peak_contact_force_N"],
     "--vary mechanism.crank_radius"),
    (["--vary", "mechanism.crank_radius=30:120 mm", "--minimize", "peak_contact_temp_K"], "--minimize"),
    (["--vary", "mechanism.crank_radius=30:120 mm", "--minimize", "peak_temp_contact_C"], "--minimize"),
    (["--vary", "mechanism.crank_radius=30:120 mm", "--minimize", "mechanism.crank_radius",
      "--subject-to", "peak_contact_force_N < 8"], "--subject-to"),
    (["--vary", "mechanism.crank_radius=30:120 mm", "--minimize", "mechanism.crank_radius",
      "--subject-to", "peak_flux_W <= 8"], "--subject-to"),
    (["--vary", "mechanism.slots=3:40", "--vary", "mechanism.crank_radius=30:120 mm", "--minimize",
      "mechanism.crank_radius"], "--vary mechanism.slots"),
    (["--vary", "mechanism.crank_radius=30:120 mm", "--minimize", "mechanism.wheel_inertia"], "--minimize"),
])
def test_bad_requests_are_refused_in_one_line(scenario_file, tmp_path, args, field):
    out = tmp_path / "out"
    r = invoke("size", scenario_file, *args, "--out", out)
    assert r.exit_code == 2
    assert one_line_error(r).startswith(f"error: {field}:")
    assert not out.exists()


def test_slot_count_is_enumerated(sized, scenario_file):
    """The slot count is not differentiable (a whole number): each count gets its own continuous optimum and the
    best feasible one wins. At w = 6 rad/s the 4-slot optimum is the closed form r = J2 w^2 Phi_4 / N_max; the
    5-slot wheel's gentler kinematics allow a smaller crank, so 5 slots win."""
    import mechsim
    result = mechsim.size(scenario_file, vary=["mechanism.slots=4:5", "mechanism.crank_radius=30:120 mm"],
                          minimize="mechanism.crank_radius", subject_to=[f"peak_contact_force_N <= {N_MAX}"])
    choices = {c["slots"]: c for c in result.summary["slot_choices"]}
    assert set(choices) == {4, 5} and all(c["feasible"] for c in choices.values())
    lam = math.sin(math.pi / 4)
    alpha, _, _ = closed_form()
    d = 1 - 2 * lam * math.cos(alpha) + lam**2
    r4 = J2 * 6.0**2 * lam**2 * (1 - lam**2) * math.sin(alpha) / d**2.5 / N_MAX
    assert choices[4]["objective"] == pytest.approx(r4, rel=1e-6)
    assert choices[5]["objective"] < r4
    assert result.design.si["mechanism"]["slots"] == 5
    assert result.objective_value == choices[5]["objective"]
    assert abs(result.summary["quantities_at_optimum"]["peak_contact_force_N"]) <= N_MAX * (1 + 1e-8)


def test_minimising_a_quantity_with_a_bound_active(scenario_file):
    """Minimise the peak force itself: the crank radius goes to its upper bound and the speed to the index-time
    limit, N* = J2 w*^2 Phi_4 / r_high; the shadow prices are dN*/dr_high = -N*/r_high and dN*/dt_max = -2 N*/t_max
    (the bound's multiplier from the same KKT solve as the limits')."""
    import mechsim
    alpha, w, r = closed_form()
    n_star = r * N_MAX / 0.12           # J2 w*^2 Phi / r_high
    result = mechsim.size(scenario_file, vary=["mechanism.crank_radius=30:120 mm", "drive.speed=4:10 rad/s"],
                          minimize="peak_contact_force_N", subject_to=[f"index_time_s <= {T_MAX}"])
    assert result.objective_value == pytest.approx(n_star, rel=1e-6)
    assert result.values["drive.speed"] == pytest.approx(w, rel=1e-6)
    radius, speed = result.bounds
    assert radius["active"] == "high" and speed["active"] is None
    assert radius["shadow_price"] == pytest.approx(-n_star / 0.12, rel=1e-6)
    assert result.constraints[0]["active"]
    assert result.constraints[0]["shadow_price"] == pytest.approx(-2 * n_star / T_MAX, rel=1e-6)
    from matplotlib.backends.backend_agg import FigureCanvasAgg
    from mechsim.scenarios.studies.sizing import convergence_figure
    import dataclasses
    long = result.history.iloc[np.arange(18) % len(result.history)].reset_index(drop=True)
    long["iteration"] = np.arange(18)                   # 18 iterations: matplotlib ticked every 2.5 of them
    fig = convergence_figure(dataclasses.replace(result, history=long))
    FigureCanvasAgg(fig).draw()
    ticks = fig.axes[-1].get_xticks()                   # the convergence plot counts iterations in whole numbers
    assert len(ticks) >= 2 and np.all(ticks == np.round(ticks))


def test_infeasible_limits_exit_3_with_the_history(scenario_file, tmp_path):
    """No design within the bounds meets a 0.5 N limit (the largest crank at the slowest admissible speed gives
    4.1 N): exit 3 with one line saying so; the convergence table and summary are written, no design.toml."""
    out = tmp_path / "out"
    r = invoke("size", scenario_file, "--vary", "mechanism.crank_radius=30:120 mm", "--vary", "drive.speed=4:10 rad/s",
               "--minimize", "mechanism.crank_radius", "--subject-to", "peak_contact_force_N <= 0.5",
               "--subject-to", f"index_time_s <= {T_MAX}", "--out", out)
    assert r.exit_code == 3
    assert "no feasible design found" in one_line_error(r)
    s = json.loads((out / "summary.json").read_text())["sizing"]
    assert not s["success"] and s["max_violation_relative"] > 1
    assert (out / "convergence.csv").exists() and not (out / "design.toml").exists()
    # the least violation: the force falls as 1/r, so the largest crank, at the closed form's force for its speed
    x = {d["key"]: d["value"] for d in s["design"]}
    _, w_star, r_star = closed_form()
    phi = r_star * N_MAX / (J2 * w_star**2)
    assert x["mechanism.crank_radius"] == pytest.approx(0.12, rel=1e-9)
    assert s["quantities_at_optimum"]["peak_contact_force_N"] == pytest.approx(
        J2 * x["drive.speed"] ** 2 * phi / 0.12, rel=1e-6)
    # ended where its iterates settled there (SLSQP alone went on for 17 iterations and 40 runs to the same design)
    assert s["iterations"] <= 6 and "the least violation it reaches" in s["message"]


# ------------------------------------------------------------------------------------------------ verification
# `mechsim size` checks the written design on its own run (summary.json peaks, the events' index time) against the
# limits as given; a limit the run breaks is tightened by the excess and a margin (sizing.py `tightening`) and the
# sizing solved again (at most 3 times), else exit 3 without design.toml. Here the run is the closed form's (the
# scenario's DAE with rtol 1e-10 for the sizing: they agree to ~1e-11), and a discrepancy is forced by adding to
# what the run reports (sizing.size's `check`), so that the re-solved optimum has a closed form too.

def test_written_design_is_checked_on_its_own_run(sized):
    """The checks are in summary.json (`verification`), convergence.csv (the run's values on the design's row) and
    the printout; the run reports the sizing's values to the feasibility tolerance (1e-8 of the limit)."""
    out, s = sized
    v = s["verification"]
    assert v["holds"] and v["resolves"] == 0
    checks = {e["quantity"]: e for e in v["limits"]}
    assert set(checks) == {"peak_contact_force_N", "index_time_s"}
    for q, limit in (("peak_contact_force_N", N_MAX), ("index_time_s", T_MAX)):
        e = checks[q]
        assert e["checked"] and e["holds"] and e["limit"] == limit
        assert abs(e["run_value"] - e["sizing_value"]) <= 1e-8 * limit
        assert e["run_value"] <= limit * (1 + 1e-8)
    h = pd.read_csv(out / "convergence.csv")
    assert h["peak_contact_force_N_run"].iloc[-1] == pytest.approx(checks["peak_contact_force_N"]["run_value"],
                                                                    rel=1e-12)
    assert h["peak_contact_force_N_run"].iloc[:-1].isna().all()


def _offset_check(offset):
    """The design's own run, with `offset(value)` added to the peak force it reports (a forced discrepancy)."""
    from mechsim.scenarios.studies.sizing import design_run

    def check(design):
        got = design_run(design)
        got["peak_contact_force_N"] = offset(got["peak_contact_force_N"])
        return got
    return check


def _size_direct(scenario_file, **kwargs):
    import mechsim
    from mechsim.scenarios.studies.sizing import size
    return size(mechsim.load(scenario_file), ["mechanism.crank_radius=30:120 mm", "drive.speed=4:10 rad/s"],
                "mechanism.crank_radius", [f"peak_contact_force_N <= {N_MAX}", f"index_time_s <= {T_MAX}"],
                **kwargs)


def test_a_limit_the_run_breaks_is_tightened_and_solved_again(scenario_file):
    """A run that reports the force 1e-3 N_MAX higher than the sizing breaks the limit by that much at the first
    optimum; the limit is tightened to N' = N_MAX - (e + 2e-8 N_MAX + 0.1 e), e the excess, and the re-solved
    optimum is the closed form at N': r' = r* N_MAX / N' (w* unchanged); its run, with the same offset, holds."""
    from mechsim.scenarios.studies.sizing import EXCESS_MARGIN, FEASIBLE
    delta = 1e-3 * N_MAX
    result = _size_direct(scenario_file, check=_offset_check(lambda q: q + delta))
    _, w, r = closed_form()
    v = result.summary["verification"]
    assert v["holds"] and v["resolves"] == 1
    first = {e["quantity"]: e for e in v["stages"][0]["limits"]}["peak_contact_force_N"]
    # the first optimum has the force at its limit (aimed FEASIBLE inside it), the run delta above that: the
    # excess the limit is tightened by is the run's over the sizing's value, delta
    excess = first["run_value"] - first["sizing_value"]
    assert excess == pytest.approx(delta, rel=1e-6)
    assert first["run_value"] - N_MAX == pytest.approx(delta - FEASIBLE * N_MAX, rel=1e-6)
    tightened = N_MAX - (excess + 2 * FEASIBLE * N_MAX + EXCESS_MARGIN * excess)
    assert first["tightened_to"] == pytest.approx(tightened, rel=1e-14)
    assert result.values["mechanism.crank_radius"] == pytest.approx(r * N_MAX / tightened, rel=1e-6)
    assert result.values["drive.speed"] == pytest.approx(w, rel=1e-6)
    final = {e["quantity"]: e for e in v["limits"]}["peak_contact_force_N"]
    assert final["holds"] and final["run_value"] <= N_MAX and final["limit_solved"] == first["tightened_to"]
    # margin left: the run is below the limit by the margin (0.1 e + 2e-8 N_MAX), to the solver's 1e-6
    assert N_MAX - final["run_value"] == pytest.approx(EXCESS_MARGIN * excess + 2 * FEASIBLE * N_MAX, rel=1e-2)
    assert result.summary["constraints"][0]["constraint"].startswith("peak_contact_force_N <= 7.99")
    assert set(result.history["solve"]) == {0, 1}


def test_a_limit_the_run_keeps_breaking_exits_3_without_a_design(scenario_file, tmp_path):
    """A run that always reports 1e-3 over the force limit, whatever the design: after the allowed re-solves
    (one here, to keep the test short) the sizing fails with one line naming the limit and the excess; saved, it
    writes the convergence table and summary (verification: does not hold) and no design.toml."""
    from mechsim.scenarios.studies.sizing import SizingFailed
    with pytest.raises(SizingFailed) as err:
        _size_direct(scenario_file, check=_offset_check(lambda q: N_MAX * (1 + 1e-3)), max_resolves=1)
    message = str(err.value)
    assert "\n" not in message
    assert message.startswith(f"the design's own run breaks peak_contact_force_N <= {N_MAX:g}")
    assert "0.008 beyond it (0.001 of the limit)" in message and "after 1 tightened re-solves" in message
    result = err.value.result
    assert not result.success and not result.summary["verification"]["holds"]
    assert result.summary["verification"]["resolves"] == 1
    result.save(tmp_path / "out")
    assert (tmp_path / "out" / "summary.json").exists() and not (tmp_path / "out" / "design.toml").exists()
    h = pd.read_csv(tmp_path / "out" / "convergence.csv")
    assert set(h["solve"]) == {0, 1}


# ------------------------------------------------------------------------------------------------ list entries
@pytest.mark.parametrize("name, key, spec, change", [
    ("chain-mech1-torque", "mechanism.sprocket_radii[0]", "2:4 cm", 2e-4),
    ("chain-mech1-torque", "mechanism.sprockets[1][0]", "-50:50 cm", -3e-4),
    ("rolling-a-speed", "mechanism.profile_centre[1]", "0.2:0.4 m", 0.05),
])
def test_list_entries_are_varied_and_written_into_the_design(tmp_path, name, key, spec, change):
    """`--vary` takes a list entry as the loader's messages name it: its bound in the list's unit, the design
    scenario with that entry set (the list's other entries as they were), design.toml that loads back to it, and
    the sensitivity table's unit for it (scenarios/keys.py `field_unit`)."""
    from mechsim.scenarios.output.writer import resolved_scenario_toml
    from mechsim.scenarios.studies.sizing import Problem, parse_bound
    from mechsim.scenarios.keys import field_unit, lookup
    base = mechsim.load(name)
    bound = parse_bound(f"{key}={spec}", base.si)
    assert (bound.key, bound.unit) == (key, "m") and field_unit(base.si, key) == "m"
    value = lookup(base.si, key) + change
    design = Problem(base, [bound], key, [], []).scenario_at([value])
    assert lookup(design.si, key) == value
    whole = key.split("[")[0]
    before, after = np.array(lookup(base.si, whole), float), np.array(lookup(design.si, whole), float)
    changed = np.argwhere(before != after)
    assert [list(map(int, c)) for c in changed] == [[int(i) for i in key[len(whole):].strip("[]").split("][")]]
    path = tmp_path / "design.toml"
    path.write_text(resolved_scenario_toml(design.si))
    assert lookup(mechsim.load(str(path)).si, key) == value


@pytest.mark.parametrize("text, fragment", [
    ("mechanism.sprocket_radii=2:4 cm", "name one entry"),
    ("mechanism.sprocket_radii[3]=2:4 cm", "no such entry"),
    ("mechanism.sprockets[1]=2:4 cm", "name one entry"),
])
def test_list_entry_requests_are_refused_in_one_line(text, fragment):
    from mechsim.scenarios.studies.sizing import parse_bound
    with pytest.raises(ScenarioError, match=fragment):
        parse_bound(text, mechsim.load("chain-mech1-kinematic").si)


class _Sawtooth:
    """One limit q(u) <= L on a sawtooth in u0 (teeth of slope 0.5 and width W, each step up 0.5 W: a trend of
    slope 1, as a cycle-averaged peak's across repetitions), smooth in u1; the optimiser sees the trend, the local
    derivative is the tooth's. Stands in for `Problem` in `_restore` (violation, c_aimed, c_jac, record)."""
    W = 1e-3

    def __init__(self, u_start, outside):
        self.L = self.q(u_start) / (1.0 + outside)
        self.rows = []

    def q(self, u):
        return 0.5 * u[0] + 0.5 * self.W * np.floor(u[0] / self.W) + 0.2 * u[1]

    def c(self, u):
        return np.array([(self.L - self.q(u)) / self.L])

    def c_aimed(self, u):
        from mechsim.scenarios.studies.sizing import FEASIBLE
        return self.c(u) - FEASIBLE

    def c_jac(self, u, local=False):
        return -np.array([[0.5 if local else 1.0, 0.2]]) / self.L

    def violation(self, u):
        return float(max(0.0, -self.c(u)[0]))

    def record(self, u):
        self.rows.append(np.array(u))


def test_a_design_just_outside_a_sawtooth_limit_is_moved_onto_it():
    """Where the optimiser ends just outside a limit (5e-8 of it: SLSQP stops on its objective tolerance, its steps
    taken with a cycle-averaged peak's trend, whose slope is not the teeth's), `_restore` moves the design onto the
    limit with the local derivative in one Newton step (exact on the linear tooth); the trend's step would leave
    half the aimed residual outside."""
    from mechsim.scenarios.studies.sizing import FEASIBLE, _restore
    u0 = np.array([0.6005, 0.3])          # mid-tooth
    problem = _Sawtooth(u0, 5e-8)
    assert problem.violation(u0) > FEASIBLE
    u = _restore(problem, u0)
    assert problem.violation(u) == 0.0 and problem.c(u)[0] == pytest.approx(FEASIBLE, rel=1e-6)
    assert len(problem.rows) == 1
    step = np.linalg.lstsq(problem.c_jac(u0), -problem.c_aimed(u0), rcond=None)[0]
    assert problem.violation(u0 + step) > FEASIBLE


def test_a_sizing_limit_may_name_the_maximum(scenario_file):
    """The module's problem with the limit on the contact force's maximum by name (`max_contact_force_N`, summary.json
    peaks.contact_force_N.max; docs/sensitivity.md "Quantities"): the force does not change sign, so its max is its
    peak, and at the scenario's 6 rad/s the smallest crank radius is r = J2 w^2 Phi_4 / N_max; the design's own run
    reports the same max at the limit."""
    result = mechsim.size(scenario_file, vary=["mechanism.crank_radius=30:120 mm"], minimize="mechanism.crank_radius",
                          subject_to=[f"max_contact_force_N <= {N_MAX}"])
    _, w, r = closed_form()
    r = r * (6.0 / w) ** 2                  # the closed form's radius at the scenario's 6 rad/s (N ~ w^2 / r)
    assert result.objective_value == pytest.approx(r, rel=1e-6)
    (check,) = result.summary["verification"]["limits"]
    assert check["quantity"] == "max_contact_force_N" and check["holds"]
    assert check["run_value"] == pytest.approx(N_MAX, rel=1e-6)


class _Trace:
    """A sizing problem's callback face (`record`, `f`, `violation`) replaying given objectives and violations."""

    def __init__(self, objectives, violations):
        self.objectives, self.violations, self.rows = iter(objectives), iter(violations), []

    def record(self, u):
        self.rows.append(u)

    def f(self, u):
        return next(self.objectives)

    def violation(self, u):
        return next(self.violations)


def test_slsqp_is_stopped_where_its_iterates_settle_at_a_feasible_design():
    """scipy's SLSQP since 1.16 went on cycling in its line search at the optimum of a sizing whose values carry a
    run's integration noise (docs/sensitivity.md's first example: 43 iterations and 62 runs where scipy 1.15 took 7
    and 9). The callback ends it once SETTLED iterations in a row changed the normalised objective by at most the
    tolerance at a feasible design, the classic SLSQP test; not while a limit is still broken, nor on one small
    change."""
    from mechsim.scenarios.studies.sizing import FEASIBLE, SETTLED, _Settled, _settling
    assert SETTLED == 2
    callback = _settling(_Trace([1.0, 0.6, 0.6 + 1e-9, 0.6 + 2e-9], [0.1, 0.0, 0.0, 0.0]), 1e-7)
    for u in range(3):
        callback(np.array([u]))
    with pytest.raises(_Settled) as stop:
        callback(np.array([3.0]))
    assert stop.value.u.tolist() == [3.0]
    broken = _settling(_Trace([0.6, 0.6, 0.6, 0.6, 0.6], [0.0, 10 * FEASIBLE, 0.0, 10 * FEASIBLE, 0.0]), 1e-7)
    for u in range(5):                # every other iterate breaks a limit: never two feasible in a row
        broken(np.array([u]))
    # a limit broken throughout: ended where neither the objective nor the violation moves any more ...
    stuck = _settling(_Trace([1.0, 0.7, 0.7 + 1e-9, 0.7 + 2e-9], [0.5, 0.07, 0.07 + 1e-9, 0.07]), 1e-7)
    for u in range(3):
        stuck(np.array([u]))
    with pytest.raises(_Settled) as stop:
        stuck(np.array([3.0]))
    assert not stop.value.feasible and stop.value.u.tolist() == [3.0]
    # ... not while the violation still falls, though the objective stands still
    falling = _settling(_Trace([0.7] * 5, [0.5, 0.4, 0.3, 0.2, 0.1]), 1e-7)
    for u in range(5):
        falling(np.array([u]))


def test_a_sizing_on_noisy_runs_converges_in_few_runs():
    """docs/sensitivity.md's first sizing (geneva-motor for 2 s: the smallest crank radius with the peak contact
    force <= 200 N and the index time <= 0.3 s, varying the motor's stall torque too; runs at rtol 1e-8, whose
    values carry 1e-9 of noise) converges within a dozen iterations and runs with both limits met, whichever
    scipy: SLSQP of scipy 1.17 alone took 43 iterations and 62 runs to the same design."""
    result = mechsim.size("geneva-motor", vary=["mechanism.crank_radius=40:120 mm", "drive.stall_torque=20:80 N*m"],
                          minimize="mechanism.crank_radius",
                          subject_to=["peak_contact_force_N <= 200", "index_time_s <= 0.3"], set=["duration=2 s"])
    h = result.history
    assert len(h) - 1 <= 12 and h["evaluations"].iloc[-1] <= 16
    assert result.values["mechanism.crank_radius"] == pytest.approx(0.0855134545, rel=1e-7)
    assert all(c["value"] <= c["limit"] * (1 + 1e-8) for c in result.constraints)
