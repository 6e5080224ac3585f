"""Lumped (bulk) temperatures of the pin (with its crank) and the wheel; docs/theory.md §G5.

C_i dT_i/dt = gamma_i Q - h_i A_i (T_i - T_inf) - G (T_i - T_j), C_i = rho c_p V_i (Incropera et al. 2007,
§5.2; valid for Bi = h (V/A)/k < 0.1, here ~4e-4). Because the time constants (~10^3 s) dwarf the cycle
(~1 s), the cycle-mean heat may replace Q(t) (`integrate_mean_heat`). Temperatures in K.
"""
from __future__ import annotations

import math

import numpy as np

from mechsim.thermal.linear import LinearThermalSystem
from mechsim.thermal.materials import Material, get_material

STATE_NAMES = ("temp_bulk_pin", "temp_bulk_wheel")
INPUT_NAMES = ("heat_rate_pin_W", "heat_rate_wheel_W")

#: Still-air / radiation heat-transfer coefficients, W/(m^2 K), from docs/theory.md §G5 (air 300 K, dT = 20 K;
#: Incropera et al. 2007: Churchill–Chu eq. 9.34 cylinder and vertical plate, Hilpert Table 7.2, h_r = 4 eps sigma T^3).
CONVECTION_COEFFICIENTS = {
    "pin_still_air": 8.5,             # 8 mm horizontal cylinder, free convection
    "pin_orbiting_0.4_m_s": 24.0,     # cross-flow at the crank-pin speed
    "wheel_vertical_plate": 4.8,      # 0.15 m vertical plate, free convection
    "radiation_eps_0.1": 0.6,
    "radiation_eps_0.3": 1.8,
    "radiation_eps_0.8": 4.9,
}
#: Defaults inside the ranges docs/theory.md §G5 recommends (wheel 5–12, pin 10–25 W/(m^2 K)).
H_WHEEL_DEFAULT = 7.0
H_PIN_DEFAULT = 15.0
TEMP_AMBIENT_DEFAULT = 293.15


def disc_volume_area(radius, thickness) -> tuple[float, float]:
    """Solid disc: V = pi R^2 t, A = 2 pi R^2 + 2 pi R t (both faces and rim) (m^3, m^2); docs/theory.md §G5."""
    return math.pi * radius**2 * thickness, 2.0 * math.pi * radius**2 + 2.0 * math.pi * radius * thickness


def pin_volume_area(radius, exposed_length, free_end: bool = True) -> tuple[float, float]:
    """Pin: exposed cylinder V = pi R^2 l, A = 2 pi R l (+ pi R^2 for the free end) (m^3, m^2); docs/theory.md §G5."""
    area = 2.0 * math.pi * radius * exposed_length + (math.pi * radius**2 if free_end else 0.0)
    return math.pi * radius**2 * exposed_length, area


def biot_number(h, volume, area, conductivity) -> float:
    """Bi = h (V/A)/k; lumping is valid for Bi < 0.1 (Incropera et al. 2007, §5.2)."""
    return h * volume / area / conductivity


def time_constant(material: Material | str, volume, area, h) -> float:
    """tau = rho c_p (V/A)/h (s); docs/theory.md §G5 (wheel 75x4 mm, h=7: 1034 s)."""
    return get_material(material).volumetric_heat_capacity * volume / area / h


def bulk_system(capacity_pin, capacity_wheel, hA_pin, hA_wheel, conductance_pin_wheel: float = 0.0,
                temp_ambient: float = TEMP_AMBIENT_DEFAULT) -> LinearThermalSystem:
    """The two-body bulk network C T' = -K T + s_amb + B [Q_pin, Q_wheel] (docs/theory.md §G5).

    K = [[hA_p + G, -G], [-G, hA_w + G]], s_amb = [hA_p, hA_w] T_inf, B = I (inputs are the heat rates into
    each body, gamma Q and (1 - gamma) Q).
    """
    G = conductance_pin_wheel
    K = np.array([[hA_pin + G, -G], [-G, hA_wheel + G]], dtype=float)
    return LinearThermalSystem(
        state_names=STATE_NAMES, capacity=np.array([capacity_pin, capacity_wheel], dtype=float), conductance=K,
        source=np.array([hA_pin, hA_wheel], dtype=float) * temp_ambient, input_matrix=np.eye(2),
        input_names=INPUT_NAMES)


