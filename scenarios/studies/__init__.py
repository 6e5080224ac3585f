"""Studies: what runs many scenarios or differentiates them (sweeps, sensitivities, sizing, backend comparisons).

They import the scenario pipeline (`scenarios.loader`, `scenarios.runner`, `scenarios.output`); only the faces
(`scenarios.api`, `scenarios.cli`) import them.
"""
