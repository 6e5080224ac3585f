"""Forward trajectory sensitivities of a hybrid run along its mode sequence (exact, not by differencing).

Between events the state z = [q, v, work, ext] of the diffrax form (`jax_model`, docs/theory.md §K4) obeys
z' = f(t, z, p), and its sensitivity S = dz/dtheta to the design values theta obeys the variational equation

    S' = f_z S + f_p P,          P = dp/dtheta,

integrated alongside z (one jax.jvp per column, so the cost grows with the number of design values, not with
the size of p). At an event where guard g reaches zero at time tau the implicit-function rule gives the
event time's derivative and the reset map R (re-initialisation in the new mode) the jump

    dtau/dtheta = -(g_z S- + g_p P) / (g_t + g_z f-),
    S+ = R_z (S- + f- dtau/dtheta) + R_t dtau/dtheta + R_p P - f+ dtau/dtheta

(Hiskens & Pai 2000, "Trajectory sensitivity analysis of hybrid systems", IEEE TCAS-I 47(2), eqs. (14)-(17); the
jump condition of Rozenvasser 1967 and Galan, Feehery & Barton 1999, Appl. Numer. Math. 31, 17-47; R_t is there
because a prescribed drive's constraint depends on t, and P is the parameters' derivative after the event, which
moves with the event time where a transition re-bases a prescribed drive's reference).
R is the project's consistent re-initialisation (dynamics/consistent.py): positions projected onto Phi = 0 with
minimum-norm corrections, velocities by Newton's impact law in the kinetic-energy metric, work and thermal states
kept. Without an impact the law is plastic (a projection; an impact with restitution whose rebound the new mode
absorbs ends at the same velocities); an impact on another mode's constraints (`Transition.contact`: a pin that
rebounds off the flank it struck into free flight) applies the law with its restitution e there first,
v+ = v- - (1 + e) M^-1 G^T (G M^-1 G^T)^-1 (G v- + Phi_t), e read from the parameter the transition names
(`Transition.restitution_parameter`) so that e is differentiated too; the impulse on the struck constraint is
differentiated with it. It is the same `consistent.reinitialise` the loop and the compiled run call, traced by jax
with one Newton step (at a consistent point that step's derivative is the converged projection's); every restart
state and impulse it gives is checked against the ones `apply_transition` computes. The per-mode pieces (rates,
guards, KKT solve, constraint parts) are the compiled run's `jax_model`; docs/architecture.md, "The sensitivity
pass", lists what is shared.

The derivatives hold while the event sequence does not change. Each event reports the change of every design value
that would change it (`EventSensitivity.grazing`: the guard's crossing turning tangential, from its local quadratic
g ~ g' (t - tau) + g'' (t - tau)^2 / 2; `rule_change`: another of the guard's transition rules applying, e.g. a
rebound turning plastic at the bounce speed); scenarios/studies/sensitivity.py warns where one lies within the
stated change.

The mode sequence, event times and discrete updates come from a finished run (its events table) and from the
project's own transition logic (`apply_transition`); this module adds the derivatives. Not covered (raises
`SensitivityUnavailable`): runs that failed or stopped, and transitions that change a parameter not declared
discrete (a continuous value recomputed at the event would need its own derivative) other than a prescribed
drive's reference, which is re-based with the event time and differentiated here (`_rebased_drive`), and the
parameters whose derivatives the seed gives for the new mode (`Seed.piece_dp`: the chain's path pieces).
"""
from __future__ import annotations

import time as _time
from dataclasses import dataclass, field

import numpy as np

from mechsim.dynamics.consistent import reinitialise
from mechsim.dynamics.hybrid import parameter_tuple, prepare
from mechsim.dynamics.backends.diffrax_common import ida_rows, mode_z, save_times
from mechsim.dynamics.jax_model import jax_model  # also enables float64
from mechsim.dynamics.programs import kept_key, program
from mechsim.dynamics.stats import new_stats
from mechsim.dynamics.traced import compile_ahead
from mechsim.dynamics.transitions import apply_transition

import jax  # noqa: E402  (after jax_model has switched on float64)
import jax.numpy as jnp  # noqa: E402


class SensitivityUnavailable(ValueError):
    """The derivatives do not exist here, or this module does not trace them (the message says which)."""


