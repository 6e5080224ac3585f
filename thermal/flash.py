"""Flash (contact) temperature rise of a sliding line contact: per-body rises, Blok's partition, seed variants.

mechsim's model (docs/theory.md §G4.3, §4.6): each body i alone would rise dT_i* = theta_i(L_i) Q'/(2 k_i)
(steady moving band, Jaeger 1942); Blok's postulate (equal surface temperatures) splits the heat as
gamma_1 = dT_2*/(dT_1* + dT_2*) and gives dT_flash = 1/(1/dT_1* + 1/dT_2*). Slow sources are capped by
the time the source has been on: L_eff = max(L, c b/sqrt(chi t_on)), c = exp(-gamma_E/2) = 0.749.

The seed's own equations (S(7), S(8), S(13)) are here only to reproduce and compare with the seed; see
docs/thermal.md for why they are wrong.
"""
from __future__ import annotations

import math

import numpy as np

from mechsim.thermal.band_source import EULER_GAMMA, band_fit, band_theta_exact, band_theta_table
from mechsim.thermal.heat import frictional_heat, peclet
from mechsim.thermal.materials import Material, get_material

#: c in L_eff = max(L, c b/sqrt(chi t_on)) = exp(-gamma_E/2) = 0.7493: the Peclet number at which the
#: steady low-L centre rise of the uniform band, (2/pi)[ln(1/L) + 1 + ln 2 - gamma_E], equals the rise of
#: the stationary band switched on for t_on, (1/pi)[ln(4 chi t_on/b^2) + 2 - gamma_E] (docs/theory.md §G4.6: 0.749).
TRANSIENT_FLOOR_COEFFICIENT = math.exp(-0.5 * EULER_GAMMA)

#: The seed's S(13) constants: 0.159 (≈ 1/(2 pi), as printed) and C = 2.5 read from S&B's chart.
SEED_S13_PREFACTOR = 0.159
SEED_S13_C = 2.5


def band_theta_eval(L, distribution: str = "semi-elliptic", statistic: str = "max", evaluator: str = "table"):
    """theta(L) by the chosen evaluator: 'table' (fast, exact to 2e-5), 'fit' (closed form, ≤5 %), 'exact' (slow)."""
    if evaluator == "table":
        return band_theta_table(L, distribution, statistic)
    if evaluator == "fit":
        with np.errstate(divide="ignore"):
            return band_fit(np.asarray(L, dtype=float), distribution, statistic)
    if evaluator == "exact":
        return band_theta_exact(L, distribution, statistic)
    raise ValueError(f"unknown theta evaluator {evaluator!r}; use 'table', 'fit' or 'exact'")


def transient_peclet_floor(half_width_m, diffusivity, t_on):
    """c b/sqrt(chi t_on) with c = TRANSIENT_FLOOR_COEFFICIENT; 0 for t_on = inf, inf for t_on = 0 (docs/theory.md §G4.6)."""
    t_on = np.asarray(t_on, dtype=float)
    if np.any(t_on < 0) or np.any(np.isnan(t_on)):
        raise ValueError("transient_peclet_floor: t_on must be >= 0 (inf for no floor)")
    with np.errstate(divide="ignore"):
        return TRANSIENT_FLOOR_COEFFICIENT * np.asarray(half_width_m, dtype=float) / np.sqrt(diffusivity * t_on)


def effective_peclet(L, half_width_m, diffusivity, t_on):
    """L_eff = max(L, 0.749 b/sqrt(chi t_on)): a source on for t_on cannot exceed the switched-on stationary rise (§4.6)."""
    return np.maximum(L, transient_peclet_floor(half_width_m, diffusivity, t_on))


def single_body_rise(heat_per_length, theta, conductivity):
    """dT* = theta Q'/(2 k): rise of one body taking all the heat (Jaeger 1942; docs/theory.md §G4.3)."""
    return np.asarray(theta, dtype=float) * np.asarray(heat_per_length, dtype=float) / (2.0 * conductivity)


