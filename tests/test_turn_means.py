"""The periodic regime's means over its last turn (`periodic.mean`, docs/theory.md §K5): the trapezoidal rule on
each smooth interval's rows with the one-sided limits at its ends, so a jump costs nothing and the error is
O(h^2 |F''|). Checked against what the integrator itself integrates over the same turn:

- the crank turns once a turn: the mean crank speed is 2 pi / (b - a) (measured 5e-8 at 1 ms rows, 2.5e-7 at
  2.3 ms: the O(h^2) of a smooth speed);
- the heat generated is integrated as a state: the mean heat rate is its change over the turn / (b - a) (measured
  3e-6 and 1.5e-5, the states read between rows linearly: O(h^2) too). The thermal columns' means were the
  trapezoid on the rows across the contact's jumps: 1.1e-3 off, moving with the output step.
"""
import numpy as np
import pytest

import mechsim


@pytest.mark.parametrize("step", ["1 ms", "2.3 ms"])
def test_turn_means_equal_what_the_integrator_integrates(step):
    r = mechsim.run(mechsim.load("internal-geneva-motor", set=["output.plots=false", f'output_step="{step}"']))
    peaks, df = r.summary["peaks"], r.timeseries
    a, b = peaks["heat_rate_W"]["periodic"]["mean_over"]
    t = df["t_s"].to_numpy()
    generated = np.interp([a, b], t, df["heat_generated_J"].to_numpy())
    assert peaks["heat_rate_W"]["periodic"]["mean"] == pytest.approx((generated[1] - generated[0]) / (b - a),
                                                                      rel=5e-5)
    assert peaks["crank_speed_rad_s"]["periodic"]["mean"] == pytest.approx(2 * np.pi / (b - a), rel=1e-6)
