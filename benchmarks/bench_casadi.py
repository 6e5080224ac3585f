"""The peer a careful CasADi user would write: the Geneva's equations in CasADi symbolics on CasADi's IDAS.

Model. The mechanism's own sympy description (mass matrix, applied forces, constraints, guards and contact
heat of each mode) is translated to CasADi SX; CasADi's automatic differentiation builds the constraint
Jacobian G, Phi' = G v and gamma = d(G v)/dq v, and the index-1 equations with Baumgarte stabilisation
(Baumgarte 1972; the gains of mechsim's index-1 form, docs/theory.md §K4 'Index 1 + Baumgarte'):

    M a + G^T lam = Q(q, v, lam),   G a + gamma + 2 alpha Phi' + beta^2 Phi = 0,

linear in z = (a, lam), solved by CasADi (`ca.solve`), so each mode is an ODE x' = f(x) in x = (q, v) plus,
when the scenario has a thermal network, its states (the network's rows are linear in their rates and are
solved the same way). Guards g(x) and their time derivatives g' = dg/dx f come from the same expressions.

The hybrid model runs without mechsim's loop or transitions (the Geneva's transition rules are written out
below, `geneva_transition`):

- `simulate` (`casadi-idas`): a Python event loop, as a careful user writes it. Each mode has IDAS
  integrators on output grids in scaled time, x' = h f with h a piecewise-constant control (CasADi's `u`):
  the first interval after an event is the partial one to the next output, then h = output step up to the
  output just past the predicted boundary, then h = 0 (IDAS crosses those intervals in a few steps; CasADi
  fixes a grid when the integrator is built, so there is one per length of a geometric ladder). So the
  outputs land on the grid and IDAS restarts only where a mode changes. The boundary angle of the mode is known
  (the engagement limits), so its crossing time is predicted from the angle, speed and acceleration; the first
  output where
  a guard has crossed zero in its direction brackets the event, which is then located by Newton steps on
  g(t) with g' from the model (for the boundary guards g' = dtheta/dt = omega), each one short IDAS call from
  the last output before the crossing, with a bisection safeguard. The next mode starts from the located
  state, projected onto its constraints (position by Gauss-Newton, velocity in the kinetic-energy metric).
  Every CasADi function is called through its buffer interface (`Fast`): a plain call from Python converts
  each argument (20-50 µs a call here), which would make the peer measure CasADi's Python wrapper.
- `simulate_events` (`casadi-idas-events`): CasADi's own event support (CasADi >= 3.7, which marks it
  experimental): one integrator over the whole grid whose state carries the discrete mode variables, the
  dynamics switched by `if_else`, the guards as zero-crossing outputs and the transition rules as a CasADi
  `transition` function (`build_events`).

Needs the `bench` extra (casadi).
"""
from __future__ import annotations

import math
import time
from dataclasses import dataclass, field

import numpy as np
import sympy as sp

from mechsim.dynamics.drives import Drive
from mechsim.mechanisms.base import Mechanism

_STAT_KEYS = {"nsteps": "steps", "netfails": "rejected_steps", "nfevals": "residual_evaluations",
              "nsetups": "jacobian_evaluations", "nlinsetups": "jacobian_evaluations",
              "nncfails": "convergence_failures"}
MARGIN = 1.25


def _namespace():
    import casadi as ca
    return {"sin": ca.sin, "cos": ca.cos, "tan": ca.tan, "sqrt": ca.sqrt, "exp": ca.exp, "log": ca.log,
            "atan": ca.atan, "atan2": ca.atan2, "Abs": ca.fabs, "abs": ca.fabs, "sign": ca.sign, "pi": math.pi,
            "Max": ca.fmax, "Min": ca.fmin, "Heaviside": lambda x, *_: ca.if_else(x > 0, 1, 0)}


def _to_casadi(exprs, symbols, values):
    """CasADi expressions of sympy `exprs`, with each sympy symbol in `symbols` replaced by `values`."""
    f = sp.lambdify(list(symbols), list(exprs), modules=[_namespace()])
    return f(*values)


# -- the model in CasADi -------------------------------------------------------------------------------------
@dataclass
class PeerModel:
    """Every mode's equations in CasADi for one mechanism (and thermal network), shared by both variants."""

    nq: int
    nx: int
    parameter_names: tuple[str, ...]
    modes: dict            # name -> dict of CasADi expressions (rhs, guards, gdot, phi, G, M, x, p)
    guard_names: dict      # mode -> [names]
    directions: dict       # mode -> [+1/-1/0]
    state_names: tuple[str, ...]


