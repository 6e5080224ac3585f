"""Mechanism models: symbolic multibody descriptions plus closed-form kinematics (import nothing of ours)."""
from mechsim.mechanisms.base import Field, Guard, InitialState, Mechanism, Mode, Transition
from mechsim.mechanisms.geneva.model import Geneva

#: scenario `mechanism.type` -> model class
MECHANISMS: dict[str, type[Mechanism]] = {"geneva": Geneva}
from mechsim.mechanisms.chain.model import ChainDwell; MECHANISMS["chain_dwell"] = ChainDwell  # noqa: E402,E702
from mechsim.mechanisms.rolling.model import RollingPairFourBar; MECHANISMS["rolling_pair"] = RollingPairFourBar  # noqa: E402,E702

__all__ = ["Field", "Guard", "InitialState", "Mechanism", "Mode", "Transition", "Geneva", "MECHANISMS"]
