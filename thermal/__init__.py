"""Pure-physics thermal models of a sliding pin–slot line contact (imports nothing else from mechsim).

materials (Material, library), hertz (line contact), heat (Q, Peclet), band_source (exact/fast/fit moving
band), circle_source (3-D check, Tian–Kennedy), flash (per-body rises, Blok partition, seed formulas),
linear (C T' = -K T + s + B u networks), lumped (bulk pin/wheel), conduction1d (1-D MOL + exact solutions).
Formulas and sources: docs/theory.md §G3–7 and docs/thermal.md.

Each name below is imported from its module on first use (PEP 562): loading a scenario, which reads the materials
and the models' fields only, imports none of the networks (linear, scipy.sparse).
"""
#: each public name -> the module of mechsim.thermal that defines it
_WHERE = {
    **dict.fromkeys(('MATERIALS', 'Material', 'get_material'), 'materials'),
    **dict.fromkeys(('axis_shear_ratio', 'effective_modulus', 'effective_radius', 'half_width', 'line_contact',
                     'max_shear_coefficients', 'mean_pressure', 'peak_pressure', 'seed_half_width', 'seed_max_pressure',
                     'seed_reduced_modulus'), 'hertz'),
    **dict.fromkeys(('frictional_heat', 'heat_per_length', 'mean_flux', 'peclet'), 'heat'),
    **dict.fromkeys(('band_fit', 'band_stationary_transient', 'band_stationary_transient_centre_asymptote',
                     'band_theta', 'band_theta_avg_exact', 'band_theta_exact', 'band_theta_high', 'band_theta_low',
                     'band_theta_max_exact', 'band_theta_table', 'flux_shape', 'high_peclet_coefficient',
                     'low_peclet_constant'), 'band_source'),
    **dict.fromkeys(('circle_theta', 'circle_theta_avg_exact', 'circle_theta_max_exact', 'tian_kennedy'),
                     'circle_source'),
    **dict.fromkeys(('TRANSIENT_FLOOR_COEFFICIENT', 'band_theta_eval', 'blok_flash_high_peclet', 'blok_partition',
                     'effective_peclet', 'flash_temperature', 'seed_flash_rise', 'seed_normal_load',
                     'seed_sliding_speed', 'single_body_rise', 'transient_peclet_floor'), 'flash'),
    **dict.fromkeys(('LinearThermalSystem',), 'linear'),
    **dict.fromkeys(('CONVECTION_COEFFICIENTS', 'H_PIN_DEFAULT', 'H_WHEEL_DEFAULT', 'ambient_temperatures',
                     'biot_number', 'bulk_system', 'cycle_means', 'disc_volume_area', 'geneva_bulk_system',
                     'integrate_mean_heat', 'pin_volume_area', 'steady_bulk_temperatures', 'time_constant'), 'lumped'),
    **dict.fromkeys(('Conduction1D', 'Mesh1D', 'conduction_system', 'duhamel_surface', 'flux_step_profile',
                     'flux_step_surface', 'graded_mesh', 'graded_mesh_cells', 'ierfc', 'mesh_settings',
                     'moving_band_high_peclet_max', 'switched_flux_surface', 'validity'), 'conduction1d'),
}

__all__ = list(_WHERE)


def __getattr__(name: str):
    module = _WHERE.get(name)
    if module is None:
        raise AttributeError(f"module 'mechsim.thermal' has no attribute {name!r}")
    from importlib import import_module
    value = getattr(import_module(f"mechsim.thermal.{module}"), name)
    globals()[name] = value          # later look-ups skip this function
    return value


def __dir__() -> list[str]:
    return sorted(set(globals()) | set(_WHERE))
