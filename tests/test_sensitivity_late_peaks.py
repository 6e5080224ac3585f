"""The derivative of a peak read late in a run whose period moves with the value (docs/theory.md §K5).

dF/dp at a fixed time carries the phase's sensitivity, -F' dtau/dp, which grows with every cycle where the period
moves with p; the envelope rule cancels it only at the traced pass's own extremum, and the one-sided limit's rule
only with F'(tau) exact. Two built-ins read their peaks several cycles in: internal-geneva-motor's contact force is
the limit after an entry, an engagement or more into its motor-driven 5 s (which one follows the rounding: they
repeat to 1e-11); its wheel speed an interior maximum, likewise; chain-mech2-detuned's crank acceleration an
interior extremum 14.9 s into its 16 s of near-dwells. Before, the first was 7e-4 from the finite difference
(growing by 3.7e-4 an engagement), the second 2.7e-4, and the third moved by 2.9e-4 between output steps at the same
value and instant.
"""
from __future__ import annotations

import pytest

import mechsim
from conftest import located_peak, run_locating
from mechsim.scenarios.studies.sensitivity import sensitivity

#: the finite differences' runs: far tighter than the sensitivities' (the scenarios' own, rtol 1e-8 and the
#: default), so that they are the more accurate side
TIGHT = ["solver.rtol=1e-11", "solver.atol=1e-13"]
#: the sensitivities at the scenarios' tolerances against these differences: 1e-6 (contact force), 7e-7 (wheel
#: speed), 9e-7 (crank acceleration); a factor of 10 left
DERIVATIVE_REL = 1e-5


def _central(name: str, key: str, value: float, unit: str, h: float, columns: list[str]) -> dict:
    """Central differences of the run's located peaks, the step h relative (TIGHT runs). h = 1e-3: the
    differences at 1e-4, 3e-4 and 3e-3 agree with it to 1.5e-7, 1.3e-7 and 1.2e-6 (crank acceleration), 1e-8
    (contact force) and 5e-7 (wheel speed)."""
    ends = []
    for x in (value * (1 - h), value * (1 + h)):
        setting = f'{key}="{x!r} {unit}"' if unit else f"{key}={x!r}"
        result = run_locating(mechsim.load(name, set=[setting, *TIGHT]), columns)
        ends.append({c: located_peak(result, c) for c in columns})
    return {c: (ends[1][c] - ends[0][c]) / (2 * value * h) for c in columns}


def test_a_motor_driven_geneva_late_in_its_run():
    """The one-sided limit after an entry, and an interior maximum, against central differences: friction slows
    the crank, so each engagement comes later by a further dtau/dp."""
    table = sensitivity(mechsim.load("internal-geneva-motor"), ["contact.friction"],
                        ["peak_contact_force_N", "peak_wheel_speed_rad_s"]).set_index("quantity")
    assert table.loc["peak_contact_force_N", "t_s"] > 0.9 and table.loc["peak_wheel_speed_rad_s", "t_s"] > 0.9
    fd = _central("internal-geneva-motor", "contact.friction", 0.15, "", 1e-3, ["contact_force_N",
                                                                                 "wheel_speed_rad_s"])
    assert table.loc["peak_contact_force_N", "derivative"] == pytest.approx(fd["contact_force_N"], rel=DERIVATIVE_REL)
    assert table.loc["peak_wheel_speed_rad_s", "derivative"] == pytest.approx(fd["wheel_speed_rad_s"],
                                                                              rel=DERIVATIVE_REL)


def test_a_near_dwell_late_in_its_run_at_any_output_step():
    """The crank acceleration's extremum 14.9 s in: the same derivative at the scenario's 10 ms rows and at rows
    5.33 s apart (the run's instant and value agree to 2e-8 s and 1e-9), and the central difference's."""
    tables = [sensitivity(mechsim.load("chain-mech2-detuned", set=[f"output_step={step}"]), ["drive.torque"],
                          ["peak_crank_accel_rad_s2"]).set_index("quantity").loc["peak_crank_accel_rad_s2"]
              for step in ("10 ms", "5.33 s")]
    assert tables[0]["t_s"] > 14.0
    assert tables[1]["value"] == pytest.approx(tables[0]["value"], rel=1e-8)
    assert tables[1]["derivative"] == pytest.approx(tables[0]["derivative"], rel=DERIVATIVE_REL)
    fd = _central("chain-mech2-detuned", "drive.torque", 2.4e-3, "N*m", 1e-3, ["crank_accel_rad_s2"])
    assert tables[0]["derivative"] == pytest.approx(fd["crank_accel_rad_s2"], rel=DERIVATIVE_REL)


def test_event_times_late_in_an_accelerating_run():
    """geneva-torque over its own 5 s (33 engagements, the crank speeding up under a constant torque): the traced
    pass integrates each segment to the run's event time and refines it by a Newton step on its own guard; the
    sensitivities are carried over that step by their variational equation (dynamics/sensitivity.py `_event_fn`).
    They were not, and grow with the phase: the energy per cycle, exactly 2 pi in the torque (the torque's work over
    one turn), came out 6.287050 (6e-4), the cycle time 2e-3 from the central difference. Now 1.4e-8 and 2e-7."""
    table = sensitivity(mechsim.load("geneva-torque"), ["drive.torque"],
                        ["energy_per_cycle_J", "cycle_time_s"]).set_index("quantity")
    assert table.loc["energy_per_cycle_J", "derivative"] == pytest.approx(2 * 3.141592653589793, rel=1e-6)
    ends = []
    for torque in (6.0 * (1 - 1e-4), 6.0 * (1 + 1e-4)):
        result = mechsim.run(mechsim.load("geneva-torque", set=[f'drive.torque="{torque!r} N*m"', *TIGHT,
                                                                "output.plots=false"]))
        entries = result.events.loc[result.events["kind"] == "entry", "t_s"].to_numpy(float)
        ends.append(entries[32] - entries[31])      # the run's last cycle (its last entry is 7 ms before the end)
    fd = (ends[1] - ends[0]) / (2 * 6.0e-4)
    assert table.loc["cycle_time_s", "derivative"] == pytest.approx(fd, rel=DERIVATIVE_REL)
