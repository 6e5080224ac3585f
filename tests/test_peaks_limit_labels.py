"""A located extremum reported as a one-sided limit lies where the limit is taken (docs/theory.md §K5).

`_refine` takes the output row itself where it beats every reading of its bracket (between two of them): that
extremum is the row's value at the row's instant, not the limit at the interval's end the bracket's best reading
was. chain-mech2-kinematic's least crank acceleration (round-off in a dwell) was reported at the row t = 11 s
labelled as the limit after the stop impact at 10.998 s.
"""
import numpy as np
import pytest

from mechsim.scenarios.loader import load
from mechsim.scenarios.runner import run


@pytest.mark.parametrize("name", ["chain-mech2-kinematic", "chain-mech1-kinematic", "geneva-motor"])
def test_an_extremum_labelled_a_limit_is_at_an_event_or_an_end(name):
    result = run(load(name, ["output.plots=false"]))
    t = result.timeseries["t_s"].to_numpy()
    places = np.r_[result.events["t_s"].to_numpy(dtype=float), t[0], t[-1]]
    checked = 0
    for column, entry in result.summary["peaks"].items():
        for window in (entry, entry.get("startup") or {}):
            for sense in ("max", "min"):
                x = window.get(sense)
                if not isinstance(x, dict):
                    continue
                labelled = "limit from" in x["at"]
                assert labelled == (x.get("limit") in ("before", "after")) or "without bound" in x["at"], x
                if labelled:
                    checked += 1
                    assert np.min(np.abs(places - x["t_s"])) <= 1e-12 * max(1.0, abs(x["t_s"])), (column, x)
    assert checked > 0
