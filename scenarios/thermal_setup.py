"""Build the thermal model a scenario asks for: material, contact geometry, the bulk network (lumped) and the
slot-wall track meshes (1d), as one `LinearThermalSystem` wrapped in the DAE extension.

Bodies (docs/theory.md §G5, docs/thermal.md "Coupling"):
- pin: the exposed cylinder (radius R, length l_pin, one free end); takes the pin's share gamma Q;
- crank: an arm lumped on the pin side, joined to the pin by the conductance G (rod conduction through the pin's
  exposed half-length, k pi R^2/(l_pin/2), by default); convects with the pin's h;
- wheel: a solid disc (radius = pin distance at entry, thickness = the wheel's); takes (1 - gamma) Q;
- 1d only: one graded 1-D mesh into the depth of each slot's driving wall, over the swept track area
  l x (x_entry - x_min); the wheel's heat enters the mesh of the slot in contact, the mesh's far face conducts
  into the wheel's bulk node (whose capacity loses the meshes' volume, so no heat capacity is counted twice).

The Geneva-specific read-outs (contact quantities from the result columns, times of contact) live in
`geneva_contact`; a new mechanism with a sliding contact adds its own adapter to `CONTACT_ADAPTERS`.
"""
from __future__ import annotations

import math
from dataclasses import dataclass, field

import numpy as np
import pandas as pd
import scipy.sparse as sps

from mechsim.dynamics.thermal_coupling import HeatInput, ShareModel, ThermalExtension
from mechsim.mechanisms.base import Mechanism
from mechsim.thermal import (LinearThermalSystem, Material, biot_number, conduction_system, disc_volume_area,
                     effective_modulus, graded_mesh, pin_volume_area)

from mechsim.scenarios.thermal_schema import thermal_material

KELVIN = 273.15
#: default exposed pin length over wheel thickness (docs/theory.md §G5: 10 mm pin for the seed's 4 mm wheel)
PIN_LENGTH_OVER_THICKNESS = 2.5
#: default crank arm: length r, width CRANK_WIDTH_OVER_PIN_RADIUS * R, thickness = wheel thickness
CRANK_WIDTH_OVER_PIN_RADIUS = 4.0
#: default first cell of the 1-D mesh: sqrt(chi t_engagement) / MESH_FIRST_CELL_DIVISOR
MESH_FIRST_CELL_DIVISOR = 20.0
#: default depth: MESH_DEPTH_PENETRATIONS periodic penetration depths sqrt(chi n T / pi) (n T = one wheel turn)
MESH_DEPTH_PENETRATIONS = 3.0


# ------------------------------------------------------------------------------------------------ contact adapters
@dataclass(frozen=True)
class ContactGeometry:
    """What the thermal model needs to know of the mechanism (SI)."""

    contact_radius: float        # pin radius R (Hertz R' = R on a flat wall)
    contact_length: float        # wheel thickness l
    crank_radius: float
    tracks: int                  # number of distinct wall tracks (slots)
    track_length: float          # swept length of one wall track
    wheel_radius: float          # default disc radius
    engagement_angle: float      # crank angle per contact
    seed_source_speed_factor: float   # the seed's source speed over crank speed (omega1 r: r)


def geneva_geometry(mech) -> ContactGeometry:
    g = mech.geometry
    return ContactGeometry(contact_radius=g.pin_radius, contact_length=g.thickness, crank_radius=g.crank_radius,
                           tracks=g.slots, track_length=g.entry_pin_distance - g.min_pin_distance,
                           wheel_radius=g.entry_pin_distance, engagement_angle=2 * g.engagement_half_angle,
                           seed_source_speed_factor=g.crank_radius)


