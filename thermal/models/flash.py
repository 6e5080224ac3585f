"""thermal.model = 'flash': the contact's flash rise over the ambient at every output instant; no states."""
from mechsim.thermal.models.base import ThermalModel

MODEL = ThermalModel(
    name="flash", short="algebraic contact rise over ambient",
    description="algebraic flash rise over the ambient at every output instant (moving-band solution per body, "
                "Blok partition; docs/theory.md §G4.3-4.7); no thermal states")
