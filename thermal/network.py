"""The thermal network of a scenario: material, the bodies at a sliding contact, the bulk network (lumped) and
the track meshes (1d), as one `LinearThermalSystem` wrapped in the DAE extension (thermal/coupling.py).

The contact comes from the mechanism through a small interface (body-neutral, `ContactSource` below; the Geneva
implements it in mechanisms/geneva/contact.py): a cylinder on the driver body slides along one of several
flat tracks of the driven body. Bodies (docs/theory.md §G5, docs/thermal.md "Coupling"):
- pin: the driver body's contact cylinder (radius R, exposed length l_pin, one free end); takes the share gamma Q;
- crank: the driver body's arm, lumped on the pin side, joined to the pin by the conductance G (rod conduction
  through the pin's exposed half-length, k pi R^2/(l_pin/2), by default); convects with the pin's h;
- wheel: the driven body as a solid disc (default radius and thickness from the contact); takes (1 - gamma) Q;
- 1d only: one graded 1-D mesh into the depth of each track, over the swept track area l x track length; the
  driven body's heat enters the mesh of the track in contact, the mesh's far face conducts into the driven
  body's bulk node (whose capacity loses the meshes' volume, so no heat capacity is counted twice).

Which of these a model builds is the model's own module (thermal/models/); this module is the shared assembly.
"""
from __future__ import annotations

import math
from dataclasses import dataclass, field
from typing import Protocol

import numpy as np
import scipy.sparse as sps

from mechsim.thermal.conduction1d import Mesh1D, conduction_system, graded_mesh, mesh_cells
from mechsim.thermal.coupling import HeatInput, ShareModel, ThermalExtension
from mechsim.thermal.hertz import effective_modulus
from mechsim.thermal.linear import LinearThermalSystem
from mechsim.thermal.lumped import biot_number, disc_volume_area, pin_volume_area
from mechsim.thermal.materials import Material, material_with_overrides

KELVIN = 273.15
#: default exposed pin length over contact length (docs/theory.md §G5: 10 mm pin for the seed's 4 mm wheel)
PIN_LENGTH_OVER_THICKNESS = 2.5
#: default driver arm: length = the arm, width CRANK_WIDTH_OVER_PIN_RADIUS * R, thickness = contact length
CRANK_WIDTH_OVER_PIN_RADIUS = 4.0
#: at most this many cells in one track's 1-D mesh: every cell is a state of the DAE (the default mesh has a few
#: dozen; each state adds to every step and to the compiled code's size), docs/limits.md
MAX_MESH_CELLS = 400
#: default first cell of the 1-D mesh: sqrt(chi t_engagement) / MESH_FIRST_CELL_DIVISOR
MESH_FIRST_CELL_DIVISOR = 20.0
#: default depth: MESH_DEPTH_PENETRATIONS periodic penetration depths sqrt(chi n T / pi) (n T = one driven turn)
MESH_DEPTH_PENETRATIONS = 3.0


class ThermalSetupError(ValueError):
    """A [thermal] value that cannot work with this mechanism (e.g. a mesh deeper than the body): `field` names
    the key in the [thermal] section, `problem` says what is wrong."""

    def __init__(self, field: str, problem: str):
        super().__init__(f"thermal.{field}: {problem}")
        self.field = f"thermal.{field}"
        self.problem = problem


class ContactSource(Protocol):
    """What the thermal model needs of a mechanism with a sliding contact (`mechanisms.base.Mechanism`
    implements it; see its `ContactGeometry` and `CONTACT_STATE_KEYS`)."""

    name: str
    initial_keys: tuple[str, str]

    def contact_geometry(self): ...                       # contact_radius, contact_length, driver_arm, tracks,
                                                          # track_length, driven_radius, contact_angle (SI)
    def contact_state(self, table) -> dict[str, np.ndarray]: ...
    def contact_starts(self, table, events) -> np.ndarray: ...
    def closed_form(self, t, angle0, speed): ...


# ------------------------------------------------------------------------------------------------ the model
@dataclass
class Body:
    """A lumped node: name, capacity (J/K), convecting h A (W/K), volume and area."""

    name: str
    volume: float
    area: float
    h: float
    capacity: float = 0.0

    @property
    def hA(self) -> float:
        return self.h * self.area


