"""The peer a CasADi user would write: the same Geneva equations in CasADi symbolics on CasADi's IDAS.

The mechanism's own sympy description (mass matrix, applied forces, constraints, guards of each mode) is
translated to CasADi SX; CasADi's automatic differentiation then builds the constraint Jacobian G, the
velocity constraint Phi' = G v and the acceleration term gamma = d(G v)/dq v, and the semi-explicit index-1
DAE (the form CasADi's `integrator` accepts):

    x = (q, v),  z = (a, lam):   q' = v,  v' = a,
    0 = M a + G^T lam - Q(q, v, lam),   0 = G a + gamma + 2 alpha Phi' + beta^2 Phi   (Baumgarte 1972,
    the gains of mechsim's index-1 form; docs/theory.md §K4 'Index 1 + Baumgarte').

form "dae" integrates that DAE on IDAS with z kept out of the error test (`suppress_algebraic`, which
scikit-sundae cannot set); form "ode" lets CasADi solve the algebraic rows (linear in z) symbolically and
integrates the ODE x' = (v, a(x)) on IDAS.

CasADi fixes an integrator's output grid when it is built, so each mode gets two integrators in scaled time
(x' = h f(x), tau in [0, K] or [0, 1]): one returning K outputs one output step apart, one to an arbitrary
time (partial intervals and root finding). The Python event loop integrates K outputs, evaluates the guards
at each, locates the first crossing in its direction by Illinois regula falsi (each trial one short IDAS call
from the output before it), applies the mechanism's own transition (`Mechanism.on_guard`), re-projects q and
v onto the new mode's constraints and restarts. Needs the `bench` extra (casadi).
"""
from __future__ import annotations

import math
import time
from dataclasses import dataclass, field

import numpy as np
import sympy as sp

from mechsim.dynamics.drives import Drive
from mechsim.mechanisms.base import Mechanism

FORMS = ("dae", "ode")
_STAT_KEYS = {"nsteps": "steps", "netfails": "rejected_steps", "nfevals": "residual_evaluations",
              "n_call_jacF": "jacobian_evaluations", "nncfails": "convergence_failures"}


def _namespace():
    import casadi as ca
    return {"sin": ca.sin, "cos": ca.cos, "tan": ca.tan, "sqrt": ca.sqrt, "exp": ca.exp, "log": ca.log,
            "atan2": ca.atan2, "Abs": ca.fabs, "abs": ca.fabs, "sign": ca.sign, "pi": math.pi}


@dataclass
class CasadiMode:
    """One mode's integrators and functions (for one tolerance)."""

    form: str
    guard_names: list[str]
    directions: list[int]
    chunk: object          # integrator: K outputs one output step apart (time scale h = output step)
    one: object            # integrator: one output (time scale h = the interval)
    zfun: object           # (x, p) -> z = (a, lam), exact (the algebraic rows are linear in z)
    guards: object         # (x, z, p) -> guard values
    phi: object            # (q, p) -> Phi
    G: object              # (q, p) -> dPhi/dq
    mass: object           # (q, p) -> M
    _maps: dict = field(default_factory=dict)

    def columns(self, fn_name: str, n: int):
        """The n-column map of zfun or guards (built once per size)."""
        key = (fn_name, n)
        if key not in self._maps:
            self._maps[key] = getattr(self, fn_name).map(n)
        return self._maps[key]


@dataclass
class CasadiModel:
    """All modes of a mechanism in CasADi for one (form, rtol, atol, chunk length)."""

    modes: dict[str, CasadiMode]
    parameter_names: tuple[str, ...]
    nq: int
    build_time_s: float
    chunk_outputs: int
    form: str