def translate(mech: Mechanism, ext=None) -> PeerModel:
    """The mechanism's sympy modes (and the thermal extension's rows) as CasADi expressions."""
    import casadi as ca

    s = mech.symbols
    nq, k = len(s.q), mech.drive_coordinate
    ext_names = tuple(ext.names) if ext is not None else ()
    ext_params = tuple(ext.parameter_names) if ext is not None else ()
    pnames = tuple(p.name for p in s.params) + ("drive_T0", "drive_slope", "baumgarte_alpha", "baumgarte_beta") \
        + ext_params
    q, v = ca.SX.sym("q", nq), ca.SX.sym("v", nq)
    X = ca.SX.sym("T", len(ext_names))
    P = ca.SX.sym("p", len(pnames))
    by = {n: P[i] for i, n in enumerate(pnames)}
    ext_syms = {n: sp.Symbol(n, real=True) for n in ext_params}
    # time enters the equations only through a time-varying load (the wheel torque's rate times t - t0); the
    # peer integrates constant loads (`constant_load`), so t stands at the load's reference time t0
    t_value = by["T_L_time0"] if "T_L_time0" in by else 0.0
    syms = [*s.q, *s.v, *s.params, *ext_syms.values(), s.t]
    vals = [*[q[i] for i in range(nq)], *[v[i] for i in range(nq)], *[by[p.name] for p in s.params],
            *[by[n] for n in ext_params], t_value]
    entries = _to_casadi(list(mech.mass_matrix()), syms, vals)
    M = ca.vertcat(*[ca.horzcat(*entries[i * nq:(i + 1) * nq]) for i in range(nq)])
    x = ca.vertcat(q, v, X)
    modes, guard_names, directions = {}, {}, {}
    for name, mode in mech.modes().items():
        m = len(mode.constraints)
        lam = ca.SX.sym("lam", m)
        a = ca.SX.sym("a", nq)
        sym_all = syms + list(s.lam[:m])
        val_all = vals + [lam[i] for i in range(m)]
        force = ca.vertcat(*_to_casadi(list(mode.force), sym_all, val_all))
        force[k] += by["drive_T0"] - by["drive_slope"] * v[k]
        phi = ca.vertcat(*_to_casadi(list(mode.constraints), sym_all, val_all))
        G = ca.jacobian(phi, q)
        phi_dot = ca.mtimes(G, v)
        gamma = ca.jtimes(phi_dot, q, v)
        alg = ca.vertcat(ca.mtimes(M, a) + ca.mtimes(G.T, lam) - force,
                         ca.mtimes(G, a) + gamma + 2 * by["baumgarte_alpha"] * phi_dot
                         + by["baumgarte_beta"] ** 2 * phi)
        z = ca.vertcat(a, lam)
        zx = -ca.solve(ca.jacobian(alg, z), ca.substitute(alg, z, ca.DM.zeros(z.shape)))
        acc, lam_x = zx[:nq], zx[nq:]
        rhs = [v, acc]
        if ext is not None:
            Xp = ca.SX.sym("Tp", len(ext_names))
            xs_ = [sp.Symbol(f"x_{n}", real=True) for n in ext_names]
            xps_ = [sp.Symbol(f"xp_{n}", real=True) for n in ext_names]
            rows = ext.rows(xs_, xps_, dict(mode.heat), lambda n: ext_syms[n] if n in ext_syms else s.p(n))
            r = ca.vertcat(*_to_casadi(rows, sym_all + xs_ + xps_, val_all + [X[i] for i in range(len(xs_))]
                                       + [Xp[i] for i in range(len(xps_))]))
            xp_sol = -ca.solve(ca.jacobian(r, Xp), ca.substitute(r, Xp, ca.DM.zeros(Xp.shape)))
            rhs.append(ca.substitute(xp_sol, lam, lam_x))
        f = ca.substitute(ca.vertcat(*rhs), lam, lam_x)
        gexprs = ca.vertcat(*_to_casadi([g.expr for g in mode.guards], sym_all + list(s.a),
                                        val_all + [acc[i] for i in range(nq)]))
        gexprs = ca.substitute(gexprs, lam, lam_x)
        gdot = ca.jtimes(gexprs, x, f)
        modes[name] = dict(x=x, p=P, rhs=f, guards=gexprs, gdot=gdot, phi=phi, G=G, M=M, q=q, v=v)
        guard_names[name] = [g.name for g in mode.guards]
        directions[name] = [g.direction for g in mode.guards]
    names = tuple(f"q_{c}" for c in mech.coordinates) + tuple(f"v_{c}" for c in mech.coordinates) + ext_names
    return PeerModel(nq, nq * 2 + len(ext_names), pnames, modes, guard_names, directions, names)


