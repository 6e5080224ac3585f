"""The Geneva's pin-slot contact as the thermal model sees it (`Mechanism.contact_geometry`, `contact_state`,
`contact_starts`): the pin (on the crank, the driver body) slides along the driving wall of a slot (on the
wheel, the driven body); each slot wall is one track."""
from __future__ import annotations

import numpy as np

from mechsim.mechanisms.base import ContactGeometry
from mechsim.mechanisms.geneva.kinematics import GenevaGeometry


def geometry(g: GenevaGeometry) -> ContactGeometry:
    """Pin radius and wheel thickness make the line contact; the wall track spans the pin distances of one
    engagement (entry to the deepest point); one contact lasts 2 alpha0 of crank angle (docs/theory.md §G1)."""
    return ContactGeometry(contact_radius=g.pin_radius, contact_length=g.thickness, driver_arm=g.crank_radius,
                           tracks=g.slots, track_length=abs(g.entry_pin_distance - g.deepest_pin_distance),
                           driven_radius=g.wheel_radius, contact_angle=2 * g.engagement_half_angle)


def _engaged(mode) -> np.ndarray:
    """Whether each row's mode is 'engaged', compared by the column's own `==` where it is an array or a pandas
    column (pandas' string column through pyarrow: an hour's 2.2 million rows as Python strings take ten times as
    long; a pandas Series by its array's `==`, at half the Series' own cost), any other sequence as a numpy array."""
    values = getattr(mode, "array", mode)
    return np.asarray((values if hasattr(values, "dtype") else np.asarray(values)) == "engaged", dtype=bool)


def state(g: GenevaGeometry, table) -> dict[str, np.ndarray]:
    """Contact quantities of each output row, equal to the engaged mode's `heat` expressions (model.py):
    normal force, slip, source speeds over the pin R w_rel (w_rel = w2 - crank_sense w1, the wheel's turning
    against the pin; w1 + w2 external) and over the wall v_s, heat rate (friction power), track (slot counter
    floor((theta + pi)/2 pi)), and the wall's sliding acceleration a_s = dv_s/dt = (w1' v_s + w1 w_rel w2 x)/w1
    (from the normal force's arm x G = x w2/w1, `GenevaGeometry.pin_in_slot`; docs/theory.md §G1).
    table: result columns, or the closed form's `closed_form_heat` (a boolean `engaged` in place of `mode`)."""
    def col(name):
        return np.asarray(table[name], dtype=float)

    w1, w2, v_s = col("crank_speed_rad_s"), col("wheel_speed_rad_s"), col("pin_sliding_speed_m_s")
    w_rel = w2 - g.crank_sense * w1
    engaged = table["engaged"] if "engaged" in table else _engaged(table["mode"])
    with np.errstate(divide="ignore", invalid="ignore"):
        a_s = (col("crank_accel_rad_s2") * v_s + w1 * w_rel * w2 * col("pin_distance_m")) / w1
    return {
        "normal_force": col("contact_force_N"),
        "slip_speed": col("slip_speed_m_s"),
        "source_speed_driver": np.where(engaged, g.pin_radius * w_rel, 0.0),
        "source_speed_driven": v_s,
        "heat_rate": col("friction_power_W"),
        "track": np.floor((col("crank_angle_rad") + np.pi) / (2 * np.pi)),
        "sliding_accel": np.where(engaged, np.nan_to_num(a_s), 0.0),
        "engaged": engaged,
    }


def starts(g: GenevaGeometry, df, events) -> np.ndarray:
    """Times at which a contact began (entry, flank switch): from the events table where it lists them, else
    from the crank angles of entry theta = 2 pi k - alpha0 and the sign changes of the normal force (a closed
    form lists entries but no flank switches). A run that starts engaged gets the entry before t0 from its crank angle.
    df: the table or its columns (dynamics/tables.py TableColumns)."""
    a0 = g.engagement_half_angle
    t = np.asarray(df["t_s"], dtype=float)
    theta = np.asarray(df["crank_angle_rad"], dtype=float)
    w1 = np.asarray(df["crank_speed_rad_s"], dtype=float)
    mode = df["mode"]
    found: list[float] = []
    kinds = (np.array([str(k) for k in events["kind"].tolist()], dtype=object) if len(events) and "kind" in events
             else np.array([], str))
    times = events["t_s"].to_numpy(float) if len(kinds) else np.array([])
    found += times[np.isin(kinds, ["entry", "flank switch"])].tolist()
    if "entry" not in kinds:
        k = np.arange(np.floor((theta[0] + np.pi) / (2 * np.pi)) - 1, np.floor((theta[-1] + np.pi) / (2 * np.pi)) + 2)
        entries = 2 * np.pi * k - a0
        inside = (entries >= theta[0]) & (entries <= theta[-1])
        found += np.interp(entries[inside], theta, t).tolist()
    if "flank switch" not in kinds:     # a closed form lists no flank switches: the normal force changes sign
        N = np.asarray(df["contact_force_N"], dtype=float)
        engaged = _engaged(mode)
        flip = np.flatnonzero(engaged[1:] & engaged[:-1] & (np.sign(N[1:]) * np.sign(N[:-1]) < 0))
        found += [t[i] - N[i] * (t[i + 1] - t[i]) / (N[i + 1] - N[i]) for i in flip]
    if len(t) and (mode.iloc[0] if hasattr(mode, "iloc") else mode[0]) == "engaged" and w1[0] > 0:
        alpha = theta[0] - 2 * np.pi * np.floor((theta[0] + np.pi) / (2 * np.pi))
        found.append(t[0] - (alpha + a0) / w1[0])
    return np.sort(np.unique(np.asarray(found, dtype=float)))