def build(mech: Mechanism, rtol: float, atol: float, chunk_outputs: int = 100, max_steps: int = 20000,
          form: str = "dae") -> CasadiModel:
    """Translate the mechanism's modes to CasADi and build their IDAS integrators."""
    import casadi as ca

    if form not in FORMS:
        raise ValueError(f"form must be one of {FORMS}, got {form!r}")
    if chunk_outputs < 2:
        raise ValueError("chunk_outputs must be at least 2")
    wall = time.perf_counter()
    s = mech.symbols
    nq, k = len(s.q), mech.drive_coordinate
    pnames = tuple(p.name for p in s.params) + ("drive_T0", "drive_slope", "baumgarte_alpha", "baumgarte_beta",
                                                "time_scale")
    q, v, a = ca.SX.sym("q", nq), ca.SX.sym("v", nq), ca.SX.sym("a", nq)
    P = ca.SX.sym("p", len(pnames))
    by = {n: P[i] for i, n in enumerate(pnames)}
    ns = _namespace()
    entries = _lambdify(list(mech.mass_matrix()), s, [], ns)(q, v, [], by)
    M = ca.vertcat(*[ca.horzcat(*entries[i * nq:(i + 1) * nq]) for i in range(nq)])
    x = ca.vertcat(q, v)
    modes = {}
    for name, mode in mech.modes().items():
        m = len(mode.constraints)
        lam = ca.SX.sym("lam", m)
        sym_lam = list(s.lam[:m])
        force = ca.vertcat(*_lambdify(list(mode.force), s, sym_lam, ns)(q, v, lam, by))
        force[k] += by["drive_T0"] - by["drive_slope"] * v[k]
        phi = ca.vertcat(*_lambdify(list(mode.constraints), s, sym_lam, ns)(q, v, lam, by))
        G = ca.jacobian(phi, q)
        phi_dot = ca.mtimes(G, v)
        gamma = ca.jtimes(phi_dot, q, v)
        alg = ca.vertcat(ca.mtimes(M, a) + ca.mtimes(G.T, lam) - force,
                         ca.mtimes(G, a) + gamma + 2 * by["baumgarte_alpha"] * phi_dot
                         + by["baumgarte_beta"] ** 2 * phi)
        z = ca.vertcat(a, lam)
        zx = -ca.solve(ca.jacobian(alg, z), ca.substitute(alg, z, ca.DM.zeros(z.shape)))
        opts = {"reltol": rtol, "abstol": atol, "max_num_steps": max_steps, "disable_internal_warnings": True}
        if form == "dae":
            dae = {"x": x, "z": z, "p": P, "ode": by["time_scale"] * ca.vertcat(v, a), "alg": alg}
            opts["suppress_algebraic"] = True
        else:
            dae = {"x": x, "p": P, "ode": by["time_scale"] * ca.vertcat(v, zx[:nq])}
        grid = [float(i) for i in range(1, chunk_outputs + 1)]
        gexprs = _lambdify([g.expr for g in mode.guards], s, sym_lam, ns)(q, v, lam, by)
        modes[name] = CasadiMode(
            form, [g.name for g in mode.guards], [g.direction for g in mode.guards],
            chunk=ca.integrator(f"chunk_{name}", "idas", dae, 0.0, grid, opts),
            one=ca.integrator(f"one_{name}", "idas", dae, 0.0, [1.0], opts),
            zfun=ca.Function(f"z_{name}", [x, P], [zx]),
            guards=ca.Function(f"guards_{name}", [x, z, P], [ca.vertcat(*gexprs)]),
            phi=ca.Function(f"phi_{name}", [q, P], [phi]), G=ca.Function(f"G_{name}", [q, P], [G]),
            mass=ca.Function("M", [q, P], [M]))
    return CasadiModel(modes, pnames, nq, time.perf_counter() - wall, chunk_outputs, form)


def _lambdify(exprs, s, sym_lam, ns):
    """A callable (q, v, lam, params by name) -> CasADi expressions of the sympy expressions."""
    f = sp.lambdify([s.t, *s.q, *s.v, *sym_lam, *s.params], exprs, modules=[ns])

    def call(q, v, lam, by):
        nq = len(s.q)
        return f(0.0, *[q[i] for i in range(nq)], *[v[i] for i in range(nq)],
                 *[lam[i] for i in range(len(sym_lam))], *[by[p.name] for p in s.params])
    return call


@dataclass
class CasadiRun:
    """Output of one run: crank angle at the output times, statistics, events, failure (None if it finished)."""

    t: np.ndarray
    angle: np.ndarray
    stats: dict = field(default_factory=dict)
    events: list = field(default_factory=list)
    failure: str | None = None


class _Stop(Exception):
    pass


