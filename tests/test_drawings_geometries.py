"""Every Geneva geometry the loader accepts draws: a hypothesis property over the schema's ranges (slots,
crank_radius, pin_radius, thickness) builds the mechanism figure of a short closed-form run on Agg, small; and a
figure that cannot be drawn is skipped with one warning line while the run's data is still written."""
import math

import numpy as np
import pytest
from hypothesis import HealthCheck, example, given, settings
from hypothesis import strategies as st
from matplotlib.backends.backend_agg import FigureCanvasAgg

import mechsim.mechanisms.geneva.drawing as geneva_drawing
from mechsim.mechanisms.geneva.drawing import geneva_wheel_outline, locking_disc_outline, locking_radius
from mechsim.scenarios.loader import build_mechanism, load
from mechsim.scenarios.output.plots import drawing_figure
from mechsim.scenarios.output.writer import write_result
from mechsim.scenarios.runner import run

SHORT = ["thermal.model='none'", "duration='1.3 s'", "output_step='20 ms'", "output.drawing_instants=2"]
GEOMETRY = dict(max_examples=12, deadline=None, derandomize=True, database=None,
                suppress_health_check=[HealthCheck.too_slow])


def _scenario(slots: int, crank: float, pin: float, thickness: float, extra=()):
    return load("geneva-lc1", [f"mechanism.slots={slots}", f"mechanism.crank_radius='{crank!r} m'",
                               f"mechanism.pin_radius='{pin!r} m'", f"mechanism.thickness='{thickness!r} m'",
                               *SHORT, *extra])


@st.composite
def geometries(draw):
    """(slots, crank radius, pin radius, thickness) inside the schema's ranges: slots 3..72, lengths between the
    unit's 1 nm and 1 km, the pin from 1 % of the largest the Geneva accepts, min(r cos^2(pi/n), c - r), up to
    (and close to) it."""
    slots = draw(st.integers(3, 72))
    crank = 10.0 ** draw(st.floats(-6.0, 3.0))
    s = math.sin(math.pi / slots)
    largest = min(crank * (1 - s * s), crank / s - crank)
    pin = largest * draw(st.one_of(st.floats(1e-2, 0.999), st.just(0.9999)))
    thickness = 10.0 ** draw(st.floats(-8.0, 0.0))
    return slots, crank, pin, thickness


@settings(**GEOMETRY)
@given(geometries())
@example((4, 0.075, 0.024, 0.004))          # geneva-lc1 with pin_radius = 24 mm: once a math domain error
@example((24, 0.075, 0.0745 * math.cos(math.pi / 24) ** 2, 0.004))   # many slots, nearly the largest pin
def test_every_accepted_geneva_geometry_draws(geometry):
    sc = _scenario(*geometry)               # inside the schema's ranges: the loader accepts it
    g = build_mechanism(sc.si).geometry
    r, R, c, Rw = g.crank_radius, g.pin_radius, g.centre_distance, g.entry_pin_distance
    assert 0 < locking_radius(g) < r - R                   # a disc that clears the slot flanks
    wheel, disc = geneva_wheel_outline(g), locking_disc_outline(g)
    assert np.isfinite(wheel).all() and np.isfinite(disc).all()
    assert np.hypot(*wheel.T).max() == pytest.approx(Rw, rel=1e-9)          # the rim, c cos(pi/n)
    assert np.hypot(*wheel.T).min() <= (c - r - R) * (1 + 1e-9) + 1e-15   # the slot bottom the pin reaches
    result = run(sc)
    assert result.success and len(result.timeseries)
    mech = build_mechanism(sc.si)
    fig = drawing_figure(result.timeseries, mech, 2, mech.drive_cycle())
    assert fig is not None and len(fig.axes) == 2
    fig.set_size_inches(4, 2)
    fig.set_dpi(30)
    FigureCanvasAgg(fig).draw()


def test_a_figure_that_cannot_be_drawn_is_skipped_with_one_warning_and_the_data_written(tmp_path, monkeypatch,
                                                                                          capfd):
    sc = load("geneva-lc1", SHORT)
    result = run(sc)

    class Broken(geneva_drawing.GenevaDrawing):
        def __init__(self, *args, **kwargs):
            raise ValueError("math domain error")
    monkeypatch.setattr(geneva_drawing, "GenevaDrawing", Broken)   # the Geneva names its drawing by this path
    out = write_result(result, tmp_path / "run", plots=True, mechanism=build_mechanism(sc.si))
    err = capfd.readouterr().err
    lines = [line for line in err.splitlines() if line.startswith("warning:")]
    assert lines == ["warning: figure mechanism.png skipped, it could not be drawn (ValueError: math domain error)"]
    written = {p.name for p in out.iterdir()}
    assert {"summary.json", "timeseries.parquet", "timeseries.csv", "events.csv", "report.html",
            "motion_vs_time.png"} <= written
    assert "mechanism.png" not in written
