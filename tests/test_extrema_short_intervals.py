"""Intervals with (almost) no output rows are read over their length (`extrema.with_rowless`), except one within
round-off of an instant: two events a few ulps apart (an exit and the next entry of one time step, say) bound an
interval whose one-sided limits are its ends, with nothing between them to read; nine readings there would be nine
equal instants, which a re-integration returns once (the failure this guards against: a plan whose table had fewer
readings than instants). A turn mean over no column is empty, not an error."""
import numpy as np

from mechsim.dynamics.extrema import Interval, with_rowless
from mechsim.scenarios.peaks import _turn_means


class _Recorder:
    """A reader that records what it was asked and answers a line in time."""

    def __init__(self):
        self.asked = []

    def __call__(self, iv, position, times):
        self.asked.append(np.asarray(times))
        return {"f": 2.0 * np.asarray(times)}


def test_an_interval_within_round_off_of_an_instant_is_not_read():
    t = np.array([0.0, 1.0, 2.0])
    lo = 7.061472147134613
    tiny = Interval(lo, lo + 8e-14, "exit", "entry", np.array([], dtype=int))
    short = Interval(2.0, 2.5, "entry", "exit", np.array([], dtype=int))
    read = _Recorder()
    t2, values, intervals = with_rowless(t, {"f": 2.0 * t}, [tiny, short], read)
    assert len(read.asked) == 1 and read.asked[0][0] == 2.0 and read.asked[0][-1] == 2.5
    assert len(t2) == len(values["f"]) == 3 + 9
    assert intervals[0] is tiny and len(intervals[1].rows) == 9
    np.testing.assert_array_equal(values["f"][intervals[1].rows], 2.0 * t2[intervals[1].rows])


def test_a_turn_mean_over_no_column_is_empty():
    assert _turn_means(np.array([0.0, 1.0]), {}, 0.0, 1.0, [], [], []) == {}
