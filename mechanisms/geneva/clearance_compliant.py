"""External Geneva drive with slot clearance and a compliant pin-flank contact (Hunt-Crossley), finite impact forces.

The geometry and the gaps are the rigid clearance model's (`clearance.GenevaClearance`): Phi the pin centre's
offset from the slot's centre line, h = c_s/2, gaps g_drive = h - Phi and g_trail = h + Phi. No constraint holds
the pin in the slot: where the gap of flank f closes, the penetration delta = f Phi - h > 0 and its rate
delta' = f Phi' give the contact force (docs/theory.md §G2.1 'Compliant contact')

    F = K delta (1 + chi delta'),    chi = 3 (1 - e) / (2 v0)

(Hunt & Crossley 1975, ASME J. Appl. Mech. 42:440, the hysteresis damping of a Hertz-type law; v0 the approach
speed delta' at the contact's onset, floored at BOUNCE_SPEED), with a linear line-contact law of stiffness
K = E* l (E* the contact modulus of the thermal model's materials, l the wheel thickness; the same spring as the
impact flash estimate, thermal/impact.py) unless contact.stiffness gives K. Its generalized force is -f F grad Phi
(it opposes the penetration: power -F delta'); friction mu F acts along the slip as on the rigid model's flank.
Modes: free (the pin in the gap; the rigid model's free mode, its gap guards at the gap's zero itself), engaged
(in contact on flank f, the ODE with the force above), dwell (locked, as the rigid model). Events: entry, exit,
contact onset (a gap through 0, kind "impact"), the episode's first force maximum ("contact force peak", located:
dF/dt through 0), separation (delta through 0); the force law's kink at delta = 0 is an event, not smoothed.
Powers: the contact's elastic work -K delta delta' (minus its stored energy) and the hysteresis work
-K chi delta delta'^2 (the loss), so works - change of kinetic energy closes on every row with no impact term.
"""
from __future__ import annotations

from dataclasses import replace

import numpy as np
import pandas as pd

from mechsim.mechanisms.base import Guard, TransitionRule
from mechsim.mechanisms.geneva.clearance import GenevaClearance


