"""Drive models acting on a mechanism's drive coordinate.

- speed: prescribed speed, a rheonomic constraint q_k = angle0 + speed (t - time0); its multiplier gives the
  torque the drive must deliver.
- torque: constant torque T0.
- motor: linear torque-speed curve T = T_stall (1 - w / w_no_load) (DC-motor / induction-motor linear range).
Both torque drives are written as T = T0 - slope * w, so one symbolic model serves both.
"""
from __future__ import annotations

from dataclasses import dataclass

DRIVE_KINDS = ("speed", "torque", "motor")
DRIVE_PARAMETERS = ("drive_T0", "drive_slope", "drive_speed", "drive_angle0", "drive_time0")


@dataclass(frozen=True)
class Drive:
    """A drive in SI units. Only the fields of its kind are used."""

    kind: str
    speed: float = 0.0
    torque: float = 0.0
    stall_torque: float = 0.0
    no_load_speed: float = 0.0

    def __post_init__(self) -> None:
        if self.kind not in DRIVE_KINDS:
            raise ValueError(f"drive type must be one of {DRIVE_KINDS}, got {self.kind!r}")
        if self.kind == "motor" and not self.no_load_speed > 0:
            raise ValueError("drive.no_load_speed must be positive for a motor drive")

    @property
    def is_prescribed(self) -> bool:
        return self.kind == "speed"

    def parameter_values(self, angle0: float, time0: float = 0.0) -> dict[str, float]:
        if self.kind == "motor":
            t0, slope = self.stall_torque, self.stall_torque / self.no_load_speed
        elif self.kind == "torque":
            t0, slope = self.torque, 0.0
        else:
            t0, slope = 0.0, 0.0
        return {"drive_T0": t0, "drive_slope": slope, "drive_speed": self.speed,
                "drive_angle0": angle0, "drive_time0": time0}
