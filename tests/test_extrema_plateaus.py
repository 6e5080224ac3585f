"""A column held constant over a stretch (a Geneva wheel's zero speed in each dwell) has its extremum everywhere on
the stretch: the reported instant is defined as the stretch's first instant in the window, the earliest stretch
winning among levels equal to round-off (docs/theory.md §K5). Round-off on the plateau (+-1e-25 where the
integrator's reinitialisation at an event leaves a residual speed whose sign hinges on the BLAS kernel) must not
move it, nor must the output step."""
import numpy as np
import pytest

from mechsim.dynamics.extrema import TIE_ROUNDOFF, intervals_of, locate

EVENTS = [(1.0, "event 'exit' at t = 1 s"), (2.0, "event 'entry' at t = 2 s"), (3.0, "event 'exit' at t = 3 s")]


def _column(t, noise, start_dwell):
    """Bumps from 1 to 3 between dwells of zero (the column jumps at the events): dwells on [1, 2) and [3, 4]
    (on [0, 1) and [2, 3) if start_dwell); `noise(t)` added on the dwells after the first."""
    seg = np.maximum(np.ceil(t) - 1.0, 0.0)           # a row at an event holds the limit from before it
    phase = seg % 2 == (1 if start_dwell else 0)
    f = np.where(phase, 1.0 + 2.0 * np.sin(np.pi * (t - seg)) ** 2, 0.0)
    first = 0.0 if start_dwell else 1.0
    late = ~phase & (t >= first + 1.0)
    return f + np.where(late, noise(t), 0.0)


def _locate(step, noise, start_dwell=False):
    t = np.round(np.arange(0.0, 4.0 + step / 2, step), 12)
    breaks = [(1.0, "event 'entry' at t = 1 s"), (2.0, "event 'exit' at t = 2 s"),
              (3.0, "event 'entry' at t = 3 s")] if start_dwell else EVENTS
    intervals = intervals_of(t, breaks, 0.0, 4.0)

    def read(iv, position, times):
        inner = np.clip(times, iv.lo + 1e-12, iv.hi - 1e-12)
        return {"t_s": times, "f": _column(inner, noise, start_dwell), "angle": 2 * np.pi * times}
    return locate(t, {"f": _column(t, noise, start_dwell)}, intervals, read)["f"]


NOISES = {"plus": lambda t: 1e-25 * np.exp(-t), "minus": lambda t: -1e-25 * np.exp(-t),
          "mixed": lambda t: 1e-25 * np.sign(np.sin(37.0 * t)), "none": lambda t: 0.0 * t}


@pytest.mark.parametrize("step", [0.01, 0.013])
@pytest.mark.parametrize("noise", sorted(NOISES))
def test_plateau_minimum_is_at_the_first_dwells_start_whatever_the_round_off(step, noise):
    """The dwell after the exit at t = 1 s is the first: the minimum is its one-sided limit there, whichever sign
    the later dwells' round-off has and whichever the output step (no row lies at t = 1 for step 0.013). The
    value is the plateau's to round-off: TIE_ROUNDOFF of the column's magnitude (the noise's 1e-25 lies far
    inside)."""
    low = _locate(step, NOISES[noise])["min"]
    assert low.t == 1.0 and low.limit == "after" and low.constant
    assert abs(low.value) <= TIE_ROUNDOFF * 3.0
    assert low.row["angle"] == pytest.approx(2 * np.pi, rel=1e-12)   # every column read at that instant


@pytest.mark.parametrize("noise", sorted(NOISES))
def test_plateau_at_the_runs_start_wins_over_later_dwells(noise):
    """The batch lane's case: the first dwell (from t = 0) is exactly zero, later ones carry +-1e-25: the minimum
    stays at t = 0 (a later dwell's -1e-25 is a tie, not a lower value)."""
    low = _locate(0.01, NOISES[noise], start_dwell=True)["min"]
    assert low.t == 0.0 and low.value == 0.0 and low.limit is None and low.constant


def test_smooth_maximum_is_still_located_between_rows():
    """The bumps' maximum 3 lies at t = 0.5 + k; the rows at step 0.013 miss it: located to the parabola's error,
    the earliest bump winning among bumps equal to round-off."""
    high = _locate(0.013, NOISES["plus"])["max"]
    assert high.value == pytest.approx(3.0, rel=1e-10) and high.t == pytest.approx(0.5, abs=1e-5)
    assert high.where == "interior" and not high.constant
