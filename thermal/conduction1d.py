"""1-D transient conduction into the depth z beneath the contact: finite-volume method of lines + exact solutions.

rho c_p dT/dt = k d2T/dz2, -k dT/dz|_0 = q(t) - h (T_s - T_inf), far face insulated or held at T_far
(docs/theory.md §G6). Cell-centred finite volumes on a geometrically graded mesh; the surface temperature
T_s is eliminated through the half-cell conductance, so the model is the linear network
C T' = -K T + s + B u, u = [q] or [q, T_far], per unit area (W/m^2, J/(m^2 K)). The Laplacian is stiff
(eigenvalues up to ~4 chi/dz_min^2): integrate with BDF/Radau and the sparse Jacobian, or exactly (expm).
Exact solutions: Carslaw & Jaeger (1959) §2.9 (semi-infinite solid, prescribed surface flux).
"""
from __future__ import annotations

import math
from dataclasses import dataclass
from typing import Callable

import numpy as np
import scipy.sparse as sps

from mechsim.thermal.linear import LinearThermalSystem
from mechsim.thermal.materials import Material, get_material


def quad(*args, **kwargs):
    """scipy.integrate.quad, imported on first call (a fresh `mechsim run` need not load scipy.integrate)."""
    from scipy.integrate import quad as impl
    return impl(*args, **kwargs)

#: Mesh defaults (docs/theory.md §G6): first cell <= delta/10 with delta = sqrt(chi 2b/U), growth 1.1–1.2,
#: depth >= 3 sqrt(chi t_end).
GROWTH_DEFAULT = 1.15
FIRST_CELL_FRACTION = 0.1
DEPTH_DIFFUSION_LENGTHS = 3.0
#: 1-D model valid as a flash model only for L >~ 5 (lateral conduction neglected; docs/theory.md §G6).
VALID_PECLET_MIN = 5.0


@dataclass(frozen=True)
class Mesh1D:
    """Cell faces z_0 = 0 < z_1 < ... < z_n = depth (m)."""

    faces: np.ndarray

    @property
    def widths(self) -> np.ndarray:
        return np.diff(self.faces)

    @property
    def centres(self) -> np.ndarray:
        return 0.5 * (self.faces[1:] + self.faces[:-1])

    @property
    def n_cells(self) -> int:
        return len(self.faces) - 1

    @property
    def depth(self) -> float:
        return float(self.faces[-1])


def graded_mesh_cells(depth: float, n_cells: int, growth: float = GROWTH_DEFAULT) -> Mesh1D:
    """n cells growing geometrically by `growth` from the surface: z_i = H (r^i - 1)/(r^n - 1).

    Refining with (2n, sqrt(r)) keeps every old face (nested meshes for convergence studies).
    """
    if depth <= 0 or n_cells < 1 or growth < 1.0:
        raise ValueError("graded mesh needs depth > 0, n_cells >= 1, growth >= 1")
    i = np.arange(n_cells + 1)
    faces = depth * i / n_cells if growth == 1.0 else depth * (growth**i - 1.0) / (growth**n_cells - 1.0)
    return Mesh1D(np.asarray(faces, dtype=float))


def mesh_cells(first_cell: float, growth: float, depth: float) -> float:
    """How many cells a graded mesh of first cell <= `first_cell`, ratio `growth` and depth `depth` has (a float,
    so that a degenerate request can be bounded before anything is allocated)."""
    if growth == 1.0:
        return math.ceil(depth / first_cell)
    return math.ceil(math.log1p(depth * (growth - 1.0) / first_cell) / math.log(growth))


def graded_mesh(first_cell: float, growth: float = GROWTH_DEFAULT, depth: float = 2e-3) -> Mesh1D:
    """Graded mesh with first cell <= `first_cell`, ratio `growth`, total depth `depth` (m)."""
    if first_cell <= 0 or first_cell > depth:
        raise ValueError("graded mesh needs 0 < first_cell <= depth")
    return graded_mesh_cells(depth, int(mesh_cells(first_cell, growth, depth)), growth)


