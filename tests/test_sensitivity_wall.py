"""Sensitivities of the temperatures under the 1-D wall-track model (thermal.model = "1d"; docs/sensitivity.md,
"The 1-D wall-track model"): the peak contact temperature, the peak flash rise and the heat per index against
central finite differences of the IDA path, and the exact identities of the model.

geneva-motor for 0.7 s (motor drive from 5.34 rad/s, friction 0.15: one engagement with a slip reversal) on a
coarse mesh (growth 3, first cell 1 mm: 3 cells into each of the 4 slot walls, 12 mesh states) so that the
compiled pass stays small; the derivatives are those of the discretised model on that mesh whatever its
coarseness. The values traced move every part of the wall model: the mesh depth 3 sqrt(chi n P/pi) moves with
the conductivity, the density and the nominal speed (here initial.crank_speed), the track area with the crank
radius and the thickness, the heat into the track with the friction and the load.

Finite differences as tests/test_sensitivity_thermal.py (the same helper, tests/thermal_fd.py): IDA at rtol
1e-12 (the reference is the more accurate side), relative steps 5e-4 and 2.5e-4, Richardson-extrapolated:
truncation O(h^4) ~ 1e-13, round-off ~ rtol/h = 2e-9, both far below the 1e-4 asserted. Each quantity is read at the sensitivity's own row (a peak
that moves to a neighbouring row within a step does not change which row is differentiated).
"""
from __future__ import annotations

import pytest

import mechsim
from mechsim.scenarios.studies.sensitivity import THERMAL_PEAKS, sensitivity
from conftest import run_locating
from thermal_fd import assert_thermal_matches_fd

NAME = "geneva-motor"
SETS = ["thermal.model=1d", "duration=0.7 s", "thermal.mesh_growth=3", "thermal.mesh_first_cell=1 mm"]
SENS = ["solver.rtol=1e-10", "solver.atol=1e-12"]
FD = ["solver.rtol=1e-12", "solver.atol=1e-14"]
OF = list(THERMAL_PEAKS) + ["heat_per_index_J"]
H = 5e-4
#: an elasticity that is zero (a thermal value cannot move the heat per index) is compared absolutely, as in
#: tests/test_sensitivity_thermal.py
ELASTICITY_FLOOR = 1e-6
WRT = ["load.wheel_torque", "contact.friction", "mechanism.crank_radius", "mechanism.thickness",
       "thermal.conductivity", "thermal.density", "initial.crank_speed", "thermal.ambient_temperature"]
#: the values also compared with finite differences (the ambient is checked exactly: test_exact_identities)
CHECKED = 7


def _run(sets):
    """The run the finite differences read: its thermal peaks located (`run_locating`: the mechanics' are not read)."""
    r = run_locating(mechsim.load(NAME, set=SETS + sets))
    assert r.failure is None, r.failure.message()
    return r


@pytest.fixture(scope="module")
def table():
    return sensitivity(mechsim.load(NAME, set=SETS + SENS), WRT, OF)


def test_wall_temperatures_match_finite_differences(table):
    nominal = assert_thermal_matches_fd(table, lambda sets: _run(FD + sets), WRT[:CHECKED], H, ELASTICITY_FLOOR)
    assert nominal.summary["thermal"]["mesh"]["cells_per_track"] == 3


def test_exact_identities(table):
    """(1) The flash rise's elasticities in k and rho add up to -1 (scaling k and rho c_p together keeps every Peclet
    number and scales the band rises by 1/k; docs/theory.md §G4.2-§G4.6). (2) The network, meshes included, is
    linear with every source h A T_amb and starts at T_amb (docs/theory.md §G5-§G6): T - T_amb does not depend on
    T_amb, so d(contact temperature)/d T_amb = 1 and the flash rise does not depend on it. (3) No thermal value
    moves the heat per index."""
    t = table.set_index(["quantity", "wrt"])
    flash = "peak_temp_flash_rise_K"
    assert (t.loc[(flash, "thermal.conductivity"), "elasticity"] + t.loc[(flash, "thermal.density"), "elasticity"]
            == pytest.approx(-1.0, abs=1e-10))
    assert t.loc[("peak_temp_contact_C", "thermal.ambient_temperature"), "derivative"] == pytest.approx(1.0, abs=1e-9)
    assert t.loc[(flash, "thermal.ambient_temperature"), "derivative"] == 0.0
    for key in ("thermal.conductivity", "thermal.density", "thermal.ambient_temperature"):
        assert t.loc[("heat_per_index_J", key), "derivative"] == 0.0


@pytest.mark.parametrize("key", ["thermal.mesh_depth", "thermal.mesh_first_cell", "thermal.mesh_growth"])
def test_mesh_settings_are_refused(key):
    """The mesh is a discretisation choice (its depth and first cell set the cells, not the physics): its settings
    are not values to differentiate, and are refused by name before anything runs."""
    from mechsim.scenarios.units import ScenarioError
    sc = mechsim.load(NAME, set=SETS + ["thermal.mesh_depth=10 mm"])
    with pytest.raises(ScenarioError) as err:
        sensitivity(sc, [key], OF)
    assert err.value.field == key