@dataclass(frozen=True)
class Seed:
    """The run's inputs differentiated with respect to n design values.

    dp: (len(model.parameter_names), n) d(parameter tuple)/dtheta, in the model's parameter order.
    dq0, dv0: (nq, n) derivatives of the initial guess of positions and velocities (before projection).
    dx0: (n_ext, n) derivatives of the extension's initial state (thermal: the bulk temperatures start at the
        ambient); None: zero.
    discrete: parameters a transition may change (mode flags, slot counters, geometry that is not traced, ...):
        their values do not depend on the design values, so their derivative is zero; a transition changing any
        other parameter raises (a prescribed drive's re-based reference excepted: `_rebased_drive`) unless piece_dp
        gives its derivative.
    piece_dp: values -> {parameter: (n,) derivative} of the parameters a transition sets for the mode with those
        values (the chain's path pieces: mechanisms/chain/sensitivity.py `chain_piece`); applied at the start
        and after every transition. None: transitions set only discrete parameters.
    hold: the coordinate the initial state holds while the others assemble (Mechanism.initial_state: the drive's),
        so that the initial guess's derivative is completed on the constraints with that coordinate's derivative
        kept (the implicit-function rule, `_ModePieces.hold`); None: the guess's derivative is taken as given.
    """

    dp: np.ndarray
    dq0: np.ndarray
    dv0: np.ndarray
    discrete: frozenset = frozenset()
    dx0: np.ndarray | None = None
    piece_dp: object = None
    hold: int | None = None

    @property
    def n(self) -> int:
        return self.dp.shape[1]


@dataclass
class EventSensitivity:
    """One transition: its time and the time's derivative; the state just before it and that state's total
    derivative along the moving event time, dz-/dtheta = S- + f- dtau/dtheta."""

    t: float
    kind: str
    guard: str
    from_mode: str
    to_mode: str
    dt: np.ndarray
    z: np.ndarray
    dz: np.ndarray
    #: the change of each design value (signed, in the seed's units) that makes the guard's crossing tangential
    #: (grazing: beyond it the event is gone, the sequence changes) from its local quadratic, inf where the
    #: crossing cannot turn back (`_event_fn`)
    grazing: np.ndarray | None = None
    #: the change of each design value (signed, seed units) that makes another of the guard's rules apply
    #: (`_margins_fn`: a rebound turning plastic below the bounce speed), inf where none can
    rule_change: np.ndarray | None = None
    #: an impact's impulse on the struck constraint (the events table's impulse_N_s) and its derivative
    impulse: float | None = None
    dimpulse: np.ndarray | None = None


@dataclass
class Sample:
    """Requested columns at one output time: values, their gradients (n,) at that fixed time and their rates of
    change in time along the path (the total d/dt: what a sample whose instant moves with the design adds, rate
    times the instant's derivative)."""

    t: float
    mode: str
    values: dict
    grads: dict
    rates: dict = field(default_factory=dict)


@dataclass
class PathSensitivity:
    events: list[EventSensitivity]
    samples: list[Sample]
    stats: dict = field(default_factory=dict)


# -- jax pieces built from the model's sympy description -----------------------------------------------------
class _ModePieces:
    """One mode's projection onto its constraints (from the mode's `JaxMode.constraint_parts`) and its read-outs,
    as jax functions."""

    def __init__(self, mf, mech, jmode):
        from mechsim.dynamics.codegen import lambdify      # sympy: only where a piece is traced
        s = mf.symbolic
        t, q, v, lam, x, params = s["t"], list(s["q"]), list(s["v"]), list(s["lam"]), list(s["x"]), list(s["params"])
        self.jmode, self.m = jmode, len(lam)
        a_mech = list(mech.symbols.a)
        self.readout_names = list(mf.readout_names)
        self._readouts = lambdify([t, q, v, a_mech, lam, x, params], s["readout_exprs"], "jax")

    def project(self, t, q, v, p, restitution=0.0):
        """The re-initialisation of every path (`consistent.reinitialise`) with one minimum-norm Newton step onto
        Phi = 0: at a point with Phi = 0 the step's derivative is the exact derivative of the converged projection
        (the terms it drops carry a factor Phi). restitution: Newton's impact law on these constraints (a traced
        number: its derivative is the law's e-derivative)."""
        if not self.m:
            return q, v
        return reinitialise(lambda qq, vv: self.jmode.constraint_parts(t, qq, vv, p) + (None,), q, v, xp=jnp,
                            steps=1, restitution=restitution)

    def impulse(self, t, q, v_before, v_after, p):
        """The impulse on this mode's constraints that takes v_before to v_after (M (v- - v+) = G^T P, so
        P = (G M^-1 G^T)^-1 G (v- - v+); `consistent.project_velocities` reports it so)."""
        M, G, _, _ = self.jmode.constraint_parts(t, q, v_after, p)
        return jnp.linalg.solve(G @ jnp.linalg.solve(M, G.T), G @ (v_before - v_after))

    def hold(self, t, q, v, p, i: int):
        """One Newton step on Phi = 0 and on G v + Phi_t = 0 in every coordinate but i (held, as the mechanism's
        initial assembly holds the drive's): at a consistent point it changes nothing, and its derivative is the
        implicit-function rule dq_o = -Phi_qo^-1 (Phi_qi dq_i + Phi_p dp), likewise for v. Needs as many other
        coordinates as constraints (else the guess is left as it is)."""
        nq = q.shape[0]
        if not self.m or self.m != nq - 1:
            return q, v
        keep = jnp.array([c for c in range(nq) if c != i])
        _, G, phi, _ = self.jmode.constraint_parts(t, q, v, p)
        q = q.at[keep].add(-jnp.linalg.solve(G[:, keep], phi))
        _, G, _, rel = self.jmode.constraint_parts(t, q, v, p)
        v = v.at[keep].add(-jnp.linalg.solve(G[:, keep], rel))
        return q, v

    def readouts(self, t, q, v, a, lam, x, p):
        return [jnp.asarray(e, jnp.float64) for e in self._readouts(t, q, v, a, lam, x, p)]


