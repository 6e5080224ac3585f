"""The work-precision figure of `mechsim bench`: no tick labels overlap, the legend sits off the data."""
from pathlib import Path

import pandas as pd

from mechsim.benchmarks.bench_plots import work_precision_figure

ROWS = Path(__file__).resolve().parents[1] / "docs" / "benchmarks_work_precision.csv"


def _overlap(a, b) -> bool:
    return a.x0 < b.x1 and b.x0 < a.x1 and a.y0 < b.y1 and b.y0 < a.y1


def test_tick_labels_do_not_overlap_and_the_legend_is_outside():
    rows = pd.read_csv(ROWS)
    fig = work_precision_figure(rows, {"scenario": "geneva-motor", "duration_s": 5.0, "output_points": 5001})
    fig.canvas.draw()
    renderer = fig.canvas.get_renderer()
    for ax in fig.axes:
        for axis in (ax.xaxis, ax.yaxis):
            boxes = [t.get_window_extent(renderer) for t in axis.get_ticklabels()
                     if t.get_visible() and t.get_text()]
            assert len(boxes) >= 2
            assert not any(_overlap(a, b) for i, a in enumerate(boxes) for b in boxes[i + 1:]), ax.get_title()
    legend = fig.legends[0].get_window_extent(renderer)
    assert len(fig.legends[0].get_texts()) == rows["method"].nunique() + 1      # every method and error = rtol
    assert not any(_overlap(legend, ax.get_window_extent(renderer)) for ax in fig.axes)