def constant_load(mech) -> bool:
    """Whether the mechanism's load is constant in time and the same at every station (no per-station torques,
    no torque profile): what the peers' equations assume."""
    return getattr(mech, "station_torques", None) is None and getattr(mech, "torque_profile", None) is None


def geneva_transition(mech, mode: str, guard: str, values: dict, q) -> tuple[str, dict, str | None]:
    """The Geneva's mode changes as the peer writes them (docs/theory.md §G1-2): (next mode, parameter updates,
    stop reason or None)."""
    g = mech.geometry
    k = values["slot"]
    if guard in ("stall", "rest"):
        return mode, {}, "crank stalled"
    if guard == "exit":
        return "dwell", {"slot": k + 1, "lock_angle": (k + 0.5) * g.pitch}, None
    if guard == "entry":
        return "engaged", {"flank": 1.0}, None       # the slip sign is set from the state after projection
    if guard == "flank_switch":
        return "engaged", {"flank": -values["flank"]}, None
    if guard == "slip_reversal":
        return "engaged", {"slide": -values["slide"]}, None
    raise KeyError(f"unknown guard {guard!r} in mode {mode!r}")


def _slip(mech, values: dict, q, v) -> float:
    """The slip speed u on the contact flank (docs/theory.md §G1 'Pin spin'), for the sign after an entry."""
    g = mech.geometry
    alpha = q[0] - 2 * np.pi * values["slot"]
    beta = q[1] - values["slot"] * g.pitch
    return g.crank_radius * v[0] * np.sin(alpha + beta) + values["flank"] * g.pin_radius * (v[0] + v[1])


# -- calling CasADi from Python without conversions ----------------------------------------------------------
class Fast:
    """A CasADi Function evaluated through its buffer interface (`Function.buffer`): numpy arrays bound to
    its inputs and outputs once, filled in place. A plain call from Python converts every argument to a DM and
    back (20-50 µs per call, and ~0.1 µs per element, here); through the buffer a call costs what CasADi's C
    code costs. Arrays are (columns, rows) in C order, CasADi's column-major layout."""

    def __init__(self, F, bind: dict | None = None):
        if not all(F.sparsity_out(i).is_dense() for i in range(F.n_out())):
            raise ValueError(f"{F.name()}: outputs must be dense for the buffer interface")
        self.F = F
        self.args = [np.zeros(F.size_in(i)[::-1]) for i in range(F.n_in())]
        for i, array in (bind or {}).items():       # share another Fast's output array as this input
            self.args[i] = array
        self.res = [np.zeros(F.size_out(i)[::-1]) for i in range(F.n_out())]
        self._buf, self.eval = F.buffer()
        for i, a in enumerate(self.args):
            self._buf.set_arg(i, memoryview(a))
        for i, r in enumerate(self.res):
            self._buf.set_res(i, memoryview(r))

    def __call__(self, *args) -> list[np.ndarray]:
        for a, v in zip(self.args, args):
            if v is not None:
                a.reshape(-1)[:] = np.ravel(v)
        self.eval()
        return self.res

    def stats(self) -> dict:
        for mem in (1, 0):                           # the buffer's own memory block, else the first
            try:
                return self.F.stats(mem)
            except RuntimeError:
                continue
        return {}


# -- variant 1: Python event loop, per-mode integrators in scaled time ---------------------------------------
@dataclass
class LoopMode:
    runs: dict             # size -> Fast integrator over `size` output intervals (u = h per interval)
    gmaps: dict            # size -> Fast guards at every output of runs[size] (its output array bound)
    one: Fast              # integrator over one interval (u = its length)
    guards: Fast           # x, p -> g
    gdot: Fast             # x, p -> dg/dt
    rhs: Fast              # x, p -> (x', x'') in unscaled time
    phi: Fast
    G: Fast
    M: Fast
    names: list
    directions: list
    boundary: int | None   # index of the guard at a known crank angle (exit / entry), if any


@dataclass
class LoopModel:
    modes: dict[str, LoopMode]
    peer: PeerModel
    n_out: int
    dt_out: float
    build_time_s: float