def simulate(model: CasadiModel, mech: Mechanism, drive: Drive, t_end: float, dt_out: float, angle0: float,
             speed0: float, alpha: float = 10.0, beta: float = 10.0, max_events: int = 10000) -> CasadiRun:
    """Integrate the hybrid model from t = 0 with outputs every dt_out (a grid from 0, as mechsim's)."""
    if drive.is_prescribed:
        raise ValueError("the CasADi peer integrates torque and motor drives only")
    nq, K = model.nq, model.chunk_outputs
    values = dict(mech.parameter_values())
    dv = drive.parameter_values(angle0)
    values.update(drive_T0=dv["drive_T0"], drive_slope=dv["drive_slope"], baumgarte_alpha=alpha,
                  baumgarte_beta=beta, time_scale=1.0)
    init = mech.initial_state(angle0, speed0)
    values.update(init.updates)
    mode = init.mode
    stats = {name: 0 for name in _STAT_KEYS.values()}
    stats.update(segments=1, integrator_calls=0, events=0)

    def pvec(h: float) -> np.ndarray:
        values["time_scale"] = h
        return np.array([values[n] for n in model.parameter_names], float)

    def call(cm: CasadiMode, F, x, h):
        """Integrate from x over h (one or K outputs); returns x and z at the outputs (columns)."""
        pv = pvec(h)
        if cm.form == "dae":
            r = F(x0=x, z0=cm.zfun(x, pv), p=pv)
        else:
            r = F(x0=x, p=pv)
        st = F.stats()
        stats["integrator_calls"] += 1
        for key, name in _STAT_KEYS.items():
            stats[name] += int(st.get(key, 0))
        xs = np.asarray(r["xf"])
        zs = np.asarray(r["zf"]) if cm.form == "dae" else np.asarray(cm.columns("zfun", xs.shape[1])(xs, pv))
        return xs, zs

    def guards(cm: CasadiMode, xs, zs):
        return np.asarray(cm.columns("guards", xs.shape[1])(xs, zs, pvec(1.0))).reshape(-1, xs.shape[1])

    cm = model.modes[mode]
    x = _consistent(cm, init.q, init.v, pvec(1.0))
    z = np.asarray(cm.zfun(x, pvec(1.0))).ravel()
    n_out = int(np.floor(t_end / dt_out + 1e-9))
    out_t, out_a, events = [0.0], [x[0]], []
    t, j_next = 0.0, 1          # j_next: index of the next output time j * dt_out
    try:
        while j_next <= n_out:
            cm = model.modes[mode]
            g_start = guards(cm, x[:, None], z[:, None])[:, 0]
            gap = j_next * dt_out - t
            if gap < dt_out * (1 - 1e-9):      # off the grid (after an event): one call to the next output
                xs, zs = call(cm, cm.one, x, gap)
                ts = np.array([j_next * dt_out])
            else:
                xs, zs = call(cm, cm.chunk, x, dt_out)
                ts = (j_next + np.arange(K)) * dt_out
                keep = np.arange(K) < n_out - j_next + 1
                xs, zs, ts = xs[:, keep], zs[:, keep], ts[keep]
            gs = guards(cm, xs, zs)
            hit = _first_crossing(g_start, gs, cm.directions)
            col = len(ts) if hit is None else hit[0]
            out_t.extend(ts[:col])
            out_a.extend(xs[0, :col])
            j_next += col
            if hit is None:
                t, x, z = float(ts[-1]), xs[:, -1], zs[:, -1]
                continue
            gi = hit[1]
            lo = (t, x, g_start[gi]) if col == 0 else (float(ts[col - 1]), xs[:, col - 1], gs[gi, col - 1])
            t, x = _locate(lambda xx, h: call(cm, cm.one, xx, h)[0][:, 0],
                           lambda xx: float(guards(cm, xx[:, None], cm.zfun(xx, pvec(1.0)))[gi, 0]),
                           lambda xx: np.concatenate([xx[nq:], np.asarray(cm.zfun(xx, pvec(1.0))).ravel()[:nq]]),
                           lo, (float(ts[col]), xs[:, col], gs[gi, col]))
            guard = cm.guard_names[gi]
            tr = mech.on_guard(mode, guard, values, t, x[:nq], x[nq:])
            events.append(dict(t_s=t, from_mode=mode, to_mode=tr.mode, kind=tr.kind))
            stats["events"] += 1
            if tr.stop:
                raise _Stop(tr.stop)
            if stats["events"] > max_events:
                raise _Stop("too many events")
            values.update(tr.updates)
            mode = tr.mode
            cm = model.modes[mode]
            x = _consistent(cm, x[:nq], x[nq:], pvec(1.0))
            z = np.asarray(cm.zfun(x, pvec(1.0))).ravel()
            stats["segments"] += 1
    except (_Stop, RuntimeError) as exc:
        return CasadiRun(np.array(out_t), np.array(out_a), stats, events, f"t = {t:.6g} s: {exc}")
    return CasadiRun(np.array(out_t), np.array(out_a), stats, events)


