"""Drive models acting on a mechanism's drive coordinate.

- speed: prescribed speed, a rheonomic constraint q_k = angle0 + speed (t - time0); its multiplier gives the
  torque the drive must deliver.
- torque: constant torque T0.
- motor: linear torque-speed curve T = T_stall (1 - w / w_no_load) (DC-motor / induction-motor linear range).
Both torque drives are written as T = T0 - slope * w, so one symbolic model serves both.

A torque or motor drive may run a duty cycle (`duty_on`, `duty_off`): on for duty_on, then off for duty_off,
repeated from t = 0. Off means disconnected: no torque at all (T0 = slope = 0), the crank coasts on its own
inertia; it is not a brake. Each switch is a `Breakpoint` (docs/theory.md, 'Time-varying loads and drives').
"""
from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from mechsim.mechanisms.base import Breakpoint

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
    #: duty cycle (s): on for duty_on, off for duty_off, from t = 0; 0 and 0: always on
    duty_on: float = 0.0
    duty_off: float = 0.0

    def __post_init__(self) -> None:
        if self.kind not in DRIVE_KINDS:
            raise ValueError(f"drive type must be one of {DRIVE_KINDS}, got {self.kind!r}")
        if self.kind == "motor" and not self.no_load_speed > 0:
            raise ValueError("drive.no_load_speed must be positive for a motor drive")
        if self.has_duty:
            if self.is_prescribed:
                raise ValueError("drive.duty_on: a duty cycle needs drive.type 'torque' or 'motor' (a prescribed "
                                 "speed has no torque to switch off)")
            if not (self.duty_on > 0 and self.duty_off > 0):
                raise ValueError("drive.duty_on: a duty cycle needs both duty_on and duty_off, positive")

    @property
    def has_duty(self) -> bool:
        return bool(self.duty_on or self.duty_off)

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
        if self.has_duty and not self.is_on(time0):
            t0, slope = 0.0, 0.0
        return {"drive_T0": t0, "drive_slope": slope, "drive_speed": self.speed,
                "drive_angle0": angle0, "drive_time0": time0}

    def is_on(self, t: float) -> bool:
        """Whether the duty cycle has the drive on at t (always, without one): on in [m P, m P + duty_on)."""
        if not self.has_duty:
            return True
        period = self.duty_on + self.duty_off
        return t - np.floor(t / period) * period < self.duty_on

    def schedule(self, t_end: float) -> list[Breakpoint]:
        """The duty cycle's switches in (0, t_end], each a `Breakpoint` ("drive off": T0 = slope = 0; "drive on":
        the drive's own T0 and slope)."""
        if not self.has_duty:
            return []
        on = {k: v for k, v in self.parameter_values(0.0).items() if k in ("drive_T0", "drive_slope")}
        off = {"drive_T0": 0.0, "drive_slope": 0.0}
        period, out, m = self.duty_on + self.duty_off, [], 0
        while m * period < t_end:
            out.append(Breakpoint(m * period + self.duty_on, off, "drive off"))
            out.append(Breakpoint((m + 1) * period, on, "drive on"))
            m += 1
        return [b for b in out if 0 < b.time <= t_end]