def grid_sizes(n_out: int, ratio: float = 1.5) -> list[int]:
    """Grid lengths of the per-mode integrators (CasADi fixes an integrator's grid when it is built): a
    geometric ladder up to n_out, so a call covers at most `ratio` times the outputs it needs (the rest with
    h = 0: a few cheap steps)."""
    sizes, n = [], 1
    while n < n_out:
        sizes.append(n)
        n = max(n + 1, math.ceil(n * ratio))
    return sizes + [n_out]


def build(mech: Mechanism, rtol: float, atol: float, n_out: int, dt_out: float, ext=None,
          max_steps: int = 100000) -> LoopModel:
    """Per-mode IDAS integrators on output grids of up to n_out intervals (scaled time), guards, projections.
    Without friction the slip direction enters no equation, so its guard (`slip_reversal`) is left out, as a
    user who knows the model would."""
    import casadi as ca

    wall = time.perf_counter()
    peer = translate(mech, ext)
    opts = {"reltol": rtol, "abstol": atol, "max_num_steps": max_steps, "disable_internal_warnings": True}
    h = ca.SX.sym("h")
    modes = {}
    for name, e in peer.modes.items():
        x, P = e["x"], e["p"]
        dae = {"x": x, "p": P, "u": h, "ode": h * e["rhs"]}
        names = peer.guard_names[name]
        keep = [i for i, g in enumerate(names) if not (g == "slip_reversal" and mech.friction == 0)]
        names, directions = [names[i] for i in keep], [peer.directions[name][i] for i in keep]
        e = {**e, "guards": e["guards"][keep], "gdot": e["gdot"][keep]}
        boundary = next((i for i, g in enumerate(names) if g in ("exit", "entry")), None)
        dense = ca.densify      # the buffers hold dense arrays: structural zeros must be stored
        guards = ca.Function(f"g_{name}", [x, P], [dense(e["guards"])])
        runs, gmaps = {}, {}
        for n in grid_sizes(n_out):
            runs[n] = Fast(ca.integrator(f"run_{name}_{n}", "idas", dae, 0.0, [float(i) for i in range(1, n + 1)],
                                         opts))
            gmaps[n] = Fast(guards.map(f"gm_{name}_{n}", "serial", n, [1], []), bind={0: runs[n].res[0]})
        modes[name] = LoopMode(
            runs=runs, gmaps=gmaps, one=Fast(ca.integrator(f"one_{name}", "idas", dae, 0.0, [1.0], opts)),
            guards=Fast(guards), gdot=Fast(ca.Function(f"gd_{name}", [x, P], [dense(e["gdot"])])),
            rhs=Fast(ca.Function(f"f_{name}", [x, P], [dense(e["rhs"]),
                                                         dense(ca.jtimes(e["rhs"], x, e["rhs"]))])),
            phi=Fast(ca.Function(f"phi_{name}", [e["q"], P], [dense(e["phi"])])),
            G=Fast(ca.Function(f"G_{name}", [e["q"], P], [dense(e["G"])])),
            M=Fast(ca.Function(f"M_{name}", [e["q"], P], [dense(e["M"])])),
            names=names, directions=directions, boundary=boundary)
    return LoopModel(modes, peer, n_out, dt_out, time.perf_counter() - wall)


@dataclass
class PeerRun:
    """Crank angle at the output times, statistics, events, failure (None if it finished)."""

    t: np.ndarray
    angle: np.ndarray
    stats: dict = field(default_factory=dict)
    events: list = field(default_factory=list)
    failure: str | None = None
    states: np.ndarray | None = None


def _values(peer: PeerModel, mech, drive, angle0, alpha, beta, ext) -> dict:
    values = dict(mech.parameter_values())
    dv = drive.parameter_values(angle0)
    values.update(drive_T0=dv["drive_T0"], drive_slope=dv["drive_slope"], baumgarte_alpha=alpha,
                  baumgarte_beta=beta)
    if ext is not None:
        values.update(ext.parameter_values())
    return values


def _count(stats: dict | None, F: Fast, locate: bool = False) -> None:
    """Add one call's IDAS counters (only when counting: reading them back costs a dict conversion)."""
    if stats is None:
        return
    st = F.stats()
    stats["integrator_calls"] += 1
    stats["steps"] += int(st.get("nsteps", 0))
    stats["rejected_steps"] += int(st.get("netfails", 0))
    stats["residual_evaluations"] += int(st.get("nfevals", 0))
    stats["jacobian_evaluations"] += int(st.get("nlinsetups", 0))
    if locate:
        stats["locate_steps"] += int(st.get("nsteps", 0))


