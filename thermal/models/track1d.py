"""thermal.model = '1d': the lumped bulk bodies plus 1-D conduction into the depth of each track of the driven
body (each slot wall of a Geneva; docs/theory.md §G6), plus the flash rise on top. Every engagement is resolved
(the track meshes follow each one), so it is never cycle-averaged."""
from mechsim.thermal.models.base import ThermalModel


def build(setup) -> None:
    from mechsim.thermal.network import assemble, bulk_bodies, track_mesh     # (scipy: only where a run builds it)
    bodies = bulk_bodies(setup)
    mesh = track_mesh(setup, bodies[-1])
    assemble(setup, bodies, mesh)


MODEL = ThermalModel(
    name="1d", short="+ 1-D conduction into each slot wall's track",
    description="bulk pin, crank and wheel temperatures plus 1-D conduction into the depth of each slot wall's "
                "track (docs/theory.md §G6), plus the algebraic flash rise on top",
    build=build, every_cycle=True)
