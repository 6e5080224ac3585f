"""Long runs drawn honestly: a line with more rows than a few per pixel column becomes its envelope, min to max in
each pixel column (a solid block of overdrawn line said nothing), and the figure says so; a short run keeps its
lines. Many cycles against the drive angle: the envelope over all of them and the last complete cycle as a line."""
import numpy as np
import pytest
from matplotlib.collections import PolyCollection

import mechsim
from mechsim.scenarios.output.plots import ENVELOPE_NOTE, ROWS_PER_COLUMN, envelope

# prescribed speed, closed form: 120,001 rows (about 100 per pixel column) in a fraction of a second
LONG = ["duration=12 s", "output_step=0.1 ms", "thermal.model=none"]


@pytest.fixture(scope="module")
def long_run():
    return mechsim.run("geneva-lc1", set=LONG)


def _polygons(ax, gid):
    found = [c for c in ax.collections if isinstance(c, PolyCollection) and c.get_gid() == gid]
    assert len(found) == 1, [c.get_gid() for c in ax.collections]
    return np.concatenate([p.vertices for p in found[0].get_paths()])


def test_a_long_run_is_drawn_as_its_envelope_holding_every_extreme(long_run):
    force = long_run["contact_force_N"].to_numpy(float)
    t = long_run["t_s"].to_numpy(float)
    fig = long_run.plot("contact_force_N")
    ax = fig.axes[0]
    assert not [line for line in ax.get_lines() if len(line.get_xdata()) > 1000]   # no overdrawn line
    v = _polygons(ax, "contact_force_N")
    assert len(v) < 6 * 1100                         # a few vertices per pixel column, not one per row
    assert v[:, 1].max() == force.max() and v[:, 1].min() == force.min()   # the run's extremes are drawn exactly
    assert v[:, 0].min() == t[0] and v[:, 0].max() == t[-1]
    assert ENVELOPE_NOTE in fig.get_suptitle() and "120,001 rows" in fig.get_suptitle()
    # every sample lies inside its column's band, and each band's ends are samples (min to max, not a smoothing)
    edges, lo, hi = envelope(t, force, 900)
    col = np.clip(np.searchsorted(edges, t, side="right") - 1, 0, 899)
    assert (force >= lo[col]).all() and (force <= hi[col]).all()
    assert np.isin(hi, force).all() and np.isin(lo, force).all()
    # the CLI's figures: the same envelope for every line of the time figures
    figs = long_run.plot(["forces_vs_time", "motion_vs_time"])
    for f in figs.values():
        assert ENVELOPE_NOTE in f.get_suptitle()
        assert all(len(line.get_xdata()) <= 1000 for a in f.axes for line in a.get_lines())


def test_a_short_run_keeps_its_lines():
    r = mechsim.run("geneva-lc1", set=["duration=1 s", "output_step=1 ms", "thermal.model=none"])
    fig = r.plot("contact_force_N")
    (line,) = [x for x in fig.axes[0].get_lines() if x.get_gid() == "contact_force_N"]
    np.testing.assert_array_equal(line.get_ydata(), r["contact_force_N"].to_numpy(float))
    assert ENVELOPE_NOTE not in fig.get_suptitle() and len(r.timeseries) <= ROWS_PER_COLUMN * 800


def test_many_cycles_against_angle_the_envelope_and_the_last_complete_cycle(long_run):
    r = mechsim.run("geneva-lc1", set=["duration=60 s", "output_step=2 ms", "thermal.model=none"])
    fig = r.plot("contact_force_N", x="angle")
    ax = fig.axes[0]
    v = _polygons(ax, "contact_force_N#envelope")
    force = r["contact_force_N"].to_numpy(float)
    assert v[:, 1].max() == force.max() and v[:, 1].min() == force.min()
    (line,) = [x for x in ax.get_lines() if x.get_gid().startswith("contact_force_N#cycle")]
    # the last complete turn of the crank: a whole period of the drive angle, ending before the run does
    x = line.get_xdata()
    assert np.ptp(x) > 0.98 * 360 and len(x) < len(force) / 40
    assert "51 cycles: their envelope" in fig.get_suptitle()


def test_two_long_runs_compared_overlay_their_envelopes_in_one_colour(long_run):
    """`mechsim.compare(A, B)` draws B over A's figures in A's colours: long runs are envelopes on both sides."""
    c = mechsim.compare(long_run, "geneva-lc1", set=LONG, set_b={"load.wheel_torque": "9 N*m"})
    fig = c.plot("contact_force_N")
    ax = fig.axes[0]
    a, b = _polygons(ax, "contact_force_N"), _polygons(ax, "B:contact_force_N")
    assert a[:, 1].max() == long_run["contact_force_N"].max() and b[:, 1].max() > a[:, 1].max()   # more load
    (pa,) = [x for x in ax.collections if x.get_gid() == "contact_force_N"]
    (pb,) = [x for x in ax.collections if x.get_gid() == "B:contact_force_N"]
    np.testing.assert_array_equal(pa.get_edgecolor(), pb.get_edgecolor())
    assert pa.get_label().endswith("(A)") and pb.get_label().endswith("(B)")
    assert c.plot()["forces_vs_time"] is not None