def simulate(model: LoopModel, mech: Mechanism, drive: Drive, t_end: float, dt_out: float, angle0: float,
             speed0: float, alpha: float = 10.0, beta: float = 10.0, ext=None, ext_initial=None,
             max_events: int = 10000, count: bool = False, keep_states: bool = False) -> PeerRun:
    """Integrate the hybrid model from t = 0 with outputs every dt_out (the grid the model was built for).
    count: read IDAS's counters after every call (steps, rejected steps, ...; costs time, so off when timed)."""
    if drive.is_prescribed:
        raise ValueError("the CasADi peer integrates torque and motor drives only")
    n_out = int(np.floor(t_end / dt_out + 1e-9))
    if n_out != model.n_out or abs(dt_out - model.dt_out) > 1e-15:
        raise ValueError("the peer was built for another output grid")
    peer, nq = model.peer, model.peer.nq
    values = _values(peer, mech, drive, angle0, alpha, beta, ext)
    init = mech.initial_state(angle0, speed0)
    values.update(init.updates)
    mode = init.mode
    counters = dict(steps=0, rejected_steps=0, residual_evaluations=0, jacobian_evaluations=0, integrator_calls=0,
                    locate_steps=0) if count else None
    stats = dict(events=0, segments=1, newton_iterations=0, missed_predictions=0)
    pv = np.array([values[n] for n in peer.parameter_names], float)
    extra = np.asarray(ext_initial, float) if ext_initial is not None else np.zeros(peer.nx - 2 * nq)
    x = np.concatenate([_consistent(model.modes[mode], init.q, init.v, pv), extra])
    out = np.full((n_out + 1, peer.nx), np.nan)
    out[0] = x
    events: list = []
    t, j = 0.0, 0                  # j: index of the last output reached (t_j = j dt_out)
    failure = None
    while j < n_out:
        cm = model.modes[mode]
        gap = (j + 1) * dt_out - t
        K = _predict(cm, x, pv, gap, dt_out, n_out - j, nq)
        size = next(n for n in cm.runs if n >= K)
        run, gmap = cm.runs[size], cm.gmaps[size]
        u = run.args[3].reshape(-1)
        u[:] = 0.0
        u[0] = gap
        u[1:K] = dt_out
        try:
            xs = run(x, None, pv)[0][:K]
        except RuntimeError as exc:
            failure = f"t = {t:.6g} s: {exc}"
            break
        _count(counters, run)
        gs = gmap(None, pv)[0][:K].T
        g0 = cm.guards(x, pv)[0].ravel().copy()
        hit = _first_crossing(g0, gs, cm.directions)
        col = K if hit is None else hit[0]
        out[j + 1:j + 1 + col] = xs[:col]
        if hit is None:
            j += K
            t, x = j * dt_out, xs[-1].copy()
            if j < n_out and cm.boundary is not None:
                stats["missed_predictions"] += 1
            continue
        gi = hit[1]
        t_lo, x_lo, g_lo = (t, x, g0[gi]) if col == 0 else ((j + col) * dt_out, xs[col - 1].copy(), gs[gi, col - 1])
        x_hi, g_hi = xs[col].copy(), gs[gi, col]
        j += col
        try:
            tau, x = _locate(cm, pv, gi, x_lo, x_hi, g_lo, g_hi, (j + 1) * dt_out - t_lo, stats, counters)
        except RuntimeError as exc:
            failure = f"t = {t_lo:.6g} s: {exc}"
            break
        t = t_lo + tau
        guard = cm.names[gi]
        new_mode, updates, stop = geneva_transition(mech, mode, guard, values, x[:nq])
        events.append(dict(t_s=t, from_mode=mode, to_mode=new_mode, kind=guard))
        stats["events"] += 1
        if stop:
            failure = f"t = {t:.6g} s: {stop}"
            break
        if stats["events"] > max_events:
            failure = f"t = {t:.6g} s: too many events"
            break
        values.update(updates)
        mode = new_mode
        pv = np.array([values[n] for n in peer.parameter_names], float)
        x[:2 * nq] = _consistent(model.modes[mode], x[:nq], x[nq:2 * nq], pv)
        if guard == "entry":
            values["slide"] = 1.0 if _slip(mech, values, x[:nq], x[nq:2 * nq]) >= 0 else -1.0
            pv = np.array([values[n] for n in peer.parameter_names], float)
        stats["segments"] += 1
    ok = np.isfinite(out[:, 0])
    tt = dt_out * np.arange(n_out + 1)
    return PeerRun(tt[ok], out[ok, 0], {**stats, **(counters or {})}, events, failure,
                   out[ok] if keep_states else None)