# -- the compiled segment solve of z and S -------------------------------------------------------------------
N_SAVE = 16
#: sensitivity columns per compiled solve (a request for fewer is padded with zeros, more takes a multiple)
COLUMNS = 8


def _padded(a, n: int) -> np.ndarray:
    a = np.asarray(a, float)
    return np.hstack([a, np.zeros((a.shape[0], n - a.shape[1]))])
def _segment_solve(jmod, model, n: int, solver: str, max_steps: int):
    """(the compiled solve of z and S over one segment, seconds spent compiling it now: 0 when compiled before);
    the tolerances are its arguments (rtol, atol last), so one compilation serves every tolerance of the model."""
    wall = _time.perf_counter()
    fn, fresh = program("sensitivity_segment_solve", model, (n, solver, max_steps),
                        lambda: _compile_segment_solve(jmod, model, n, solver, max_steps))
    return fn, (_time.perf_counter() - wall if fresh else 0.0)


def _compile_segment_solve(jmod, model, n: int, solver: str, max_steps: int):
    def make():
        import diffrax          # traced in: a process that loads the kept program runs it without diffrax

        def field_(t, y, args):
            k, p, P = args
            z, S = y

            def f(zz, pp):
                return jmod.rates(k, t, zz, pp)
            zdot = f(z, p)
            Sdot = jax.vmap(lambda s, dp: jax.jvp(f, (z, p), (s, dp))[1], in_axes=(1, 1), out_axes=1)(S, P)
            return zdot, Sdot

        term = diffrax.ODETerm(field_)
        method = getattr(diffrax, solver)()

        def solve(k, t0, t1, z0, S0, p, P, ts, rtol, atol):
            controller = diffrax.PIDController(rtol=rtol, atol=atol)
            saveat = diffrax.SaveAt(subs=[diffrax.SubSaveAt(ts=ts), diffrax.SubSaveAt(t1=True)])
            sol = diffrax.diffeqsolve(term, method, t0, t1, None, (z0, S0), args=(k, p, P), saveat=saveat,
                                      stepsize_controller=controller, max_steps=max_steps, throw=False,
                                      adjoint=diffrax.ForwardMode())
            return dict(z=sol.ys[0][0], S=sol.ys[0][1], z1=sol.ys[1][0][0], S1=sol.ys[1][1][0],
                        result=sol.result._value, ok=sol.result._value == int(diffrax.RESULTS.successful._value),
                        steps=sol.stats["num_steps"])
        return jax.jit(solve)

    nz, npar = jmod.nz, len(model.parameter_names)
    example = (np.int32(0), 0.0, 1.0, np.zeros(nz), np.zeros((nz, n)), np.zeros(npar), np.zeros((npar, n)),
               np.ones(N_SAVE), 1e-8, 1e-10)
    return compile_ahead("sensitivity_segment_solve", kept_key(model, (n, solver, max_steps)), make, example)