def geneva_contact(df: pd.DataFrame, mech) -> dict[str, np.ndarray]:
    """Contact quantities of each output row, equal to the engaged mode's `heat` expressions (geneva.py):
    normal force, slip, source speeds over pin R(w1 + w2) and wall v_s, heat rate (friction power), track (slot
    counter floor((theta + pi)/2 pi)), and the wall's sliding acceleration a_s = dv_s/dt =
    (w1' v_s + w1 (w1 + w2) w2 x)/w1 (from r cos(alpha + beta) = w2 x/w1, docs/theory.md §G1)."""
    g = mech.geometry

    def col(name):
        return np.asarray(df[name], dtype=float)

    w1, w2, v_s = col("crank_speed_rad_s"), col("wheel_speed_rad_s"), col("pin_sliding_speed_m_s")
    engaged = np.asarray(df["mode"]) == "engaged"
    with np.errstate(divide="ignore", invalid="ignore"):
        a_s = (col("crank_accel_rad_s2") * v_s + w1 * (w1 + w2) * w2 * col("pin_distance_m")) / w1
    return {
        "normal_force": col("contact_force_N"),
        "slip_speed": col("slip_speed_m_s"),
        "source_speed_pin": np.where(engaged, g.pin_radius * (w1 + w2), 0.0),
        "source_speed_wheel": v_s,
        "heat_rate": col("friction_power_W"),
        "track": np.floor((col("crank_angle_rad") + np.pi) / (2 * np.pi)),
        "sliding_accel": np.where(engaged, np.nan_to_num(a_s), 0.0),
        "engaged": engaged,
    }


def geneva_contact_starts(df: pd.DataFrame, events: pd.DataFrame, mech) -> np.ndarray:
    """Times at which a contact began (entry, flank switch): from the events table of a DAE run, or, for the
    closed form (constant speed, no events), from the crank angles of entry theta = 2 pi k - alpha0 and the sign
    changes of the normal force. A run that starts engaged gets the entry before t0 from its crank angle."""
    g = mech.geometry
    a0 = g.engagement_half_angle
    t = df["t_s"].to_numpy(float)
    theta = df["crank_angle_rad"].to_numpy(float)
    w1 = df["crank_speed_rad_s"].to_numpy(float)
    starts: list[float] = []
    if len(events) and "kind" in events:
        starts += events.loc[events["kind"].isin(["entry", "flank switch"]), "t_s"].astype(float).tolist()
    else:
        k = np.arange(np.floor((theta[0] + np.pi) / (2 * np.pi)) - 1, np.floor((theta[-1] + np.pi) / (2 * np.pi)) + 2)
        entries = 2 * np.pi * k - a0
        inside = (entries >= theta[0]) & (entries <= theta[-1])
        starts += np.interp(entries[inside], theta, t).tolist()
        N = df["contact_force_N"].to_numpy(float)
        engaged = (df["mode"] == "engaged").to_numpy()
        flip = np.flatnonzero(engaged[1:] & engaged[:-1] & (np.sign(N[1:]) * np.sign(N[:-1]) < 0))
        starts += [t[i] - N[i] * (t[i + 1] - t[i]) / (N[i + 1] - N[i]) for i in flip]
    if len(t) and df["mode"].iloc[0] == "engaged" and w1[0] > 0:
        alpha = theta[0] - 2 * np.pi * np.floor((theta[0] + np.pi) / (2 * np.pi))
        starts.append(t[0] - (alpha + a0) / w1[0])
    return np.sort(np.asarray(starts, dtype=float))


CONTACT_ADAPTERS = {"geneva": (geneva_geometry, geneva_contact, geneva_contact_starts)}


def adapter(mech: Mechanism):
    """(geometry, contact columns, contact start times) functions of this mechanism."""
    try:
        return CONTACT_ADAPTERS[mech.name]
    except KeyError:
        raise ValueError(f"thermal: no contact adapter for mechanism {mech.name!r}") from None


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
    geometry: ContactGeometry
    nominal_speed: float
    engagement_time: float
    period: float
    temp_ambient: float
    bodies: list[Body] = field(default_factory=list)
    system: LinearThermalSystem | None = None
    extension: ThermalExtension | None = None
    mesh: object = None
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


