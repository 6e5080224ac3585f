"""Mechanism models: symbolic multibody descriptions plus closed-form kinematics (import nothing of ours)."""
from .base import Field, Guard, InitialState, Mechanism, Mode, Transition
from .geneva import Geneva

#: scenario `mechanism.type` -> model class
MECHANISMS: dict[str, type[Mechanism]] = {"geneva": Geneva}
from .chain_model import ChainDwell; MECHANISMS["chain_dwell"] = ChainDwell  # noqa: E402,E702
from .rolling_model import RollingPairFourBar; MECHANISMS["rolling_pair"] = RollingPairFourBar  # noqa: E402,E702

__all__ = ["Field", "Guard", "InitialState", "Mechanism", "Mode", "Transition", "Geneva", "MECHANISMS"]
