"""The figures of a run, read back from the Figure objects: labelled axes, one unit per axis, legends outside
the data, versus-angle figures over one cycle of the driven member with a line per cycle, and drawings."""
import math
import re

import numpy as np
import pytest
from matplotlib.backends.backend_agg import FigureCanvasAgg

from mechsim.scenarios.loader import build_mechanism, load
from mechsim.mechanisms.geneva.drawing import geneva_wheel_outline, locking_disc_outline, locking_radius
from mechsim.scenarios.output.plots import figures
from mechsim.scenarios.runner import run

#: SI suffix of a column -> the unit its axis must show
UNITS = {"_rad_s2": "rad/s²", "_rad_s": "rad/s", "_rad": "deg", "_N_m": "N·m", "_N": "N", "_m_s": "m/s",
         "_W": "W", "_C": "°C", "_K": "K", "_J": "J", "_Pa": "MPa"}

CASES = {   # scenario, overrides, driven angle column, cycle (rad), cycle start (rad)
    "geneva": ("geneva-lc1", ["duration='2.5 s'", "output_step='2 ms'"], "crank_angle_rad", 2 * math.pi, -math.pi),
    "chain": ("chain-mech1-kinematic", ["duration='20 s'", "output_step='20 ms'"], "drive_angle_rad", None, 0.0),
    "rolling": ("rolling-a-speed", ["duration='12 s'", "output_step='20 ms'"], "rolling_angle_rad", 6 * math.pi, 0.0),
}


@pytest.fixture(scope="module", params=sorted(CASES))
def case(request):
    name, overrides, column, period, start = CASES[request.param]
    sc = load(name, overrides)
    result = run(sc)
    mech = build_mechanism(sc.si)
    if period is None:
        period = mech.kin.cycle_angle     # El-Shakery eq. (31): one chain circuit
    return request.param, result, figures(result, mech), column, period, start


def _unit(column):
    return "–" if column.startswith("peclet_") else next(u for s, u in UNITS.items() if column.endswith(s))


def _axes(figs):
    for stem, fig in figs.items():
        for ax in fig.axes:
            yield stem, fig, ax


def test_every_axis_names_quantity_and_one_unit(case):
    kind, result, figs, *_ = case
    assert {"motion_vs_time", "motion_vs_angle", "forces_vs_time", "forces_vs_angle", "mechanism"} <= set(figs)
    for stem, fig, ax in _axes(figs):
        m = re.fullmatch(r".+ \((.+)\)", ax.get_ylabel())
        assert m, f"{stem}: y label {ax.get_ylabel()!r} names no unit"
        if stem.endswith(("_vs_time", "_vs_angle")):
            units = {_unit(line.get_gid().split("#")[0]) for line in ax.get_lines()}
            assert units == {m.group(1)}, f"{stem}: axis {ax.get_ylabel()!r} holds {units}"
    for stem, fig in figs.items():
        assert re.fullmatch(r".+ \((.+)\)", fig.axes[-1].get_xlabel()) if stem != "mechanism" else True


def test_legends_sit_outside_the_data(case):
    _, _, figs, *_ = case
    for stem, fig in figs.items():
        if not stem.endswith(("_vs_time", "_vs_angle")):
            continue
        FigureCanvasAgg(fig).draw()
        for ax in fig.axes:
            legend = ax.get_legend()
            if legend is not None:
                assert legend.get_window_extent().x0 >= ax.get_window_extent().x1 - 1.0, stem


def test_versus_angle_spans_one_cycle_of_the_driven_member_a_line_per_cycle(case):
    kind, result, figs, column, period, start = case
    theta = result.timeseries[column].to_numpy(float)
    cycles = np.floor((theta - start) / period + 1e-12)
    if cycles[-1] != cycles[-2]:
        cycles[-1] = cycles[-2]      # the last row closes the cycle it ends
    n_cycles = len(np.unique(cycles))
    assert n_cycles >= 2
    for stem in ("motion_vs_angle", "forces_vs_angle"):
        fig = figs[stem]
        assert ("mid-engagement" in fig.axes[-1].get_xlabel()) == (kind == "geneva")
        for ax in fig.axes:
            lo, hi = ax.get_xlim()
            assert lo == pytest.approx(math.degrees(start)) and hi == pytest.approx(math.degrees(start + period))
            per_column = {}
            for line in ax.get_lines():
                col, cyc = line.get_gid().split("#cycle")
                x = line.get_xdata()
                assert x.min() >= math.degrees(start) - 1e-9 and x.max() <= math.degrees(start + period) + 1e-9
                assert np.all(np.diff(x) > 0), f"{stem} {col}: a cycle's line runs backwards"
                per_column.setdefault(col, set()).add(int(cyc))
            assert column not in per_column
            assert all(len(c) == n_cycles for c in per_column.values()), per_column


