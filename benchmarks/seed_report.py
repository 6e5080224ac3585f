"""The seed reproduction report (`mechsim report seed`): the seed's six load cases, three models side by side.

For each built-in `geneva-seed-lc{1,2,3}-mu{015,030}` scenario, on the seed's angular-position axis
phi = alpha + alpha0 (0..90 deg for n = 4; docs/theory.md §G1):

- **seed**: the seed's model as it evaluates it (Ambaye, Lemu & Tolcha 2022): S(8) load from the torque, S(9)
  with the half-width its Peclet numbers imply (E*, so p_max = W/(pi b l) = p0/2; S(9) as printed with
  E' = 2E* is kept in two extra columns), S(11) Peclet with U = omega1 r, S(12) heat with |V1 - V2| = |v_s|,
  S(13) flash with C = 2.5, contact temperature = ambient + flash (docs/theory.md §G2-4, §4.7 "Reproduction");
- **corrected**: the same quasi-static model with its errors corrected, docs/theory.md §G4.7 recipe: wheel balance
  N = (T_L + J2 alpha2)/x, Hertz b and p0 (Johnson), driving-flank slip with the pin spin, Peclet numbers with
  the source speed over each body, exact moving band (semi-elliptic max) per body + Blok partition, transient
  floors; contact temperature = ambient + flash;
- **mechsim**: the built-in scenario through `scenarios.runner.run` (inertia and the friction arm in the wheel
  balance, lumped bulk + Jaeger flash): one engagement of a resolved run, and the last engagement after one hour
  (cycle-averaged bulk, docs/thermal.md), `mechsim_1h`.

Outputs (folder): case_<scenario>.csv per case, comparison.csv, peak_location.csv, speed_vs_torque.csv,
one PNG per quantity (benchmarks/seed_report_plots.py), report.md (benchmarks/seed_report_text.py).
"""
from __future__ import annotations

import math
from dataclasses import dataclass
from pathlib import Path
from typing import Callable

import numpy as np
import pandas as pd
from scipy.integrate import trapezoid

import mechsim.mechanisms.geneva.kinematics as gk
from mechsim.thermal import (Material, effective_modulus, flash_temperature, frictional_heat, half_width, peak_pressure,
                     peclet, seed_flash_rise, seed_half_width, seed_max_pressure, seed_normal_load,
                     seed_reduced_modulus, seed_sliding_speed)

from mechsim.scenarios.output.atomic import atomic_folder, check_replaceable

KELVIN = 273.15
#: the six built-in seed scenarios: (load case, mu code)
CASES = tuple(f"geneva-seed-lc{lc}-mu{mu}" for lc in (1, 2, 3) for mu in ("015", "030"))
MODELS = ("seed", "corrected", "mechsim", "mechsim_1h")
MODEL_LABELS = {
    "seed": "seed as printed",
    "corrected": "seed corrected",
    "mechsim": "mechsim (dynamic)",
    "mechsim_1h": "mechsim after 1 h",
}
#: per-model quantities on the phi grid (column suffixes, SI)
QUANTITIES = ("normal_load_N", "half_width_m", "pressure_max_Pa", "peclet_pin", "peclet_wheel", "heat_rate_W",
              "temp_flash_rise_K", "temp_contact_C")
#: the run that stands for "after one hour of operation" (cycle-averaged bulk; docs/thermal.md)
STEADY_DURATION_S = 3600.0
#: its output step (deg of crank): the first of these, no finer than the report's grid, whose rows the runner's
#: memory bound allows on this machine (`_hour_run`). An hour on the full report's 0.25 deg grid is 4.4 to 8.8
#: million rows (LC3 at 10.68 rad/s: about 17 GiB by that bound, refused on most machines); every 1 deg it is 2.2
#: million for LC3 (4.2 GiB by the bound), every 3 deg 0.73 million. Each is a multiple of every grid the report
#: uses and divides 45 deg, so mid-stroke stays one of its rows; the grid's rows between them are left empty
STEADY_STEPS_DEG = (1.0, 3.0, 5.0, 9.0)
#: the small report's (CI): an hour every 1 deg is a million rows, most of that report's time; every 3 deg keeps
#: the flash's dip before mid-stroke (at 42 deg) one of its rows
SMALL_STEADY_STEP_DEG = 3.0
#: fine grid for the energy per index of the analytic models (deg)
ENERGY_STEP_DEG = 0.01


