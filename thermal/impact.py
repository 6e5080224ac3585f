"""Heat of the contact's impacts: the energy each impact dissipates, as an impulsive heat input to the thermal
network beside the sliding heat, and a flash estimate at the impact (docs/theory.md §G2.2).

Partition: during an impact the contact does not slide, so both bodies see a stationary source over the same area
for the same time; equal surface temperatures (Blok's postulate) then split the heat in proportion to the thermal
effusivities e = k/sqrt(chi) (Carslaw & Jaeger 1959 §2.9, two semi-infinite solids under a surface flux):
share_pin = e_pin/(e_pin + e_wheel), one half for equal materials.

Network: the network is linear and the mechanics does not depend on the temperatures, so the impacts' heat adds to
the run's states by superposition, exactly: an energy E at t_k into input column j jumps the states by
C^-1 B_j E there and then decays with the homogeneous network, dT(t) = e^{A(t - t_k)} C^-1 B_j E for t >= t_k
(A = -C^-1 K). Into a 1-D track mesh (input column of the track in contact) the pulse is the surface cell's
energy jump, the finite-volume form of a surface heat pulse.

Flash estimate: a rigid impact has no duration. The contact is taken as a linear spring of stiffness k_c = E* l
under the effective mass m the impulse sees, closing at the approach speed v: a half-sine force pulse of duration
tau = pi sqrt(m/k_c) and peak F = v sqrt(m k_c); its heat E spread uniformly over the Hertz band 2 b(F) l during
tau raises both surfaces by (uniform flux on a semi-infinite solid, Carslaw & Jaeger 1959 §2.9)
    dT = E / (b l (e_pin + e_wheel) sqrt(pi tau)).
b sqrt(tau) ~ (m v)^(1/2) does not depend on k_c (b ~ F^(1/2) ~ k_c^(1/4), tau ~ k_c^(-1/2)): the estimate does not
depend on the spring's stiffness, only on the pulse's shape (Johnson 1985, Contact Mechanics ch. 4 and 11: the approach
of a 2-D (line) contact depends logarithmically on the bodies' size, so no Hertz impact duration exists for it).
"""
from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

from mechsim.thermal.exact import ModalNetwork
from mechsim.thermal.hertz import half_width


def impact_share_pin(k_pin: float, chi_pin: float, k_wheel: float, chi_wheel: float) -> float:
    """The pin's share of an impact's heat, e_pin/(e_pin + e_wheel) with e = k/sqrt(chi) (module docstring)."""
    e_pin, e_wheel = k_pin / math.sqrt(chi_pin), k_wheel / math.sqrt(chi_wheel)
    return e_pin / (e_pin + e_wheel)


def impact_flash(energy, approach_speed, mass, radius: float, length: float, modulus: float, effusivity_sum: float
                 ) -> dict[str, np.ndarray]:
    """Flash estimate of impacts (arrays): duration_s, peak force_N, half_width_m of the Hertz band at that force,
    rise_K of both surfaces; the linear-spring half-sine pulse of the module docstring (k_c = E* l)."""
    energy, v, m = (np.asarray(x, dtype=float) for x in (energy, approach_speed, mass))
    k_c = modulus * length
    tau = math.pi * np.sqrt(m / k_c)
    force = v * np.sqrt(m * k_c)
    b = half_width(force, radius, length, modulus)
    with np.errstate(divide="ignore", invalid="ignore"):
        rise = np.where(energy > 0, energy / (b * length * effusivity_sum * np.sqrt(math.pi * tau)), 0.0)
    return {"duration_s": tau, "force_N": force, "half_width_m": b, "rise_K": rise}


@dataclass(frozen=True)
class ImpactHeat:
    """The impacts' heat on the network: times, energies (J) and the network input column each enters, with the
    pin's share."""

    times: np.ndarray
    energies: np.ndarray
    wheel_columns: np.ndarray
    share_pin: float

    def response(self, network: ModalNetwork, capacity: np.ndarray, input_matrix: np.ndarray, loss: np.ndarray,
                 t: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray]:
        """At times t: (the states' increments (len(t), n), heat generated, into the pin, convected (J)) from the
        impacts up to each time (superposition, module docstring; convected = loss . int dT, exact in the modes)."""
        n = len(capacity)
        dT = np.zeros((len(t), n))
        generated, pin, convected = np.zeros(len(t)), np.zeros(len(t)), np.zeros(len(t))
        for t_k, E, j in zip(self.times, self.energies, self.wheel_columns):
            after = t >= t_k
            if not after.any() or E == 0:
                continue
            x = (input_matrix[:, 0] * self.share_pin + input_matrix[:, int(j)] * (1 - self.share_pin)) * E / capacity
            s = t[after] - t_k
            dT[after] += network.exp(s, x)
            z0 = network.Vinv @ x
            lam = network.lam[None, :]
            small = np.abs(lam * s[:, None]) < 1e-12                  # int_0^s e^{lam u} du, exact
            integral = np.where(small, s[:, None], np.expm1(lam * s[:, None]) / np.where(small, 1.0, lam))
            convected[after] += (integral * z0[None, :]) @ (loss @ network.V)
            generated[after] += E
            pin[after] += self.share_pin * E
        return dT, generated, pin, convected
