"""Coupler-curve atlas: components and their colouring, tables, finite span for irrational ratios, plot."""
import ast
import io
import math
import pathlib
import re

import numpy as np
import pytest

from mechsim.mechanisms.rolling.atlas import coupler_atlas
from mechsim.mechanisms.rolling.pair import rolling_span
from mechsim.scenarios.output.rolling_plots import BRANCH_COLOURS, plot_coupler_atlas
from mechsim.mechanisms.rolling.sets import SETS, make

UNIT_COLUMN = re.compile(r"^[A-Za-z0-9_]+_(m|rad|m_per_rad)$")
CATEGORICAL = {"component", "branch", "kind", "closed", "branches", "start_kind", "end_kind", "component_1",
               "component_2", "branch_1", "branch_2", "converged", "induced"}


@pytest.fixture(scope="module")
def atlas_b():
    return coupler_atlas(make("B"))


def test_column_names_carry_units(atlas_b):
    for name in ("curve", "trochoid", "closure", "nonclosure", "cusps", "crunodes", "trochoid_crunodes",
                 "component_table"):
        for col in getattr(atlas_b, name).columns:
            assert col in CATEGORICAL or UNIT_COLUMN.match(col), (name, col)


def test_multicursal_components(atlas_b):
    """Set B: 4 closure intervals -> 4 closed dichromatic components (docs/theory.md §K2.2), each traced by
    branch +1 one way and -1 back, the colours changing only at the stretched/folded ends."""
    ct = atlas_b.component_table
    assert list(ct.kind) == ["dichromatic"] * 4 and ct.closed.all()
    m = atlas_b.mechanism
    for c in atlas_b.components:
        rows = atlas_b.curve[atlas_b.curve.component == c.index]
        br, phi = rows.branch.to_numpy(), rows.rolling_angle_rad.to_numpy()
        C = rows.C_x_m.to_numpy() + 1j * rows.C_y_m.to_numpy()
        assert abs(C[0] - C[-1]) <= 1e-6  # closed (merge point within sqrt of round-off)
        switches = np.nonzero(br[1:] != br[:-1])[0]
        assert len(switches) == 2
        for k in switches:  # a switch happens at an interval end
            assert min(abs(phi[j] - e) for e in (c.interval.start, c.interval.end) for j in (k, k + 1)) <= 1e-12
        steps = np.abs(np.diff(C))
        assert steps.max() <= 0.05  # no gaps: the cosine grid resolves the sqrt at the ends
        # rows agree with the closed form
        for s in (1, -1):
            sel = br == s
            assert np.max(np.abs(m.coupler(phi[sel], s) - C[sel])) <= 1e-12


def test_bicursal_atlas_monochromatic():
    at = coupler_atlas(make("A"))
    assert list(at.component_table.kind) == ["monochromatic"] * 2
    assert len(at.nonclosure) == 0 and len(at.cusps) == 0
    for c in at.components:
        rows = at.curve[at.curve.component == c.index]
        assert rows.branch.nunique() == 1
        assert rows.rolling_angle_rad.iloc[-1] - rows.rolling_angle_rad.iloc[0] == pytest.approx(6 * math.pi)
        assert abs(rows.C_x_m.iloc[0] - rows.C_x_m.iloc[-1]) <= 1e-12


def test_line_atlas_nonclosure_contains_a_cusp():
    at = coupler_atlas(make("D"))
    nc = at.nonclosure
    assert ((nc.rolling_angle_start_rad < -16.407963) & (nc.rolling_angle_end_rad > -16.407963)).any()
    assert len(at.cusps) == 4 and set(at.cusps.component) == {0, 1}


def test_irrational_ratio_finite_span():
    """R/r = sqrt 2 never closes: the span is n_revolutions turns of B0 about O, components are open."""
    m = make("irrational")
    (a, b), periodic = rolling_span(m)
    assert not periodic
    assert b - a == pytest.approx(3 * 2 * math.pi * (m.pair.R + m.pair.r) / m.pair.r, rel=1e-15)
    B = m.trochoid(np.array([a, b]))["B"]
    assert abs(B[1] - B[0]) > 1e-3  # does not close
    at = coupler_atlas(m)
    assert not at.periodic and not at.component_table.closed.any()
    assert (at.crunodes.residual_m <= 1e-9).all() and at.crunodes.converged.all()


def test_named_sets_build():
    for name in SETS:
        m = make(name)
        assert m.l2 > 0 and m.pair.r > 0
    assert make("cusp").l4 == make("cusp").pair.r


def test_plot(atlas_b):
    fig = plot_coupler_atlas(atlas_b)
    ax = fig.axes[0]
    colours = {line.get_color() for line in ax.get_lines()}
    assert set(BRANCH_COLOURS.values()) <= colours
    buf = io.BytesIO()
    fig.savefig(buf, format="png", dpi=40)
    assert buf.getvalue()[:4] == b"\x89PNG"
    fig2 = plot_coupler_atlas(coupler_atlas(make("C")))
    labels = [line.get_label() for line in fig2.axes[0].get_lines()]
    assert "cusps" in labels


def test_mechanisms_import_nothing_of_ours_downstream():
    root = pathlib.Path(__file__).resolve().parents[1] / "mechanisms"
    for path in list(root.glob("rolling_*.py")) + [root / "planar_rolling.py"]:
        tree = ast.parse(path.read_text())
        for node in ast.walk(tree):
            names = []
            if isinstance(node, ast.Import):
                names = [a.name for a in node.names]
            elif isinstance(node, ast.ImportFrom) and node.module and node.level == 0:
                names = [node.module]
            for n in names:
                assert n.split(".")[0] not in {"dynamics", "thermal", "scenarios"}, (path, n)
