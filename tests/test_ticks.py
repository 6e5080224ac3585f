"""scenarios/output/ticks.py: inside `ticks_once` an axis asked again for its ticks in the same state gets the same
ticks, and any change of that state (limits, size, dpi, formatter) computes them again, so what is drawn equals
drawing without it; afterwards matplotlib's own method is back."""
import io

import numpy as np
import pytest
from matplotlib.axis import Axis
from matplotlib.backends.backend_agg import FigureCanvasAgg
from matplotlib.figure import Figure
from matplotlib.ticker import FuncFormatter
from PIL import Image

from mechsim.scenarios.output.ticks import ticks_once


def _figure():
    fig = Figure(figsize=(4, 3), layout="constrained")
    axes = fig.subplots(2, 1, sharex=True)
    t = np.linspace(0, 2, 400)
    axes[0].plot(t, np.sin(5 * t))
    axes[1].plot(t, 1e4 * np.cos(3 * t))           # an offset/scientific formatter on this one
    axes[1].set_xlabel("time (s)")
    return fig


def _pixels(fig):
    buf = io.BytesIO()
    FigureCanvasAgg(fig).print_png(buf)
    return np.asarray(Image.open(buf))


def _changes(fig, step):
    """Draw, change one thing the ticks depend on, draw again: the second image."""
    canvas = FigureCanvasAgg(fig)
    canvas.draw()
    ax = fig.axes[1]
    if step == "limits":
        ax.set_xlim(0.3, 1.7)
    elif step == "size":
        fig.set_size_inches(6, 2)
    elif step == "dpi":
        fig.set_dpi(150)
    elif step == "formatter":
        ax.yaxis.set_major_formatter(FuncFormatter(lambda v, _: f"<{v:g}>"))
    canvas.draw()
    return np.asarray(canvas.buffer_rgba()).copy()


@pytest.mark.parametrize("step", ["limits", "size", "dpi", "formatter"])
def test_a_change_of_state_computes_the_ticks_again(step):
    plain = _changes(_figure(), step)
    with ticks_once():
        once = _changes(_figure(), step)
    assert np.array_equal(once, plain)


def test_same_pixels_and_matplotlib_restored():
    original = Axis._update_ticks
    with ticks_once():
        inside = _pixels(_figure())
        assert Axis._update_ticks is not original
    assert Axis._update_ticks is original
    assert np.array_equal(inside, _pixels(_figure()))
