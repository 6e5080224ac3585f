"""The figures of an output folder are drawn in two processes where the platform forks (scenarios/output/render.py):
the folder must hold the same images as drawing them one by one here with matplotlib's own `savefig` (so the
one-draw save of plots.py `save` changes no pixel): the same decoded pixels, mode, size and PNG metadata (the
encoder is scenarios/output/png.py, not Pillow's, so the compressed bytes differ), and a share that the forked
process fails to draw is drawn by this one."""
import io
import os
import subprocess
import sys

import pytest
from matplotlib.figure import Figure
from PIL import Image

from mechsim.scenarios import api
from mechsim.scenarios.output import render
from mechsim.scenarios.output.figures import result_figures


def _png(fig) -> bytes:
    buf = io.BytesIO()
    from mechsim.scenarios.output.plots import DPI
    fig.savefig(buf, dpi=DPI, format="png")
    return buf.getvalue()


def image(data: bytes) -> tuple:
    """What a PNG shows: mode, size, metadata (dpi, Software) and the decoded pixels."""
    with Image.open(io.BytesIO(data)) as im:
        return im.mode, im.size, im.info, im.tobytes()


def test_the_folder_holds_every_figure_as_drawn_in_one_process(tmp_path):
    result = api.run("geneva-lc1", set=["duration='1.5 s'", "output_step='5 ms'"])
    folder = result.save(tmp_path / "out")
    expected = {stem: image(_png(fig)) for stem, fig in result_figures(result, result.mechanism).items()}
    assert len(expected) >= 7
    assert {p.stem: image(p.read_bytes()) for p in folder.glob("*.png")} == expected


def test_a_share_the_forked_process_fails_is_drawn_here(tmp_path):
    parent = os.getpid()

    def maker(stem, fail_in_child=False):
        def make():
            if fail_in_child and os.getpid() != parent:
                raise RuntimeError("not drawable there")
            fig = Figure(figsize=(2, 1.5))
            fig.add_subplot().plot([0, 1], [0, 1])
            return {stem: fig}
        return make

    makers = [maker(f"f{i}", fail_in_child=True) for i in range(4)]
    with render.FigureWriter(makers, tmp_path) as writer:
        writer.finish()
    assert sorted(p.stem for p in tmp_path.glob("*.png")) == ["f0", "f1", "f2", "f3"]
    assert all(p.read_bytes().startswith(b"\x89PNG") for p in tmp_path.glob("*.png"))


def test_no_fork_once_jax_is_loaded(tmp_path):
    """A diffrax run loads JAX, whose threads make a fork unsafe: then every figure is drawn here."""
    code = ("import sys\nfrom mechsim.scenarios.output import render\nbefore = render.can_fork()\nimport jax\n"
            "print(before == sys.platform.startswith('linux'), render.can_fork())")
    env = {**os.environ, "PYTHONPATH": os.pathsep.join(p for p in sys.path if p)}
    out = subprocess.run([sys.executable, "-c", code], env=env, capture_output=True, text=True, timeout=240)
    assert out.returncode == 0, out.stderr
    assert out.stdout.split() == ["True", "False"]


_FORKED = """
import io, os, sys, tempfile
from pathlib import Path
from mechsim.scenarios import api
from mechsim.scenarios.output import render
from mechsim.scenarios.output.figures import result_figures
from mechsim.scenarios.output.plots import DPI
assert render.can_fork()
tmp = Path(tempfile.mkdtemp())
writer = render.FigureWriter([lambda: {}] * 5, tmp / "split")
split = (writer.child is not None, len(writer.mine), len(writer.theirs))
writer.finish()
result = api.run("geneva-lc1", set=["duration='1.5 s'", "output_step='5 ms'"])
folder = result.save(tmp / "out")
from figure_images import folder_shows_the_drawn_figures
n, same = folder_shows_the_drawn_figures(result, folder)
print(*split, n, same)
"""


@pytest.mark.skipif(not sys.platform.startswith("linux"), reason="figures are drawn in one process off Linux")
def test_a_fresh_process_forks_and_its_folder_shows_the_same_images():
    """In a process without JAX (as `mechsim run` of a closed-form or IDA scenario): a forked writer takes two of
    five figures, and a whole output folder drawn that way shows what drawing every figure here shows.
    (In the test session other files may have loaded JAX, which turns forking off, so this runs apart.)"""
    env = {**os.environ, "PYTHONPATH": os.pathsep.join(p for p in sys.path if p)}
    out = subprocess.run([sys.executable, "-c", _FORKED], env=env, capture_output=True, text=True, timeout=300)
    assert out.returncode == 0, out.stderr[-2000:]
    child, mine, theirs, n, same = out.stdout.split()
    assert (child, mine, theirs, same) == ("True", "3", "2", "True") and int(n) >= 7