@dataclass(frozen=True)
class ReportConfig:
    """How much to run: phi grid step, crank turns of the resolved mechsim run."""

    small: bool
    phi_step_deg: float
    turns: int

    @classmethod
    def make(cls, small: bool) -> "ReportConfig":
        # small: one index (start 5 deg before entry), 1 deg grid; full: 5 crank turns, 0.25 deg grid
        return cls(small=True, phi_step_deg=1.0, turns=0) if small else cls(small=False, phi_step_deg=0.25, turns=5)

    def describe(self) -> str:
        if self.small:
            return (f"--small: one index (crank from -50 deg to +50 deg, first engagement), output every "
                    f"{self.phi_step_deg:g} deg of crank, the hour's run every {SMALL_STEADY_STEP_DEG:g} deg")
        return (f"full: {self.turns} crank turns from the scenario's start (-180 deg), last engagement shown, output "
                f"every {self.phi_step_deg:g} deg of crank")


@dataclass(frozen=True)
class Case:
    """One seed load case, read from its built-in scenario (SI)."""

    name: str
    load_case: int
    torque: float            # T: the wheel torque T_L (the seed's T_Gw, which S(8) treats as T)
    speed: float             # omega1
    mu: float
    geometry: gk.GenevaGeometry
    wheel_inertia: float
    material: Material
    ambient_K: float
    distribution: str

    @property
    def label(self) -> str:
        return f"LC{self.load_case}, mu = {self.mu:g}"

    @property
    def period(self) -> float:
        return 2 * math.pi / self.speed


def load_case(name: str) -> Case:
    """The Case of a built-in seed scenario."""
    from mechsim.scenarios.loader import build_mechanism, load
    from mechsim.scenarios.thermal_schema import thermal_material
    si = load(name, []).si
    mech = build_mechanism(si)
    th = si["thermal"]
    return Case(name=name, load_case=int(name.split("-lc")[1][0]), torque=float(si["load"]["wheel_torque"]),
                speed=float(si["drive"]["speed"]), mu=float(si["contact"]["friction"]), geometry=mech.geometry,
                wheel_inertia=float(si["mechanism"]["wheel_inertia"]), material=thermal_material(th),
                ambient_K=float(th["ambient_temperature"]), distribution=th["distribution"])


def phi_grid(step_deg: float) -> np.ndarray:
    """Open grid 0 < phi < 90 deg (the engagement ends are where the load jumps: left out)."""
    n = int(round(90.0 / step_deg))
    return np.arange(1, n) * step_deg


def _alpha(case: Case, phi_deg):
    return np.radians(phi_deg) - case.geometry.engagement_half_angle


# ------------------------------------------------------------------------------------------------ (a) the seed
def seed_model(case: Case, phi_deg) -> pd.DataFrame:
    """The seed's model as it evaluates it (docs/theory.md §G2-4, §4.7 "Reproduction").

    theta1 + theta2 = |alpha| + |beta| (docs/theory.md §G1 "Seed check"); S(8) W = (T/r) cos(theta1 + theta2);
    S(7) |v_s| = omega1 r sin(theta1 + theta2); b = sqrt(4WR/(pi l E*)) (the seed's Peclet numbers 0.35...0.58
    need E*, not its printed E' = 2E*); S(9b) p_max = W/(pi b l); S(11) L = omega1 r b/(2 chi) for both bodies;
    S(12) Q = mu W |v_s|; S(13) with C = 2.5 and L = the contact length.
    """
    g, mat = case.geometry, case.material
    a = _alpha(case, phi_deg)
    s = np.abs(a) + np.abs(gk.wheel_angle(g.ratio, a))
    W = seed_normal_load(case.torque, s, g.crank_radius)
    V = seed_sliding_speed(case.speed, g.crank_radius, s)
    b = half_width(W, g.pin_radius, g.thickness, effective_modulus(mat))
    b_printed = seed_half_width(W, g.pin_radius, g.thickness, seed_reduced_modulus(mat))
    U = case.speed * g.crank_radius
    L = peclet(U, b, mat.diffusivity)
    Q = frictional_heat(case.mu, W, V)
    rise = seed_flash_rise(Q, b, U, g.thickness, mat)
    return pd.DataFrame({
        "seed_normal_load_N": W, "seed_half_width_m": b, "seed_pressure_max_Pa": seed_max_pressure(W, b, g.thickness),
        "seed_peclet_pin": L, "seed_peclet_wheel": L, "seed_heat_rate_W": Q, "seed_temp_flash_rise_K": rise,
        "seed_temp_contact_C": case.ambient_K + rise - KELVIN,
        "seed_sliding_speed_m_s": V, "seed_source_speed_m_s": np.full_like(W, U),
        "seed_half_width_printed_m": b_printed,
        "seed_pressure_max_printed_Pa": seed_max_pressure(W, b_printed, g.thickness),
    })


