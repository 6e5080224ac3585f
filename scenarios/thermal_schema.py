"""The [thermal] section: which thermal model runs alongside the mechanics, with its material, surroundings,
body geometry and 1-D mesh. Absent keys get sound defaults (derived from the mechanism where they depend on
it, see thermal/network.py and docs/thermal.md "Coupling"); values are SI after validation."""
from __future__ import annotations

from dataclasses import replace

from mechsim.mechanisms.base import Field, Mechanism
from mechsim.thermal import MATERIALS, Material
from mechsim.thermal.materials import MATERIAL_KEYS, material_with_overrides
from mechsim.thermal.models import MODELS

from mechsim.scenarios.units import ScenarioError

FLASH_METHODS = ("jaeger", "seed-blok")
DISTRIBUTIONS = ("semi-elliptic", "uniform")
AVERAGING = ("resolved", "cycle", "auto")
MESH_DIRECTIONS = ("depth",)


#: the thermal keys by the models that read them (docs/thermal.md, "The [thermal] section"); a key given under a model
#: that does not read it is refused (`Field.only_if`), so is any under 'none'
BULK_KEYS = ("convection_pin", "convection_wheel", "pin_crank_conductance", "pin_exposed_length", "crank_volume",
             "crank_area", "wheel_radius", "wheel_thickness")
MESH_KEYS = ("mesh_direction", "mesh_first_cell", "mesh_growth", "mesh_depth")
#: the parts' material and elastic constants: read by every thermal model and, whatever the model, by a compliant
#: contact's stiffness E* l (scenarios/loader.py `_with_contact_modulus`), so never refused
MATERIAL_ELASTIC = ("material", "E", "nu")


def _by_model(fields: dict[str, Field]) -> dict[str, Field]:
    """The [thermal] fields with the models that read each (`Field.only_if` on thermal.model): the flash rise's
    thermal properties and band every model; the bulk bodies' keys the models with bulk states (every one with a
    `build`); the 1-D mesh's the models that resolve every engagement in the depth (`every_cycle`); the material
    and elastic constants any (`MATERIAL_ELASTIC`)."""
    states = tuple(name for name, m in MODELS.items() if m.build is not None)
    mesh = tuple(name for name, m in MODELS.items() if m.every_cycle)
    readers = {key: mesh if key in MESH_KEYS else states if key in BULK_KEYS else tuple(MODELS) for key in fields}
    return {key: spec if key == "model" or key in MATERIAL_ELASTIC else replace(spec, only_if=("model", readers[key]))
            for key, spec in fields.items()}


