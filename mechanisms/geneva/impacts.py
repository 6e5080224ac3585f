"""The clearance model's impact tables and their summaries: one row per pin-flank impact and per impact on the
locking play (docs/geneva.md 'Clearance and impacts'). Apart from the figures drawn of them (clearance_plots.py), so
that a run without figures does not import matplotlib."""
from __future__ import annotations

import numpy as np
import pandas as pd


def local_angle_deg(theta):
    """The crank angle within its turn, degrees, 0 at mid-engagement (`Geneva.drive_cycle`)."""
    theta = np.asarray(theta, dtype=float)
    return np.degrees(theta - 2 * np.pi * np.floor((theta + np.pi) / (2 * np.pi)))


def impacts_table(events: pd.DataFrame) -> pd.DataFrame:
    """One row per pin-flank impact: time, crank turn and angle within it, flank struck, impulse, energy lost,
    and whether the pin rebounded; `impacts_in_turn` counts the impacts of the same crank turn; the approach speed
    and, with a thermal model, the impact's flash estimate (docs/theory.md §G2.2)."""
    cols = ["t_s", "turn", "crank_angle_deg", "flank", "impulse_N_s", "energy_lost_J", "rebound"]
    if events is None or not len(events) or "impulse_N_s" not in events:
        return pd.DataFrame(columns=cols + ["impacts_in_turn"])
    # the events' columns as arrays, the impacts' rows taken from them (a frame's boolean selection and groupby
    # cost more than the table)
    kind = events["kind"].to_numpy(dtype=str)
    at = np.flatnonzero(np.char.startswith(kind, "impact"))
    kind = kind[at]
    theta = events["crank_q"].to_numpy(float)[at]
    turn = np.floor((theta + np.pi) / (2 * np.pi)).astype(int)
    _, of_turn, per_turn = np.unique(turn, return_inverse=True, return_counts=True)
    out = pd.DataFrame({
        "t_s": events["t_s"].to_numpy(float)[at],
        "turn": turn,
        "crank_angle_deg": local_angle_deg(theta),
        "flank": np.where(events["guard"].to_numpy(dtype=str)[at] == "close_driving", "driving", "trailing"),
        "impulse_N_s": events["impulse_N_s"].to_numpy(float)[at],
        "energy_lost_J": events["energy_lost_J"].to_numpy(float)[at],
        "rebound": (kind == "impact") & (events["to_mode"].to_numpy(dtype=str)[at] == "free"),
        "impacts_in_turn": per_turn[of_turn].astype(np.int64),
    })
    for extra in ("approach_speed_m_s", "impact_flash_rise_K"):      # the latter with a thermal model
        if extra in events:
            out[extra] = events[extra].to_numpy(float)[at]
    return out


def impacts_summary(impacts: pd.DataFrame) -> dict:
    """The run's impacts in figures (summary['impacts']; sweep tables): count, the largest impulse |P| (an impact is
    a located event, so this is the located peak) with its instant and crank angle, the impacts per crank turn
    (largest and mean over the turns that have any) and their energy lost; with a thermal model the largest
    flash estimate."""
    if impacts is None or not len(impacts):
        return {"count": 0, "peak_impulse_N_s": 0.0, "impacts_per_turn_max": 0, "impacts_per_turn_mean": 0.0,
                "energy_lost_J": 0.0}
    k = int(np.argmax(np.abs(impacts["impulse_N_s"].to_numpy(float))))
    per_turn = impacts.groupby("turn").size()
    out = {"count": int(len(impacts)), "peak_impulse_N_s": float(abs(impacts["impulse_N_s"].iloc[k])),
           "peak_impulse_at_t_s": float(impacts["t_s"].iloc[k]),
           "peak_impulse_at_crank_angle_deg": float(impacts["crank_angle_deg"].iloc[k]),
           "peak_impulse_flank": str(impacts["flank"].iloc[k]),
           "impacts_per_turn_max": int(per_turn.max()), "impacts_per_turn_mean": float(per_turn.mean()),
           "energy_lost_J": float(impacts["energy_lost_J"].sum())}
    if "impact_flash_rise_K" in impacts:
        out["impact_flash_rise_max_K"] = float(impacts["impact_flash_rise_K"].max())
    return out


def lock_impacts_table(events: pd.DataFrame, pitch: float) -> pd.DataFrame:
    """One row per impact of the wheel on an end of its locking play (the lock impacts in the dwell and the exit's
    plastic lock impact where the lock takes the wheel): time, crank turn and angle, the end struck (leading:
    the wheel ahead of its nominal dwell angle; at exit the side of the lock angle (turn + 1/2) pitch the wheel is
    on), impulse (at the crank radius, the lock constraint's), energy lost."""
    cols = ["t_s", "turn", "crank_angle_deg", "end", "impulse_N_s", "energy_lost_J", "rebound"]
    if events is None or not len(events) or "impulse_N_s" not in events:
        return pd.DataFrame(columns=cols)
    kind = events["kind"].astype(str)
    ev = events[kind.str.startswith("lock impact") | ((kind == "exit") & events["impulse_N_s"].notna())]
    theta = ev["crank_q"].to_numpy(float)
    turn = np.floor((theta + np.pi) / (2 * np.pi))
    lead = np.where(ev["kind"] == "exit", ev["wheel_q"].to_numpy(float) >= (turn + 0.5) * pitch,
                    ev["guard"] == "lock_lead")
    return pd.DataFrame({
        "t_s": ev["t_s"].to_numpy(float), "turn": turn.astype(int),
        "crank_angle_deg": local_angle_deg(theta), "end": np.where(lead, "leading", "trailing"),
        "impulse_N_s": ev["impulse_N_s"].to_numpy(float), "energy_lost_J": ev["energy_lost_J"].to_numpy(float),
        "rebound": ((ev["kind"] == "lock impact") & (ev["to_mode"] == "play")).to_numpy()})


def lock_impacts_summary(table: pd.DataFrame) -> dict:
    """summary['lock_impacts']: count, the largest impulse |P| and the energy lost at the locking arc (a contact
    apart from the pin's: not in the pin contact's heat, docs/theory.md §G2.2)."""
    if table is None or not len(table):
        return {"count": 0, "peak_impulse_N_s": 0.0, "energy_lost_J": 0.0}
    return {"count": int(len(table)), "peak_impulse_N_s": float(table["impulse_N_s"].abs().max()),
            "energy_lost_J": float(table["energy_lost_J"].sum())}