def _predict(cm: LoopMode, x, pv, gap: float, dt: float, remaining: int, nq: int) -> int:
    """Outputs to integrate: up to the first one past the predicted crossing of the mode's boundary angle
    (g = theta - theta_b, g' = omega, g'' = the crank's acceleration: the later of the crossings at constant
    speed and at constant acceleration, capped at twice the first), with the margin MARGIN and two outputs; all that remain when the mode has
    no boundary or the crank is not predicted to reach it."""
    if cm.boundary is None:
        return remaining
    g = float(cm.guards(x, pv)[0].flat[cm.boundary])
    w = float(cm.gdot(x, pv)[0].flat[cm.boundary])
    acc = float(cm.rhs(x, pv)[0].flat[nq])
    if g >= 0:
        return min(remaining, 2)
    disc = w * w - 2 * acc * g
    T_quad = -2 * g / (w + math.sqrt(disc)) if disc > 0 and w + math.sqrt(disc) > 0 else math.inf
    # the later of constant speed and constant acceleration, at most twice the constant-speed time (a strong
    # deceleration at the start of a mode does not last: the quadratic alone may never reach the boundary)
    T = min(max(T_quad, -g / w), -2 * g / w) if w > 0 else T_quad
    if not math.isfinite(T):
        return remaining
    steps = 1 + math.ceil(max(T * MARGIN - gap, 0.0) / dt) + 2
    return max(1, min(remaining, steps))


def _locate(cm: LoopMode, pv, gi: int, x_lo, x_hi, g_lo: float, g_hi: float, span: float, stats: dict,
            counters: dict | None, tol: float = 1e-2, max_iter: int = 30):
    """(tau, x) at the zero of guard gi in (0, span] after x_lo.

    The first trial is the zero of the cubic Hermite interpolant of g (values and slopes g' at both outputs);
    then Newton on g(tau) with g' from the model, each trial one IDAS call of length tau from x_lo, a trial
    outside the bracket replaced by bisection. When the Newton correction d is below tol * span the state is
    moved by d x' + d^2/2 x'' (a Taylor step whose error, of order d^3, is far below the integration error)
    instead of one more IDAS call.
    """
    a, b = 0.0, span
    d_lo = float(cm.gdot(x_lo, pv)[0].flat[gi])
    d_hi = float(cm.gdot(x_hi, pv)[0].flat[gi])
    tau = min(max(_hermite_zero(g_lo, g_hi, span * d_lo, span * d_hi) * span, 1e-3 * span), span)
    x = x_lo
    for _ in range(max_iter):
        x = cm.one(x_lo, None, pv, tau)[0].ravel().copy()
        _count(counters, cm.one, True)
        stats["newton_iterations"] += 1
        g = float(cm.guards(x, pv)[0].flat[gi])
        if g == 0:
            break
        if (g > 0) == (g_lo > 0):
            a = tau
        else:
            b = tau
        d = -g / float(cm.gdot(x, pv)[0].flat[gi])
        if abs(d) <= tol * span and a <= tau + d <= b:
            f, fd = (r.ravel() for r in cm.rhs(x, pv))
            return tau + d, x + d * f + 0.5 * d * d * fd
        new = tau + d
        if not a < new < b:
            new = 0.5 * (a + b)
        if b - a <= 1e-15 * span:
            break
        tau = new
    return tau, x


def _hermite_zero(g0: float, g1: float, d0: float, d1: float) -> float:
    """The zero in [0, 1] of the cubic Hermite interpolant with values g0, g1 (opposite signs) and slopes d0,
    d1 (per unit interval), by bisection."""
    def cubic(s):
        h00, h10, h01, h11 = 2 * s**3 - 3 * s**2 + 1, s**3 - 2 * s**2 + s, -2 * s**3 + 3 * s**2, s**3 - s**2
        return h00 * g0 + h10 * d0 + h01 * g1 + h11 * d1
    a, b = 0.0, 1.0
    while b - a > 1e-12:
        m = 0.5 * (a + b)
        if (cubic(m) > 0) == (g0 > 0):
            a = m
        else:
            b = m
    return 0.5 * (a + b)


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