class GenevaCompliant(GenevaClearance):
    """External Geneva with slot clearance and a Hunt-Crossley pin-flank contact; `Geneva.from_config` builds it
    where contact.model = "compliant"."""

    parameter_names = GenevaClearance.parameter_names + ("stiffness", "v_onset", "peaked")
    #: the gap guards fire at the gap's zero: the contact force's kink is located, not anticipated
    GAP_ARM = 0.0
    #: no restart onto a flank constraint (the contact is a spring): every formulation holds
    refused_formulations: dict = {}

    def __init__(self, geometry, crank_inertia, wheel_inertia, wheel_torque=0.0, friction=0.0, crank_damping=0.0,
                 wheel_damping=0.0, *, slot_clearance: float = 0.0, restitution: float = 0.0,
                 stiffness: float) -> None:
        super().__init__(geometry, crank_inertia, wheel_inertia, wheel_torque, friction, crank_damping,
                         wheel_damping, slot_clearance=slot_clearance, restitution=restitution)
        if not (np.isfinite(stiffness) and stiffness > 0):
            raise ValueError(f"contact.stiffness: must be positive and finite, got {stiffness!r}")
        self.stiffness = float(stiffness)

    def structure_key(self) -> tuple:
        return super().structure_key() + ("compliant",)

    def parameter_values(self) -> dict[str, float]:
        return dict(super().parameter_values(), stiffness=self.stiffness, v_onset=self.BOUNCE_SPEED, peaked=0.0)

    def describe(self) -> dict:
        return dict(super().describe(), contact_model="compliant (Hunt-Crossley)", contact_stiffness_N_m=self.stiffness)

    def initial_state(self, angle: float, speed: float):
        """The exact-fit model's start; a start within an engagement is in the gap (the pin on the slot's centre
        line, both gaps open), where no contact force acts."""
        init = super().initial_state(angle, speed)
        if init.mode != "engaged":
            return init
        return replace(init, mode="free")

    # -- the contact law ------------------------------------------------------------------------------------
    def _law(self, phi, rate, flank, p):
        """(delta, delta', F) of the contact on `flank` (module docstring): phi the offset, rate its time rate."""
        delta = flank * phi - p["clearance"] / 2
        ddot = flank * rate
        chi = 1.5 * (1 - p["restitution"]) / p["v_onset"]
        return delta, ddot, p["stiffness"] * delta * (1 + chi * ddot)

    def modes(self):
        import sympy as sp
        base = super().modes()
        s, P = self.symbols, self.symbols.p
        theta, psi = s.q
        w1, w2 = s.v
        flank, slide = P("flank"), P("slide")
        g = self.geometry
        k = P("slot")
        alpha, beta = theta - 2 * sp.pi * k, psi - k * P("pitch")
        phi = g.pin_in_slot(P("r"), P("c"), alpha, beta, sp)[0]
        rate = sp.diff(phi, theta) * w1 + sp.diff(phi, psi) * w2
        params = {n: P(n) for n in ("clearance", "restitution", "v_onset", "stiffness")}
        delta, ddot, F = self._law(phi, rate, flank, params)
        elastic = P("stiffness") * delta
        eng = base["engaged"]
        lam = s.lam[0]
        on = {lam: flank * F}                             # the rigid flank's multiplier is the signed force f F
        guards = {gd.name: gd for gd in eng.guards}
        fdot = sum(sp.diff(F, q) * v for q, v in zip(s.q, s.v)) + sum(sp.diff(F, v) * a for v, a in zip(s.v, s.a))
        # the friction force of the rigid flank (its generalized force reads lam): the first two entries of eng.force
        # carry damping, friction and the load; the contact adds -f F grad Phi
        force = tuple(sp.sympify(Q).subs(on) - flank * F * sp.diff(phi, q) for Q, q in zip(eng.force, s.q))
        zero = sp.Integer(0)
        engaged = replace(
            eng, constraints=(), force=force,
            guards=(guards["exit"], Guard("separation", delta, -1),
                    # the episode's first force maximum; after it (peaked = 1) the guard is -1 and never fires
                    Guard("force_peak", (1 - P("peaked")) * fdot - P("peaked"), -1),
                    guards["slip_reversal"], guards["stall"], guards["rest"]),
            powers=dict({n: sp.sympify(e).subs(on) for n, e in eng.powers.items()},
                        elastic=-elastic * ddot, hysteresis=-(F - elastic) * ddot),
            readouts={n: sp.sympify(e).subs(on) for n, e in eng.readouts.items()},
            heat={n: sp.sympify(e).subs(on) for n, e in eng.heat.items()})
        free = replace(base["free"], powers=dict(base["free"].powers, elastic=zero, hysteresis=zero))
        dwell = replace(base["dwell"], powers=dict(base["dwell"].powers, elastic=zero, hysteresis=zero))
        return {"engaged": engaged, "dwell": dwell, "free": free}

    # -- transitions -----------------------------------------------------------------------------------------
    def transitions(self):
        """The rigid clearance model's table (entry, exit, apex, stall, rest, slip reversal) with the impacts
        replaced by the contact's onset on either flank, its force peak and its separation."""
        table = super().transitions()
        for guard, f in (("close_driving", 1.0), ("close_trailing", -1.0)):
            table[("free", guard)] = TransitionRule(
                "engaged", lambda q, v, p, xp, f=f: self._onset(q, v, p, xp, f), kind="impact",
                record=lambda q, v, p, f=f: self._reading(q, v, p, f, onset=True))
        table[("engaged", "separation")] = TransitionRule(
            "free", kind="separation", record=lambda q, v, p: self._reading(q, v, p, p["flank"]))
        # an episode the pin's exit ends: its readings there close the episode's loss
        table[("engaged", "exit")] = replace(table[("engaged", "exit")],
                                             record=lambda q, v, p: self._reading(q, v, p, p["flank"]))
        table[("engaged", "force_peak")] = TransitionRule(
            "engaged", lambda q, v, p, xp: {"peaked": 1.0}, kind="contact force peak",
            record=lambda q, v, p: self._reading(q, v, p, p["flank"]))
        return table

    def _onset(self, q, v, p, xp, f):
        """Flank f, the approach speed delta' (floored at BOUNCE_SPEED) that sets the damping, friction along the
        slip there, the force peak not yet passed."""
        rate = self._normal(q, v, p, xp, f)[1]
        g = self.geometry
        alpha, beta = self._local(q, p)
        phi, _, s_ab, _ = g.pin_in_slot(p["r"], p["c"], alpha, beta, xp)
        u = v[0] * s_ab + v[1] * f * p["clearance"] / 2 + f * p["R"] * (v[1] - g.crank_sense * v[0])
        return {"flank": f, "v_onset": xp.maximum(f * rate, p["bounce_speed"]), "peaked": 0.0,
                "slide": xp.where(u >= 0, 1.0, -1.0)}

    def _reading(self, q, v, p, f, onset=False):
        """The events row's readings (numpy): the flank, delta, delta', the signed contact force, the speeds; at the
        onset the approach speed and the effective mass (G M^-1 G^T)^-1 of the flank's normal (the crank held where
        its speed is prescribed), which the impact's flash estimate reads (thermal/impact.py)."""
        (g1, g2), rate = self._normal(q, v, p, np, f)
        alpha, beta = self._local(q, p)
        phi = self.geometry.pin_in_slot(p["r"], p["c"], alpha, beta, np)[0]
        pp = dict(p, v_onset=max(f * rate, p["bounce_speed"])) if onset else p
        delta, ddot, F = self._law(phi, rate, f, pp)
        out = {"flank_side": f, "penetration_m": delta, "penetration_rate_m_s": ddot,
               "contact_force_N": f * (0.0 if onset else F),
               "crank_speed_rad_s": v[0], "wheel_speed_rad_s": v[1]}
        if onset:
            crank = 0.0 if p["drive_speed"] != 0 else g1 * g1 / p["J1"]
            out.update(approach_speed_m_s=ddot, impact_mass_kg=1.0 / (crank + g2 * g2 / p["J2"]))
        return out

    # -- outputs ---------------------------------------------------------------------------------------------
    def completed_events(self, events, table):
        """Each contact episode's heat (its hysteresis work, from the work states recorded at its onset and end, the
        table's last row for an episode the run's end closes) on its onset row, `heat_J`: the contact's heat of the
        impact (thermal/plan.py). The rows' energy_lost_J stays 0: the loss is the hysteresis work column."""
        if events is None or not len(events) or "work_hysteresis_J" not in events:
            return events
        episodes = contact_episodes(events, table)
        heat = np.full(len(events), np.nan)
        heat[episodes["row"].to_numpy(int)] = episodes["energy_lost_J"].to_numpy(float)
        return events.assign(heat_J=heat)

    def extra_outputs(self, timeseries, events) -> dict:
        """impacts.csv: one row per contact episode (`contact_episodes`)."""
        return {"impacts": contact_episodes(events, timeseries).drop(columns="row")}

    def extra_figures(self, timeseries, tables: dict) -> dict:
        """clearance_vs_angle: the pin's offset in its slot and the episodes' peak forces over a crank turn."""
        from mechsim.mechanisms.geneva.clearance_plots import gap_figure
        impacts = tables.get("impacts")
        return {"clearance_vs_angle": gap_figure(timeseries, impacts if impacts is not None else contact_episodes(
            None).drop(columns="row"), self.slot_clearance, force=True)}

    def extra_summary(self, tables: dict) -> dict:
        """summary['impacts']: the rigid model's figures of the episodes (`impacts.impacts_summary`) and
        the largest located force peak with its instant."""
        from mechsim.mechanisms.geneva.impacts import impacts_summary
        impacts = tables.get("impacts")
        # an episode the exit or the run's end closes has no rebound speed, so no impulse: 0 for the largest's search
        out = impacts_summary(None if impacts is None else impacts.fillna({"impulse_N_s": 0.0}))
        if impacts is not None and len(impacts) and np.isfinite(impacts["peak_force_N"]).any():
            k = int(np.nanargmax(impacts["peak_force_N"].to_numpy(float)))
            out.update(peak_force_N=float(impacts["peak_force_N"].iloc[k]),
                       peak_force_at_t_s=float(impacts["peak_force_at_t_s"].iloc[k]),
                       duration_at_peak_force_s=float(impacts["duration_s"].iloc[k]))
        return {"impacts": out}


