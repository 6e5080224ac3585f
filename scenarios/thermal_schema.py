"""The [thermal] section: which thermal model runs alongside the mechanics."""
from __future__ import annotations

from mechanisms.base import Field, Mechanism

THERMAL_MODELS = ("none",)


def thermal_section(mech_cls: type[Mechanism]) -> dict[str, Field]:
    """Keys of [thermal] for this mechanism (a mechanism without sliding contact accepts only 'none')."""
    choices = THERMAL_MODELS if mech_cls.has_sliding_contact else ("none",)
    return {"model": Field("str", default="none", choices=choices,
                           help="thermal model: none" + ("" if mech_cls.has_sliding_contact else
                                                         " (this mechanism has no sliding contact)"))}