def nominal_speed(si: dict, mech: Mechanism) -> tuple[float, str]:
    """A representative drive speed for defaults (prescribed, else initial, else motor no-load speed)."""
    d = si["drive"]
    if d["type"] == "speed":
        return float(d["speed"]), "the prescribed speed"
    w0 = abs(float(si["initial"].get(mech.initial_keys[1], 0.0)))
    if w0 > 0:
        return w0, "the initial crank speed"
    if d["type"] == "motor" and d.get("no_load_speed"):
        return float(d["no_load_speed"]), "the motor's no-load speed"
    return 1.0, "1 rad/s (no speed given)"


def build(si: dict, mech: Mechanism) -> ThermalSetup | None:
    """The thermal model of a validated scenario, or None when thermal.model = 'none'."""
    th = dict(si.get("thermal", {}))
    model = th.get("model", "none")
    if model == "none":
        return None
    geo_fn, _, _ = adapter(mech)
    geo = geo_fn(mech)
    mat = thermal_material(th)
    w_nom, w_why = nominal_speed(si, mech)
    t_eng = geo.engagement_angle / w_nom
    setup = ThermalSetup(model=model, section=th, material=mat, geometry=geo, nominal_speed=w_nom,
                         engagement_time=t_eng, period=2 * np.pi / w_nom,
                         temp_ambient=float(th["ambient_temperature"]))
    if w_why != "the prescribed speed":
        setup.notes.append(f"defaults that need a speed use {w_why}, {w_nom:.6g} rad/s")
    if model == "flash":
        return setup
    _network(setup, th)
    return setup


def _network(setup: ThermalSetup, th: dict) -> None:
    geo, mat = setup.geometry, setup.material
    rho_c, k = mat.volumetric_heat_capacity, mat.conductivity
    R, l = geo.contact_radius, geo.contact_length
    th.setdefault("pin_exposed_length", None)
    l_pin = th["pin_exposed_length"] or PIN_LENGTH_OVER_THICKNESS * l
    th["pin_exposed_length"] = l_pin
    v_pin, a_pin = pin_volume_area(R, l_pin)
    if th.get("crank_volume") is None:
        width = CRANK_WIDTH_OVER_PIN_RADIUS * R
        th["crank_volume"] = geo.crank_radius * width * l
        th["crank_area"] = 2 * geo.crank_radius * width + 2 * (geo.crank_radius + width) * l
    if th.get("pin_crank_conductance") is None:
        th["pin_crank_conductance"] = k * math.pi * R**2 / (0.5 * l_pin)
    th["wheel_radius"] = th.get("wheel_radius") or geo.wheel_radius
    th["wheel_thickness"] = th.get("wheel_thickness") or l
    v_w, a_w = disc_volume_area(th["wheel_radius"], th["wheel_thickness"])
    G = th["pin_crank_conductance"]

    bodies = [Body("pin", v_pin, a_pin, th["convection_pin"])]
    if th["crank_volume"] > 0 and G > 0:
        bodies.append(Body("crank", th["crank_volume"], th["crank_area"], th["convection_pin"]))
    wheel = Body("wheel", v_w, a_w, th["convection_wheel"])
    bodies.append(wheel)

    mesh_sys = None
    if setup.model == "1d":
        chi = mat.diffusivity
        first = th.get("mesh_first_cell") or math.sqrt(chi * setup.engagement_time) / MESH_FIRST_CELL_DIVISOR
        depth = th.get("mesh_depth") or MESH_DEPTH_PENETRATIONS * math.sqrt(chi * geo.tracks * setup.period / math.pi)
        th["mesh_first_cell"], th["mesh_depth"] = first, depth
        if first > depth:
            from mechsim.scenarios.units import ScenarioError
            raise ScenarioError("thermal.mesh_first_cell", f"{first!r} m exceeds the mesh depth {depth!r} m")
        setup.mesh = graded_mesh(first, th["mesh_growth"], depth)
        mesh_sys = conduction_system(setup.mesh, mat, h=0.0, far="fixed").system
        setup.track_area = geo.contact_length * geo.track_length
        wheel.volume -= geo.tracks * setup.track_area * depth
        if wheel.volume <= 0:
            from mechsim.scenarios.units import ScenarioError
            raise ScenarioError("thermal.mesh_depth", f"{depth!r} m: the slot-wall meshes would exceed the wheel")
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
