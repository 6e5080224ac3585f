"""What every mechanism's drawing shares (lengths in mm): colours, the force arrow's length, rotation, arcs, the
temperature colour and the axes' finish.

A drawing is a class built once on a matplotlib axes, `Drawing(ax, mech, force_peak=None, temperature=None,
arrow_length_mm=None, trace=None)` (the parts that never move drawn there for good; `trace` the run's table), whose
`update(row)` moves the parts to one output row and returns the artists it changed, so an animation redraws only
those. Its class attributes `force_column` and `force_label` name the force its arrow shows. A mechanism names its
drawing as "module:Class" (`Mechanism.drawing`): matplotlib is imported only when something is drawn.
"""
from __future__ import annotations

import math

import numpy as np
from matplotlib.colors import Normalize

MM = 1e3
TEMPERATURE_MAP = "inferno"
STEEL, STEEL_EDGE, CRANK = "#c9d3dc", "#3b4b5a", "tab:red"
ARROW_CLIP = 1.6


def arrow_length(force: float, scale: float, nominal: float) -> float:
    """Signed arrow length (mm) of a force: force x scale, cut at +-ARROW_CLIP x nominal."""
    return float(np.clip(force * scale, -ARROW_CLIP * nominal, ARROW_CLIP * nominal))


def rotate(points: np.ndarray, angle: float) -> np.ndarray:
    c, s = math.cos(angle), math.sin(angle)
    return points @ np.array([[c, s], [-s, c]])


def arc(centre, radius, a0, a1, n=24) -> np.ndarray:
    a = np.linspace(a0, a1, n)
    return np.column_stack([centre[0] + radius * np.cos(a), centre[1] + radius * np.sin(a)])


def colour(norm: Normalize, value) -> tuple:
    from matplotlib import colormaps
    return colormaps[TEMPERATURE_MAP](norm(float(value)))


def finish_axes(ax) -> None:
    ax.set_aspect("equal")
    ax.set_xlabel("x (mm)")
    ax.set_ylabel("y (mm)")
    ax.grid(True, lw=0.3, alpha=0.5)
