"""Geneva dynamics in the single coordinate theta (crank angle): an independent reference for the DAE.

Engaged (docs/theory.md §G2, friction included, driving flank): the wheel's moment balance gives
    N = (J2 (G theta'' + G' theta'^2) + c2 G theta' + T_L) / (x - sigma mu R)
and the crank's, with the normal-force arm x G (= r cos(alpha + beta) for the external drive) and the friction
arm s = du/dtheta' = s_slide - crank_sense R (sliding plus pin spin; r sin(alpha + beta) + R external),
    J1 theta'' = T_in - c1 theta' - N (x G + sigma mu s),
which is docs/theory.md (Part G)'s (J1 + J2 G (G + kappa_f)) theta'' + J2 G' (G + kappa_f) theta'^2 = T_in - T_L (G + kappa_f)
with damping added. Dwell: J1 theta'' = T_in - c1 theta'. T_in = T0 - slope theta'.
Integrated with scipy's DOP853, restarting at every engagement boundary and slip reversal. The geometry's
formulas (`GenevaGeometry.wheel_motion`, `pin_in_slot`) make it the reference of the internal Geneva too.
"""
from __future__ import annotations

import numpy as np
from scipy.integrate import solve_ivp

from mechsim.mechanisms.geneva.model import Geneva


def _engaged_terms(m: Geneva, alpha: float, omega: float):
    g = m.geometry
    beta, G, Gp, xc = g.wheel_motion(g.ratio, alpha)
    s_slide = g.pin_in_slot(g.crank_radius, g.centre_distance, alpha, beta)[2]
    arm = s_slide - g.crank_sense * g.pin_radius
    u = omega * (s_slide + g.pin_radius * (G - g.crank_sense))
    return G, Gp, g.centre_distance * xc, arm, u


def acceleration(m: Geneva, theta: float, omega: float, drive_T0: float, drive_slope: float,
                 sigma: float | None = None) -> float:
    """theta'' of the reduced model (sigma = sign of the slip; taken from the state when None)."""
    g = m.geometry
    k = np.floor((theta + np.pi) / (2 * np.pi))
    alpha = theta - 2 * np.pi * k
    T_in = drive_T0 - drive_slope * omega
    if abs(alpha) >= g.engagement_half_angle:
        return (T_in - m.crank_damping * omega) / m.crank_inertia
    G, Gp, x, arm, u = _engaged_terms(m, alpha, omega)
    if sigma is None:
        sigma = 1.0 if u >= 0 else -1.0
    mu, R = m.friction, g.pin_radius
    D = x - sigma * mu * R
    h = (x * G + sigma * mu * arm) / D
    J1, J2 = m.crank_inertia, m.wheel_inertia
    num = T_in - m.crank_damping * omega - h * (J2 * Gp * omega**2 + m.wheel_damping * G * omega + m.wheel_torque)
    return num / (J1 + h * J2 * G)


def integrate(m: Geneva, drive_T0: float, drive_slope: float, theta0: float, omega0: float,
              t_eval: np.ndarray, rtol: float = 1e-12, atol: float = 1e-12, method="DOP853",
              stats: dict | None = None) -> tuple[np.ndarray, np.ndarray]:
    """theta(t), omega(t) at t_eval (t_eval[0] is the start), piecewise between boundaries.

    method: any `solve_ivp` method (name or OdeSolver class); stats, if given, accumulates nfev, njev, nlu,
    segments and events (for the work-precision benchmark).
    """
    g = m.geometry
    a0 = g.engagement_half_angle
    t, y = float(t_eval[0]), np.array([theta0, omega0], dtype=float)
    out = np.full((len(t_eval), 2), np.nan)
    out[0] = y
    t_end = float(t_eval[-1])
    while t < t_end:
        k = np.floor((y[0] + np.pi) / (2 * np.pi))
        alpha = y[0] - 2 * np.pi * k
        engaged = -a0 <= alpha < a0
        # next boundary in theta
        if engaged:
            nxt = 2 * np.pi * k + a0
        elif alpha >= a0:
            nxt = 2 * np.pi * (k + 1) - a0
        else:
            nxt = 2 * np.pi * k - a0
        sigma = None
        if engaged:
            sigma = 1.0 if _engaged_terms(m, alpha, y[1])[4] >= 0 else -1.0

        def rhs(_t, s):
            return [s[1], acceleration(m, s[0], s[1], drive_T0, drive_slope, sigma)]

        def boundary(_t, s):
            return s[0] - nxt

        boundary.terminal, boundary.direction = True, 1

        def slip(_t, s):
            kk = np.floor((s[0] + np.pi) / (2 * np.pi))
            return _engaged_terms(m, s[0] - 2 * np.pi * kk, s[1])[4] if engaged else 1.0

        slip.terminal, slip.direction = True, 0
        mask = (t_eval > t) & (t_eval <= t_end)
        sol = solve_ivp(rhs, (t, t_end), y, method=method, rtol=rtol, atol=atol, t_eval=t_eval[mask],
                        events=[boundary, slip], dense_output=False)
        if stats is not None:
            for key in ("nfev", "njev", "nlu"):
                stats[key] = stats.get(key, 0) + int(getattr(sol, key, 0))
            stats["segments"] = stats.get("segments", 0) + 1
            stats["events"] = stats.get("events", 0) + int(sol.status == 1)
        n = len(sol.t)
        if n:
            idx = np.flatnonzero(mask)[:n]
            out[idx] = np.asarray(sol.y).T[:n]
        if sol.status == 1:
            te = [e for e in sol.t_events if len(e)]
            t = float(min(e[0] for e in te))
            ye = [ys[0] for ys, ts in zip(sol.y_events, sol.t_events) if len(ts) and ts[0] == t][0]
            y = np.array(ye, dtype=float)
            # step just past the boundary so the mode test sees the new side
            y[0] += 1e-15 * max(1.0, abs(y[0]))
        elif sol.status == 0:
            break
        else:
            raise RuntimeError(sol.message)
    return out[:, 0], out[:, 1]