def blok_partition(resistance_1, resistance_2):
    """Blok's postulate for two bodies with rise-per-heat R_i = dT_i*/Q' (K m/W): (share of body 1, R_flash).

    gamma_1 = R_2/(R_1 + R_2), R_flash = 1/(1/R_1 + 1/R_2) (docs/theory.md §G4.6). R = inf (no steady limit)
    takes no heat, R = 0 (source just switched on) takes it all; if R_1 = R_2 in {0, inf} the share is 1/2.
    """
    r1 = np.asarray(resistance_1, dtype=float)
    r2 = np.asarray(resistance_2, dtype=float)
    with np.errstate(divide="ignore", invalid="ignore"):
        share_1 = r2 / (r1 + r2)
        share_1 = np.where(np.isinf(r1) & np.isfinite(r2), 0.0, share_1)
        share_1 = np.where(np.isinf(r2) & np.isfinite(r1), 1.0, share_1)
        share_1 = np.where(np.isnan(share_1), 0.5, share_1)
        r_flash = 1.0 / (1.0 / r1 + 1.0 / r2)
    return share_1, r_flash


def blok_flash_high_peclet(heat_per_length, half_width_m, speed_1, speed_2, effusivity_1, effusivity_2, coefficient=1.11):
    """Blok (1937) high-Pe flash rise 1.11 Q'/(sqrt(2b)(e_1 sqrt U_1 + e_2 sqrt U_2)) (docs/theory.md §G4.6).

    Equal to the Jaeger/Blok partition when both L_i >> 1 with coefficient = semi-elliptic A = 1.1115.
    """
    denom = np.sqrt(2.0 * np.asarray(half_width_m, dtype=float)) * (
        effusivity_1 * np.sqrt(np.abs(speed_1)) + effusivity_2 * np.sqrt(np.abs(speed_2)))
    return coefficient * np.asarray(heat_per_length, dtype=float) / denom


def flash_temperature(N, slip, U_wall, U_pin, b, length, mu,
                      material_pin: Material | str, material_wheel: Material | str,
                      t_on_pin=np.inf, t_on_wall=np.inf, distribution: str = "semi-elliptic",
                      method: str = "jaeger", statistic: str = "max", evaluator: str = "table") -> dict:
    """Flash temperature rise of the pin–slot line contact, vectorised over time series (SI in, SI out).

    N normal force (N, signed), slip speed (m/s, signed), source speeds over the wall U_wall and over the pin
    U_pin (m/s), Hertz half-width b (m), contact length (m), friction coefficient mu, materials (or names),
    times the source has been on over each body t_on_pin/t_on_wall (s; inf = no transient floor, 0 = just
    switched on: zero rise).

    method='jaeger' (mechsim): per-body exact moving-band rises at L_eff, Blok partition (docs/theory.md §G4.3,
    §4.6). method='seed-blok': the seed's S(13) as printed with C = 2.5, using U_pin and the pin material
    (the seed used U = omega1 r1), no partition: seed formula, for comparison only (docs/theory.md §G4.4).

    Returns arrays: heat_rate_W, heat_per_length_W_m, peclet_pin, peclet_wheel, peclet_eff_pin,
    peclet_eff_wheel, temp_rise_pin_alone_K, temp_rise_wheel_alone_K, heat_share_pin, heat_rate_pin_W,
    heat_rate_wheel_W, temp_flash_rise_K.
    """
    pin, wheel = get_material(material_pin), get_material(material_wheel)
    b = np.asarray(b, dtype=float)
    heat = frictional_heat(mu, N, slip)
    heat_l = heat / length
    L_pin = peclet(U_pin, b, pin.diffusivity)
    L_wheel = peclet(U_wall, b, wheel.diffusivity)
    out = {"heat_rate_W": heat, "heat_per_length_W_m": heat_l, "peclet_pin": L_pin, "peclet_wheel": L_wheel}

    if method == "seed-blok":
        rise = seed_flash_rise(heat, b, U_pin, length, pin)
        nan = np.full(np.shape(rise), np.nan)
        out.update(peclet_eff_pin=L_pin, peclet_eff_wheel=L_wheel, temp_rise_pin_alone_K=nan,
                   temp_rise_wheel_alone_K=nan, heat_share_pin=nan, heat_rate_pin_W=nan, heat_rate_wheel_W=nan,
                   temp_flash_rise_K=rise)
        return out
    if method != "jaeger":
        raise ValueError(f"unknown flash method {method!r}; use 'jaeger' or 'seed-blok'")

    L_pin_eff = effective_peclet(L_pin, b, pin.diffusivity, t_on_pin)
    L_wheel_eff = effective_peclet(L_wheel, b, wheel.diffusivity, t_on_wall)
    r_pin = band_theta_eval(L_pin_eff, distribution, statistic, evaluator) / (2.0 * pin.conductivity)
    r_wheel = band_theta_eval(L_wheel_eff, distribution, statistic, evaluator) / (2.0 * wheel.conductivity)
    share_pin, r_flash = blok_partition(r_pin, r_wheel)
    with np.errstate(invalid="ignore"):
        rise = np.where(heat_l > 0, r_flash * heat_l, 0.0)
        out.update(
            peclet_eff_pin=L_pin_eff, peclet_eff_wheel=L_wheel_eff,
            temp_rise_pin_alone_K=np.where(heat_l > 0, r_pin * heat_l, 0.0),
            temp_rise_wheel_alone_K=np.where(heat_l > 0, r_wheel * heat_l, 0.0),
            heat_share_pin=share_pin, heat_rate_pin_W=share_pin * heat, heat_rate_wheel_W=(1.0 - share_pin) * heat,
            temp_flash_rise_K=rise,
        )
    return out


