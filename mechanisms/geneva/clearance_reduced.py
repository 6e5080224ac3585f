"""The Geneva with slot clearance in reduced coordinates: an independent reference for the clearance DAE.

Frictionless (mu = 0), torque or motor drive T_in = T0 - slope theta'. Per mode the minimal coordinates:
  dwell: theta; the wheel at its lock angle.
  free: (theta, psi): J1 theta'' = T_in - c1 theta', J2 psi'' = -T_L - c2 psi'.
  on flank f (+1 driving, -1 trailing): theta; the pin centre at the lateral offset f h (h = c_s/2) from the slot's
      centre line, which fixes the wheel: with the pin centre at distance rho and polar angle beta0 from the wheel
      centre (beta0, rho = c sqrt(D): docs/theory.md §G1), rho sin(beta0 - beta) = f h, so
          beta_f(alpha) = beta0(alpha) - asin(f h / rho(alpha)),
      G = beta_f' = G0 + f h rho' / (rho X),  G' = G0' + f h [rho''/(rho X) - rho'^2/(rho^2 X) - rho'^2/X^3],
      X = sqrt(rho^2 - h^2) (the pin distance along the slot, the normal force's arm about the wheel centre),
      rho' = r c sin(alpha) / rho. Lagrange in theta: (J1 + J2 G^2) theta'' = T_in - c1 theta'
      - G (J2 G' theta'^2 + c2 G theta' + T_L); the wheel's moment balance gives the normal force
      N = (J2 (G theta'' + G' theta'^2) + c2 G theta' + T_L) / X.
Lock play delta (`lock_clearance`): the dwell holds the wheel on an end s of its play (psi = psi_lock + s delta/2;
theta alone) or leaves it free within the play ('play': the free equations above); the ends' impacts reverse the
wheel's speed, psi'+ = -e psi'- (Newton's law on the lock constraint r (psi - psi_end), which moves the wheel only),
plastic below the bounce speed (e r |psi'| against it), held where the load presses the wheel on (-s T_L >= 0); the
play is split where the wheel turns back, so that a short rebound cannot be stepped over.
Events: entry (dwell -> free), gap closure (Newton's law e on the flank's normal, in the mass metric, with the
normal Phi's gradient (r cos(alpha + beta), -X); rebound speed below the bounce speed: plastic, onto the flank),
separation (f N falls through 0 -> free), exit (-> dwell at the nominal lock angle; with play: a wheel within it
goes on free, one outside it is taken to the nearer end with its speed removed). scipy's DOP853 between them.
Written from the geometry alone: nothing of dynamics/ (docs/geneva.md 'Clearance and impacts').
"""
from __future__ import annotations

import numpy as np
from scipy.integrate import solve_ivp


def _pin(m, alpha):
    """(beta0, G0, G0', rho, rho', rho'') of the pin centre at local crank angle alpha (`wheel_motion`)."""
    g = m.geometry
    r, c = g.crank_radius, g.centre_distance
    beta0, G0, G0p, xc = (float(v) for v in g.wheel_motion(g.ratio, alpha))
    rho = c * xc
    rho_p = r * c * np.sin(alpha) / rho
    rho_pp = r * c * np.cos(alpha) / rho - r * c * np.sin(alpha) * rho_p / rho**2
    return beta0, G0, G0p, rho, rho_p, rho_pp


def flank_motion(m, alpha: float, f: float):
    """(beta_f, G, G', X): the wheel's local angle, its first and second derivatives in alpha and the pin's
    distance along the slot with the pin on flank f."""
    h = f * m.slot_clearance / 2
    beta0, G0, G0p, rho, rp, rpp = _pin(m, alpha)
    X = np.sqrt(rho**2 - h**2)
    G = G0 + h * rp / (rho * X)
    Gp = G0p + h * (rpp / (rho * X) - rp**2 / (rho**2 * X) - rp**2 / X**3)
    return beta0 - np.arcsin(h / rho), G, Gp, X


def offset(m, alpha: float, beta: float) -> float:
    """Phi: the pin centre's lateral offset from the slot's centre line (> 0 towards the driving flank)."""
    g = m.geometry
    return float(g.pin_in_slot(g.crank_radius, g.centre_distance, alpha, beta)[0])