# ------------------------------------------------------------------------------------------------ (b) corrected
def corrected_model(case: Case, phi_deg) -> pd.DataFrame:
    """The seed's quasi-static model with its errors corrected: the docs/theory.md §G4.7 recipe.

    N = (T_L + J2 alpha2)/x (wheel balance, §2, no friction arm); Hertz b, p0 (§3); slip on the driving flank
    u = v_s + R(omega1 + omega2) (§1 pin spin); L_wall = |v_s| b/(2chi), L_pin = R(omega1 + omega2) b/(2chi)
    (§4.2); exact band theta per body + Blok partition (§4.3, §4.6) with the floors of §4.7: pin t_on = time
    since entry, wall t_on = min(2b/U_wall, 2 sqrt(2b/a_s)), a_s = (omega1 + omega2) omega2 x the slot-sliding
    acceleration (7.30 m/s^2 at alpha = 0 for LC1).
    """
    g, mat, w1 = case.geometry, case.material, case.speed
    a = _alpha(case, phi_deg)
    w2 = w1 * gk.speed_ratio(g.ratio, a)
    a2 = w1 * w1 * gk.speed_ratio_derivative(g.ratio, a)
    x = gk.pin_distance(g, a)
    v_s = gk.pin_sliding_speed(g, a, w1)
    u = v_s + g.pin_radius * (w1 + w2)
    N = (case.torque + case.wheel_inertia * a2) / x
    E_star = effective_modulus(mat)
    b = half_width(N, g.pin_radius, g.thickness, E_star)
    U_wall, U_pin = np.abs(v_s), g.pin_radius * (w1 + w2)
    a_s = np.abs((w1 + w2) * w2 * x)
    with np.errstate(divide="ignore"):
        t_cross = np.where(U_wall > 0, 2 * b / np.where(U_wall > 0, U_wall, 1.0), np.inf)
        t_turn = np.where(a_s > 0, 2 * np.sqrt(2 * b / np.where(a_s > 0, a_s, 1.0)), np.inf)
    res = flash_temperature(N, u, U_wall, U_pin, b, g.thickness, case.mu, mat, mat,
                            t_on_pin=np.radians(phi_deg) / w1, t_on_wall=np.minimum(t_cross, t_turn),
                            distribution=case.distribution)
    rise = res["temp_flash_rise_K"]
    return pd.DataFrame({
        "corrected_normal_load_N": N, "corrected_half_width_m": b,
        "corrected_pressure_max_Pa": peak_pressure(N, g.pin_radius, g.thickness, E_star),
        "corrected_peclet_pin": res["peclet_pin"], "corrected_peclet_wheel": res["peclet_wheel"],
        "corrected_heat_rate_W": res["heat_rate_W"], "corrected_temp_flash_rise_K": rise,
        "corrected_temp_contact_C": case.ambient_K + rise - KELVIN,
        "corrected_slip_speed_m_s": u, "corrected_heat_share_pin": res["heat_share_pin"],
    })


def energy_per_index(model: Callable[[Case, np.ndarray], pd.DataFrame], case: Case, prefix: str) -> float:
    """Heat of one engagement, integral of Q dt = integral of Q dphi/omega1 over 0..90 deg (fine trapezoid)."""
    phi = np.linspace(0.0, 90.0, int(round(90.0 / ENERGY_STEP_DEG)) + 1)
    Q = model(case, phi)[f"{prefix}_heat_rate_W"].to_numpy(float)
    return float(trapezoid(Q, np.radians(phi)) / case.speed)