def _first_crossing(g0: np.ndarray, gs: np.ndarray, directions: list[int]):
    """(column, guard) of the first output at which a guard has crossed zero in its direction, or None."""
    prev = np.column_stack([g0, gs[:, :-1]])
    best = None
    for i, d in enumerate(directions):
        a, b = prev[i], gs[i]
        if d > 0:
            cross = (a < 0) & (b >= 0)
        elif d < 0:
            cross = (a > 0) & (b <= 0)
        else:
            cross = (a * b < 0) | ((a != 0) & (b == 0))
        idx = np.flatnonzero(cross)
        if len(idx) and (best is None or idx[0] < best[0]):
            best = (int(idx[0]), i)
    return best


def _hermite(t0, x0, d0, t1, x1, d1, t):
    """Cubic Hermite interpolant of x between (t0, x0, x0') and (t1, x1, x1') at t."""
    h = t1 - t0
    s = (t - t0) / h
    h00, h10, h01, h11 = 2 * s**3 - 3 * s**2 + 1, s**3 - 2 * s**2 + s, -2 * s**3 + 3 * s**2, s**3 - s**2
    return h00 * x0 + h10 * h * d0 + h01 * x1 + h11 * h * d1


def _locate(integrate, guard, deriv, lo, hi, tol=1e-13, max_iter=12):
    """The crossing time in (t_lo, t_hi] and the state there.

    A first estimate from the cubic Hermite interpolant of the two outputs (bisection on the interpolated
    guard), then Newton steps on the true guard, each one IDAS call from the output before the crossing,
    with the interpolant's slope; a step that leaves the bracket falls back to bisection.
    integrate(x_lo, h) -> (x, z) at t_lo + h; guard(x) -> value; deriv(x) -> x' (columns).
    """
    t_lo, x_lo, g_lo = lo
    t_hi, x_hi, g_hi = hi
    d_lo, d_hi = deriv(x_lo), deriv(x_hi)

    def g_interp(t):
        return guard(_hermite(t_lo, x_lo, d_lo, t_hi, x_hi, d_hi, t))

    a, b, fa = t_lo, t_hi, g_lo
    for _ in range(60):                    # root of the interpolated guard
        m = 0.5 * (a + b)
        fm = g_interp(m)
        if fm * fa > 0:
            a, fa = m, fm
        else:
            b = m
        if b - a <= 1e-15 * max(1.0, abs(b)):
            break
    t = b
    a, b = t_lo, t_hi
    x = x_hi
    for _ in range(max_iter):
        x = integrate(x_lo, t - t_lo)
        g = guard(x)
        if g * g_lo > 0:
            a = t
        else:
            b = t
        eps = 1e-7 * (t_hi - t_lo)
        slope = (g_interp(t + eps) - g_interp(t - eps)) / (2 * eps)
        step = -g / slope if slope != 0 else 0.0
        t_new = t + step
        if not a <= t_new <= b:
            t_new = 0.5 * (a + b)
        if abs(t_new - t) <= tol * max(1.0, abs(t)):
            break
        t = t_new
    return t, x


def _consistent(cm: CasadiMode, q, v, p) -> np.ndarray:
    """x = (q, v) with q projected onto Phi = 0 and v onto G v = 0 (kinetic-energy metric)."""
    q = np.array(q, float).ravel()
    v = np.array(v, float).ravel()
    for _ in range(30):
        phi = np.asarray(cm.phi(q, p)).ravel()
        if np.max(np.abs(phi), initial=0.0) <= 1e-14 * max(1.0, np.max(np.abs(q))):
            break
        q = q - np.linalg.lstsq(np.asarray(cm.G(q, p)), phi, rcond=None)[0]
    G, M = np.asarray(cm.G(q, p)), np.asarray(cm.mass(q, p))
    if G.size:
        MiGt = np.linalg.solve(M, G.T)
        v = v - MiGt @ np.linalg.solve(G @ MiGt, G @ v)
    return np.concatenate([q, v])
