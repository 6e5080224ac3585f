"""The Geneva's `closed_form_contact` (what the thermal switch search reads: engaged, slip, normal force) and
`closed_form_heat` (what contact_state reads) are the closed form's own columns, to the bit, so the switch times
and the contact state through them equal those through the full columns."""
import math

import numpy as np

from mechsim.scenarios.loader import load
from mechsim.scenarios.runner import build_mechanism
from mechsim.thermal.exact import closed_form_columns, contact_columns, switch_times


def test_closed_form_contact_is_the_closed_form_columns():
    for friction, torque in ((0.15, "7 N*m"), (0.3, "0 N*m")):          # no load: the wheel inertia flips the flank
        mech = build_mechanism(load("geneva-lc1", [f"contact.friction={friction}",
                                                   f"load.wheel_torque={torque}"]).si)
        t = np.linspace(0.0, 2.5, 1777)
        full = mech.closed_form(t, -math.pi, 5.34)
        lean = mech.closed_form_contact(t, -math.pi, 5.34)
        assert np.array_equal(lean["engaged"], full["mode"] == "engaged")
        for name in ("slip_speed_m_s", "contact_force_N"):
            assert lean[name].tobytes() == full[name].tobytes()
        heat = mech.closed_form_heat(t, -math.pi, 5.34)
        assert np.array_equal(heat["engaged"], full["mode"] == "engaged")
        for name, values in heat.items():
            if name != "engaged":
                assert values.tobytes() == np.asarray(full[name], dtype=float).tobytes(), name
        state, ref = mech.contact_state(heat), mech.contact_state(full)
        assert state.keys() == ref.keys()
        assert all(np.asarray(state[k]).tobytes() == np.asarray(ref[k]).tobytes() for k in ref)
        columns = closed_form_columns(mech, -math.pi, 5.34)
        grid = np.linspace(0.0, 2.5, 501)
        times = switch_times(contact_columns(mech, -math.pi, 5.34, columns), grid, grid_columns=columns(grid))
        assert times and times == switch_times(columns, grid)