# ------------------------------------------------------------------------------------------------ (c) mechsim
MECHSIM_COLUMNS = {   # report quantity -> runner column
    "normal_load_N": "contact_force_N", "half_width_m": "hertz_half_width_m",
    "pressure_max_Pa": "hertz_pressure_max_Pa", "peclet_pin": "peclet_pin", "peclet_wheel": "peclet_wheel",
    "heat_rate_W": "heat_rate_W", "temp_flash_rise_K": "temp_flash_rise_K", "temp_contact_C": "temp_contact_C",
}
MECHSIM_EXTRA = {     # kept for checks: the wheel balance, slip, bulk temperatures
    "t_s": "t_s", "crank_angle_rad": "crank_angle_rad", "wheel_speed_rad_s": "wheel_speed_rad_s",
    "wheel_accel_rad_s2": "wheel_accel_rad_s2", "pin_distance_m": "pin_distance_m",
    "slip_speed_m_s": "slip_speed_m_s", "pin_sliding_speed_m_s": "pin_sliding_speed_m_s", "flank": "flank",
    "heat_share_pin": "heat_share_pin", "temp_bulk_pin_C": "temp_bulk_pin_C",
    "temp_bulk_wheel_C": "temp_bulk_wheel_C",
}


def _overrides(case: Case, config: ReportConfig, steady: bool, step_deg: float | None = None) -> list[str]:
    """Runner overrides that put the output rows on the phi grid (crank angle = start + k * step; step_deg, the
    grid's step unless given)."""
    step = math.radians(config.phi_step_deg if step_deg is None else step_deg) / case.speed
    if steady:
        return [f"duration={STEADY_DURATION_S!r} s", f"output_step={step!r} s"]
    if config.small:
        return ["initial.crank_angle=-50 deg", f"duration={math.radians(100.0) / case.speed!r} s",
                f"output_step={step!r} s"]
    return ["initial.crank_angle=-180 deg", f"duration={config.turns * 2 * math.pi / case.speed!r} s",
            f"output_step={step!r} s"]


def _last_engagement(df: pd.DataFrame, case: Case, phi: np.ndarray, step_deg: float, prefix: str,
                     grid_step_deg: float | None = None) -> tuple[pd.DataFrame, dict]:
    """The last complete engagement of a run whose rows are every step_deg of crank, on the phi grid (a step of
    grid_step_deg, step_deg's unless given; step_deg a multiple of it: the grid's rows between the run's are left
    empty) as prefix_* columns, and its bookkeeping."""
    grid_step_deg = step_deg if grid_step_deg is None else grid_step_deg
    a0 = case.geometry.engagement_half_angle
    theta = df["crank_angle_rad"].to_numpy(float)
    k = np.floor((theta + np.pi) / (2 * np.pi))
    phi_row = np.degrees(theta - 2 * np.pi * k + a0)
    engaged = (df["mode"] == "engaged").to_numpy()
    slots = np.intersect1d(np.intersect1d(k[engaged], k[phi_row < 0]), k[phi_row > 90])
    if not len(slots):
        raise RuntimeError(f"{case.name}: the run has no complete engagement to report")
    kk = slots[-1]
    on_grid = np.abs(phi_row - np.rint(phi_row / step_deg) * step_deg) < 1e-6
    key = np.rint(phi_row / grid_step_deg)
    sel = (k == kk) & engaged & on_grid
    rows = df.loc[sel].assign(_key=key[sel].astype(int)).drop_duplicates("_key").set_index("_key")
    grid_keys = np.rint(phi / grid_step_deg).astype(int)
    out = {}
    for name, col in {**MECHSIM_COLUMNS, **MECHSIM_EXTRA}.items():
        values = rows[col].reindex(grid_keys) if col in rows else pd.Series(np.nan, index=grid_keys)
        out[f"{prefix}_{name}"] = values.to_numpy(float)
    info = {"engagement": int(kk), "t_entry_s": float(np.interp(2 * np.pi * kk - a0, theta, df["t_s"]))}
    if "heat_generated_J" in df and df["heat_generated_J"].notna().all():
        before = df.loc[(k == kk) & (phi_row < 0), "heat_generated_J"].iloc[-1]
        after = df.loc[(k == kk) & (phi_row > 90), "heat_generated_J"].iloc[0]
        info["energy_per_index_J"] = float(after - before)
    return pd.DataFrame(out), info


