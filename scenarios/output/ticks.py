"""Work out each axis's ticks once per layout state while a figure is saved (docs/benchmarks.md, "Cold start").

Saving a figure with constrained layout asks every axis for its ticks six or seven times: twice per pass of the
layout (its bounding box, and again to place the axis label), in two passes, and twice more in the draw. Each
time matplotlib (matplotlib/axis.py, `Axis._update_ticks`) calls the locator, formats every label and moves every
tick artist, although the answer depends only on the view interval, the axes' size in pixels (the locator's
tick space), the dpi and the locator and formatter themselves. Inside `ticks_once()` an axis asked again in the
same state gets the ticks it was given last time (the same tick artists, already at those places with those
labels); any change of that state computes them again. The figures' pixels do not change
(tests/test_figure_writer.py compares them with `savefig`'s); about a tenth of a figure's CPU time is saved.
Where matplotlib has no `Axis._update_ticks` (another version), nothing is changed.
"""
from __future__ import annotations

from contextlib import contextmanager
from typing import Iterator

from matplotlib.axis import Axis


def _state(axis: Axis) -> tuple:
    """What an axis's ticks depend on: view interval, axes box in pixels, dpi, the locators and formatters."""
    return (tuple(map(float, axis.get_view_interval())), tuple(axis.axes.bbox.bounds),
            axis.axes.figure.dpi, id(axis.major.locator), id(axis.major.formatter),
            id(axis.minor.locator), id(axis.minor.formatter))


@contextmanager
def ticks_once() -> Iterator[None]:
    """Within the block, `Axis._update_ticks` answers a repeated question from memory (this thread's drawing
    only: used around one figure's save)."""
    original = getattr(Axis, "_update_ticks", None)
    if original is None or "_update_ticks" not in Axis.__dict__:
        yield
        return
    memo: dict[int, tuple[tuple, list]] = {}

    def update_ticks(self):
        state = _state(self)
        known = memo.get(id(self))
        if known is not None and known[0] == state:
            return list(known[1])
        ticks = original(self)
        memo[id(self)] = (state, list(ticks))
        return ticks

    Axis._update_ticks = update_ticks
    try:
        yield
    finally:
        Axis._update_ticks = original
