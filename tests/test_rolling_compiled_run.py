"""The rolling-pair 4-bar on diffrax's compiled whole run (`RollingPairFourBar.transitions`,
dynamics/backends/diffrax_run.py): its one transition is the dead point, where the driven link reverses under a torque and
a prescribed speed must stop (the table's two evaluations agree: tests/test_transition_table.py); the runs of
tests/test_rolling_dynamics.py that meet dead points, in one compiled call, against the segment loop, the
independent dead-point condition and energy."""
from dataclasses import replace

import numpy as np
import pytest

from mechsim.dynamics import hybrid
from mechsim.dynamics.backends.diffrax_backend import DiffraxBackend, default_options
from mechsim.dynamics.drives import Drive
from mechsim.dynamics.settings import SolverSettings
from mechsim.dynamics.tables import events_table, timeseries
from mechsim.mechanisms.rolling.model import Bodies, RollingPairFourBar
from mechsim.mechanisms.rolling.sets import make

RTOL = 1e-9


def mechanism(set_name="A", **kw):
    """The bodies of tests/test_rolling_dynamics.py: rods 0.2 / 0.3 kg, link 4 = 0.5 kg disc + 0.1 kg arm."""
    kin = make(set_name)
    return RollingPairFourBar(kin, Bodies.uniform(kin, 0.2, 0.3, 0.5, 0.1), **kw)


def both(mech, drive, t_end, angle0, speed0=0.0):
    """The run in one compiled call and on the segment loop (same diffrax options otherwise)."""
    settings = SolverSettings(backend="diffrax", formulation="index1", rtol=RTOL, atol=RTOL * 1e-2)
    o = default_options(settings)
    out = []
    for opts in (o, replace(o, compiled_run=False)):
        traj = hybrid.simulate(mech, drive, settings, t_end, 0.01, angle0, speed0,
                               backend=DiffraxBackend(settings, opts))
        out.append((traj, timeseries(traj, mech.angle_coordinates)))
    return out


def _crank_dead_point(mech, q):
    """w . B'(phi) = 0: the coupler's line through the contact point (independent of the model)."""
    kin = mech.kin
    tr = kin.trochoid(np.array([q[2]]))
    w = tr["B"][0] - (kin.a0 + kin.l2 * np.exp(1j * q[0]))
    return (w.real * tr["dB"][0].real + w.imag * tr["dB"][0].imag) / (kin.l3 * abs(tr["dB"][0]))


def _agree(whole, segments):
    (tw, dw), (ts, ds) = whole, segments
    assert "inside 1 compiled" in tw.stats["notes"]["segments"]
    ew, es = events_table(tw), events_table(ts)
    assert list(ew["kind"]) == list(es["kind"])
    # event times located on each path's own interpolant, equal to the integration error (as the Geneva's, 1e-6 s)
    np.testing.assert_allclose(ew["t_s"], es["t_s"], rtol=0, atol=1e3 * RTOL)
    assert np.array_equal(dw["t_s"], ds["t_s"])
    for c in ("crank_angle_rad", "coupler_angle_rad", "rolling_angle_rad"):   # 1e-11 rad measured
        assert np.max(np.abs(dw[c] - ds[c])) <= 100 * RTOL, c
    return ew, dw


def test_crank_torque_dead_points_in_one_call():
    """Set A driven at the crank (5 N m, no gravity), 4 s: two dead points, each where the coupler line passes
    through the contact point, the crank reversing; energy closes; the same events and rows as the segment loop."""
    mech = mechanism(driven_link="crank")
    theta0 = float(mech.kin.solve(np.array([0.0]), 1).theta2[0])
    whole, segments = both(mech, Drive("torque", torque=5.0), 4.0, theta0)
    assert whole[0].failure is None and segments[0].failure is None
    ev, df = _agree(whole, segments)
    assert len(ev) == 2 and set(ev["kind"]) == {"dead point"}
    for _, row in ev.iterrows():
        q = np.array([row["crank_q"], row["coupler_q"], row["rolling_q"]])
        assert abs(_crank_dead_point(mech, q)) <= 1e-8       # as on IDA (tests/test_rolling_dynamics.py)
        i = int(np.searchsorted(df["t_s"], row["t_s"]))
        assert df["crank_speed_rad_s"].iloc[i - 1] * df["crank_speed_rad_s"].iloc[i] < 0
    closure = df["work_drive_J"] - (df["kinetic_energy_J"] - df["kinetic_energy_J"].iloc[0])
    assert np.max(np.abs(closure)) <= 1e-6 * df["work_drive_J"].abs().max()


def test_rolling_input_dead_point_in_one_call():
    """Set B, torque on the rolling link from phi = 3: one dead point at the closure end 5.781935 rad
    (docs/theory.md §K2.2), the link reversing."""
    mech = mechanism("B")
    whole, segments = both(mech, Drive("torque", torque=2.0), 3.0, 3.0)
    assert whole[0].failure is None
    ev, df = _agree(whole, segments)
    assert list(ev["kind"]) == ["dead point"]
    assert ev["rolling_q"].iloc[0] == pytest.approx(5.781935, abs=1e-6)


def test_prescribed_speed_stops_at_the_margin_in_one_call():
    """A prescribed crank speed stops at |transmission| = dead_point_margin: the compiled run hands the guard
    back to on_guard, which stops the run with the same physics failure as on the segment loop."""
    mech = mechanism(driven_link="crank", prescribed=True, dead_point_margin=0.01)
    theta0 = float(mech.kin.solve(np.array([0.0]), 1).theta2[0])
    (tw, _), (ts, _) = both(mech, Drive("speed", speed=1.0), 4.0, theta0, 1.0)
    for traj in (tw, ts):
        f = traj.failure
        assert f is not None and f["kind"] == "physics" and "dead point" in f["reason"]
        q = np.array([f["where"][c] for c in mech.coordinates])
        assert abs(mech.transmissions(q)[1]) == pytest.approx(0.01, abs=1e-6)
    assert tw.failure["time"] == pytest.approx(ts.failure["time"], abs=1e3 * RTOL)
