"""Mechanism models: symbolic multibody descriptions plus closed-form kinematics (import nothing of ours).

`MECHANISMS` maps a scenario's `mechanism.type` to its model class; each model module is imported when its type
is first looked up, so a Geneva run does not pay for importing the chain's and the rolling pair's models."""
from __future__ import annotations

from collections.abc import Mapping
from importlib import import_module

from mechsim.mechanisms.base import Field, Guard, InitialState, Mechanism, Mode, Transition, ValidityCondition


class MechanismRegistry(Mapping):
    """type name -> model class, from "module:Class" entries imported on first look-up."""

    def __init__(self, entries: dict[str, str]):
        self._entries = dict(entries)
        self._loaded: dict[str, type[Mechanism]] = {}

    def __getitem__(self, name: str) -> type[Mechanism]:
        if name not in self._loaded:
            module, cls = self._entries[name].split(":")
            self._loaded[name] = getattr(import_module(module), cls)
        return self._loaded[name]

    def __iter__(self):
        return iter(self._entries)

    def __len__(self) -> int:
        return len(self._entries)


#: scenario `mechanism.type` -> model class
MECHANISMS = MechanismRegistry({
    "geneva": "mechsim.mechanisms.geneva.model:Geneva",
    "internal_geneva": "mechsim.mechanisms.internal_geneva.model:InternalGeneva",
    "chain_dwell": "mechsim.mechanisms.chain.model:ChainDwell",
    "rolling_pair": "mechsim.mechanisms.rolling.model:RollingPairFourBar",
})


def __getattr__(name: str):
    if name == "Geneva":                       # the package's long-standing export, imported on use
        return MECHANISMS["geneva"]
    raise AttributeError(f"module 'mechsim.mechanisms' has no attribute {name!r}")


__all__ = ["Field", "Guard", "InitialState", "Mechanism", "Mode", "Transition", "ValidityCondition", "Geneva",
           "MECHANISMS"]