def mesh_settings(half_width_m: float, source_speed: float, diffusivity: float, t_end: float,
                  growth: float = GROWTH_DEFAULT) -> dict:
    """Sound defaults from docs/theory.md §G6: first cell delta/10 (delta = sqrt(chi 2b/U), the penetration depth
    during one pass), depth 3 sqrt(chi t_end) (at least 10 delta), growth 1.15."""
    delta = math.sqrt(diffusivity * 2.0 * half_width_m / source_speed)
    depth = max(DEPTH_DIFFUSION_LENGTHS * math.sqrt(diffusivity * t_end), 10.0 * delta)
    return {"first_cell": FIRST_CELL_FRACTION * delta, "growth": growth, "depth": depth}


@dataclass(frozen=True)
class Conduction1D:
    """The discretised half-space: the linear network plus the surface-temperature read-out
    T_s = surface_weight T_0 + surface_flux_gain q + surface_offset."""

    mesh: Mesh1D
    material: Material
    system: LinearThermalSystem
    h: float
    temp_ambient: float
    surface_weight: float
    surface_flux_gain: float
    surface_offset: float

    @property
    def flux_vector(self) -> np.ndarray:
        """b in C T' = -K T + b q + ...: the fraction of the surface flux that enters each cell."""
        return self.system.input_matrix[:, 0]

    def surface_temperature(self, T, q) -> np.ndarray:
        """T_s from the first cell and the flux (T may be (n,) or (n, n_times), q scalar or (n_times,))."""
        T0 = np.asarray(T)[0]
        return self.surface_weight * T0 + self.surface_flux_gain * np.asarray(q, dtype=float) + self.surface_offset

    def convected_flux(self, T, q) -> np.ndarray:
        """Heat lost to the surroundings at the surface, h (T_s - T_inf) (W/m^2)."""
        return self.h * (self.surface_temperature(T, q) - self.temp_ambient)


def conduction_system(mesh: Mesh1D, material: Material | str, *, h: float = 0.0, temp_ambient: float = 0.0,
                      far: str = "insulated") -> Conduction1D:
    """Finite-volume network for the graded mesh (per unit area).

    Cells: C_i = rho c dz_i, face conductance k/(z_{i+1} - z_i). Surface: with g = 2k/dz_0,
    T_s = (q + h T_inf + g T_0)/(g + h), so cell 0 receives g/(g+h) q and loses gh/(g+h) (T_0 - T_inf).
    far='insulated' (zero flux) or 'fixed' (T_far is the second input; half-cell conductance 2k/dz_n).
    """
    m = get_material(material)
    if far not in ("insulated", "fixed"):
        raise ValueError(f"far face must be 'insulated' or 'fixed', got {far!r}")
    k = m.conductivity
    dz, zc = mesh.widths, mesh.centres
    n = mesh.n_cells
    g_int = k / np.diff(zc)                                  # conductances between neighbouring cells
    diag = np.zeros(n)
    diag[:-1] += g_int
    diag[1:] += g_int
    g0 = 2.0 * k / dz[0]
    loss = g0 * h / (g0 + h)
    diag[0] += loss
    source = np.zeros(n)
    source[0] = loss * temp_ambient
    names = ["heat_flux_W_m2"]
    B = np.zeros((n, 1))
    B[0, 0] = g0 / (g0 + h)
    if far == "fixed":
        g_far = 2.0 * k / dz[-1]
        diag[-1] += g_far
        B = np.hstack([B, np.zeros((n, 1))])
        B[-1, 1] = g_far
        names.append("temp_far_K")
    K = sps.diags([-g_int, diag, -g_int], [-1, 0, 1], format="csr")
    system = LinearThermalSystem(
        state_names=tuple(f"temp_cell_{i}" for i in range(n)), capacity=m.volumetric_heat_capacity * dz,
        conductance=K, source=source, input_matrix=B, input_names=tuple(names))
    return Conduction1D(mesh=mesh, material=m, system=system, h=h, temp_ambient=temp_ambient,
                        surface_weight=g0 / (g0 + h), surface_flux_gain=1.0 / (g0 + h),
                        surface_offset=h * temp_ambient / (g0 + h))