def test_geneva_wheel_outline_has_slots_2R_wide_and_locking_arcs():
    """The wheel's slot flanks lie R off the slot line, the slot bottom at c - r - R, the rim at c cos(pi/n),
    and between slots the locking arc is the crank's locking disc (radius r - 2R about the dwell position)."""
    sc = load("geneva-lc1", [])
    g = build_mechanism(sc.si).geometry
    c, r, R, n = g.centre_distance, g.crank_radius, g.pin_radius, g.slots
    pts = geneva_wheel_outline(g)
    rho = np.hypot(*pts.T)
    assert rho.max() == pytest.approx(g.entry_pin_distance, rel=1e-12)
    assert rho.min() == pytest.approx(c - r - R, rel=1e-9)         # the slot bottom, reached by the pin
    for j in range(n):
        a = j * g.pitch
        along = pts @ [math.cos(a), math.sin(a)]
        across = pts @ [-math.sin(a), math.cos(a)]
        strip = (along > c - r) & (np.abs(across) <= R * (1 + 1e-9))   # the open slot: nothing inside 2R
        np.testing.assert_allclose(np.abs(across[strip]), R, rtol=1e-9)
        assert (across[strip] > 0).sum() >= 2 and (across[strip] < 0).sum() >= 2     # both flanks present
        L = c * np.array([math.cos(a + g.pitch / 2), math.sin(a + g.pitch / 2)])
        on_arc = np.abs(np.hypot(*(pts - L).T) - locking_radius(g)) < 1e-12
        assert on_arc.sum() >= 10
    disc = locking_disc_outline(g)
    assert np.hypot(*disc.T).max() == pytest.approx(locking_radius(g), rel=1e-12)
    assert locking_radius(g) < r - R             # the arc clears the slot flanks (r - R from the arc centre)


def test_a_column_unbounded_toward_events_is_drawn_clipped_with_its_events_marked():
    """chain-mech2-kinematic's coupler force grows like 1/distance toward each crank stop (summary peaks,
    `singular`): at 10 ms rows the last row before a stop reaches 3 to 83 N depending on how near it fell, against
    0.02-0.03 N elsewhere. The forces panel is ranged on every line's rows farther than POLE_GUARD of the run from
    the stops, so it holds them all and stops far below the rows next to a stop; each stop is dotted, and the
    panel says which column is unbounded."""
    from mechsim.scenarios.output.plots import POLE_GUARD
    sc = load("chain-mech2-kinematic", [])
    result = run(sc)
    figs = figures(result, build_mechanism(sc.si))
    ax = next(a for a in figs["forces_vs_time"].axes if a.get_ylabel() == "force (N)")
    df, events = result.timeseries, result.events
    stops = np.sort(events.loc[events["kind"] == "stop impact", "t_s"].to_numpy(float))
    assert len(stops) == 4 and [s["t_s"] for s in result.summary["peaks"]["coupler_force_N"]["singular"]] == list(stops)
    t = df["t_s"].to_numpy(float)
    far = np.min(np.abs(t[:, None] - stops[None, :]), axis=1) > POLE_GUARD * (t[-1] - t[0])
    forces = df[["coupler_force_N", "coupler_shear_N", "joint_force_N"]].to_numpy(float)
    lo, hi = ax.get_ylim()
    assert lo <= forces[far].min() and hi >= forces[far].max()
    assert hi < 0.05 * forces.max()
    (marks,) = [c for c in ax.collections if c.get_label() == "_poles"]
    dotted = sorted(float(segment[0, 0]) for segment in marks.get_segments())
    np.testing.assert_allclose(dotted, stops, rtol=0, atol=1e-12)
    assert any("coupler force: grows without bound toward 4 events" in text.get_text() for text in ax.texts)
    import mechsim
    own = mechsim.run(sc).plot(["coupler_force_N"]).axes[0]   # a figure of chosen columns draws it so too
    assert own.get_ylim()[1] < 0.05 * forces.max() and any("grows without bound" in x.get_text() for x in own.texts)


