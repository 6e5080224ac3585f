"""What a thermal model declares: its name, what it computes (for `mechsim list`-style help and the run's
summary), how it builds its network, and whether it can be cycle-averaged."""
from __future__ import annotations

from dataclasses import dataclass
from typing import Callable


@dataclass(frozen=True)
class ThermalModel:
    """name: the scenario's `thermal.model`; short: a few words for the schema help; description: what it
    computes and its source (the run's summary['thermal']['why']); build: adds the network to a
    `thermal.network.ThermalSetup` (use `bulk_bodies`, `track_mesh`, `assemble` there), None for a model with
    no thermal states; every_cycle: the model follows each engagement, so it is never cycle-averaged."""

    name: str
    short: str
    description: str
    build: Callable | None = None
    every_cycle: bool = False
