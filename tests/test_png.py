"""scenarios/output/png.py: what a decoder reads back is the image given (each row filtered "None" or "Up", the
latter modulo 256, W3C PNG 2nd ed. §9.2), every chunk's CRC holds, and a figure written this way shows what matplotlib's `savefig` writes: the
same mode, size, metadata (dpi, Software) and pixels."""
import io

import numpy as np
import pytest
from matplotlib.backends.backend_agg import FigureCanvasAgg
from matplotlib.figure import Figure
from PIL import Image

from mechsim.scenarios.output.png import png_bytes


def decoded(data: bytes) -> Image.Image:
    with Image.open(io.BytesIO(data)) as im:
        im.verify()                                    # signature, chunk order, every CRC
    im = Image.open(io.BytesIO(data))
    im.load()
    return im


@pytest.mark.parametrize("shape", [(1, 1), (1, 7), (9, 1), (37, 53), (64, 300), (90, 120)])
def test_random_images_decode_to_themselves(shape):
    rng = np.random.default_rng(sum(shape))
    rgba = rng.integers(0, 256, (*shape, 4), dtype=np.uint8)
    rgba[1::3] = 255 - rgba[1::3]                      # rows far apart: the Up differences wrap modulo 256
    for row in range(2, shape[0], 5):                      # rows equal to the one above: these take "Up"
        rgba[row] = rgba[row - 1]
    im = decoded(png_bytes(rgba, dpi=72))
    assert im.mode == "RGBA" and im.size == (shape[1], shape[0])
    assert np.array_equal(np.asarray(im), rgba)
    assert im.info["dpi"] == pytest.approx((72, 72), abs=0.01)


def test_a_figure_shows_what_savefig_writes():
    fig = Figure(figsize=(3, 2))                       # no layout engine: both draw the same layout
    ax = fig.subplots()
    ax.plot(np.linspace(0, 1, 200), np.sin(np.linspace(0, 9, 200)), label="sine")
    ax.set_xlabel("time (s)")
    ax.legend()
    buf = io.BytesIO()
    fig.savefig(buf, dpi=110, format="png")
    theirs = decoded(buf.getvalue())
    canvas = FigureCanvasAgg(fig)
    fig.set_dpi(110)
    canvas.draw()
    ours = decoded(png_bytes(canvas.buffer_rgba(), dpi=110))
    assert (ours.mode, ours.size, ours.info) == (theirs.mode, theirs.size, theirs.info)
    assert ours.tobytes() == theirs.tobytes()


def test_only_rgba_images():
    with pytest.raises(ValueError, match="RGBA"):
        png_bytes(np.zeros((4, 4, 3), np.uint8), dpi=72)