class _Tools:
    """The jitted pieces of one model (jax dispatches the lambdified expressions op by op otherwise, which costs
    seconds per call): the event rule of all modes, and each mode's reset and read-outs, compiled when the path
    first needs them (a run need not visit every mode: chain-mech1-torque for 12 s enters 3 of its 4), so a pass
    compiles only what its own path uses and a later pass of the same model only what is new to it. Only the
    read-outs depend on the columns a pass asks for: a pass with other columns compiles its read-outs alone."""

    def __init__(self, mech, model, jmod, n: int):
        self.mech, self.model, self.jmod, self.n = mech, model, jmod, n
        self._pieces: dict = {}
        nz, nq, npar = jmod.nz, jmod.nq, len(model.parameter_names)
        z, S, p, P = np.zeros(nz), np.zeros((nz, n)), np.zeros(npar), np.zeros((npar, n))
        # the examples fix the shapes: each piece is compiled ahead of time, so its compilation is counted apart
        # from the solve (the seconds `_compiled` returns)
        self._examples = {"event": (np.int32(0), np.int32(0), 0.0, z, S, p, P),
                          "reset": (0.0, z, np.zeros(nq), p, S, P, np.zeros(n)),
                          "sample": (0.0, z, S, p, P, np.zeros(nq)), "margins": (z, S, p, P)}
        self._compiled_fns: dict = {}

    def _compiled(self, key: tuple, make) -> tuple:
        """(the compiled piece `key`, seconds spent compiling it now: 0 when compiled before); `make()` gives the
        jitted function, key[0] names its example arguments."""
        fn = self._compiled_fns.get(key)
        if fn is not None:
            return fn, 0.0
        wall = _time.perf_counter()
        fn = self._compiled_fns[key] = compile_ahead("sensitivity_tools", kept_key(self.model, (self.n, key)), make,
                                                     self._examples[key[0]])
        return fn, _time.perf_counter() - wall

    def piece(self, name: str) -> _ModePieces:
        """Mode `name`'s projection and read-outs (lambdified on first use)."""
        if name not in self._pieces:
            self._pieces[name] = _ModePieces(self.model.modes[name], self.mech, self.jmod.modes[self.jmod.index(name)])
        return self._pieces[name]

    def event(self):
        """The event rule of every mode (mode and guard are traced): `_event_fn`."""
        return self._compiled(("event",), lambda: _event_fn(self.jmod))

    def reset(self, name: str, hold: int | None = None, impact: tuple | None = None):
        """The re-initialisation in mode `name` (with `hold`: the initial state's; with `impact`, an impact law
        first, `_reset_fn`)."""
        return self._compiled(("reset", name, hold, impact), lambda: self._reset_fn(name, self.piece(name), hold,
                                                                                   impact))

    def rule_margins(self, mode: str, guard: str):
        """The `when` values of the rules of (mode, guard) that have one, with their derivatives along the event
        (`_margins_fn`), or None where no rule has one (the choice of rule cannot change)."""
        rules = (self.mech.transition_rules() or {}).get((mode, guard), ())
        whens = tuple(r.when for r in rules if r.when is not None and not r.numeric)
        if not whens:
            return None
        return self._compiled(("margins", mode, guard), lambda: _margins_fn(self.jmod, self.model, whens))

    def sample(self, name: str, columns: tuple, rates: bool = False):
        """The read-outs `columns` of mode `name` with their gradients, and with `rates` their rates (`_sample_fn`)."""
        return self._compiled(("sample", name, columns, rates),
                              lambda: self._sample_fn(name, self.piece(name), columns, rates))

    def _reset_fn(self, name, pc, hold: int | None = None, impact: tuple | None = None):
        """(z+, dz+ = R_t dt + R_z dz + R_p P, f(z+), P_1, dP_1) of the re-initialisation in mode `name` at time t
        (the initial state's: with `hold`, the guess first completed with that coordinate held, `_ModePieces.hold`).

        impact: None, or (contact, e_index, e) of an impact (`Transition.contact`, `Transition.restitution`): where
        contact is another mode, Newton's law with restitution e (the parameter number e_index where it is one, so
        that e is differentiated; else the number e) on that mode's constraints comes first, then the projection
        onto the new mode's (`transitions.apply_transition`). P_1 is the impulse on the struck mode's first
        constraint (the events table's impulse_N_s; 0 without an impact), dP_1 its derivative."""
        nq = self.jmod.nq
        jm = self.jmod.modes[self.jmod.index(name)]
        struck = self.piece(impact[0]) if impact is not None and impact[0] != name else None

        def reset(t, z, shift, p, dz, P, dt):
            # R depends on t through rheonomic constraints (a prescribed drive): R_t dtau is part of the jump
            def r(tt, zz, pp):
                qq, vv = zz[:nq] - shift, zz[nq:2 * nq]
                if hold is not None:
                    qq, vv = pc.hold(tt, qq, vv, pp, hold)
                impulse = jnp.zeros(())
                if struck is not None:
                    e = pp[impact[1]] if impact[1] is not None else impact[2]
                    q_hit, v_hit = struck.project(tt, qq, vv, pp, restitution=e)
                    impulse = struck.impulse(tt, q_hit, vv, v_hit, pp)[0]
                    qq, vv = q_hit, v_hit
                q_new, v_new = pc.project(tt, qq, vv, pp)
                if impact is not None and struck is None:
                    impulse = pc.impulse(tt, q_new, vv, v_new, pp)[0]
                return jnp.concatenate([q_new, v_new, zz[2 * nq:]]), impulse
            (z_new, imp), (dz_new, dimp) = jax.vmap(lambda c, a, b: jax.jvp(r, (t, z, p), (c, a, b)),
                                                    in_axes=(0, 1, 1), out_axes=((None, None), (1, 0)))(dt, dz, P)
            return z_new, dz_new, jm.rates(t, z_new, p), imp, dimp
        return jax.jit(reset)

    def _sample_fn(self, name, pc, columns: tuple, rates: bool):
        jm = self.jmod.modes[self.jmod.index(name)]
        coords, work_names = self.model.coordinates, self.model.work_names
        ext_names = self.model.extension_names

        def everything(t, zz, pp, offset):
            q, v, w, x = jm.split(zz)
            a, lam = jm.kkt(t, q, v, x, pp)
            cols = {}
            for i, c in enumerate(coords):
                for suffix, val in (("angle_rad", q[i] + offset[i]), ("speed_rad_s", v[i]), ("accel_rad_s2", a[i]),
                                    ("position_m", q[i] + offset[i]), ("speed_m_s", v[i]), ("accel_m_s2", a[i])):
                    cols[f"{c}_{suffix}"] = val
            for rname, val in zip(pc.readout_names, pc.readouts(t, q, v, a, lam, x, pp)):
                cols[rname] = val
            for i, wname in enumerate(work_names):
                cols[f"work_{wname}_J"] = w[i]
            for i, xname in enumerate(ext_names):
                cols[xname] = x[i]
            return jnp.stack([jnp.asarray(cols[c] if c in cols else jnp.nan, jnp.float64) for c in columns])

        def sample(t, z, S, p, P, offset):
            values, grads = jax.vmap(lambda s, dp: jax.jvp(lambda zz, pp: everything(t, zz, pp, offset), (z, p),
                                                           (s, dp)), in_axes=(1, 1), out_axes=(None, 1))(S, P)
            if not rates:
                return values, grads, jnp.full_like(values, jnp.nan)
            dvalues = jax.jvp(lambda tt, zz: everything(tt, zz, p, offset), (t, z),
                              (jnp.ones_like(t), jm.rates(t, z, p)))[1]
            return values, grads, dvalues
        return jax.jit(sample)


