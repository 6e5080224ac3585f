"""How finely runs resolve a difference between two designs: the one rule of `mechsim compare`'s table and of the
sweep figures (docs/api.md "Comparing two designs", docs/sweeps.md "Plots").

A located figure (a peak, a turn's mean, a cycle's time or work) carries the integrator's global error over a turn,
a few times its local error test's: TOLERANCES_RESOLVED x rtol of its scale. A figure read from a column (a peak,
a start-up peak, a turn's mean) is scaled by the largest magnitude the column's peaks reach, not by itself: a
motor's least torque 0.016 N m is 40 (1 - w/w0) N m for a crank speed near the no-load speed, good to rtol x 40 N m,
and a speed's mean acceleration over a periodic turn is zero to rtol x the speed's scale; a temperature in degrees
Celsius is integrated as the absolute temperature, so its scale is in kelvin. Any other figure (a
cycle's time, a flow's work per cycle, the heat generated) is scaled by its own magnitude; a count is exact.
Values closer than that are equal at the runs' accuracy.
"""
from __future__ import annotations

#: a located figure's error, in units of the run's rtol times its scale
TOLERANCES_RESOLVED = 10
#: figures that are no integrated quantity: every difference is real
EXACT_FIGURES = ("case_wall_time_s", "impacts_per_turn_max", "validity_violated_conditions")
#: 0 degrees Celsius in kelvin
KELVIN = 273.15
#: the figures read from one column, by the prefix of their names (`peak_max_contact_force_N`: `contact_force_N`)
COLUMN_FIGURES = ("startup_peak_max_", "startup_peak_min_", "peak_max_", "peak_min_", "cycle_mean_")


def figure_column(figure: str) -> str | None:
    """The column a figure is read from (`peak_max_contact_force_N`: `contact_force_N`), else None."""
    return next((figure[len(p):] for p in COLUMN_FIGURES if figure.startswith(p)), None)


def column_scale(column: str, largest: float) -> float:
    """A column's scale from the largest magnitude its figures reach: in kelvin for one in degrees Celsius."""
    return largest + KELVIN if column.endswith("_C") else largest


def floor(rtol: float, scale: float) -> float:
    """The smallest difference of a figure that runs at `rtol` resolve, its scale as the module says."""
    return TOLERANCES_RESOLVED * rtol * scale