EPISODE_COLUMNS = ["t_s", "turn", "crank_angle_deg", "flank", "approach_speed_m_s", "separation_speed_m_s",
                   "peak_force_N", "peak_force_at_t_s", "duration_s", "impulse_N_s", "energy_lost_J", "rebound",
                   "impacts_in_turn", "row"]


def contact_episodes(events: pd.DataFrame, table=None) -> pd.DataFrame:
    """One row per contact episode of the compliant model, from its events (onset "impact", "contact force peak",
    "separation" or the exit that ends it): onset time, crank turn and angle, flank, approach and separation speeds
    (normal, m/s), the first force maximum (located: its event) and its instant, duration, the impulse
    m (v_in + v_out) of the normal's effective mass m at the onset (signed as the force; the rigid law's impulse it
    tends to as K grows), energy lost (the hysteresis work between the onset and the end: the table's last row
    where the run ends in contact, its duration then not known), whether the pin left the flank (rebound), the
    episodes in the crank turn; `row` the onset's row in `events`."""
    from mechsim.mechanisms.geneva.impacts import local_angle_deg
    if events is None or not len(events) or "work_hysteresis_J" not in events:
        return pd.DataFrame(columns=EPISODE_COLUMNS)
    ev = events.reset_index(drop=True)
    rows = []
    current = None
    for i, e in enumerate(ev.itertuples(index=False)):
        if e.kind == "impact":
            current = dict(row=i, t_s=e.t_s, theta=e.crank_q, flank=e.flank_side, v_in=e.approach_speed_m_s,
                           mass=e.impact_mass_kg, w0=e.work_hysteresis_J, peak=np.nan, peak_t=np.nan)
        elif current is None:
            continue
        elif e.kind == "contact force peak":
            current.update(peak=abs(e.contact_force_N), peak_t=e.t_s)
        elif e.from_mode == "engaged" and e.to_mode != "engaged":
            end = e.work_hysteresis_J
            v_out = -e.penetration_rate_m_s if e.kind == "separation" else np.nan
            rows.append(dict(current, t_end=e.t_s, v_out=v_out, w1=end, rebound=e.kind == "separation"))
            current = None
    if current is not None:                                    # in contact when the run ended
        last = np.nan
        if table is not None and len(table) and "work_hysteresis_J" in table:
            last = float(np.asarray(table["work_hysteresis_J"], dtype=float)[-1])
        rows.append(dict(current, t_end=np.nan, v_out=np.nan, w1=last, rebound=False))
    if not rows:
        return pd.DataFrame(columns=EPISODE_COLUMNS)
    r = pd.DataFrame(rows)
    theta = r["theta"].to_numpy(float)
    out = pd.DataFrame({
        "t_s": r["t_s"].to_numpy(float),
        "turn": np.floor((theta + np.pi) / (2 * np.pi)).astype(int),
        "crank_angle_deg": local_angle_deg(theta),
        "flank": np.where(r["flank"].to_numpy(float) > 0, "driving", "trailing"),
        "approach_speed_m_s": r["v_in"].to_numpy(float),
        "separation_speed_m_s": r["v_out"].to_numpy(float),
        "peak_force_N": r["peak"].to_numpy(float),
        "peak_force_at_t_s": r["peak_t"].to_numpy(float),
        "duration_s": (r["t_end"] - r["t_s"]).to_numpy(float),
        "impulse_N_s": (r["flank"] * r["mass"] * (r["v_in"] + r["v_out"])).to_numpy(float),
        "energy_lost_J": (r["w0"] - r["w1"]).to_numpy(float),
        "rebound": r["rebound"].to_numpy(bool),
    })
    out["impacts_in_turn"] = out.groupby("turn")["t_s"].transform("size")
    out["row"] = r["row"].to_numpy(int)
    return out