def integrate(m, drive_T0: float, drive_slope: float, theta0: float, omega0: float, t_eval: np.ndarray,
              rtol: float = 1e-11, atol: float = 1e-12, bounce_speed: float | None = None,
              max_free_step: float = 1e-5):
    """theta(t), psi(t) at t_eval and the events [(t, kind, to)], from a dwell start (theta0 in a dwell)."""
    g = m.geometry
    if m.friction != 0:
        raise ValueError("the reduced clearance reference is frictionless")
    a0, pitch, h, e = g.engagement_half_angle, g.pitch, m.slot_clearance / 2, m.restitution
    bounce = m.BOUNCE_SPEED if bounce_speed is None else bounce_speed
    J1, J2, c1, c2, TL = m.crank_inertia, m.wheel_inertia, m.crank_damping, m.wheel_damping, m.wheel_torque
    k = float(np.floor((theta0 + np.pi) / (2 * np.pi)))
    alpha = theta0 - 2 * np.pi * k
    if abs(alpha) < a0:
        raise ValueError("start in a dwell")
    if alpha >= a0:
        k += 1
    half_play = getattr(m, "lock_clearance", 0.0) / 2
    mode, lock, f = "dwell", (k - 0.5) * pitch, 0.0
    end = -1.0                                         # the end of the lock's play the wheel rests on
    t, t_end = float(t_eval[0]), float(t_eval[-1])
    y = np.array([theta0, omega0, lock + end * half_play, 0.0])   # theta, theta', psi, psi' (psi' read when free)
    out = np.full((len(t_eval), 2), np.nan)
    out[0] = theta0, y[2]
    events = []

    def T_in(w):
        return drive_T0 - drive_slope * w

    def flank_accel(th, w):
        alpha = th - 2 * np.pi * k
        _, G, Gp, X = flank_motion(m, alpha, f)
        a = (T_in(w) - c1 * w - G * (J2 * Gp * w**2 + c2 * G * w + TL)) / (J1 + J2 * G * G)
        return a, (J2 * (G * a + Gp * w**2) + c2 * G * w + TL) / X

    def free_rhs(_t, s):
        return [s[1], (T_in(s[1]) - c1 * s[1]) / J1, s[3], (-TL - c2 * s[3]) / J2]

    def entry(_t, s):
        return s[0] - (2 * np.pi * k - a0)
    entry.terminal, entry.direction = True, 1

    def held(end):                                     # at rest on `end` after a plastic hit: pressed there?
        return -end * TL >= 0

    while t < t_end:
        if mode == "play":
            def lead(_t, s):
                return lock + half_play - s[2]

            def trail(_t, s):
                return s[2] - lock + half_play
            def apex(_t, s):                           # the wheel turns back: its speed away from `end` ends
                return -end * s[3]
            lead.terminal = trail.terminal = apex.terminal = True
            lead.direction = trail.direction = apex.direction = -1
            rhs, evs, state = free_rhs, [entry, lead, trail, apex], y
            names = ["entry", "lock_lead", "lock_trail", "play_apex"]
        elif mode == "free":
            rhs = free_rhs

            def close_d(_t, s):
                return h - offset(m, s[0] - 2 * np.pi * k, s[2] - k * pitch)

            def close_t(_t, s):
                return h + offset(m, s[0] - 2 * np.pi * k, s[2] - k * pitch)

            def exit_(_t, s):
                return s[0] - (2 * np.pi * k + a0)
            close_d.terminal = close_t.terminal = exit_.terminal = True
            close_d.direction = close_t.direction = -1
            exit_.direction = 1
            evs, names, state = [close_d, close_t, exit_], ["close_driving", "close_trailing", "exit"], y
        else:
            def rhs(_t, s):
                return [s[1], flank_accel(s[0], s[1])[0] if mode == "engaged" else (T_in(s[1]) - c1 * s[1]) / J1]
            if mode == "engaged":
                def sep(_t, s):
                    return f * flank_accel(s[0], s[1])[1]

                def exit_(_t, s):
                    return s[0] - (2 * np.pi * k + a0)
                sep.terminal = exit_.terminal = True
                sep.direction, exit_.direction = -1, 1
                evs, names = [sep, exit_], ["separation", "exit"]
            else:
                evs, names = [entry], ["entry"]
            state = y[:2]
        mask = (t_eval > t) & (t_eval <= t_end)
        # a rebound's flight can be shorter than a step, its gap zero at both ends: free flights take short steps
        sol = solve_ivp(rhs, (t, t_end), state, method="DOP853", rtol=rtol, atol=atol, t_eval=t_eval[mask],
                        events=evs, max_step=max_free_step if mode == "free" else np.inf)
        n = len(sol.t)
        if n:
            idx = np.flatnonzero(mask)[:n]
            if mode in ("free", "play"):
                out[idx] = sol.y[[0, 2]].T[:n]
            elif mode == "engaged":
                out[idx, 0] = sol.y[0][:n]
                out[idx, 1] = [k * pitch + flank_motion(m, th - 2 * np.pi * k, f)[0] for th in sol.y[0][:n]]
            else:
                out[idx] = np.c_[sol.y[0][:n], np.full(n, y[2])]
        if sol.status != 1:
            if sol.status != 0:
                raise RuntimeError(sol.message)
            break
        hit = min((ts[0], j) for j, ts in enumerate(sol.t_events) if len(ts))
        t, j = hit
        s = np.array(sol.y_events[j][0], dtype=float)
        name = names[j]
        alpha = s[0] - 2 * np.pi * k
        if name == "entry":
            mode, y = "free", (np.array([s[0], s[1], y[2], 0.0]) if len(s) == 2 else s)
        elif name == "exit":
            if mode == "engaged":                      # the wheel follows the pin on its flank
                beta, G, _, _ = flank_motion(m, alpha, f)
                psi, w2 = k * pitch + beta, G * s[1]
            else:
                psi, w2 = s[2], s[3]
            k += 1
            lock = (k - 0.5) * pitch
            if half_play > 0 and abs(psi - lock) < half_play:
                mode, y, end = "play", np.array([s[0], s[1], psi, w2]), (-1.0 if w2 >= 0 else 1.0)
            else:                                      # the lock takes the wheel to its nominal angle or nearer end
                end = 1.0 if psi - lock >= 0 else -1.0
                mode = "dwell" if half_play == 0 or held(end) else "play"
                y = np.array([s[0], s[1], lock + end * half_play, 0.0])
        elif name == "play_apex":                      # splits the play only: a short rebound cannot be stepped over
            end, y = -end, s
            continue
        elif name in ("lock_lead", "lock_trail"):
            end = 1.0 if name == "lock_lead" else -1.0
            if e * g.crank_radius * abs(s[3]) > bounce:
                mode, y = "play", np.array([s[0], s[1], lock + end * half_play, -e * s[3]])
                name = "lock impact"
            else:
                mode = "dwell" if held(end) else "play"
                y = np.array([s[0], s[1], lock + end * half_play, 0.0])
                name = "lock impact" if mode == "dwell" else "lock impact, leaves"
        elif name == "separation":
            beta, G, _, _ = flank_motion(m, alpha, f)
            mode, y = "free", np.array([s[0], s[1], k * pitch + beta, G * s[1]])
        else:                                          # gap closure: Newton's law on the flank's normal
            f = 1.0 if name == "close_driving" else -1.0
            beta = s[2] - k * pitch
            X = float(g.pin_in_slot(g.crank_radius, g.centre_distance, alpha, beta)[1])
            g1, g2 = g.crank_radius * np.cos(alpha + beta), -X
            rate = g1 * s[1] + g2 * s[3]
            ee = e if e * abs(rate) > bounce else 0.0
            lam = (1 + ee) * rate / (g1 * g1 / J1 + g2 * g2 / J2)
            w1, w2 = s[1] - g1 * lam / J1, s[3] - g2 * lam / J2
            if ee > 0:
                mode, y = "free", np.array([s[0], w1, s[2], w2])
            else:
                mode, y = "engaged", np.array([s[0], w1, s[2], w2])
            name = "impact"
        events.append((t, name, mode))
    return out[:, 0], out[:, 1], events