# ---------------------------------------------------------------------------------------------- exact solutions
def ierfc(u):
    """ierfc(u) = e^{-u^2}/sqrt(pi) - u erfc(u) (Carslaw & Jaeger 1959, App. II)."""
    from scipy.special import erfc     # here: a fresh `mechsim run` need not load scipy.special
    u = np.asarray(u, dtype=float)
    return np.exp(-u * u) / math.sqrt(math.pi) - u * erfc(u)


def flux_step_profile(z, t, flux, material: Material | str):
    """Constant flux q from t = 0: dT(z, t) = (2q/k) sqrt(chi t) ierfc(z/(2 sqrt(chi t))) (C&J 1959 §2.9; docs/theory.md §G6)."""
    m = get_material(material)
    root = np.sqrt(m.diffusivity * np.asarray(t, dtype=float))
    return 2.0 * flux / m.conductivity * root * ierfc(np.asarray(z, dtype=float) / (2.0 * root))


def flux_step_surface(t, flux, material: Material | str):
    """Surface rise under constant flux: 2 q sqrt(t)/(sqrt(pi) e) = 2q sqrt(chi t/pi)/k (docs/theory.md §G6)."""
    m = get_material(material)
    return 2.0 * flux * np.sqrt(np.clip(np.asarray(t, dtype=float), 0.0, None)) / (math.sqrt(math.pi) * m.effusivity)


def switched_flux_surface(t, flux, t_on, material: Material | str):
    """Flux q on for 0 < t < t_on, then off: (2q/(sqrt(pi) e))(sqrt t - sqrt(t - t_on)) after t_on (docs/theory.md §G6)."""
    t = np.asarray(t, dtype=float)
    return flux_step_surface(t, flux, material) - flux_step_surface(t - t_on, flux, material)


def duhamel_surface(t: float, flux: Callable[[float], float], material: Material | str, breakpoints=()) -> float:
    """Surface rise for a general flux history q(tau), (1/(sqrt(pi) e)) int_0^t q(tau)/sqrt(t - tau) dtau
    (Duhamel; docs/theory.md §G6). quad with the algebraic weight; pass the jumps of q as breakpoints."""
    m = get_material(material)
    edges = [0.0] + sorted(b for b in breakpoints if 0.0 < b < t) + [t]
    total = 0.0
    for a, b in zip(edges[:-2], edges[1:-1]):                       # smooth pieces away from tau = t
        total += quad(lambda s: flux(s) / math.sqrt(t - s), a, b, limit=200)[0]
    a = edges[-2]
    total += quad(flux, a, t, weight="alg", wvar=(0.0, -0.5), limit=200)[0]
    return total / (math.sqrt(math.pi) * m.effusivity)


def moving_band_high_peclet_max(mean_flux, half_width_m, source_speed, material: Material | str):
    """High-L maximum under a uniform moving band, 2 q_bar sqrt(2 b chi/(pi U))/k (= flux step with t_on = 2b/U; §6)."""
    m = get_material(material)
    return 2.0 * mean_flux * np.sqrt(2.0 * half_width_m * m.diffusivity / (math.pi * np.abs(source_speed))) / m.conductivity


def validity(peclet_number) -> tuple[bool, str]:
    """Is the 1-D model a valid flash model at this Peclet number (L >~ 5)? Returns (ok, message); docs/theory.md §G6."""
    L = float(np.min(peclet_number))
    if L >= VALID_PECLET_MIN:
        return True, f"1-D conduction valid as a flash model (L = {L:.3g} >= {VALID_PECLET_MIN:g})"
    return False, (f"1-D conduction not valid as a flash model at L = {L:.3g} < {VALID_PECLET_MIN:g}: lateral conduction "
                   "is neglected and the rise is over-predicted; use the exact moving-band solution (docs/theory.md "
                   "§G4.3, mechsim.thermal.band_source)")
