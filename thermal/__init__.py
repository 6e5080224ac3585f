"""Pure-physics thermal models of a sliding pin–slot line contact (imports nothing else from mechsim).

materials (Material, library), hertz (line contact), heat (Q, Peclet), band_source (exact/fast/fit moving
band), circle_source (3-D check, Tian–Kennedy), flash (per-body rises, Blok partition, seed formulas),
linear (C T' = -K T + s + B u networks), lumped (bulk pin/wheel), conduction1d (1-D MOL + exact solutions).
Formulas and sources: docs/theory.md §G3–7 and docs/thermal.md.
"""
from mechsim.thermal.materials import MATERIALS, Material, get_material
from mechsim.thermal.hertz import (axis_shear_ratio, effective_modulus, effective_radius, half_width, line_contact,
                    max_shear_coefficients, mean_pressure, peak_pressure, seed_half_width, seed_max_pressure,
                    seed_reduced_modulus)
from mechsim.thermal.heat import frictional_heat, heat_per_length, mean_flux, peclet
from mechsim.thermal.band_source import (band_fit, band_stationary_transient, band_stationary_transient_centre_asymptote,
                          band_theta, band_theta_avg_exact, band_theta_exact, band_theta_high, band_theta_low,
                          band_theta_max_exact, band_theta_table, flux_shape, high_peclet_coefficient,
                          low_peclet_constant)
from mechsim.thermal.circle_source import circle_theta, circle_theta_avg_exact, circle_theta_max_exact, tian_kennedy
from mechsim.thermal.flash import (TRANSIENT_FLOOR_COEFFICIENT, band_theta_eval, blok_flash_high_peclet, blok_partition,
                    effective_peclet, flash_temperature, seed_flash_rise, seed_normal_load, seed_sliding_speed,
                    single_body_rise, transient_peclet_floor)
from mechsim.thermal.linear import LinearThermalSystem
from mechsim.thermal.lumped import (CONVECTION_COEFFICIENTS, H_PIN_DEFAULT, H_WHEEL_DEFAULT, ambient_temperatures, biot_number,
                     bulk_system, cycle_means, disc_volume_area, geneva_bulk_system, integrate_mean_heat, pin_volume_area,
                     steady_bulk_temperatures, time_constant)
from mechsim.thermal.conduction1d import (Conduction1D, Mesh1D, conduction_system, duhamel_surface, flux_step_profile,
                           flux_step_surface, graded_mesh, graded_mesh_cells, ierfc, mesh_settings,
                           moving_band_high_peclet_max, switched_flux_surface, validity)

__all__ = [name for name in dir() if not name.startswith("_") and name not in {
    "materials", "hertz", "heat", "band_source", "circle_source", "flash", "linear", "lumped", "conduction1d"}]