# ---------------------------------------------------------------------------------------------- seed formulas
def seed_normal_load(torque, theta_sum, crank_radius):
    """Seed S(8): W_N = (T/r1) cos(theta1 + theta2) (N). Seed formula, for comparison only.

    A projection of the crank force T/r1, not an equilibrium (docs/theory.md §G2: 0 N at entry, 93.33 N at
    the centre for T = 7 N m); mechsim uses N = (T_L + J2 alpha2)/x from the dynamics.
    """
    return np.asarray(torque, dtype=float) / crank_radius * np.cos(theta_sum)


def seed_sliding_speed(omega1, crank_radius, theta_sum):
    """Seed S(7): V_P/W = omega1 r1 sin(theta1 + theta2) (m/s), the pin-centre sliding speed (no pin spin).

    Equal to |v_s| of docs/theory.md §G1; the contact slip adds R (omega1 + omega2) (pin spin).
    """
    return np.asarray(omega1, dtype=float) * crank_radius * np.sin(theta_sum)


def seed_flash_rise(heat_rate, half_width_m, speed, length, material: Material | str,
                    C: float = SEED_S13_C, prefactor: float = SEED_S13_PREFACTOR):
    """Seed S(13) as printed, T_f = 0.159 C mu W |V1 - V2|/(K l) * chi/(U b), with C = 2.5 (K).

    Seed formula, for comparison only. Read literally (L = Peclet number) it has units K m; it is evaluated
    here the only dimensionally consistent way, with L = the contact length l, which reproduces the seed's
    numbers (docs/theory.md §G4.4, §4.7: 6.7 K at phi = 30 deg, mu = 0.15). It under-predicts the exact
    maximum by 1.3-1.9x at the seed's Peclet numbers because chi/(U b) = 1/(2L) puts a spurious 1/L in.
    Zero where b = 0 (the rise scales as sqrt(W)).
    """
    m = get_material(material)
    heat = np.asarray(heat_rate, dtype=float)
    denom = np.abs(np.asarray(speed, dtype=float)) * np.asarray(half_width_m, dtype=float)
    factor = np.divide(m.diffusivity, denom, out=np.zeros(np.broadcast(heat, denom).shape), where=denom > 0)
    return prefactor * C * heat / (m.conductivity * length) * factor
