"""The figures of an output folder are drawn in two processes where the platform forks (scenarios/output/render.py):
the folder must hold the same PNG files, byte for byte, as drawing them one by one here, and a share that the
forked process fails to draw is drawn by this one."""
import io
import os

import pytest
from matplotlib.figure import Figure

from mechsim.scenarios import api
from mechsim.scenarios.output import render
from mechsim.scenarios.output.figures import result_figures


def _png(fig) -> bytes:
    buf = io.BytesIO()
    from mechsim.scenarios.output.plots import DPI
    fig.savefig(buf, dpi=DPI, format="png")
    return buf.getvalue()


def test_the_folder_holds_every_figure_as_drawn_in_one_process(tmp_path):
    result = api.run("geneva-lc1", set=["duration='1.5 s'", "output_step='5 ms'"])
    folder = result.save(tmp_path / "out")
    expected = {stem: _png(fig) for stem, fig in result_figures(result, result.mechanism).items()}
    assert len(expected) >= 7
    assert {p.stem: p.read_bytes() for p in folder.glob("*.png")} == expected


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
    import subprocess
    import sys
    code = ("import sys\nfrom mechsim.scenarios.output import render\nbefore = render.can_fork()\nimport jax\n"
            "print(before == sys.platform.startswith('linux'), render.can_fork())")
    env = {**os.environ, "PYTHONPATH": os.pathsep.join(p for p in sys.path if p)}
    out = subprocess.run([sys.executable, "-c", code], env=env, capture_output=True, text=True, timeout=240)
    assert out.returncode == 0, out.stderr
    assert out.stdout.split() == ["True", "False"]


@pytest.mark.skipif(not render.can_fork(), reason="figures are drawn in one process here")
def test_half_of_the_figures_go_to_a_forked_process(tmp_path):
    writer = render.FigureWriter([lambda: {}] * 5, tmp_path)
    try:
        assert writer.child is not None and len(writer.mine) == 3 and len(writer.theirs) == 2
    finally:
        writer.finish()
