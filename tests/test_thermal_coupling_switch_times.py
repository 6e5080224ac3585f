"""The contact switch times of the closed-form thermal path: all brackets bisected together (one closed-form call
per halving) give the times of bracket-by-bracket bisection."""
import math

import numpy as np

from mechsim.scenarios.loader import load
from mechsim.scenarios.runner import build_mechanism
from mechsim.thermal.exact import closed_form_columns, contact_code, switch_times


def _one_at_a_time(columns, t_grid, tol=1e-13):
    code = contact_code(columns(t_grid))
    out = []
    for i in np.flatnonzero(code[1:] != code[:-1]):
        a, b, ca = float(t_grid[i]), float(t_grid[i + 1]), code[i]
        while b - a > tol * max(1.0, abs(b)):
            mid = 0.5 * (a + b)
            if contact_code(columns(mid))[0] == ca:
                a = mid
            else:
                b = mid
        out.append(0.5 * (a + b))
    return sorted(out)


def test_vectorised_switch_times_equal_scalar_bisection():
    mech = build_mechanism(load("geneva-lc1", ["duration=3.6 s"]).si)
    columns = closed_form_columns(mech, -math.pi, 5.34)
    t = np.linspace(0.0, 3.6, 721)
    fast, ref = switch_times(columns, t), _one_at_a_time(columns, t)
    assert len(fast) == len(ref) >= 9                # entry, slip reversal, exit in each of three turns
    np.testing.assert_allclose(fast, ref, rtol=0, atol=1e-14)
    for s in fast:                                   # the contact code changes across each time
        c = contact_code(columns(np.array([s - 1e-9, s + 1e-9])))
        assert c[0] != c[1]


def test_multilevel_search_gives_the_bisection_times_to_the_bit():
    """Several halvings per closed-form call walk the tree of the midpoints bisection would compute, in the same
    floating-point operations, so the times equal one-at-a-time bisection exactly (not merely within tol)."""
    for friction, torque, speed in ((0.05, "2 N*m", 3.0), (0.3, "12 N*m", 8.0), (0.15, "0 N*m", 5.34)):
        si = load("geneva-lc1", ["duration=2.5 s", f"contact.friction={friction}",
                                 f'load.wheel_torque="{torque}"']).si
        columns = closed_form_columns(build_mechanism(si), 0.3, speed)
        t = np.arange(0.0, 2.5 + 0.0025, 0.005)
        ref = _one_at_a_time(columns, t)
        assert len(ref) >= 4
        for levels in (1, 3, 6, 8):
            assert switch_times(columns, t, levels=levels) == ref
        assert switch_times(columns, t, grid_columns=columns(t)) == ref     # the run's table saves the grid call


def test_switches_searched_once_are_those_searched_with_the_known_instants_left_out():
    """A run's thermal integration and its located peaks search the same brackets (`contact_switches`, kept for the
    run): the peaks' search leaves out the brackets that hold an event, afterwards instead of before; each
    bracket's bisection is its own, so the times are those of `switch_times` given the known instants, to the bit,
    whichever call comes first."""
    from mechsim.thermal import exact
    from mechsim.thermal.exact import contact_columns, contact_switches
    si = load("geneva-lc1", ["duration=2.5 s", "contact.friction=0.15"]).si
    mech = build_mechanism(si)
    contact = contact_columns(mech, 0.3, 5.34, closed_form_columns(mech, 0.3, 5.34))
    t = np.arange(0.0, 2.5 + 0.0025, 0.005)
    every = switch_times(contact, t)
    known = np.array(every[::3])                       # a third of them known (events), some rows apart
    known = np.sort(np.r_[known, 0.5 * (t[10] + t[11])])      # and a bracket with no switch
    ref = switch_times(contact, t, known=known)
    assert 0 < len(ref) < len(every)
    for first in (None, known):
        exact._SWITCHES.clear()
        assert contact_switches(mech, 0.3, 5.34, t, known=first) == (every if first is None else ref)
        assert contact_switches(mech, 0.3, 5.34, t, known=known) == ref        # from the kept search
        assert contact_switches(mech, 0.3, 5.34, t) == every