def geneva_bulk_system(material_pin: Material | str = "aisi1045", material_wheel: Material | str = "aisi1045", *,
                       pin_radius: float = 4e-3, pin_exposed_length: float = 10e-3,
                       wheel_radius: float = 75e-3, wheel_thickness: float = 4e-3,
                       crank_volume: float = 0.0, crank_area: float = 0.0,
                       h_pin: float = H_PIN_DEFAULT, h_wheel: float = H_WHEEL_DEFAULT,
                       conductance_pin_wheel: float = 0.0,
                       temp_ambient: float = TEMP_AMBIENT_DEFAULT) -> LinearThermalSystem:
    """Bulk network from geometry: pin (plus an optional crank volume/area lumped with it, same material and h)
    and the wheel as a solid disc. Defaults: the seed's geometry (docs/theory.md §G0) and §5's h."""
    pin, wheel = get_material(material_pin), get_material(material_wheel)
    v_p, a_p = pin_volume_area(pin_radius, pin_exposed_length)
    v_p, a_p = v_p + crank_volume, a_p + crank_area
    v_w, a_w = disc_volume_area(wheel_radius, wheel_thickness)
    return bulk_system(pin.volumetric_heat_capacity * v_p, wheel.volumetric_heat_capacity * v_w,
                       h_pin * a_p, h_wheel * a_w, conductance_pin_wheel, temp_ambient)


def _mean_inputs(heat_mean, share_pin) -> np.ndarray:
    return np.array([share_pin * heat_mean, (1.0 - share_pin) * heat_mean], dtype=float)


def cycle_means(times, heat_rate, heat_share_pin) -> tuple[float, float]:
    """Cycle-mean heat Q_bar = (1/T) int Q dt and heat-weighted pin share gamma_bar = int gamma Q dt / int Q dt
    over one period sampled at `times` (trapezoid rule); the inputs of `integrate_mean_heat` (docs/theory.md §G5)."""
    t = np.asarray(times, dtype=float)
    Q = np.broadcast_to(np.asarray(heat_rate, dtype=float), t.shape)
    g = np.broadcast_to(np.asarray(heat_share_pin, dtype=float), t.shape)
    energy = np.trapezoid(Q, t)
    span = t[-1] - t[0]
    if span <= 0:
        raise ValueError("cycle_means: times must span a positive interval")
    share = np.trapezoid(g * Q, t) / energy if energy > 0 else 0.5
    return float(energy / span), float(share)


def steady_bulk_temperatures(system: LinearThermalSystem, heat_mean, share_pin) -> np.ndarray:
    """Steady [T_pin, T_wheel] under the mean heat Q_bar split gamma_pin : 1 - gamma_pin (docs/theory.md §G5)."""
    return system.steady_state(_mean_inputs(heat_mean, share_pin))


def integrate_mean_heat(system: LinearThermalSystem, heat_mean, share_pin, times, temp_initial=None) -> np.ndarray:
    """Bulk temperatures at `times` (s, from 0) under a constant cycle-mean heat, exact (matrix exponential).

    Valid because tau >> cycle period (docs/theory.md §G5); returns (len(times), 2). Starts at ambient by default.
    """
    if temp_initial is None:
        temp_initial = ambient_temperatures(system)
    return system.propagate(temp_initial, _mean_inputs(heat_mean, share_pin), times)


def ambient_temperatures(system: LinearThermalSystem) -> np.ndarray:
    """Ambient temperature per state recovered from s = hA T_inf (zero where a body has no convection)."""
    hA = np.asarray(system.conductance.sum(axis=1)).ravel()          # row sums: the coupling G cancels
    return np.divide(system.source, hA, out=np.zeros_like(system.source), where=hA > 0)
