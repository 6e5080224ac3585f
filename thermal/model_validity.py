"""The conditions the thermal model's formulas need on every output row, declared as data (docs/thermal.md,
"Validity"): the Hertz half-width small against the contact radius (2-D line contact, Johnson 1985 ch. 4) and,
for the seed's flash formula, its Peclet range (seed S(13): the intermediate regime 0.1 < L < 5, after
Stachowiak & Batchelor). mechsim's own flash rise (exact moving band per body, the fast table with its exact
asymptotes, and the transient floor; docs/theory.md §G4.3, §G4.6) holds at every Peclet number, so it adds no
range.

Each condition is a plain dict with the fields of `mechanisms.base.ValidityCondition` (name, description,
quantity, bound, sense, unit, source, needs): the thermal layer imports nothing of the mechanisms', and the
runner reads both the same way.
"""
from __future__ import annotations

import numpy as np

from mechsim.thermal.heat import peclet

#: b <= HERTZ_HALF_WIDTH_RATIO R: the line-contact formulas (half-space, b << R) need a band narrow against the pin
HERTZ_HALF_WIDTH_RATIO = 0.1
#: Peclet range of the seed's S(13) with C = 2.5: the intermediate regime (low L < 0.1, high L > 5)
SEED_FLASH_PECLET_RANGE = (0.1, 5.0)


def _in_contact(values: np.ndarray, half_width: np.ndarray) -> np.ndarray:
    """values where the bodies touch (a band of positive width), NaN elsewhere (no contact: nothing to check)."""
    return np.where(half_width > 0, values, np.nan)


def conditions(section: dict, geometry, material) -> list[dict]:
    """The thermal conditions of one scenario: `section` the resolved [thermal] table (its `flash` method),
    `geometry` the mechanism's ContactGeometry (contact_radius, driver_arm), `material` the contact's Material."""
    radius = float(geometry.contact_radius)

    def width_ratio(c):
        b = np.asarray(c["hertz_half_width_m"], dtype=float)
        return _in_contact(b / radius, b)

    out = [dict(name="hertz_half_width", description=(
        f"Hertz half-width b <= {HERTZ_HALF_WIDTH_RATIO:g} R (pin radius R = {radius:.4g} m): the 2-D line-contact "
        "formulas assume b << R"), quantity=width_ratio, bound=HERTZ_HALF_WIDTH_RATIO, sense="max", unit="",
        source="Johnson (1985) Contact Mechanics ch. 4; docs/theory.md §G3", needs=("hertz_half_width_m",))]
    if section.get("flash") == "seed-blok":
        arm, chi = float(geometry.driver_arm), float(material.diffusivity)

        def seed_peclet(c):       # as the seed evaluates S(13): U = omega1 r over the pin (thermal/plan.py)
            b = np.asarray(c["hertz_half_width_m"], dtype=float)
            return _in_contact(peclet(arm * np.asarray(c["crank_speed_rad_s"], dtype=float), b, chi), b)

        low, high = SEED_FLASH_PECLET_RANGE
        source = "seed eq. (13) for 0.1 < L < 5 (Stachowiak & Batchelor); docs/theory.md §G4.4"
        needs = ("hertz_half_width_m", "crank_speed_rad_s")
        out += [dict(name="flash_peclet_low", description=f"Peclet number L = b omega1 r/(2 chi) >= {low:g}: the "
                     "seed's flash formula (thermal.flash = 'seed-blok') is its intermediate-speed regime",
                     quantity=seed_peclet, bound=low, sense="min", unit="", source=source, needs=needs),
                dict(name="flash_peclet_high", description=f"Peclet number L = b omega1 r/(2 chi) <= {high:g}: the "
                     "seed's flash formula (thermal.flash = 'seed-blok') is its intermediate-speed regime",
                     quantity=seed_peclet, bound=high, sense="max", unit="", source=source, needs=needs)]
    return out
