"""External Geneva drive with slot clearance: the pin (radius R) in a slot of width 2R + c_s, rigid impacts.

The slot's centre-line offset of the pin centre, Phi(alpha, beta) (`GenevaGeometry.pin_in_slot`, docs/theory.md
§G1), is positive towards the driving flank (the wall ahead of the pin in the wheel's indexing sense). The gaps of
the two flanks are
    g_drive = c_s/2 - Phi,    g_trail = c_s/2 + Phi.
Modes (docs/geneva.md 'Clearance and impacts'):
  engaged (flank f = +1 driving, -1 trailing): Phi - f c_s/2 = 0, normal force N = lam (f N > 0 compressive);
      friction as in the exact-fit model, with the pin centre's sliding speed along the slot
      v_s = theta' r sin(alpha + beta) + psi' Phi (the wheel frame turning at the offset Phi);
  free: no constraint; the wheel turns under its own inertia, load and damping, the crank under its drive;
  dwell: as in the exact-fit model, the wheel held at its nominal lock angle; with lock play delta
      (lock_clearance > 0) held on an end s of its play, r (psi - psi_lock - s delta/2) = 0, under the load;
  play (lock_clearance > 0 only): the wheel free within psi_lock +- delta/2, as in free flight.
Transitions: entry (dwell -> free: the locked wheel meets the pin on the slot's centre line, both gaps c_s/2
open); gap closure on either flank (free -> engaged, a Newton impact with restitution e on the flank's normal
relative velocity, in the kinetic-energy metric; the pin rebounds into the gap unless the rebound speed e v_n is
below BOUNCE_SPEED, where it stays on the flank, a plastic impact); separation (f N falls through 0: engaged ->
free); exit (the pin leaves the slot: the locking arc takes the wheel at its nominal dwell angle, a plastic lock
impact that also removes the wheel's small lag behind it, at most asin(c_s / (2 x_exit)); docs/geneva.md).
With lock play: entry with the wheel where the play left it (the gaps c_s/2 +- x_e sin d); the ends of the play
struck with the same Newton law on the lock constraint; exit into the play, or onto its nearer end with a plastic
lock impact where the pin holds the wheel outside it (docs/theory.md §G2.1 'Lock play').
The impact is frictionless (Newton's law along the normal only). Theory and sources: docs/theory.md §G2.1.
"""
from __future__ import annotations

from dataclasses import replace

import numpy as np

from mechsim.mechanisms.base import Guard, Mode, TransitionRule
from mechsim.mechanisms.geneva.model import Geneva


