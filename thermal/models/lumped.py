"""thermal.model = 'lumped': bulk temperatures of the driver's contact body (pin), its arm (crank) and the driven
body (wheel) as states (docs/theory.md §G5), plus the flash rise on top."""
from mechsim.thermal.models.base import ThermalModel


def build(setup) -> None:
    from mechsim.thermal.network import assemble, bulk_bodies     # (scipy: only where a run builds it)
    assemble(setup, bulk_bodies(setup))


MODEL = ThermalModel(
    name="lumped", short="+ bulk pin/crank/wheel states",
    description="bulk pin, crank and wheel temperatures (docs/theory.md §G5) as extra states, plus the algebraic "
                "flash rise on top",
    build=build)