def _consistent(cm: LoopMode, q, v, p) -> np.ndarray:
    """(q, v) with q projected onto Phi = 0 (Gauss-Newton) and v onto G v = 0 (kinetic-energy metric)."""
    q = np.array(q, float).ravel()
    v = np.array(v, float).ravel()
    nq = len(q)
    for _ in range(30):
        phi = cm.phi(q, p)[0].ravel()
        if np.max(np.abs(phi), initial=0.0) <= 1e-14 * max(1.0, np.max(np.abs(q))):
            break
        q = q - np.linalg.lstsq(cm.G(q, p)[0].T.reshape(-1, nq), phi, rcond=None)[0]
    G = cm.G(q, p)[0].T.reshape(-1, nq).copy()
    M = cm.M(q, p)[0].T.copy()
    if G.size:
        MiGt = np.linalg.solve(M, G.T)
        v = v - MiGt @ np.linalg.solve(G @ MiGt, G @ v)
    return np.concatenate([q, v])


# -- variant 2: CasADi's own event support -------------------------------------------------------------------
#: the Geneva's discrete (mode) parameters, carried as states (zero rate) by the event-support variant
DISCRETE = ("slot", "lock_angle", "flank", "slide")


@dataclass
class EventsModel:
    integrator: Fast
    peer: PeerModel
    indicators: list       # (mode, guard) of each zero-crossing output
    n_out: int
    dt_out: float
    build_time_s: float


def build_events(mech: Mechanism, rtol: float, atol: float, n_out: int, dt_out: float, ext=None,
                 max_steps: int = 100000, max_events: int = 1000) -> EventsModel:
    """One IDAS integrator for the whole run with CasADi's event support (CasADi >= 3.7, 'experimental').

    The state is x = (q, v, thermal states, engaged flag, slot, lock angle, flank, slide); the rate is the
    engaged or dwell right-hand side by `if_else` on the flag (zero for the discrete states). Each guard of each
    mode is one zero-crossing output, positive while it cannot fire (CasADi fires on a fall through zero:
    -g for a rising guard, g for a falling one, 1 in the other mode). The `transition` function applies the
    Geneva's rules (`geneva_transition`) and projects q and v onto the new mode's constraints (two Gauss-Newton
    steps on Phi, velocity in the kinetic-energy metric), all symbolic. Not covered: the stall guard (a
    transition cannot stop the integration); without friction the slip guard is left out as in `build`.
    """
    import casadi as ca

    wall = time.perf_counter()
    peer = translate(mech, ext)
    g = mech.geometry
    nq = peer.nq
    e0 = next(iter(peer.modes.values()))
    x, P = e0["x"], e0["p"]
    D = ca.SX.sym("d", 1 + len(DISCRETE))           # engaged flag, then DISCRETE
    dv = {n: D[1 + i] for i, n in enumerate(DISCRETE)}
    idx = {n: peer.parameter_names.index(n) for n in DISCRETE}
    old = ca.vertcat(*[P[idx[n]] for n in DISCRETE])
    new = ca.vertcat(*[dv[n] for n in DISCRETE])

    def sub(expr):
        return ca.substitute(expr, old, new)

    eng, dw = peer.modes["engaged"], peer.modes["dwell"]
    engaged = D[0] > 0.5
    rhs = ca.vertcat(ca.if_else(engaged, sub(eng["rhs"]), sub(dw["rhs"])), ca.DM.zeros(D.shape))
    X = ca.vertcat(x, D)
    zero, indicators = [], []
    for name, e, active in (("engaged", eng, engaged), ("dwell", dw, ca.logic_not(engaged))):
        for i, (gname, direction) in enumerate(zip(peer.guard_names[name], peer.directions[name])):
            if gname == "stall" or (gname == "slip_reversal" and mech.friction == 0):
                continue
            value = -sub(e["guards"][i]) if direction > 0 else sub(e["guards"][i])
            zero.append(ca.if_else(active, value, 1.0))
            indicators.append((name, gname))

    def project(e, q, v, d):
        """q, v of mode e made consistent with its constraints (symbolic, discrete values d)."""
        def at(expr, qq, vv=v):
            return ca.substitute(ca.substitute(sub_d(expr, d), e["q"], qq), e["v"], vv)
        for _ in range(2):
            Gq = at(e["G"], q)
            q = q - ca.mtimes(ca.pinv(Gq), at(e["phi"], q))
        Gq, Mq = at(e["G"], q), at(e["M"], q)
        MiGt = ca.solve(Mq, Gq.T)
        v = v - ca.mtimes(MiGt, ca.solve(ca.mtimes(Gq, MiGt), ca.mtimes(Gq, v)))
        return q, v

    def sub_d(expr, d):
        return ca.substitute(expr, old, ca.vertcat(*[d[n] for n in DISCRETE]))

    q, v = x[:nq], x[nq:2 * nq]
    rest = x[2 * nq:]
    index = ca.SX.sym("index")
    post = X
    for i, (mode, gname) in enumerate(indicators):
        d = dict(dv)
        k = dv["slot"]
        if gname == "exit":
            d.update(slot=k + 1, lock_angle=(k + 0.5) * g.pitch)
            flag, target = 0.0, dw
        elif gname == "entry":
            d.update(flank=1.0)
            flag, target = 1.0, eng
        elif gname == "flank_switch":
            d.update(flank=-dv["flank"])
            flag, target = 1.0, eng
        else:                                       # slip_reversal
            d.update(slide=-dv["slide"])
            flag, target = 1.0, eng
        qn, vn = project(target, q, v, d)
        if gname == "entry":                        # the slip sign from the projected state
            alpha = qn[0] - 2 * math.pi * d["slot"]
            beta = qn[1] - d["slot"] * g.pitch
            u = g.crank_radius * vn[0] * ca.sin(alpha + beta) + g.pin_radius * (vn[0] + vn[1])
            d.update(slide=ca.if_else(u >= 0, 1.0, -1.0))
        after = ca.vertcat(qn, vn, rest, flag, *[d[n] for n in DISCRETE])
        post = ca.if_else(index == i, after, post)
    transition = ca.Function("transition", {"index": index, "t": ca.SX.sym("t"), "x": X, "p": P, "post_x": post},
                             ca.event_in(), ca.event_out())
    opts = {"reltol": rtol, "abstol": atol, "max_num_steps": max_steps, "disable_internal_warnings": True,
            "transition": transition, "max_events": max_events, "event_tol": 1e-12}
    dae = {"x": X, "p": P, "ode": rhs, "zero": ca.vertcat(*zero)}
    F = ca.integrator("events", "idas", dae, 0.0, [dt_out * i for i in range(1, n_out + 1)], opts)
    return EventsModel(Fast(F), peer, indicators, n_out, dt_out, time.perf_counter() - wall)