def _tools(mech, model, jmod, n: int) -> _Tools:
    """The model's jitted tools for n seed directions (each piece compiled on its first use, `_Tools`)."""
    return program("sensitivity_tools", model, (n,), lambda: _Tools(mech, model, jmod, n))[0]


def path_sensitivities(mech, drive, settings, events: list[dict], seed: Seed, sample_times, columns,
                       t_end: float, dt_out: float, angle0: float, speed0: float, ext=None, ext_initial=None,
                       t0: float = 0.0, solver: str = "Dopri8", rates: bool = False) -> PathSensitivity:
    """Integrate z and S = dz/dtheta along the mode sequence of a finished run.

    events: the run's events-table rows (t_s, from_mode, to_mode, kind, guard), in order; the run must have
    reached t_end. sample_times: output times at which `columns` (coordinate columns like `wheel_accel_rad_s2`,
    mode read-outs like `contact_force_N`, work columns `work_<name>_J`) are evaluated with their gradients, and
    with `rates` their rates of change in time too (`Sample.rates`; NaN without: one jvp more per sample).
    Tolerances are the run's (settings.rtol, settings.atol), applied to z and S alike.
    """
    wall0, cpu0 = _time.perf_counter(), _time.process_time()
    start = prepare(mech, drive, settings, t_end, dt_out, angle0, speed0, ext, ext_initial, t0)
    model = start.model
    jmod = jax_model(model)
    columns = tuple(columns)
    n_used = seed.n
    n = COLUMNS * -(-n_used // COLUMNS)      # padded with zero columns: one compilation serves 1..COLUMNS values
    tools = _tools(mech, model, jmod, n)
    nq, nz = jmod.nq, jmod.nz
    P = _padded(seed.dp, n)
    # the statistics every path reports (dynamics/stats.py), with the pass's wall and CPU time beside them
    stats = new_stats("sensitivity", solver, start.derive_time, unavailable={
        key: "not counted by the sensitivity pass" for key in ("accepted_steps", "rejected_steps",
                                                              "residual_evaluations", "jacobian_evaluations")})

    def compiled(piece):
        """A tool of the pass (`_Tools`), its compilation (if this is its first use) counted in the statistics."""
        fn, seconds = piece
        stats["compile_time_s"] += seconds
        return fn
    solve, compile_s = _segment_solve(jmod, model, n, solver, settings.max_steps)
    stats["compile_time_s"] += compile_s
    stats["compilations"] += bool(compile_s)

    # the initial state: the projection of the initial guess, differentiated (the guess is re-based by a constant)
    mode, values, p, offset = start.mode, start.values, np.asarray(start.p), np.asarray(start.offset, float)
    init = mech.initial_state(angle0, speed0)
    guess = np.concatenate([np.asarray(init.q, float), np.asarray(init.v, float), np.zeros(nz - 2 * nq)])
    nw = len(model.work_names)
    dx0 = np.zeros((nz - 2 * nq - nw, seed.n)) if seed.dx0 is None else seed.dx0
    dguess = np.vstack([_padded(seed.dq0, n), _padded(seed.dv0, n), np.zeros((nw, n)), _padded(dx0, n)])
    z = mode_z(model.modes[mode], start.y)
    guess[2 * nq + nw:] = z[2 * nq + nw:]
    names = list(model.parameter_names)
    if seed.piece_dp is not None:
        P = _pieces_set(P, names, seed.piece_dp(values))
    initial = compiled(tools.reset(mode, seed.hold))
    z_init, S, _, _, _ = (np.asarray(x) for x in initial(t0, guess, offset, p, dguess, P, np.zeros(n)))
    _check_restart(z_init[:2 * nq], z[:2 * nq], "the initial state")

    samples_t = np.sort(np.asarray(list(sample_times), float))
    samples: list[Sample] = []
    out_events: list[EventSensitivity] = []
    rows = [e for e in events if e.get("kind") != "rebound absorbed"]
    t = t0
    for ts_j in samples_t[samples_t == t0]:
        vals, grads, dvals = (np.asarray(x) for x in compiled(tools.sample(mode, columns, rates))(t0, z, S, p, P,
                                                                                                 offset))
        samples.append(Sample(t0, mode, dict(zip(columns, map(float, vals))), dict(zip(columns, grads[:, :n_used])),
                              dict(zip(columns, map(float, dvals)))))
    for i in range(len(rows) + 1):
        t1 = float(rows[i]["t_s"]) if i < len(rows) else t_end
        k = jmod.index(mode)
        # integrate to t1, saving at the sample times inside (t, t1], in chunks of N_SAVE
        inside = samples_t[(samples_t > t) & (samples_t <= t1)] if i < len(rows) else samples_t[samples_t > t]
        while True:
            chunk = inside[:N_SAVE]
            stop = t1 if len(inside) <= N_SAVE else float(chunk[-1])
            ts = save_times(chunk, t, stop, N_SAVE)
            out = jax.device_get(solve(np.int32(k), float(t), float(stop), z, S, p, P, ts, float(settings.rtol),
                                       float(settings.atol)))
            stats["segments"] += 1
            stats["steps"] += int(out["steps"])
            if not bool(out["ok"]):
                from mechsim.dynamics.backends.diffrax_solvers import result_message
                raise SensitivityUnavailable(f"the sensitivity integration failed in mode '{mode}' after "
                                             f"t = {t:.6g} s: {result_message(out['result'])}")
            sample = compiled(tools.sample(mode, columns, rates)) if len(chunk) else None
            for j, ts_j in enumerate(chunk):
                vals, grads, dvals = (np.asarray(x) for x in sample(float(ts_j), out["z"][j], out["S"][j], p, P,
                                                                    offset))
                samples.append(Sample(float(ts_j), mode, dict(zip(columns, map(float, vals))),
                                      dict(zip(columns, grads[:, :n_used])), dict(zip(columns, map(float, dvals)))))
            t, z, S = float(stop), np.asarray(out["z1"]), np.asarray(out["S1"])
            inside = inside[len(chunk):]
            if stop == t1:
                break
        if i == len(rows):
            break
        row = rows[i]
        mf = model.modes[mode]
        if row["from_mode"] != mode:
            raise SensitivityUnavailable(f"events table out of step: row at t = {t1:.6g} s leaves "
                                         f"'{row['from_mode']}', the path is in '{mode}'")
        j = list(mf.guard_names).index(row["guard"])
        event = compiled(tools.event())
        t, z, dtau, dz, gdot, a_end, lam_end, graze = (np.asarray(x) for x in event(np.int32(k), np.int32(j),
                                                                                    float(t), z, S, p, P))
        t = float(t)
        if not (np.isfinite(gdot) and abs(gdot) > 0):
            raise SensitivityUnavailable(f"guard '{row['guard']}' reaches zero tangentially at t = {t:.6g} s "
                                         "(grazing): the event time is not differentiable there")
        y_end = ida_rows(mf, nq, z, np.zeros_like(z), a_end, lam_end[:mf.m])[0][0]     # the IDA layout
        res = apply_transition(mech, model, parameter_tuple, mode, values, t, y_end, [j], offset)
        if res.failure or res.y is None:
            raise SensitivityUnavailable(f"the transition at t = {t:.6g} s does not restart here "
                                         f"({(res.failure or {}).get('reason', 'no state')})")
        changed = [key for key in res.values if res.values[key] != values.get(key)]
        if model.prescribed and "drive_time0" in changed:
            P = _rebased_drive(P, names, values, t, dtau)
        pieces = {}
        if seed.piece_dp is not None:
            # every parameter of the new piece gets its own derivative (even one whose number did not change)
            pieces = seed.piece_dp(res.values)
            P = _pieces_set(P, names, pieces)
        traced = [key for key in changed if key not in seed.discrete and key not in pieces and not (
            model.prescribed and key in ("drive_angle0", "drive_time0"))]
        if traced:
            raise SensitivityUnavailable(f"the transition '{row['kind']}' at t = {t:.6g} s recomputes "
                                         f"{', '.join(traced)}, whose derivative is not traced")
        rule_change = np.full(n_used, np.inf)
        margins = tools.rule_margins(mode, row["guard"])
        if margins is not None:
            w, dw = (np.asarray(x) for x in compiled(margins)(z, dz, p, P))
            # the rules up to the one taken (the first with w > 0) decide: the change that brings one to zero
            upto = int(np.argmax(w > 0)) + 1 if np.any(w > 0) else len(w)
            with np.errstate(divide="ignore", invalid="ignore"):
                steps = np.where(dw[:upto, :n_used] != 0, -w[:upto, None] / dw[:upto, :n_used], np.inf)
            rule_change = steps[np.argmin(np.abs(steps), axis=0), np.arange(n_used)]
        tr = res.transition
        impact = None
        if tr is not None and tr.restitution is not None and tr.contact is not None:
            names_ix = {nm: i for i, nm in enumerate(names)}
            e_index = names_ix[tr.restitution_parameter] if tr.restitution_parameter else None
            if e_index is not None and float(p[e_index]) != float(tr.restitution):
                raise SensitivityUnavailable(f"the impact at t = {t:.6g} s has restitution {tr.restitution:g}, its "
                                             f"parameter '{tr.restitution_parameter}' {float(p[e_index]):g}")
            impact = (tr.contact, e_index, 0.0 if e_index is not None else float(tr.restitution))
        shift = np.asarray(res.offset, float) - offset
        new_mode, p_new = res.mode, np.asarray(res.p)
        reset = compiled(tools.reset(new_mode, impact=impact))
        z_new, dz_new, f_new, imp, dimp = (np.asarray(x) for x in reset(t, z, shift, p_new, dz, P, dtau))
        z_ref = mode_z(model.modes[new_mode], res.y)
        _check_restart(z_new, z_ref, f"the restart after '{row['kind']}' at t = {t:.6g} s")
        impulse = None
        if impact is not None:
            impulse = float(imp)
            ref = res.rows[-1].get("impulse_N_s")
            if ref is not None and not abs(impulse - ref) <= 1e-8 * max(abs(ref), 1e-300) + 1e-15:
                raise SensitivityUnavailable(f"the impact at t = {t:.6g} s: the differentiated impulse {impulse:.9g} "
                                             f"differs from the project's {ref:.9g}")
        out_events.append(EventSensitivity(t, row["kind"], row["guard"], mode, res.mode, dtau[:n_used], z.copy(),
                                           dz[:, :n_used], graze[:n_used], rule_change, impulse,
                                           None if impact is None else dimp[:n_used]))
        S = dz_new - np.outer(f_new, dtau)
        z = z_ref
        mode, values, p, offset = new_mode, res.values, p_new, np.asarray(res.offset, float)
    stats["events"] = stats["restarts"] = len(out_events)
    stats["solve_time_s"] = _time.perf_counter() - wall0 - stats["compile_time_s"]
    stats["wall_time_s"] = _time.perf_counter() - wall0
    stats["cpu_time_s"] = _time.process_time() - cpu0
    return PathSensitivity(out_events, samples, stats)


def _rebased_drive(P: np.ndarray, names: list[str], values: dict, t: float, dtau: np.ndarray) -> np.ndarray:
    """dp/dtheta after a re-based prescribed drive (dynamics/transitions.py `rebased`): its reference becomes
    angle0' = angle0 - shift + speed (tau - time0) and time0' = tau at the event time tau, so
    d angle0' = d angle0 + (tau - time0) d speed + speed (d tau - d time0) and d time0' = d tau (the shift is a
    whole number of symmetry steps: no derivative)."""
    P = P.copy()
    ia, it, isp = names.index("drive_angle0"), names.index("drive_time0"), names.index("drive_speed")
    d_tau = np.zeros(P.shape[1])
    d_tau[:len(dtau)] = dtau
    P[ia] = P[ia] + (t - values["drive_time0"]) * P[isp] + values["drive_speed"] * (d_tau - P[it])
    P[it] = d_tau
    return P


def _pieces_set(P: np.ndarray, names: list[str], rows: dict) -> np.ndarray:
    """dp/dtheta with the rows of the parameters a transition sets replaced by their derivatives (`Seed.piece_dp`)."""
    P = P.copy()
    for name, row in rows.items():
        P[names.index(name)] = 0.0
        P[names.index(name), :len(row)] = row
    return P


def _check_restart(mine: np.ndarray, ref: np.ndarray, what: str) -> None:
    """The jax reset must give the project's restart state (to far below any tolerance of a run)."""
    scale = max(1.0, float(np.max(np.abs(ref))))
    if not np.max(np.abs(mine - ref)) <= 1e-8 * scale:
        raise SensitivityUnavailable(f"{what}: the differentiated reset does not reproduce the project's "
                                     f"re-initialisation (difference {np.max(np.abs(mine - ref)):.2e})")


def _margins_fn(jmod, model, whens: tuple):
    """(w, dw) of the rules' `when` functions at the event state z with their derivatives along the moving event,
    dw = w_z dz + w_p P: the rule that applies is the first with w > 0, so where a w reaches zero within a change
    of the design values another rule applies there (a rebound becoming a plastic impact at the bounce speed)."""
    from mechsim.dynamics.backends.jax_transitions import ByName
    nq = jmod.nq
    index = {n: i for i, n in enumerate(model.parameter_names)}

    def margins(z, dz, p, P):
        def w(zz, pp):
            named = ByName(pp, index)
            return jnp.stack([jnp.asarray(f(zz[:nq], zz[nq:2 * nq], named, jnp), jnp.float64) for f in whens])
        return jax.vmap(lambda a, b: jax.jvp(w, (z, p), (a, b)), in_axes=(1, 1), out_axes=(None, 1))(dz, P)
    return jax.jit(margins)


def _event_fn(jmod):
    """Event time refined by one Newton step on the guard, its derivative by the implicit-function rule
    (Hiskens & Pai 2000, eq. (14)), and the state's total derivative at the moving event, S + f dtau (jitted;
    mode k and guard j are traced)."""
    def event(k, j, t, z, S, p, P):
        def g(tt, zz, pp):
            return jmod.guards(k, tt, zz, pp)[j]
        f = jmod.rates(k, t, z, p)
        g0, gdot = jax.jvp(lambda tt, zz: g(tt, zz, p), (t, z), (jnp.ones_like(t), f))
        delta = jnp.where(jnp.abs(g0) < 1e-6 * jnp.abs(gdot) * jnp.maximum(1.0, jnp.abs(t)), -g0 / gdot, 0.0)
        # the sensitivities carried over the step too, by their variational equation S' = f_z S + f_p P: they
        # grow with the phase where p moves the period, so S at the run's event time, a tolerance away from this
        # path's own, is not S at the event (geneva-torque's cycle time by the drive torque, 33 engagements in:
        # 2e-3 of the derivative)
        Sdot = jax.vmap(lambda s, dp: jax.jvp(lambda zz, pp: jmod.rates(k, t, zz, pp), (z, p), (s, dp))[1],
                        in_axes=(1, 1), out_axes=1)(S, P)
        t = t + delta
        z = z + f * delta
        S = S + Sdot * delta
        f = jmod.rates(k, t, z, p)
        gdot = jax.jvp(lambda tt, zz: g(tt, zz, p), (t, z), (jnp.ones_like(t), f))[1]
        dg = jax.vmap(lambda s, dp: jax.jvp(lambda zz, pp: g(t, zz, pp), (z, p), (s, dp))[1], in_axes=(1, 1))(S, P)
        dtau = -dg / gdot

        def rate(tt, zz):
            return jax.jvp(lambda t_, z_: g(t_, z_, p), (tt, zz), (jnp.ones_like(tt), jmod.rates(k, tt, zz, p)))[1]
        gddot = jax.jvp(rate, (t, z), (jnp.ones_like(t), f))[1]
        # the guard near tau: g ~ gdot (t - tau) + gddot (t - tau)^2 / 2, turning back at gdot^2 / (2 |gddot|) past
        # zero where gdot gddot < 0; a change of the design values that moves g by that much makes the crossing
        # tangential (grazing), and beyond it the event is gone
        graze = jnp.where(gdot * gddot < 0, -jnp.sign(gdot) * gdot ** 2 / (2 * jnp.abs(gddot)) / dg, jnp.inf)
        _, a, lam, _ = jmod.evaluate(k, t, z, p)
        return t, z, dtau, S + jnp.outer(f, dtau), gdot, a, lam, graze
    return jax.jit(event)
