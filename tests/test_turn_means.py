"""The periodic regime's means over its last turn (`periodic.mean`, docs/theory.md §K5): Simpson's rule on each gap
between a smooth interval's instants (its ends, with the one-sided limits there, and its rows), with the column
read at the gap's midpoint, so a jump costs nothing and the error is O(h^4 |F''''|). Checked against what the
integrator itself integrates over the same turn, whose ends lie in a dwell:

- the crank turns once a turn: the mean crank speed is 2 pi / (b - a);
- the wheel turns one index a turn (the ends in a dwell, where it stands): the mean wheel speed is
  (2 pi / slots) / (b - a);
- the heat generated is integrated as a state: the mean heat rate is its change over the turn / (b - a) (no heat
  in the dwell, where the rows are interpolated to a and b).

The run's rtol 1e-7 bounds each speed's error, so the means' too; measured at most 1e-8 (internal-geneva-motor
and geneva-motor, 1 and 2.3 ms rows). The trapezoidal rule before: 1.8e-4 (geneva-torque's wheel speed at 1 ms),
5.8e-5 (internal-geneva-motor's wheel at 2.3 ms), 1.5e-5 (its heat rate), moving with the output step.
"""
import numpy as np
import pytest

import mechsim


@pytest.mark.parametrize("name, step", [("internal-geneva-motor", "1 ms"), ("internal-geneva-motor", "2.3 ms"),
                                        ("geneva-motor", "2.3 ms")])
def test_turn_means_equal_what_the_integrator_integrates(name, step):
    r = mechsim.run(mechsim.load(name, set=["output.plots=false", f'output_step="{step}"']))
    peaks, df = r.summary["peaks"], r.timeseries
    a, b = peaks["crank_speed_rad_s"]["periodic"]["mean_over"]
    slots = r.scenario["mechanism"]["slots"]
    assert peaks["crank_speed_rad_s"]["periodic"]["mean"] == pytest.approx(2 * np.pi / (b - a), rel=1e-7)
    assert peaks["wheel_speed_rad_s"]["periodic"]["mean"] == pytest.approx(2 * np.pi / slots / (b - a), rel=1e-7)
    if "heat_rate_W" in peaks:
        assert peaks["heat_rate_W"]["periodic"]["mean_over"] == [a, b]
        t = df["t_s"].to_numpy()
        generated = np.interp([a, b], t, df["heat_generated_J"].to_numpy())
        assert peaks["heat_rate_W"]["periodic"]["mean"] == pytest.approx((generated[1] - generated[0]) / (b - a),
                                                                          rel=1e-7)


def test_a_flash_rise_mean_hardly_moves_with_the_output_step():
    """The flash rise starts like sqrt(t - t_on) where a contact begins (docs/theory.md §G4.6), where Simpson's rule
    loses its order: the knots graded toward each interval's ends (`peaks.ONSET_GRADING`) keep its mean over the
    turn within 5e-5 between 1, 2.3 and 10 ms rows (4.5e-4 and 5e-3 of it apart at 2.3 and 10 ms before)."""
    means = [mechsim.run(mechsim.load("internal-geneva-motor", set=["output.plots=false", f'output_step="{step}"'])
                         ).summary["peaks"]["temp_flash_rise_K"]["periodic"]["mean"]
             for step in ("1 ms", "2.3 ms", "10 ms")]
    assert max(means) - min(means) <= 5e-5 * max(means)