def _hour_run(case: Case, config: ReportConfig):
    """(output step in deg, the loaded scenario) of the hour's run: the first of STEADY_STEPS_DEG the loader accepts
    (its bound on the rows' memory, scenarios/schema.py `check_derived`), from SMALL_STEADY_STEP_DEG on for the
    small report; the last one's refusal as it is."""
    from mechsim.scenarios.loader import load
    from mechsim.scenarios.units import ScenarioError
    finest = max(config.phi_step_deg, SMALL_STEADY_STEP_DEG if config.small else 0.0)
    steps = [s for s in STEADY_STEPS_DEG if s >= finest - 1e-12]
    for step in steps:
        try:
            return step, load(case.name, _overrides(case, config, True, step))
        except ScenarioError as exc:
            if exc.field != "output_step" or step == steps[-1]:
                raise


def mechsim_model(case: Case, config: ReportConfig, phi: np.ndarray, steady: bool = False) -> tuple[
        pd.DataFrame, dict]:
    """The built-in scenario through the runner, its last complete engagement on the phi grid."""
    from mechsim.scenarios.loader import load
    from mechsim.scenarios.runner import run
    step_deg, scenario = (_hour_run(case, config) if steady else
                          (config.phi_step_deg, load(case.name, _overrides(case, config, False))))
    result = run(scenario)
    if result.failure:
        raise RuntimeError(f"{case.name}: the run failed: {result.failure.message()}")
    prefix = "mechsim_1h" if steady else "mechsim"
    table, info = _last_engagement(result.timeseries, case, phi, step_deg, prefix, config.phi_step_deg)
    info["step_deg"] = step_deg
    th = result.summary.get("thermal", {})
    if "cycle" in th:
        info["energy_per_index_J"] = th["cycle"]["mean_heat_rate_W"] * th["cycle"]["period_s"]
    info["averaging"] = th.get("averaging")
    info["method"] = result.summary["model"]["method"]
    info["warnings"] = list(result.summary.get("warnings", []))
    info["wall_time_s"] = result.summary["solver"]["wall_time_s"]
    return table, info


# ------------------------------------------------------------------------------------------------ tables
def stroke_half(phi_deg: float) -> str:
    """Which half of the stroke phi lies in: the pin moves inward for phi < 45 deg, outward after (§1)."""
    if abs(phi_deg - 45.0) < 1e-9:
        return "mid-stroke"
    return "first half (pin moving in)" if phi_deg < 45.0 else "second half (pin moving out)"


def _peak(phi: np.ndarray, values: np.ndarray) -> tuple[float, float, str]:
    """(max value, its phi, stroke half); a peak mirrored at 90 - phi within 1e-9 is reported as both halves."""
    if not np.isfinite(values).any():
        return float("nan"), float("nan"), ""
    i = int(np.nanargmax(values))
    v, p = float(values[i]), float(phi[i])
    j = int(np.argmin(np.abs(phi - (90.0 - p))))
    if abs(phi[j] - (90.0 - p)) < 1e-9 and abs(p - 45.0) > 1e-9 and abs(values[j] - v) <= 1e-9 * max(abs(v), 1e-300):
        return v, min(p, 90.0 - p), "both halves (symmetric)"
    return v, p, stroke_half(p)


def case_table(case: Case, config: ReportConfig, say: Callable[[str], None] | None = None) -> tuple[
        pd.DataFrame, dict]:
    """phi_deg plus every model's columns for one case; info with energies and run notes."""
    phi = phi_grid(config.phi_step_deg)
    parts = [pd.DataFrame({"phi_deg": phi}), seed_model(case, phi), corrected_model(case, phi)]
    info = {"energy_per_index_J": {"seed": energy_per_index(seed_model, case, "seed"),
                                   "corrected": energy_per_index(corrected_model, case, "corrected")}}
    for steady in (False, True):
        table, run_info = mechsim_model(case, config, phi, steady)
        model = "mechsim_1h" if steady else "mechsim"
        parts.append(table)
        info["energy_per_index_J"][model] = run_info.get("energy_per_index_J", float("nan"))
        info[model] = run_info
        if say:
            say(f"  {case.name} {model}: {run_info['method']}, {run_info['averaging']}, rows every "
                f"{run_info['step_deg']:g} deg, wall {run_info['wall_time_s']:.2f} s")
    return pd.concat(parts, axis=1), info