class GenevaClearance(Geneva):
    """External Geneva with slot clearance c_s > 0 and rigid (Newton) impacts; `Geneva.from_config` builds it
    where `mechanism.slot_clearance` > 0."""

    parameter_names = Geneva.parameter_names + ("clearance", "restitution", "bounce_speed")
    #: a rebound slower than this (normal relative speed after the impact, m/s) is taken as a plastic impact, the
    #: pin staying on the flank: without it a rebounding pin under a closing force strikes infinitely often in a
    #: finite time (Zeno); the same device as Project Chrono's minimum bounce speed (ChSystemNSC SetMinBounceSpeed)
    BOUNCE_SPEED = 1e-3
    peak_columns = Geneva.peak_columns + ("gap_m",)
    #: the contact has impacts: their energy lost is heat of the contact (thermal/plan.py, docs/theory.md §G2.2)
    impacts = True
    #: the fraction of the clearance at which a closing gap fires its impact (see `modes`)
    GAP_ARM = 1e-9
    #: formulations refused at load (solver.formulation, IDA), with the reason: the index-3 Newton matrix fails at a
    #: restart onto a nonlinear constraint at working tolerances (docs/stability.md), and a plastic impact is one
    refused_formulations = {"index3": (
        "cannot hold the rigid pin-flank impacts: IDA's index-3 Newton matrix, conditioned like h^-3, fails at the "
        "first restart onto a flank (docs/geneva.md 'Clearance and impacts'); use 'index2' or 'index1'")}
    #: the traced values include the clearance and the restitution (docs/sensitivity.md, "Impacts")
    sensitivity_map = "mechsim.mechanisms.geneva.sensitivity:CLEARANCE_MAP"

    def __init__(self, geometry, crank_inertia, wheel_inertia, wheel_torque=0.0, friction=0.0, crank_damping=0.0,
                 wheel_damping=0.0, *, slot_clearance: float = 0.0, restitution: float = 0.0,
                 lock_clearance: float = 0.0) -> None:
        super().__init__(geometry, crank_inertia, wheel_inertia, wheel_torque, friction, crank_damping,
                         wheel_damping)
        if not (np.isfinite(slot_clearance) and slot_clearance > 0):
            raise ValueError(f"mechanism.slot_clearance: must be positive here, got {slot_clearance!r}")
        if not 0.0 <= restitution <= 1.0:
            raise ValueError(f"contact.restitution: must lie in [0, 1], got {restitution!r}")
        self.slot_clearance = float(slot_clearance)
        self.restitution = float(restitution)
        self.lock_clearance = self._checked_lock_play(lock_clearance)
        if self.lock_clearance > 0:
            self.parameter_names = GenevaClearance.parameter_names + ("lock_play", "lock_end")

    def structure_key(self) -> tuple:
        return super().structure_key() + ("clearance",) + (("lock play",) if self.lock_clearance > 0 else ())

    def parameter_values(self) -> dict[str, float]:
        values = dict(super().parameter_values(), clearance=self.slot_clearance, restitution=self.restitution,
                      bounce_speed=self.BOUNCE_SPEED)
        if self.lock_clearance > 0:
            values.update(lock_play=self.lock_clearance, lock_end=-1.0)
        return values

    def closed_form(self, t, angle0, speed):
        """None: with clearance the motion at a prescribed crank speed is integrated (impacts, free flight)."""
        return None

    def describe(self) -> dict:
        out = dict(super().describe(), slot_clearance_m=self.slot_clearance, restitution=self.restitution)
        if self.lock_clearance > 0:
            out["lock_clearance_rad"] = self.lock_clearance
        return out

    def extra_outputs(self, timeseries, events) -> dict:
        """impacts.csv: one row per pin-flank impact (`impacts.impacts_table`)."""
        from mechsim.mechanisms.geneva.impacts import impacts_table, lock_impacts_table
        out = {"impacts": impacts_table(events)}
        if self.lock_clearance > 0:
            out["lock_impacts"] = lock_impacts_table(events, self.geometry.pitch)
        return out

    def extra_summary(self, tables: dict) -> dict:
        """summary['impacts'] from the impacts table (`impacts.impacts_summary`)."""
        from mechsim.mechanisms.geneva.impacts import impacts_summary, lock_impacts_summary
        out = {"impacts": impacts_summary(tables.get("impacts"))}
        if self.lock_clearance > 0:
            out["lock_impacts"] = lock_impacts_summary(tables.get("lock_impacts"))
        return out

    def extra_figures(self, timeseries, tables: dict) -> dict:
        """clearance_vs_angle: the pin's offset in its slot and the impacts over a crank turn; with lock play
        lock_play_vs_angle: the wheel in its play and the lock impacts over the dwell."""
        from mechsim.mechanisms.geneva.clearance_plots import gap_figure
        from mechsim.mechanisms.geneva.impacts import impacts_table
        impacts = tables.get("impacts")
        out = {"clearance_vs_angle": gap_figure(timeseries, impacts if impacts is not None else impacts_table(None),
                                                self.slot_clearance)}
        if self.lock_clearance > 0:
            from mechsim.mechanisms.geneva.clearance_plots import lock_figure
            from mechsim.mechanisms.geneva.impacts import lock_impacts_table
            lock = tables.get("lock_impacts")
            out["lock_play_vs_angle"] = lock_figure(
                timeseries, lock if lock is not None else lock_impacts_table(None, self.geometry.pitch),
                self.lock_clearance, self.geometry.pitch, self.geometry.engagement_half_angle)
        return out

    def contact_starts(self, table, events) -> np.ndarray:
        """Times at which the pin came to rest on a flank (a plastic impact into the engaged mode): where the
        sliding contact, and its heat source, begins (`Mechanism.contact_starts`)."""
        if events is None or not len(events):
            return np.array([])
        on = (events["to_mode"] == "engaged") & (events["from_mode"] == "free")
        return np.sort(events.loc[on, "t_s"].to_numpy(float))

    # -- symbolic model ---------------------------------------------------------------------------------
    def modes(self) -> dict[str, Mode]:
        import sympy as sp
        base = super().modes()
        s, P = self.symbols, self.symbols.p
        theta, psi = s.q
        w1, w2 = s.v
        r, c, R, mu, half = P("r"), P("c"), P("R"), P("mu"), P("clearance") / 2
        k, flank, slide = P("slot"), P("flank"), P("slide")
        c1, c2 = P("c1"), P("c2")
        T_L = P("T_L") + P("T_L_rate") * (s.t - P("T_L_time0"))     # as the exact-fit model's (constant here)
        g = self.geometry
        alpha, beta = theta - 2 * sp.pi * k, psi - k * P("pitch")
        phi, x, s_slide, _ = g.pin_in_slot(r, c, alpha, beta, sp)
        lam = s.lam[0]
        arm = self.GAP_ARM * P("clearance")

        # engaged on flank f: the constraint moved to the flank, the sliding speed with the frame term psi' Phi
        v_s = w1 * s_slide + w2 * flank * half
        u = v_s + flank * R * (w2 - g.crank_sense * w1)
        fric_mag = mu * flank * lam
        fric_force = [-fric_mag * slide * sp.diff(u, vi) for vi in (w1, w2)]
        eng = base["engaged"]
        guards = {gd.name: gd for gd in eng.guards}
        engaged = replace(
            eng, constraints=(phi - flank * half,),
            force=(-c1 * w1 + fric_force[0], -c2 * w2 + fric_force[1] - T_L),
            guards=(guards["exit"], Guard("separation", flank * lam, -1), Guard("slip_reversal", slide * u, -1),
                    guards["stall"], guards["rest"]),
            powers=dict(eng.powers, friction=-fric_mag * slide * u),
            readouts=dict(eng.readouts, friction_force_N=fric_mag * slide, slip_speed_m_s=u, pin_sliding_speed_m_s=v_s,
                          friction_power_W=fric_mag * slide * u, pin_offset_m=phi, gap_m=half - flank * phi),
            heat=dict(eng.heat, slip_speed=u, source_speed_driven=v_s, heat_rate=fric_mag * slide * u))
        dwell = base["dwell"]
        dwell = replace(dwell, readouts=dict(dwell.readouts, pin_offset_m=sp.Integer(0), gap_m=half))
        zero = sp.Integer(0)
        free = Mode(
            name="free", constraints=(), force=(-c1 * w1, -c2 * w2 - T_L),
            # the gap guards fire GAP_ARM of the clearance before contact: a free flight that starts on a flank (a
            # separation, a rebound) starts below it, so round-off in the gap there cannot close it again at once
            # the apex of a flight from flank f (its gap's rate -f Phi' falls through 0) ends the flight's rising part:
            # the gap then falls monotonically to its closure, which a step cannot cross unseen, while a short
            # rebound's whole rise and fall within one step leaves the gap guard negative at both ends
            guards=(guards["exit"], Guard("close_driving", half - phi - arm, -1),
                    Guard("close_trailing", half + phi - arm, -1),
                    Guard("apex", self._apex_guard(half - flank * phi, -flank * (sp.diff(phi, theta) * w1
                                                                                  + sp.diff(phi, psi) * w2),
                                                   arm, P("bounce_speed")), -1),
                    guards["stall"], guards["rest"]),
            powers={"load": -T_L * w2, "friction": zero, "damping": -c1 * w1**2 - c2 * w2**2},
            readouts=dict(dwell.readouts, pin_distance_m=x, lock_force_N=zero, pin_offset_m=phi,
                          gap_m=half - sp.Abs(phi)),
            heat=dwell.heat)
        modes = {"engaged": engaged, "dwell": dwell, "free": free}
        if self.lock_clearance > 0:
            modes.update(self._play_modes(dwell, free))
        return modes

    def _apex_guard(self, gap, rate, arm, speed):
        """The flight apex guard: the watched gap's rate, armed only once the gap has opened past `arm` (the rate
        itself where the gap guards fire at the gap's zero, GAP_ARM = 0).

        A flight that leaves a flank without a rebound starts with the gap and its rate both zero: after a
        separation (the normal force falling through zero) the rate has a double zero there (g' ~ g''' t^2 / 2),
        after a plastic impact that slides off a simple one, so its sign at the start is round-off and a root
        found there is no apex. Within the arm of the flank (|gap| < arm, where the gap guards cannot see a
        closure either) the guard is held up by `speed` (the bounce speed) times (1 - |gap|/arm); outside it the
        guard is the rate itself, so an apex is located exactly where it was, and a step that carries a short
        rebound past its closure (the gap below -arm) still ends with the rate negative (docs/theory.md §G2.1)."""
        if self.GAP_ARM == 0:
            return rate
        lift = 1 - abs(gap) / arm
        return rate + speed * (lift + abs(lift)) / 2

    # -- transitions -----------------------------------------------------------------------------------------
    def transitions(self):
        """Entry into the open gap, impacts at gap closure (rebound or plastic), separation, exit; stall and rest
        stops as in the exact-fit model (`Geneva.transitions`)."""
        table = super().transitions()
        stall, rest = table[("dwell", "stall")], table[("dwell", "rest")]
        table.pop(("engaged", "flank_switch"))
        table[("dwell", "entry")] = TransitionRule("free", kind="entry")
        table[("engaged", "separation")] = TransitionRule("free", kind="separation")
        table[("free", "exit")] = table[("engaged", "exit")]
        # past the apex the guard watches the other turning point (flank only directs it in flight): the restart
        # cannot fire it again from round-off in the rate there
        table[("free", "apex")] = TransitionRule("free", lambda q, v, p, xp: {"flank": -p["flank"]},
                                                 kind="flight apex")
        for guard, f in (("close_driving", 1.0), ("close_trailing", -1.0)):
            # the events' kind says what followed (the flank struck is the guard): "impact" into free is a rebound,
            # into engaged the pin stays on the flank; "impact, slides off" a plastic impact the pin leaves at once
            table[("free", guard)] = (
                TransitionRule("free", lambda q, v, p, xp, f=f: {"flank": f}, kind="impact",
                               when=lambda q, v, p, xp, f=f: self._rebound_speed(q, v, p, xp, f) - p["bounce_speed"],
                               restitution=self.restitution, contact="engaged", restitution_parameter="restitution"),
                TransitionRule("engaged", lambda q, v, p, xp, f=f: {"flank": f, "slide": self._slide_after(
                    q, v, p, xp, f)}, kind="impact", restitution=0.0, contact="engaged",
                    when=lambda q, v, p, xp, f=f: self._pressing(q, v, p, xp, f)),
                TransitionRule("free", lambda q, v, p, xp, f=f: {"flank": f}, kind="impact, slides off",
                               restitution=0.0, contact="engaged"))
        for mode in ("free",):
            table[(mode, "stall")] = stall
            table[(mode, "rest")] = rest
        if self.lock_clearance > 0:
            self._play_transitions(table)
        return table

    @staticmethod
    def _local(q, p):
        """The local crank and wheel angles (alpha, beta) of the current slot (as model.py's rules read them)."""
        return q[0] - 2 * np.pi * p["slot"], q[1] - p["slot"] * p["pitch"]

    def _normal(self, q, v, p, xp, f):
        """(dg/dq of the struck flank's constraint Phi - f c_s/2, its rate G v): dPhi/dtheta = r cos(alpha + beta),
        dPhi/dpsi = -x (`GenevaGeometry.pin_in_slot`: a = r cos(alpha + beta) external, x the pin distance)."""
        g = self.geometry
        alpha, beta = self._local(q, p)
        _, x, _, arm = g.pin_in_slot(p["r"], p["c"], alpha, beta, xp)
        G = (arm, -x)
        return G, G[0] * v[0] + G[1] * v[1]

    def _after_impact(self, q, v, p, xp, f, e):
        """The velocities after Newton's law with restitution e on the flank (diagonal mass matrix J1, J2):
        v+ = v - M^-1 G^T (G M^-1 G^T)^-1 (1 + e) G v (`dynamics/consistent.reinitialise`'s law, written out)."""
        (g1, g2), rate = self._normal(q, v, p, xp, f)
        J1, J2 = p["J1"], p["J2"]
        impulse = (1 + e) * rate / (g1 * g1 / J1 + g2 * g2 / J2)
        return v[0] - g1 * impulse / J1, v[1] - g2 * impulse / J2

    def _rebound_speed(self, q, v, p, xp, f):
        """e |Phi'|: the normal relative speed (m/s) after the impact (Phi the lateral offset, a length)."""
        return p["restitution"] * xp.abs(self._normal(q, v, p, xp, f)[1])

    def _pressing(self, q, v, p, xp, f):
        """>= 0 where the free motion presses the pin onto flank f after a plastic impact there: f Phi'' of the
        free mode at the velocities after it, with Phi'' = r cos(alpha + beta) theta'' - x psi''
        - r sin(alpha + beta) (theta'^2 + 2 theta' psi') - Phi psi'^2 (Phi's Hessian in (alpha, beta)) and the free
        accelerations theta'' = (T_in - c1 theta') / J1 (0 at a prescribed speed), psi'' = -(T_L + c2 psi') / J2.
        For one frictionless contact the contact force has this sign (the one-constraint complementarity problem:
        N = -Phi''_free / (G M^-1 G^T)), so where it is negative the pin leaves the flank at once."""
        g = self.geometry
        alpha, beta = self._local(q, p)
        phi, x, _, arm = g.pin_in_slot(p["r"], p["c"], alpha, beta, xp)
        w1, w2 = self._after_impact(q, v, p, xp, f, 0.0)
        a1 = xp.where(p["drive_speed"] != 0, 0.0,
                      (p["drive_T0"] - p["drive_slope"] * w1 - p["c1"] * w1) / p["J1"])
        a2 = -(p["T_L"] + p["c2"] * w2) / p["J2"]
        s_ab = g.pin_in_slot(p["r"], p["c"], alpha, beta, xp)[2]       # r sin(alpha + beta) external
        acc = arm * a1 - x * a2 - s_ab * (w1 * w1 + 2 * w1 * w2) - phi * w2 * w2
        return f * acc + 1e-300

    def _slide_after(self, q, v, p, xp, f):
        """The friction direction on the flank after a plastic impact: the sign of the slip at the velocities
        after it (kept at +1 where the slip vanishes)."""
        g = self.geometry
        alpha, beta = self._local(q, p)
        w1, w2 = self._after_impact(q, v, p, xp, f, 0.0)
        u = (w1 * g.pin_in_slot(p["r"], p["c"], alpha, beta, xp)[2] + w2 * f * p["clearance"] / 2
             + f * p["R"] * (w2 - g.crank_sense * w1))
        return xp.where(u >= 0, 1.0, -1.0)

    # -- the locking arc's play in the dwell (mechanism.lock_clearance > 0) -------------------------------------
    #: the pull (N, at the crank radius) at which a held wheel leaves its end of the play: a wheel at rest without load
    #: has a lock force of exactly zero, a release guard at zero would be identically zero (no root to find)
    LOCK_RELEASE_FORCE = 1e-9

    def _checked_lock_play(self, play) -> float:
        """The lock's angular play delta (rad), refused where the pin could not enter the slot it meets: a wheel
        turned by delta/2 off its nominal dwell angle moves the slot's centre line by x_e sin(delta/2) at the pin's
        entry (x_e the entry pin distance), which must stay below the half clearance c_s/2, or the pin strikes the
        slot mouth's corner (docs/geneva.md 'Clearance and impacts')."""
        if not (np.isfinite(play) and play >= 0):
            raise ValueError(f"mechanism.lock_clearance: must be a finite angle >= 0, got {play!r}")
        play = float(play)
        x_e = self.geometry.entry_pin_distance
        if play > 0 and x_e * np.sin(play / 2) >= self.slot_clearance / 2:
            raise ValueError(
                f"mechanism.lock_clearance: {play:g} rad moves the slot mouth by x_entry sin(play/2) = "
                f"{x_e * np.sin(play / 2):.4g} m at the pin's entry, not below the half slot clearance "
                f"{self.slot_clearance / 2:.4g} m: the pin would strike the slot's corner (at most "
                f"{2 * np.arcsin(self.slot_clearance / (2 * x_e)):.6g} rad here)")
        return play

    def initial_state(self, angle: float, speed: float):
        """As the exact fit's; with lock play a dwell start holds the wheel on the trailing end of its play, where
        the (resisting) load keeps it at rest."""
        state = super().initial_state(angle, speed)
        if self.lock_clearance <= 0 or state.mode != "dwell":
            return state
        q = np.array(state.q, dtype=float)
        q[1] -= self.lock_clearance / 2
        return replace(state, updates={**state.updates, "lock_end": -1.0}, q=q)

    def _play_modes(self, dwell: Mode, free: Mode) -> dict[str, Mode]:
        """The dwell with lock play delta: 'dwell' holds the wheel on an end s = lock_end of its play, the
        constraint r (psi - psi_lock - s delta/2) = 0 (a length, as the exact fit's lock; its multiplier, the lock
        force at radius r, is compressive where s lam > 0), under the load; 'play' leaves it free between the
        ends under its own inertia, load and damping, the crank under its drive. In 'play' lock_end is the end the
        wheel last moved away from: the apex guard -s psi' watches its turning point, as the slot's flight apex."""
        import sympy as sp
        s, P = self.symbols, self.symbols.p
        psi, (w1, w2) = s.q[1], s.v
        r, end, half = P("r"), P("lock_end"), P("lock_play") / 2
        T_L = P("T_L") + P("T_L_rate") * (s.t - P("T_L_time0"))
        lock, lam = P("lock_angle"), s.lam[0]
        zero = sp.Integer(0)
        guards = {gd.name: gd for gd in dwell.guards}
        arm = self.GAP_ARM * r * P("lock_play")
        powers = {"load": -T_L * w2, "friction": zero, "damping": -P("c1") * w1**2 - P("c2") * w2**2}
        held = replace(
            dwell, constraints=(r * (psi - lock - end * half),), force=(-P("c1") * w1, -P("c2") * w2 - T_L),
            guards=(guards["entry"], Guard("lock_release", end * lam + self.LOCK_RELEASE_FORCE, -1), guards["stall"],
                    guards["rest"]),
            powers=powers)
        play = Mode(
            name="play", constraints=(), force=(-P("c1") * w1, -P("c2") * w2 - T_L),
            guards=(guards["entry"], Guard("lock_lead", r * (lock + half - psi) - arm, -1),
                    Guard("lock_trail", r * (psi - lock + half) - arm, -1), Guard("lock_apex", -end * w2, -1),
                    guards["stall"], guards["rest"]),
            powers=powers, readouts=dict(dwell.readouts, lock_force_N=zero), heat=dwell.heat)
        return {"dwell": held, "play": play}

    def _play_transitions(self, table) -> None:
        """Lock play: the wheel strikes an end of its play with Newton's law (restitution e and the bounce speed of
        the pin's impacts, on the lock constraint's rate r psi'); a plastic impact holds it there where the load
        presses it on, else it leaves at once. Entry takes the wheel as it is (the gaps then differ); exit leaves
        a wheel within its play free in it with its speed, and takes one outside it (the pin on a flank turns the
        wheel by asin(c_s / (2 x_exit)) >= delta/2) to the nearer end with a plastic lock impact."""
        stall, rest = table[("dwell", "stall")], table[("dwell", "rest")]
        entry = TransitionRule("free", self._entry_flank, kind="entry")
        table[("dwell", "entry")] = table[("play", "entry")] = entry
        table[("play", "stall")], table[("play", "rest")] = stall, rest
        table[("dwell", "lock_release")] = TransitionRule("play", kind="lock release")
        table[("play", "lock_apex")] = TransitionRule("play", lambda q, v, p, xp: {"lock_end": -p["lock_end"]},
                                                      kind="play apex")
        for guard, e in (("lock_lead", 1.0), ("lock_trail", -1.0)):
            table[("play", guard)] = (
                TransitionRule("play", lambda q, v, p, xp, e=e: {"lock_end": e}, kind="lock impact",
                               when=lambda q, v, p, xp: p["restitution"] * p["r"] * xp.abs(v[1]) - p["bounce_speed"],
                               restitution=self.restitution, contact="dwell", restitution_parameter="restitution"),
                TransitionRule("dwell", lambda q, v, p, xp, e=e: {"lock_end": e}, kind="lock impact",
                               restitution=0.0, contact="dwell",
                               when=lambda q, v, p, xp, e=e: self._lock_pressing(p, e)),
                TransitionRule("play", lambda q, v, p, xp, e=e: {"lock_end": e}, kind="lock impact, leaves",
                               restitution=0.0, contact="dwell"))
        exit_ = table[("engaged", "exit")]

        def offset(q, p):                                 # the wheel off its next lock angle
            return q[1] - (p["slot"] + 0.5) * p["pitch"]

        def nearer(q, v, p, xp):
            return {**exit_.updates(q, v, p, xp), "lock_end": xp.where(offset(q, p) >= 0, 1.0, -1.0)}
        def inside(q, v, p, xp):                          # the wheel within its play: on free, moving away
            return {**exit_.updates(q, v, p, xp), "lock_end": xp.where(v[1] >= 0, -1.0, 1.0)}
        rules = (
            TransitionRule("play", inside, kind="exit",
                           when=lambda q, v, p, xp: p["lock_play"] / 2 - xp.abs(offset(q, p))),
            TransitionRule("dwell", nearer, kind="exit", restitution=0.0, contact="dwell",
                           when=lambda q, v, p, xp: self._lock_pressing(p, xp.where(offset(q, p) >= 0, 1.0, -1.0))),
            TransitionRule("play", nearer, kind="exit", restitution=0.0, contact="dwell"))
        table[("engaged", "exit")] = table[("free", "exit")] = rules

    @staticmethod
    def _lock_pressing(p, end):
        """>= 0 where the wheel at rest on end `end` of its play is pressed onto it: its free acceleration
        -(T_L)/J2 at zero speed points out of the play there (the one-constraint complementarity test of the pin's
        `_pressing`)."""
        return -end * p["T_L"] + 1e-300

    def _entry_flank(self, q, v, p, xp):
        """Entry with the wheel where its play left it: the pin meets the slot off its centre line (Phi =
        -rho sin(beta - beta0)) and with a lateral rate Phi' of either sign; flank directs the flight's apex guard
        (-flank Phi', see `modes`), set so that it starts positive."""
        (g1, g2), _ = self._normal(q, v, p, xp, 1.0)
        rate = g1 * v[0] + g2 * v[1]
        return {"flank": xp.where(rate > 0, -1.0, 1.0)}