def simulate_events(model: EventsModel, mech: Mechanism, drive: Drive, t_end: float, dt_out: float, angle0: float,
                    speed0: float, alpha: float = 10.0, beta: float = 10.0, ext=None, ext_initial=None,
                    count: bool = False) -> PeerRun:
    """One call of the event-support integrator; events are counted from the engaged flag and the discrete
    states at the outputs (two mode changes between two outputs would count as none)."""
    if drive.is_prescribed:
        raise ValueError("the CasADi peer integrates torque and motor drives only")
    n_out = int(np.floor(t_end / dt_out + 1e-9))
    if n_out != model.n_out or abs(dt_out - model.dt_out) > 1e-15:
        raise ValueError("the peer was built for another output grid")
    peer, nq = model.peer, model.peer.nq
    values = _values(peer, mech, drive, angle0, alpha, beta, ext)
    init = mech.initial_state(angle0, speed0)
    values.update(init.updates)
    pv = np.array([values[n] for n in peer.parameter_names], float)
    extra = np.asarray(ext_initial, float) if ext_initial is not None else np.zeros(peer.nx - 2 * nq)
    d0 = [1.0 if init.mode == "engaged" else 0.0] + [values[n] for n in DISCRETE]
    x0 = np.concatenate([init.q, init.v, extra, d0])
    F = model.integrator
    failure = None
    try:
        xs = F(x0, None, pv)[0]
    except RuntimeError as exc:
        xs, failure = np.full((n_out, len(x0)), np.nan), str(exc)
    disc = xs[:, peer.nx:]
    changes = int(np.count_nonzero(np.any(np.diff(np.vstack([d0, disc]), axis=0) != 0, axis=1)))
    stats = {"events": changes, "segments": changes + 1}
    if count:
        st = F.stats()
        stats.update(steps=int(st.get("nsteps", 0)), rejected_steps=int(st.get("netfails", 0)),
                     residual_evaluations=int(st.get("nfevals", 0)),
                     jacobian_evaluations=int(st.get("nlinsetups", 0)))
    t = dt_out * np.arange(n_out + 1)
    angle = np.concatenate([[x0[0]], xs[:, 0]])
    ok = np.isfinite(angle)
    return PeerRun(t[ok], angle[ok], stats, [], failure)