def thermal_section(mech_cls: type[Mechanism]) -> dict[str, Field]:
    """Keys of [thermal] for this mechanism (a mechanism without sliding contact accepts only 'none')."""
    if not mech_cls.has_sliding_contact:
        return {"model": Field("str", default="none", choices=("none",),
                               help="thermal model: none (this mechanism has no sliding contact)")}
    return _by_model({
        "model": Field("str", default="none", choices=("none", *MODELS),
                       help="none; " + "; ".join(f"{name} ({m.short})" for name, m in MODELS.items())),
        "flash": Field("str", default="jaeger", choices=FLASH_METHODS,
                       help="flash rise: jaeger (exact moving band + Blok partition) or seed-blok (seed S(13))"),
        "distribution": Field("str", default="semi-elliptic", choices=DISTRIBUTIONS,
                              help="heat flux over the Hertz band"),
        "material": Field("str", default="aisi1045", choices=tuple(sorted(MATERIALS)),
                          help="library material of pin, crank and wheel"),
        "E": Field("quantity", "Pa", default=None, positive=True, help="Young's modulus (overrides the library)"),
        "nu": Field("float", default=None, minimum=-1.0, maximum=0.5,
                    why="Poisson's ratio of an isotropic solid lies between -1 and 0.5", help="Poisson's ratio (overrides the library)"),
        "density": Field("quantity", "kg/m^3", default=None, positive=True, help="density (overrides the library)"),
        "specific_heat": Field("quantity", "J/(kg*K)", default=None, positive=True,
                               help="specific heat (overrides the library)"),
        "conductivity": Field("quantity", "W/(m*K)", default=None, positive=True,
                              help="thermal conductivity (overrides the library)"),
        "ambient_temperature": Field("quantity", "K", default=293.15, positive=True,
                                     help="surroundings and initial temperature"),
        "convection_pin": Field("quantity", "W/(m^2*K)", default=15.0, nonnegative=True,
                                help="heat-transfer coefficient of pin and crank (docs/theory.md §G5: 10-25)"),
        "convection_wheel": Field("quantity", "W/(m^2*K)", default=7.0, nonnegative=True,
                                  help="heat-transfer coefficient of the wheel (docs/theory.md §G5: 5-12)"),
        "pin_crank_conductance": Field("quantity", "W/K", default=None, nonnegative=True,
                                       help="pin-crank conductance (default: conduction along the pin's exposed "
                                            "half-length, k pi R^2/(l_pin/2))"),
        "pin_exposed_length": Field("quantity", "m", default=None, positive=True,
                                    help="exposed pin length (default 2.5 x wheel thickness: 10 mm for the seed)"),
        "crank_volume": Field("quantity", "m^3", default=None, nonnegative=True,
                              help="crank arm volume lumped with the pin side (default: bar r x 4R x thickness)"),
        "crank_area": Field("quantity", "m^2", default=None, nonnegative=True,
                            help="crank arm surface area (default: that bar's)"),
        "wheel_radius": Field("quantity", "m", default=None, positive=True,
                              help="wheel disc radius (default: pin distance at entry, c cos(pi/n))"),
        "wheel_thickness": Field("quantity", "m", default=None, positive=True,
                                 help="wheel disc thickness (default: the mechanism's thickness)"),
        "averaging": Field("str", default="auto", choices=AVERAGING,
                           help="resolved; cycle (mechanics until periodic, cycle-mean heat drives the bulk); auto"),
        "mesh_direction": Field("str", default="depth", choices=MESH_DIRECTIONS,
                                help="1-D conduction direction (depth into the slot wall; docs/thermal.md)"),
        "mesh_first_cell": Field("quantity", "m", default=None, positive=True,
                                 help="first cell of the 1-D mesh (default sqrt(chi t_engagement)/20)"),
        "mesh_growth": Field("float", default=1.2, minimum=1.0, maximum=10.0,
                             why="beyond 10x per cell the 1-D mesh is a handful of cells, no longer a mesh", help="cell growth ratio of the 1-D mesh"),
        "mesh_depth": Field("quantity", "m", default=None, positive=True,
                            help="1-D mesh depth (default 3 sqrt(chi n T_cycle / pi), the periodic penetration)"),
    })


def thermal_material(section: dict) -> Material:
    """The library material with any explicit property overrides; ScenarioError naming the field if invalid."""
    try:
        return material_with_overrides(section)
    except ValueError as exc:
        problem = str(exc).split(": ", 1)[-1]                 # "<attribute> must ..."
        attribute = problem.split(" ", 1)[0]
        field = next((k for k, a in MATERIAL_KEYS.items() if a == attribute), "material")
        raise ScenarioError(f"thermal.{field}", problem) from None


def check_thermal(si: dict) -> None:
    """Cross-field checks of a validated [thermal] section (one ScenarioError naming the field)."""
    th = si.get("thermal", {})
    if th.get("model", "none") == "none" or "flash" not in th:
        return
    thermal_material(th)
    if MODELS[th["model"]].every_cycle and th["averaging"] == "cycle":
        averaged = " or ".join(f"'{name}'" for name, m in MODELS.items() if not m.every_cycle)
        raise ScenarioError("thermal.averaging", f"'cycle' is available for model = {averaged}; model = "
                                                 f"'{th['model']}' resolves every cycle (use 'resolved' or 'auto')")
    first, depth = th.get("mesh_first_cell"), th.get("mesh_depth")
    if first is not None and depth is not None and first > depth:
        raise ScenarioError("thermal.mesh_first_cell", f"must not exceed mesh_depth ({depth!r} m), got {first!r} m")
    if (th.get("crank_volume") is None) != (th.get("crank_area") is None):
        missing = "crank_area" if th.get("crank_area") is None else "crank_volume"
        raise ScenarioError(f"thermal.{missing}", "give crank_volume and crank_area together (or neither)")