#: (per-model quantity, comparison name with unit, report its stroke half)
PEAK_QUANTITIES = (
    ("normal_load_N", "normal_load_N", False), ("half_width_m", "half_width_m", False),
    ("pressure_max_Pa", "pressure_max_Pa", False), ("heat_rate_W", "heat_rate_W", True),
    ("temp_flash_rise_K", "flash_rise_K", True), ("temp_contact_C", "contact_temp_C", True),
)


def comparison_rows(case: Case, table: pd.DataFrame, info: dict) -> list[dict]:
    """One row per model: peaks (with phi and stroke half), Peclet maxima, energy per index, mean heat rate."""
    phi = table["phi_deg"].to_numpy(float)
    rows = []
    for model in MODELS:
        row = {"case": case.name, "load_case": case.load_case, "mu": case.mu, "wheel_torque_N_m": case.torque,
               "crank_speed_rad_s": case.speed, "model": model}
        for q, name, halves in PEAK_QUANTITIES:
            v, p, half = _peak(phi, table[f"{model}_{q}"].to_numpy(float))
            row[f"peak_{name}"] = v
            row[f"phi_peak_{name.rsplit('_', 1)[0]}_deg"] = p
            if halves:
                row[f"stroke_half_peak_{name.rsplit('_', 1)[0]}"] = half
        row["peak_contact_rise_K"] = row["peak_contact_temp_C"] + KELVIN - case.ambient_K
        contact = table[f"{model}_temp_contact_C"].to_numpy(float)
        for half, inside in (("first_half", phi < 45.0), ("second_half", phi > 45.0)):
            v, p, _ = _peak(phi[inside], contact[inside])
            row[f"peak_contact_temp_{half}_C"] = v
            row[f"phi_peak_contact_temp_{half}_deg"] = p
        row["peak_peclet_pin"] = float(np.nanmax(table[f"{model}_peclet_pin"]))
        row["peak_peclet_wheel"] = float(np.nanmax(table[f"{model}_peclet_wheel"]))
        row["flash_rise_at_45deg_K"] = float(np.interp(45.0, phi, table[f"{model}_temp_flash_rise_K"]))
        energy = info["energy_per_index_J"][model]
        row["energy_per_index_J"] = energy
        row["mean_heat_rate_W"] = energy / case.period
        rows.append(row)
    return rows


#: the quantities of the speed-vs-torque comparison: (comparison column, description)
SPEED_TORQUE_METRICS = (
    ("peak_flash_rise_K", "peak flash rise (K)"),
    ("peak_contact_rise_K", "peak contact temperature rise over ambient (K)"),
    ("peak_contact_temp_C", "peak contact temperature (degC)"),
    ("mean_heat_rate_W", "mean heat rate over a crank turn (W)"),
    ("energy_per_index_J", "heat per index (J)"),
)


#: LC3 "heats more" than LC2 only if larger by more than this (relative): equal values stay equal under round-off
SAME_RELATIVE = 1e-9


def speed_vs_torque(comparison: pd.DataFrame) -> pd.DataFrame:
    """The seed's last conclusion tested: doubling the speed (LC3) against doubling the torque (LC2), per model
    and mu; ratios are ratios of the comparison table's values."""
    rows = []
    for model in MODELS:
        for mu in sorted(comparison["mu"].unique()):
            sub = comparison[(comparison["model"] == model) & (comparison["mu"] == mu)].set_index("load_case")
            if not {1, 2, 3} <= set(sub.index):
                continue
            for metric, text in SPEED_TORQUE_METRICS:
                v1, v2, v3 = (float(sub.loc[lc, metric]) for lc in (1, 2, 3))
                rows.append({"model": model, "mu": mu, "metric": metric, "description": text,
                             "lc1": v1, "lc2_double_torque": v2, "lc3_double_speed": v3,
                             "ratio_lc2_lc1": v2 / v1 if v1 else float("nan"),
                             "ratio_lc3_lc1": v3 / v1 if v1 else float("nan"),
                             "ratio_lc3_lc2": v3 / v2 if v2 else float("nan"),
                             "speed_heats_more": bool(v3 > v2 * (1 + SAME_RELATIVE))})
    return pd.DataFrame(rows)


