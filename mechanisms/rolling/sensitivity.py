"""The rolling-pair four-bar's parameters and refusals as traced formulas of its scenario values, for the design
sensitivities (docs/sensitivity.md, "Geometry of the chain and the rolling pair"): its `ParameterMap`, checked
against the mechanism by scenarios/studies/sensitivity_map.py."""
from __future__ import annotations

from mechsim.mechanisms.parameter_map import ParameterMap


def rolling_list_keys(si: dict) -> tuple[str, ...]:
    """The rolling pair's points: the crank's pivot, and the fixed circle's centre or the line's point."""
    point = "profile_centre" if si["mechanism"].get("profile", "circle") == "circle" else "line_point"
    return (f"mechanism.{point}[0]", f"mechanism.{point}[1]", "mechanism.crank_pivot[0]", "mechanism.crank_pivot[1]")


#: the rolling pair's geometry: scenario key -> model parameter (mechanisms/rolling/model.py `parameter_values`)
ROLLING_GEOMETRY = {"mechanism.disc_radius": "r", "mechanism.crank_length": "l2", "mechanism.coupler_length": "l3",
                     "mechanism.arm_length": "l4", "mechanism.arm_angle": "psi", "mechanism.crank_pivot[0]": "A0x",
                     "mechanism.crank_pivot[1]": "A0y", "mechanism.coupler_point_distance": "lc",
                     "mechanism.coupler_point_angle": "alpha"}
ROLLING_CIRCLE = {"mechanism.fixed_radius": "R", "mechanism.profile_centre[0]": "Ox",
                   "mechanism.profile_centre[1]": "Oy", "mechanism.contact_angle": "gamma0"}
ROLLING_LINE = {"mechanism.line_point[0]": "Px", "mechanism.line_point[1]": "Py", "mechanism.line_angle": "tangent"}


def rolling_parameters(x: dict, si: dict, mech) -> dict:
    """Rolling-pair four-bar (mechanisms/rolling/model.py `Bodies.uniform`, `from_config`): the geometry enters the
    model as itself (the profile's R, O, gamma0 or line point and angle, the disc's r, the links l2, l3, l4, the arm's
    angle, the pivot A0, the coupler point); slender crank and coupler rods (centre at mid-length, I = m l^2 / 12),
    the rolling link a uniform disc (m r^2 / 2 about B0) welded to a slender arm (m l4^2 / 3 about B0), moved to the
    joint centre of mass c4 = m_arm l4 / 2 / m4 (docs/theory.md §K3), unless the scenario gives the inertias and
    centres itself (then those enter as themselves: crank_com c2, coupler_com c3, rolling_com c4; a given rolling_com
    does not move the uniform I4, which keeps the uniform c4, as `from_config` does); the centre's direction from
    the arm, rolling_com_angle, is d4."""
    m = si["mechanism"]
    circle = m.get("profile", "circle") == "circle"
    geometry = {**ROLLING_GEOMETRY, **(ROLLING_CIRCLE if circle else ROLLING_LINE)}
    out = {name: x[key] for key, name in geometry.items()}
    l2, l3, l4, r = out["l2"], out["l3"], out["l4"], out["r"]
    m2, m3 = x["mechanism.crank_mass"], x["mechanism.coupler_mass"]
    disc, arm = x["mechanism.disc_mass"], x["mechanism.arm_mass"]
    m4 = disc + arm
    uniform_c4 = arm * l4 / 2 / m4
    i4 = (disc * r**2 / 2 + arm * l4**2 / 3 - m4 * uniform_c4**2) if m["rolling_inertia"] is None else (
        x["mechanism.rolling_inertia"])
    out.update({"m2": m2, "I2": m2 * l2**2 / 12 if m["crank_inertia"] is None else x["mechanism.crank_inertia"],
                "m3": m3, "I3": m3 * l3**2 / 12 if m["coupler_inertia"] is None else x["mechanism.coupler_inertia"],
                "m4": m4, "I4": i4, "g": x["load.gravity"], "b2": x["load.crank_damping"],
                "b4": x["load.rolling_damping"], "d4": x["mechanism.rolling_com_angle"],
                "c2": l2 / 2 if m["crank_com"] is None else x["mechanism.crank_com"],
                "c3": l3 / 2 if m["coupler_com"] is None else x["mechanism.coupler_com"],
                "c4": uniform_c4 if m["rolling_com"] is None else x["mechanism.rolling_com"]})
    return out


def rolling_refuse(plan, key: str) -> str | None:
    """The other profile's values do not enter the model; the start's assembly choice is not a continuous value."""
    if key == "mechanism.start_rolling_angle":
        return ("it only chooses which assembly a crank-driven start takes (the one whose rolling angle is nearest "
                "it): the start does not move with it (zero derivative) except where two assemblies are equally near, "
                "where it jumps to the other branch")
    circle = plan.scenario.si["mechanism"].get("profile", "circle") == "circle"
    other = ROLLING_LINE if circle else ROLLING_CIRCLE
    if key in other:
        return f"it belongs to the {'line' if circle else 'circle'} profile; this design rolls on a " \
               f"{'circle' if circle else 'line'}"
    return None


MAP = ParameterMap(
    keys=("mechanism.crank_mass", "mechanism.crank_inertia", "mechanism.coupler_mass", "mechanism.coupler_inertia",
          "mechanism.disc_mass", "mechanism.arm_mass", "mechanism.rolling_inertia", "load.gravity",
          "load.crank_damping", "load.rolling_damping", "mechanism.fixed_radius", "mechanism.disc_radius",
          "mechanism.contact_angle", "mechanism.line_angle", "mechanism.crank_length", "mechanism.coupler_length",
          "mechanism.arm_length", "mechanism.arm_angle", "mechanism.coupler_point_distance",
          "mechanism.coupler_point_angle", "mechanism.crank_com", "mechanism.coupler_com", "mechanism.rolling_com",
          "mechanism.rolling_com_angle"),
    parameters=rolling_parameters, speed_key="initial.drive_speed",
    discrete=frozenset({"dead_sign"}), engage="", release="", list_keys=rolling_list_keys,
    refuse=rolling_refuse, hold_drive=True,
    peaks=("peak_contact_force_N", "peak_drive_torque_N_m", "peak_coupler_force_N", "peak_crank_accel_rad_s2",
           "peak_crank_speed_rad_s"))
