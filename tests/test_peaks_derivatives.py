"""`mechsim sensitivity` differentiates the located peak F* = F(t*, p) (docs/theory.md §K5, docs/sensitivity.md
"Peaks"): at an interior maximum dF/dt = 0, so dF*/dp is dF/dp at the fixed instant t* (the envelope rule); the
check is central differences of the runs' located peaks, which no output row can bias."""
import pytest

import mechsim
from conftest import located_peak, run_locating
from mechsim.scenarios.studies.sensitivity import sensitivity

#: the issue's case (7.5 N*m load, rtol 1e-10); its contact force peaks at t = 0.42 s, so 0.6 s holds it
SETS = ["duration=0.6 s", "output_step=1 ms", "solver.rtol=1e-10", "solver.atol=1e-12"]
FD_SETS = ["duration=0.6 s", "output_step=4 ms", "solver.rtol=1e-12", "solver.atol=1e-14"]


def _peak(torque: float, friction: float) -> float:
    """The run's located peak of the contact force (the only peak located: `run_locating`)."""
    r = run_locating(mechsim.load("geneva-motor", set=FD_SETS + [f'load.wheel_torque="{torque!r} N*m"',
                                                                  f"contact.friction={friction!r}"]), ["contact_force_N"])
    assert r.failure is None
    return located_peak(r, "contact_force_N")


def test_peak_contact_force_derivatives_match_differences_of_the_located_peak():
    """Before, the row's derivative was reported: 32.237 against 32.313 from differences of the peak (2.4e-3
    off). Central differences with relative step 1e-3 (truncation ~1e-7 here); the differences run at rtol 1e-12,
    coarse rows (4 ms), so that a row-based value could not pass."""
    table = sensitivity(mechsim.load("geneva-motor", set=SETS + ['load.wheel_torque="7.5 N*m"']),
                        ["load.wheel_torque", "contact.friction"], of=["peak_contact_force_N"])
    assert not table.attrs["warnings"]
    d = table.set_index("wrt")["derivative"]
    value = table["value"].iloc[0]
    assert value == pytest.approx(_peak(7.5, 0.15), rel=1e-8)
    h_t, h_mu = 7.5e-3, 0.15e-3
    fd_t = (_peak(7.5 + h_t, 0.15) - _peak(7.5 - h_t, 0.15)) / (2 * h_t)
    fd_mu = (_peak(7.5, 0.15 + h_mu) - _peak(7.5, 0.15 - h_mu)) / (2 * h_mu)
    assert d["load.wheel_torque"] == pytest.approx(fd_t, rel=1e-4)
    assert d["contact.friction"] == pytest.approx(fd_mu, rel=1e-4)