def peak_location(comparison: pd.DataFrame) -> pd.DataFrame:
    """Where the peak contact temperature and flash rise occur, per case and model (the seed claims 10-15 and
    70-75 deg, crankpin)."""
    cols = ["case", "load_case", "mu", "model", "peak_contact_temp_C", "peak_contact_rise_K", "phi_peak_contact_temp_deg",
            "stroke_half_peak_contact_temp", "peak_flash_rise_K", "phi_peak_flash_rise_deg",
            "stroke_half_peak_flash_rise", "peak_contact_temp_first_half_C", "phi_peak_contact_temp_first_half_deg",
            "peak_contact_temp_second_half_C", "phi_peak_contact_temp_second_half_deg", "in_seed_window"]
    out = comparison.copy()
    p = out["phi_peak_contact_temp_deg"]
    out["in_seed_window"] = ((p >= 10) & (p <= 15)) | ((p >= 70) & (p <= 75))
    return out[cols]


# ------------------------------------------------------------------------------------------------ the report
@dataclass
class SeedReport:
    config: ReportConfig
    cases: list[Case]
    tables: dict[str, pd.DataFrame]
    comparison: pd.DataFrame
    speed_torque: pd.DataFrame
    peaks: pd.DataFrame
    notes: dict


def build(config: ReportConfig, say: Callable[[str], None] | None = None) -> SeedReport:
    """Evaluate the three models for the six cases and the comparison tables (no files)."""
    cases = [load_case(name) for name in CASES]
    tables, rows, notes = {}, [], {}
    for case in cases:
        table, info = case_table(case, config, say)
        tables[case.name] = table
        rows += comparison_rows(case, table, info)
        notes[case.name] = info
    comparison = pd.DataFrame(rows)
    return SeedReport(config, cases, tables, comparison, speed_vs_torque(comparison), peak_location(comparison),
                      notes)


def write(report: SeedReport, out_dir: Path, force: bool = False) -> Path:
    """CSV tables, figures and report.md into out_dir, atomically (a temporary sibling, then one rename)."""
    from mechsim.benchmarks.seed_report_plots import write_figures
    from mechsim.benchmarks.seed_report_text import markdown
    out_dir = Path(out_dir)
    with atomic_folder(out_dir, force) as tmp:
        for name, table in report.tables.items():
            table.to_csv(tmp / f"case_{name}.csv", index=False, float_format="%.12g")
        report.comparison.to_csv(tmp / "comparison.csv", index=False, float_format="%.12g")
        report.speed_torque.to_csv(tmp / "speed_vs_torque.csv", index=False, float_format="%.12g")
        report.peaks.to_csv(tmp / "peak_location.csv", index=False, float_format="%.12g")
        figures = write_figures(report, tmp)
        (tmp / "report.md").write_text(markdown(report, figures))
    return out_dir


def summary_lines(report: SeedReport) -> list[str]:
    """Short console summary: peak flash rise and contact temperature per case and model."""
    lines = []
    c = report.comparison
    for name in CASES:
        sub = c[c["case"] == name].set_index("model")
        parts = [f"{m} {sub.loc[m, 'peak_flash_rise_K']:.1f} K / {sub.loc[m, 'peak_contact_temp_C']:.1f} C"
                 for m in MODELS]
        lines.append(f"{name}: peak flash / contact: " + "; ".join(parts))
    return lines


def cli_main(out_dir: Path | None, small: bool, force: bool, say: Callable[[str], None] | None = None
             ) -> tuple[Path, list[str]]:
    """`mechsim report seed`: check the target, build, write; (folder, console lines)."""
    target = Path(out_dir) if out_dir is not None else Path("results") / ("report-seed-small" if small else "report-seed")
    check_replaceable(target, force)
    config = ReportConfig.make(small)
    if say:
        say(f"seed report: {config.describe()}")
    report = build(config, say)
    write(report, target, force)
    return target, summary_lines(report) + [f"-> {target}"]
