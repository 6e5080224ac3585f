"""Sensitivities of the located thermal peaks of a closed-form run (a prescribed crank speed, resolved; docs/
sensitivity.md, "Temperatures"): `mechsim run` locates them on the closed form (scenarios/thermal_peaks.py
`ClosedFormThermalReader`); `mechsim sensitivity` reports that value and differentiates the DAE pass's own located
peak (the speed as a constraint) at its t* by the envelope rule. The seed's load case 1 (geneva-lc1, lumped) for 1 s:
one engagement, whose contact temperature and flash rise peak inside it. The table's value is the run's located
peak, the DAE pass's traced value equals it to the solver's tolerance, and the derivatives equal central
differences of the run's located peak (the closed form itself) at two steps to 1e-4 relative."""
from __future__ import annotations

import pytest

import mechsim
from mechsim.scenarios.studies.sensitivity import sensitivity

NAME = "geneva-lc1"
SETS = ["duration=1 s", "thermal.model=lumped", "solver.rtol=1e-10", "solver.atol=1e-12"]
COLUMNS = {"peak_temp_contact_C": "temp_contact_C", "peak_temp_flash_rise_K": "temp_flash_rise_K"}
WRT = {"contact.friction": "", "mechanism.crank_radius": "m"}
#: relative steps of the central differences. The located peak's error (the quadrature's, round-off on the cycle's
#: pieces, plus the locating polynomial's, 1e-11 relative: tests/test_peaks_thermal_closed_form.py) over the step
#: is below 1e-6 of these derivatives (elasticities >= 0.12) at 5e-5; their h^2 truncation below 1e-7 at 1e-4
STEPS = (1e-4, 5e-5)


@pytest.fixture(scope="module")
def table():
    return sensitivity(mechsim.load(NAME, set=SETS), list(WRT), list(COLUMNS))


def _peaks(sets) -> dict:
    r = mechsim.run(mechsim.load(NAME, set=SETS + sets))
    assert r.failure is None and r.summary["peaks"]["temp_contact_C"]["how"].startswith("located: the closed form")
    return {q: r.summary["peaks"][c]["max"] for q, c in COLUMNS.items()}


def test_value_is_the_runs_located_peak(table):
    """The value and instant are the run's located peak; the DAE pass's own located value (elasticity = p/y dy/dp
    on the traced value) agrees with it to the two integrations' tolerance (rtol 1e-10: 1e-8 relative bound)."""
    own = _peaks([])
    for q in COLUMNS:
        part = table[table["quantity"] == q]
        assert part["value"].iloc[0] == own[q]["value"] and part["t_s"].iloc[0] == own[q]["t_s"]
        assert own[q]["at"] == "interior" and own[q]["value"] > own[q]["best_row_value"] + 1e-6
        row = part.iloc[0]
        traced = row["parameter"] * row["derivative"] / row["elasticity"]
        assert traced == pytest.approx(own[q]["value"], rel=1e-8)
    assert not [w for w in table.attrs["warnings"] if "peak_temp" in w]


def test_derivatives_match_central_differences_of_the_run(table):
    worst = {}
    for key, unit in WRT.items():
        part = table[table["wrt"] == key].set_index("quantity")
        p = float(part["parameter"].iloc[0])

        def evaluate(v):
            return {q: e["value"] for q, e in _peaks([f"{key}={v!r} {unit}".strip()]).items()}
        for h in STEPS:
            plus, minus = evaluate(p * (1 + h)), evaluate(p * (1 - h))
            for q in COLUMNS:
                fd = (plus[q] - minus[q]) / (2 * p * h)
                worst[(key, q, h)] = abs(float(part.loc[q, "derivative"]) - fd) / abs(fd)
    print({k: f"{v:.2g}" for k, v in worst.items()})
    assert max(worst.values()) <= 1e-4, worst
