"""Internal Geneva drive as the two-mode multibody model of the external one (mechanisms/geneva/model.py).

The modes, guards, friction, read-outs, transitions, closed form, reduced reference and contact are the external
Geneva's: they read every formula in which the pin meets the slot from the geometry (`wheel_motion`,
`pin_position`, `pin_in_slot`, `crank_sense`), and `InternalGenevaGeometry` supplies the internal ones
(docs/internal_geneva.md). Coordinates, signs and modes as for the external drive: theta the crank angle
(0 at the first mid-engagement), psi the wheel angle (+2 pi/n per index), both counter-clockwise, so here both
grow together; engaged for |theta - 2 pi k| < pi/2 + pi/n, locked in between.
"""
from __future__ import annotations

from mechsim.mechanisms.geneva.model import Geneva
from mechsim.mechanisms.internal_geneva.kinematics import InternalGenevaGeometry


class InternalGeneva(Geneva):
    """Internal Geneva drive with n >= 3 slots, driven at the crank inside the wheel, loaded at the wheel."""

    name = "internal_geneva"
    geometry_class = InternalGenevaGeometry
    drawing = "mechsim.mechanisms.internal_geneva.drawing:InternalGenevaDrawing"
    sensitivity_map = "mechsim.mechanisms.internal_geneva.sensitivity:MAP"

    def describe(self) -> dict:
        g = self.geometry
        return {
            "centre_distance_m": g.centre_distance,
            "entry_pin_distance_m": g.entry_pin_distance,
            "deepest_pin_distance_m": g.deepest_pin_distance,
            "engagement_half_angle_rad": g.engagement_half_angle,
            "dwell_fraction": g.dwell_fraction,
        }
