"""Thermo-elastic material properties (SI) and a small named library.

Source of the library values: seed paper Table 2 (SAE-AISI 1045 at 20 °C), restated in
docs/theory.md (Part G) (header "Materials").
"""
from __future__ import annotations

import math
from dataclasses import dataclass


@dataclass(frozen=True)
class Material:
    """Isotropic elastic, heat-conducting solid.

    E (Pa), nu (-), density (kg/m^3), specific_heat (J/(kg K)), conductivity (W/(m K)).
    """

    name: str
    E: float
    nu: float
    density: float
    specific_heat: float
    conductivity: float

    def __post_init__(self):
        for field_name in ("E", "density", "specific_heat", "conductivity"):
            value = getattr(self, field_name)
            if not (value > 0 and math.isfinite(value)):
                raise ValueError(f"material {self.name!r}: {field_name} must be positive and finite, got {value!r}")
        if not (-1.0 < self.nu < 0.5):
            raise ValueError(f"material {self.name!r}: nu must lie in (-1, 0.5), got {self.nu!r}")

    @property
    def volumetric_heat_capacity(self) -> float:
        """rho*c_p (J/(m^3 K))."""
        return self.density * self.specific_heat

    @property
    def diffusivity(self) -> float:
        """Thermal diffusivity chi = k/(rho c_p) (m^2/s); docs/theory.md §G0."""
        return self.conductivity / self.volumetric_heat_capacity

    @property
    def effusivity(self) -> float:
        """Thermal effusivity e = sqrt(k rho c_p) (W s^0.5/(m^2 K)); docs/theory.md §G0, §4.6."""
        return math.sqrt(self.conductivity * self.volumetric_heat_capacity)

    @property
    def plane_strain_compliance(self) -> float:
        """(1 - nu^2)/E (1/Pa): one body's share of 1/E* (Johnson 1985, ch. 4)."""
        return (1.0 - self.nu**2) / self.E


#: Named materials. AISI 1045: seed Table 2 / docs/theory.md §G0 (rho=7860, E=207 GPa, nu=0.3,
#: c_p=485, k=42.3  ->  chi=1.1096e-5 m^2/s, e=12698 W s^0.5/(m^2 K)).
MATERIALS: dict[str, Material] = {
    "aisi1045": Material(name="aisi1045", E=207e9, nu=0.3, density=7860.0, specific_heat=485.0, conductivity=42.3),
}


def get_material(name: str | Material) -> Material:
    """Look a material up by (case-insensitive) name; a `Material` is passed through.

    Raises ValueError naming the unknown material and the known ones.
    """
    if isinstance(name, Material):
        return name
    key = str(name).strip().lower()
    try:
        return MATERIALS[key]
    except KeyError:
        known = ", ".join(sorted(MATERIALS))
        raise ValueError(f"unknown material {name!r}; known materials: {known}") from None


#: keys of a scenario's [thermal] section that override a library material's properties (key -> attribute)
MATERIAL_KEYS = {"E": "E", "nu": "nu", "density": "density", "specific_heat": "specific_heat",
                 "conductivity": "conductivity"}


def material_with_overrides(section: dict) -> Material:
    """The library material `section["material"]` with any property in MATERIAL_KEYS set in `section` (SI) in
    place of the library's; ValueError (from Material) on an invalid value."""
    base = get_material(section.get("material") or "aisi1045")
    values = {attr: section[key] if section.get(key) is not None else getattr(base, attr)
              for key, attr in MATERIAL_KEYS.items()}
    overridden = [key for key in MATERIAL_KEYS if section.get(key) is not None]
    name = base.name + (" (" + ", ".join(overridden) + " set)" if overridden else "")
    return Material(name=name, **values)