def test_the_envelope_of_many_cycles_holds_every_cycles_line(monkeypatch):
    """A quantity that drifts from cycle to cycle (the lumped bulk temperatures warming over 2 minutes), sampled at
    phases that drift too (5 ms rows, a turn of 1.18 s): the pixel columns are finer than a cycle's rows, so a
    column holds samples of only some cycles. The band must still hold every cycle's line as drawn (linear between
    its rows); taken over the columns' samples alone, its top edge fell below the latest cycles' lines in the
    columns they have no sample in, a sawtooth along the hottest cycle."""
    from matplotlib.axes import Axes
    drawn = {}
    fill_between = Axes.fill_between

    def record(self, x, y1, y2=0, **kw):
        drawn[kw.get("gid")] = (np.asarray(x, float), np.asarray(y1, float), np.asarray(y2, float))
        return fill_between(self, x, y1, y2, **kw)
    monkeypatch.setattr(Axes, "fill_between", record)
    r = mechsim.run("geneva-seed-lc1-mu015", set=["duration=120 s", "output_step=5 ms"])
    r.plot(["temp_bulk_wheel_C", "temp_bulk_pin_C"], x="angle")
    from mechsim.scenarios.loader import build_mechanism
    from mechsim.scenarios.output.plots import DEG, cycle_index
    cycle = build_mechanism(mechsim.load("geneva-seed-lc1-mu015").si).drive_cycle()
    k, within = cycle_index(r["crank_angle_rad"].to_numpy(float), cycle)
    x = (within + cycle.start) * DEG
    assert len(np.unique(k)) > 40                                # drawn as the envelope
    for column in ("temp_bulk_wheel_C", "temp_bulk_pin_C"):
        xs, y1, y2 = drawn[f"{column}#envelope"]
        edges, lo, hi = np.r_[xs[0], xs[1::2]], y1[::2], y2[::2]
        y = r[column].to_numpy(float)
        tiny = 1e-12 * np.abs(y).max()
        for kk in np.unique(k):
            line_x, line_y = x[k == kk], y[k == kk]
            crossed = edges[(edges > line_x[0]) & (edges < line_x[-1])]
            points = np.r_[line_x, crossed]
            values = np.interp(points, line_x, line_y)          # the cycle's line as drawn
            right = np.clip(np.searchsorted(edges, points, side="right") - 1, 0, len(lo) - 1)
            on_edge = np.isin(points, edges[1:-1])
            # a point in a column; a point on an edge belongs to the columns on both sides of it
            for c, which in ((right, slice(None)), (right - 1, on_edge)):
                assert (values[which] >= lo[c[which]] - tiny).all(), (column, kk)
                assert (values[which] <= hi[c[which]] + tiny).all(), (column, kk)


def test_two_runs_of_many_cycles_compared_against_angle_are_both_envelopes():
    """`compare` folds B over A's angle figure the way A is drawn: above MAX_CYCLE_LINES cycles, B's envelope over
    all its cycles and its last complete cycle (dashed), not 51 overdrawn dashed lines; every artist says its run."""
    many = ["duration=60 s", "output_step=2 ms", "thermal.model=none"]
    c = mechsim.compare("geneva-lc1", "geneva-lc1", set=many, set_b={"load.wheel_torque": "9 N*m"})
    fig = c.plot("contact_force_N", x="angle")
    ax = fig.axes[0]
    b_lines = [line for line in ax.get_lines() if line.get_gid().startswith("B:contact_force_N#cycle")]
    assert len(b_lines) == 1 and b_lines[0].get_linestyle() == "--"
    assert np.ptp(b_lines[0].get_xdata()) > 0.98 * 360                # the last complete turn
    band = _polygons(ax, "B:contact_force_N#envelope")
    force_b = c.b.timeseries["contact_force_N"].to_numpy(float)
    assert band[:, 1].max() == force_b.max() > c.a.timeseries["contact_force_N"].max()   # more load
    labels = [a.get_label() for a in (*ax.get_lines(), *ax.collections) if not a.get_label().startswith("_")]
    assert labels and all(label.endswith((" (A)", " (B)")) for label in labels), labels
    assert sum(label.endswith(" (B)") for label in labels) == 2       # B's envelope and its last cycle
    from figure_images import titles_outside
    assert not titles_outside(fig)          # the two names and the cycle note fit: the note on a line of its own
