"""The thermal models a scenario can name (`[thermal] model = "..."`), one module each; this registry is the only
list of them (the scenario schema, the runner and the docs read it). Adding a model: a module here that defines
its `MODEL` (a `ThermalModel`), plus its line below (docs/CONTRIBUTING.md, "Adding a thermal model")."""
from mechsim.thermal.models.base import ThermalModel
from mechsim.thermal.models import flash, lumped, track1d

MODELS: dict[str, ThermalModel] = {
    "flash": flash.MODEL,
    "lumped": lumped.MODEL,
    "1d": track1d.MODEL,
}

__all__ = ["MODELS", "ThermalModel"]
