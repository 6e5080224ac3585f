"""The flash rise and the contact temperature of a contact state, in any array namespace (numpy or jax.numpy).

These are the formulas the run's thermal finish evaluates (`ThermalPlan._add_columns` with
`flash_temperature`, thermal/plan.py and thermal/flash.py, flash = 'jaeger'), written once in namespace-neutral
form so that jax can differentiate them at a row for the design sensitivities (docs/sensitivity.md); a test
checks that they give the run's columns on every engaged row. Valid where the contact carries load and slips
(N != 0, slip != 0, source speeds > 0): the rows where the rise is largest.
"""
from __future__ import annotations

import numpy as np

from mechsim.thermal.band_source import band_theta_table_xp
from mechsim.thermal.flash import TRANSIENT_FLOOR_COEFFICIENT

KELVIN = 273.15


def contact_temperature(contact: dict, t_on_pin, base_pin, base_wheel, mu, radius, length, modulus, conductivity,
                        diffusivity, distribution: str = "semi-elliptic", xp=np) -> dict:
    """Flash rise and contact temperature (K) of one body pair of equal material (docs/theory.md §G3-§G4.6).

    contact: normal_force, slip_speed, source_speed_driver (over the pin), source_speed_driven (over the wall),
    sliding_accel (of the wall, §G4.6); t_on_pin: time since the contact began; base_pin, base_wheel: the base
    temperatures (bulk states, or the ambient). Steps: Hertz half-width b = sqrt(4 |N| R/(pi l E*)) (§G3),
    heat Q = mu |N| |u| (§G4.1), Peclet numbers L_i = U_i b/(2 chi) (§G4.2), the wall's time under the band
    min(2b/U_wall, 2 sqrt(2b/a_s)) and the floors L_eff = max(L, c b/sqrt(chi t_on)) (§G4.6), the band rises
    R_i = theta_max(L_eff,i)/(2k) (§G4.3, the table), Blok's partition gamma = R_w/(R_p + R_w) and
    dT_flash = Q/l / (1/R_p + 1/R_w), T_contact = gamma T_pin + (1 - gamma) T_wheel + dT_flash (§G4.6).
    """
    N = xp.abs(contact["normal_force"])
    U_pin = xp.abs(contact["source_speed_driver"])
    U_wall = xp.abs(contact["source_speed_driven"])
    a_s = xp.abs(contact["sliding_accel"])
    b = xp.sqrt(4.0 * N * radius / (np.pi * length * modulus))
    t_on_wall = xp.minimum(2.0 * b / U_wall, 2.0 * xp.sqrt(2.0 * b / a_s))
    heat = mu * N * xp.abs(contact["slip_speed"])
    resistance = []
    for U, t_on in ((U_pin, t_on_pin), (U_wall, t_on_wall)):
        L = U * b / (2.0 * diffusivity)
        L_eff = xp.maximum(L, TRANSIENT_FLOOR_COEFFICIENT * b / xp.sqrt(diffusivity * t_on))
        resistance.append(band_theta_table_xp(L_eff, distribution, "max", xp) / (2.0 * conductivity))
    r_pin, r_wall = resistance
    share = r_wall / (r_pin + r_wall)
    rise = r_pin * r_wall / (r_pin + r_wall) * heat / length
    return {"heat_rate_W": heat, "hertz_half_width_m": b, "heat_share_pin": share, "temp_flash_rise_K": rise,
            "temp_contact_K": share * base_pin + (1.0 - share) * base_wheel + rise}