@dataclass
class ThermalSetup:
    """Everything the runner and post-processing need to know about the thermal model of one scenario."""

    model: str
    section: dict
    material: Material
    geometry: object                 # the mechanism's ContactGeometry
    nominal_speed: float
    engagement_time: float
    period: float
    temp_ambient: float
    bodies: list[Body] = field(default_factory=list)
    system: LinearThermalSystem | None = None
    extension: ThermalExtension | None = None
    mesh: Mesh1D | None = None
    mesh_states: dict[int, list[int]] = field(default_factory=dict)   # track -> state indices (surface first)
    track_area: float = 0.0
    notes: list[str] = field(default_factory=list)
    warnings: list[str] = field(default_factory=list)

    @property
    def initial(self) -> np.ndarray:
        n = self.system.size if self.system is not None else 0
        return np.concatenate([np.full(n, self.temp_ambient), np.zeros(3)])

    def index(self, name: str) -> int:
        return self.system.state_names.index(name)

    def describe(self) -> dict:
        out = {"material": {"name": self.material.name, "E_Pa": self.material.E, "nu": self.material.nu,
                            "density_kg_m3": self.material.density,
                            "specific_heat_J_kgK": self.material.specific_heat,
                            "conductivity_W_mK": self.material.conductivity,
                            "diffusivity_m2_s": self.material.diffusivity},
               "ambient_temperature_C": self.temp_ambient - KELVIN}
        if self.bodies:
            out["bodies"] = {b.name: {"volume_m3": b.volume, "area_m2": b.area, "h_W_m2K": b.h,
                                      "capacity_J_K": b.capacity,
                                      "biot": biot_number(b.h, b.volume, b.area, self.material.conductivity)
                                      if b.area > 0 else 0.0} for b in self.bodies}
            out["pin_crank_conductance_W_K"] = self.section["pin_crank_conductance"]
        if self.system is not None:
            out["states"] = len(self.system.state_names)
            tc = self.system.time_constants()
            out["time_constants_s"] = [float(x) for x in tc[:4]] + ([float(tc[-1])] if len(tc) > 4 else [])
        if self.mesh is not None:
            out["mesh"] = {"direction": self.section["mesh_direction"], "cells_per_track": self.mesh.n_cells,
                           "tracks": self.geometry.tracks, "first_cell_m": float(self.mesh.widths[0]),
                           "growth": self.section["mesh_growth"], "depth_m": self.mesh.depth,
                           "track_area_m2": self.track_area}
        return out


def nominal_speed(si: dict, mech: ContactSource) -> tuple[float, str]:
    """A representative drive speed for defaults (prescribed, else initial, else motor no-load speed)."""
    d = si["drive"]
    if d["type"] == "speed":
        return float(d["speed"]), "the prescribed speed"
    w0 = abs(float(si["initial"].get(mech.initial_keys[1], 0.0)))
    if w0 > 0:
        return w0, "the initial drive speed"
    if d["type"] == "motor" and d.get("no_load_speed"):
        return float(d["no_load_speed"]), "the motor's no-load speed"
    return 1.0, "1 rad/s (no speed given)"


def prepare(si: dict, mech: ContactSource, model) -> ThermalSetup:
    """The common part of every thermal model: material, contact geometry, nominal speed and times; `model`
    (a thermal.models.ThermalModel) then adds its network with its `build`."""
    th = dict(si.get("thermal", {}))
    geo = mech.contact_geometry()
    w_nom, w_why = nominal_speed(si, mech)
    out = ThermalSetup(model=model.name, section=th, material=material_with_overrides(th), geometry=geo,
                       nominal_speed=w_nom, engagement_time=geo.contact_angle / w_nom, period=2 * np.pi / w_nom,
                       temp_ambient=float(th["ambient_temperature"]))
    if w_why != "the prescribed speed":
        out.notes.append(f"defaults that need a speed use {w_why}, {w_nom:.6g} rad/s")
    if model.build is not None:
        model.build(out)
    return out


def bulk_bodies(setup: ThermalSetup) -> list[Body]:
    """The lumped bodies with the section's geometry or its defaults (written back into the section, so the
    resolved scenario shows them): pin, crank (when it has a volume and a conductance to the pin), wheel."""
    geo, th, k = setup.geometry, setup.section, setup.material.conductivity
    R, l = geo.contact_radius, geo.contact_length
    th.setdefault("pin_exposed_length", None)
    l_pin = th["pin_exposed_length"] or PIN_LENGTH_OVER_THICKNESS * l
    th["pin_exposed_length"] = l_pin
    v_pin, a_pin = pin_volume_area(R, l_pin)
    if th.get("crank_volume") is None:
        width = CRANK_WIDTH_OVER_PIN_RADIUS * R
        th["crank_volume"] = geo.driver_arm * width * l
        th["crank_area"] = 2 * geo.driver_arm * width + 2 * (geo.driver_arm + width) * l
    if th.get("pin_crank_conductance") is None:
        th["pin_crank_conductance"] = k * math.pi * R**2 / (0.5 * l_pin)
    th["wheel_radius"] = th.get("wheel_radius") or geo.driven_radius
    th["wheel_thickness"] = th.get("wheel_thickness") or l
    v_w, a_w = disc_volume_area(th["wheel_radius"], th["wheel_thickness"])
    bodies = [Body("pin", v_pin, a_pin, th["convection_pin"])]
    if th["crank_volume"] > 0 and th["pin_crank_conductance"] > 0:
        bodies.append(Body("crank", th["crank_volume"], th["crank_area"], th["convection_pin"]))
    bodies.append(Body("wheel", v_w, a_w, th["convection_wheel"]))
    return bodies