def test_a_comparison_clips_the_unbounded_column_of_either_run():
    """`mechsim compare` overlays two runs: the forces panel is ranged on both runs' rows away from their own stops,
    each run's stops are dotted (in time: A's four and B's five; in the cycle: the same four places), and both
    runs' rows farther from them are inside the range."""
    import mechsim
    from mechsim.scenarios.output.plots import POLE_GUARD
    c = mechsim.compare("chain-mech2-kinematic", "chain-mech2-kinematic", set_b={"drive.speed": "1.2 rad/s"})
    figs = c.plot()
    stops = [np.sort(r.events.loc[r.events["kind"] == "stop impact", "t_s"].to_numpy(float)) for r in (c.a, c.b)]
    assert [len(s) for s in stops] == [4, 5]
    ax = next(a for a in figs["forces_vs_time"].axes if a.get_ylabel() == "force (N)")
    (marks,) = [m for m in ax.collections if m.get_label() == "_poles"]
    np.testing.assert_allclose(sorted(float(s[0, 0]) for s in marks.get_segments()), np.sort(np.r_[stops[0], stops[1]]),
                               rtol=0, atol=1e-12)
    lo, hi = ax.get_ylim()
    span = max(r.timeseries["t_s"].iloc[-1] for r in (c.a, c.b))
    for r, s in zip((c.a, c.b), stops):
        t = r.timeseries["t_s"].to_numpy(float)
        f = r.timeseries[["coupler_force_N", "coupler_shear_N", "joint_force_N"]].to_numpy(float)
        far = np.min(np.abs(t[:, None] - s[None, :]), axis=1) > POLE_GUARD * span
        assert lo <= f[far].min() and f[far].max() <= hi < 0.05 * f.max()
    angle = next(a for a in figs["forces_vs_angle"].axes if a.get_ylabel() == "force (N)")
    (marks,) = [m for m in angle.collections if m.get_label() == "_poles"]
    assert len(marks.get_segments()) == 4


def test_the_energy_figure_counts_the_impacts_work(case):
    """The chain's crank stops are impacts that take energy (e = 0; docs/chain_dwell.md): the energy figure's work
    panel draws their work on the system, minus the energy lost up to each row, so its lines add up to the kinetic
    energy's change on every row as the summary's balance does at the end. Runs without impacts draw no such line."""
    kind, result, figs, *_ = case
    lines = {line.get_gid(): line.get_ydata() for ax in figs["energy_vs_time"].axes for line in ax.get_lines()}
    lost = result.summary["energy"]["impact_losses_J"]
    if kind != "chain":
        assert "work_impacts_J" not in lines and lost == pytest.approx(0, abs=1e-12)
        return
    impacts = result.events[result.events.energy_lost_J.fillna(0) > 1e-12 * lost]
    drawn = lines["work_impacts_J"]
    # (an arc entry's loss is round-off, 5e-20 J: a step of its size)
    assert len(impacts) >= 3 and np.count_nonzero(np.abs(np.diff(drawn)) > 1e-12 * lost) == len(impacts)
    assert drawn[-1] == pytest.approx(-lost, rel=1e-12) and lost == pytest.approx(impacts.energy_lost_J.sum(), rel=1e-12)
    works = sum(y - y[0] for gid, y in lines.items() if gid.startswith("work_"))
    change = lines["kinetic_energy_J"] - lines["kinetic_energy_J"][0]
    scale = max(np.abs(y - y[0]).max() for gid, y in lines.items() if gid.startswith("work_"))
    closure = result.summary["energy"]["closure_error_relative"]
    assert np.abs(works - change).max() <= max(10 * abs(closure), 1e-12) * scale


def test_the_drawing_shows_the_largest_force_its_arrows_are_scaled_to(case):
    """The drawing's arrows share one scale, so evenly spaced instants may all fall where the force is a hundredth
    of it (rolling-b-components' panels showed 0.2-0.6 N of a 55 N run). One panel is at the row of the largest
    force of the stretch drawn, titled so: no other panel's force is larger, and over these runs, whose drive
    repeats or is drawn whole, it is the run's largest row."""
    from figure_images import titles_outside
    kind, result, figs, *_ = case
    fig = figs["mechanism"]
    column = build_mechanism(result.scenario).drawing_class().force_column
    df = result.timeseries
    t = df["t_s"].to_numpy(float)
    force = np.abs(df[column].to_numpy(float))
    shown = {}
    for ax in fig.axes:
        m = re.match(r"t = ([0-9.]+) s", ax.get_title())
        if m:
            shown[ax.get_title()] = force[np.argmin(np.abs(t - float(m.group(1))))]
    largest = [title for title in shown if title.endswith("its largest force")]
    assert len(largest) == 1 and shown[largest[0]] == max(shown.values())
    # a turn's best row lies within half a row of its peak: below the run's best row by at most |f''| h^2 / 8 (the
    # second difference at the best row, twice over for the curvature's change between turns)
    i = int(np.nanargmax(np.where(np.isfinite(force), force, -np.inf)))
    miss = 2 * abs(force[i + 1] - 2 * force[i] + force[i - 1]) / 8 if 0 < i < len(force) - 1 else 0.0
    assert shown[largest[0]] >= force[i] - miss
    assert titles_outside(fig) == []
