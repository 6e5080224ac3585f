"""A quantity needs its unit written out (scenarios/units.py `to_si`), also where pint would read the text as a
dimensionless number: an angle written "1e5" or "2.5" is refused with the field's name, like the bare number 2.5,
while "2.5 rad" and "2.5 deg" convert; a unitless field takes the bare number."""
import math

import pytest

from mechsim.scenarios.units import ScenarioError, to_si


@pytest.mark.parametrize("text", ["1e5", "2.5", " 7 ", "-3"])
def test_a_number_in_a_string_without_unit_is_refused_for_an_angle(text):
    with pytest.raises(ScenarioError, match="needs a unit") as err:
        to_si("mechanism.arm_angle", text, "rad")
    assert "mechanism.arm_angle" in str(err.value)


def test_the_same_numbers_with_units_convert():
    assert to_si("mechanism.arm_angle", "2.5 rad", "rad") == 2.5
    assert math.isclose(to_si("mechanism.arm_angle", "180 deg", "rad"), math.pi, rel_tol=1e-15)
    assert to_si("contact.friction", "0.25", "") == 0.25