def track_mesh(setup: ThermalSetup, driven: Body) -> Mesh1D:
    """The graded 1-D mesh into the depth of each track (defaults in the module constants); the driven body
    loses the meshes' volume."""
    geo, th, chi = setup.geometry, setup.section, setup.material.diffusivity
    first = th.get("mesh_first_cell") or math.sqrt(chi * setup.engagement_time) / MESH_FIRST_CELL_DIVISOR
    depth = th.get("mesh_depth") or MESH_DEPTH_PENETRATIONS * math.sqrt(chi * geo.tracks * setup.period / math.pi)
    th["mesh_first_cell"], th["mesh_depth"] = first, depth
    if first > depth:
        raise ThermalSetupError("mesh_first_cell", f"{first!r} m exceeds the mesh depth {depth!r} m")
    cells = mesh_cells(first, th["mesh_growth"], depth)
    if cells > MAX_MESH_CELLS:
        raise ThermalSetupError("mesh_first_cell", f"{first:.3g} m with mesh_growth {th['mesh_growth']:g} over a depth "
                                                   f"of {depth:.3g} m needs {cells:.3g} cells per track; at most "
                                                   f"{MAX_MESH_CELLS} (raise mesh_first_cell or mesh_growth)")
    mesh = graded_mesh(first, th["mesh_growth"], depth)
    setup.track_area = geo.contact_length * geo.track_length
    driven.volume -= geo.tracks * setup.track_area * depth
    if driven.volume <= 0:
        raise ThermalSetupError("mesh_depth", f"{depth!r} m: the track meshes would exceed the driven body")
    return mesh


def assemble(setup: ThermalSetup, bodies: list[Body], mesh: Mesh1D | None = None) -> None:
    """The network C T' = -K T + s + B u of the bodies (first the driver's contact body, last the driven body)
    and, with a mesh, one mesh per track; and its DAE extension with the heat share. Sets setup.system,
    setup.extension, setup.bodies, setup.mesh, setup.mesh_states; warns where a body is not isothermal."""
    geo, mat, th = setup.geometry, setup.material, setup.section
    rho_c, k = mat.volumetric_heat_capacity, mat.conductivity
    G = th["pin_crank_conductance"]
    setup.mesh = mesh
    mesh_sys = conduction_system(mesh, mat, h=0.0, far="fixed").system if mesh is not None else None
    for b in bodies:
        b.capacity = rho_c * b.volume
    setup.bodies = bodies

    names = [f"temp_bulk_{b.name}_K" for b in bodies]
    n_bulk = len(bodies)
    ip, iw = 0, n_bulk - 1
    n_cells = setup.mesh.n_cells if setup.mesh is not None else 0
    for j in range(geo.tracks if n_cells else 0):
        setup.mesh_states[j] = list(range(len(names), len(names) + n_cells))
        names += [f"temp_wall_{j}_{i}_K" for i in range(n_cells)]
    n = len(names)
    C = np.zeros(n)
    K = sps.lil_matrix((n, n))
    s = np.zeros(n)
    for i, b in enumerate(bodies):
        C[i] = b.capacity
        K[i, i] += b.hA
        s[i] = b.hA * setup.temp_ambient
    if len(bodies) == 3:
        K[0, 0] += G
        K[1, 1] += G
        K[0, 1] -= G
        K[1, 0] -= G
    if n_cells:
        inputs = [HeatInput("pin")] + [HeatInput("wheel", j, geo.tracks) for j in range(geo.tracks)]
        B = np.zeros((n, len(inputs)))
        B[ip, 0] = 1.0
        A = setup.track_area
        Km = sps.csr_matrix(mesh_sys.conductance) * A
        g_far = mesh_sys.input_matrix[-1, 1] * A        # half-cell conductance of the far face to the bulk
        for j, idx in setup.mesh_states.items():
            C[idx] = mesh_sys.capacity * A
            sl = slice(idx[0], idx[-1] + 1)
            K[sl, sl] = Km
            last = idx[-1]
            K[last, iw] -= g_far
            K[iw, last] -= g_far
            K[iw, iw] += g_far
            B[idx[0], 1 + j] = mesh_sys.input_matrix[0, 0]
    else:
        inputs = [HeatInput("pin"), HeatInput("wheel")]
        B = np.zeros((n, 2))
        B[ip, 0] = 1.0
        B[iw, 1] = 1.0
    setup.system = LinearThermalSystem(state_names=tuple(names), capacity=C, conductance=sps.csr_matrix(K),
                                       source=s, input_matrix=B,
                                       input_names=tuple(f"heat_rate_{x.body}{'_%d' % x.track if x.tracks else ''}_W"
                                                         for x in inputs))
    share = ShareModel(contact_radius=geo.contact_radius, contact_length=geo.contact_length,
                       modulus=effective_modulus(mat), k_pin=k, k_wheel=k, chi_pin=mat.diffusivity,
                       chi_wheel=mat.diffusivity, t_ref=setup.engagement_time, distribution=th["distribution"])
    setup.extension = ThermalExtension(setup.system, tuple(inputs), share)
    for b in bodies:
        bi = biot_number(b.h, b.volume, b.area, k) if b.area > 0 else 0.0
        if bi >= 0.1:
            setup.warnings.append(f"thermal: the {b.name}'s Biot number h(V/A)/k = {bi:.3g} >= 0.1, so it is not "
                                  "isothermal and the lumped model does not hold (Incropera §5.2; docs/theory.md §G5)")
