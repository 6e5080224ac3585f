"""One mode of a derived model as jax.numpy functions: the ODE form the diffrax backend integrates.

Built from the SAME sympy pieces the IDA residual is generated from (`ModeFunctions.symbolic`), lambdified to
jax.numpy in float64. The state is z = [q, v, work, ext]; accelerations and multipliers come from the
augmented KKT system of the mode (index-1 with Baumgarte's stabilisation, docs/theory.md §K4):

    [[M, G^T - dQ/dlam], [G, 0]] [a; lam] = [Q(lam = 0); -gamma - 2 alpha Phi' - beta^2 Phi]

(Q is linear in lam, which is how Coulomb friction on a constraint force enters). Work states integrate the
mode's power flows; extension (thermal) rows are linear in their rates, F = A x' + b, so x' = -A^-1 b.
"""
from __future__ import annotations

from dataclasses import dataclass
from functools import cached_property
from typing import Callable

import jax

from mechsim.dynamics import user_cache
from mechsim.dynamics.backends import xla_options

xla_options.request()  # XLA's CPU options, before JAX starts its backend (dynamics/backends/xla_options.py)
jax.config.update("jax_enable_x64", True)
user_cache.use_for_jax(jax)        # compiled programs reused across processes (dynamics/user_cache.py)

import jax.numpy as jnp  # noqa: E402

from mechsim.dynamics import kkt  # noqa: E402
from mechsim.dynamics.model import ModeFunctions  # noqa: E402
from mechsim.dynamics.programs import program  # noqa: E402


def _stack(values, shape) -> jnp.ndarray:
    if not len(values):
        return jnp.zeros(shape)
    return jnp.reshape(jnp.stack([jnp.asarray(x, dtype=jnp.float64) for x in values]), shape)


@dataclass(frozen=True, eq=False)
class JaxMode:
    """The jax functions of one mode. All take the parameter vector p (traced) last.

    Layout: z = [q (nq), v (nq), work (nw), ext (ne)]; the IDA layout (`ida_rows`) is
    y = [q, v, lam (m), mu (m, index2 only: zero), work, ext].
    """

    name: str
    nq: int
    m: int
    nw: int
    ne: int
    n_mu: int
    guard_names: tuple[str, ...]
    guard_directions: tuple[int, ...]
    alpha_index: int
    beta_index: int
    #: the mode's sympy pieces, lambdified when the mode is first traced (`_functions`): a process that loads its
    #: programs traced already (dynamics/traced.py) needs only the layout above, not the derivation behind them
    source: ModeFunctions
    parameter_names: tuple[str, ...]

    @cached_property
    def _functions(self) -> tuple[bool, Callable, Callable]:
        """(ext_diagonal, the KKT pieces' function, the powers', guards' and extension rows' function)."""
        return _lambdified(self.source, self.parameter_names)

    @property
    def ext_diagonal(self) -> bool:
        return self._functions[0]

    @property
    def _kkt_parts(self) -> Callable:
        return self._functions[1]

    @property
    def _post(self) -> Callable:
        return self._functions[2]

    @property
    def nz(self) -> int:
        return 2 * self.nq + self.nw + self.ne

    @property
    def ng(self) -> int:
        return len(self.guard_names)

    def split(self, z):
        nq, nw = self.nq, self.nw
        return z[:nq], z[nq:2 * nq], z[2 * nq:2 * nq + nw], z[2 * nq + nw:]

    def _kkt_pieces(self, t, q, v, x, p) -> tuple:
        """(M, G, Q0, Ql, gamma, Phi, Phi') at one state, from the one lambdified list of the mode."""
        nq, m = self.nq, self.m
        parts = self._kkt_parts(t, q, v, x, p)
        i = 0

        def take(n, shape):
            nonlocal i
            out = _stack(parts[i:i + n], shape)
            i += n
            return out

        M = take(nq * nq, (nq, nq))
        G = take(m * nq, (m, nq))
        Q0 = take(nq, (nq,))
        Ql = take(nq * m, (nq, m))
        return M, G, Q0, Ql, take(m, (m,)), take(m, (m,)), take(m, (m,))

    def constraint_parts(self, t, q, v, p) -> tuple:
        """(M, G, Phi, Phi') at one state: the mass matrix and the constraints' value, Jacobian and time
        derivative G v + Phi_t (what a projection onto the constraints needs; `dynamics/sensitivity.py`)."""
        M, G, _, _, _, phi, phi_dot = self._kkt_pieces(t, q, v, jnp.zeros(self.ne), p)
        return M, G, phi, phi_dot

    def kkt(self, t, q, v, x, p):
        """Accelerations a and multipliers lam from the Baumgarte-stabilised KKT system."""
        M, G, Q0, Ql, gamma, phi, phi_dot = self._kkt_pieces(t, q, v, x, p)
        alpha, beta = p[self.alpha_index], p[self.beta_index]
        return kkt.solve(M, G, Ql, Q0, -gamma - 2.0 * alpha * phi_dot - beta ** 2 * phi, xp=jnp)

    def _post_parts(self, t, q, v, a, lam, x, p):
        vals = self._post(t, q, v, a, lam, x, p)
        nw, ng, ne = self.nw, self.ng, self.ne
        powers = _stack(vals[:nw], (nw,))
        guards = _stack(vals[nw:nw + ng], (ng,))
        na = ne if self.ext_diagonal else ne * ne
        A = _stack(vals[nw + ng:nw + ng + na], (ne,) if self.ext_diagonal else (ne, ne))
        b = _stack(vals[nw + ng + na:], (ne,))
        return powers, guards, A, b

    def evaluate(self, t, z, p):
        """(z', a, lam, guard values) at one state."""
        q, v, _, x = self.split(z)
        a, lam = self.kkt(t, q, v, x, p)
        powers, guards, A, b = self._post_parts(t, q, v, a, lam, x, p)
        if not self.ne:
            xp = jnp.zeros(0)
        else:
            xp = -b / A if self.ext_diagonal else jnp.linalg.solve(A, -b)
        return jnp.concatenate([v, a, powers, xp]), a, lam, guards

    @cached_property
    def _jitted(self) -> Callable:
        # (the KKT solve's mode is a static argument: jit's trace cache is keyed by the function and the arguments,
        # not by the `kkt.unrolled_solves` switch the trace reads)
        return jax.jit(lambda t, z, p, unrolled: self.evaluate(t, z, p), static_argnums=3)

    @property
    def traced_once(self) -> Callable:
        """`evaluate` as a jitted function: traced once per argument types and reused wherever a program calls it
        again (every stage of a step, the guards, the event location), instead of retraced at each call site. Once
        per KKT solve too (`kkt.unrolled_solves` or not): a trace made outside the switch (a batched sweep's segment
        solve) reused inside it put LAPACK's solve into the compiled whole run, several times slower, which was
        then kept so on disk for every later process."""
        jitted, unrolled = self._jitted, kkt.unrolled()
        return lambda t, z, p: jitted(t, z, p, unrolled)

    def rates(self, t, z, p):
        """The vector field z' = f(t, z)."""
        return self.evaluate(t, z, p)[0]

    def guards(self, t, z, p):
        """Guard values; accelerations and multipliers enter through the KKT solve."""
        return self.evaluate(t, z, p)[3]

    def ida_rows(self, t, z, p):
        """(y, y') in the IDA state layout: y' = [v, a, lam' = 0, mu' = 0, work', x']."""
        zp, a, lam, _ = self.evaluate(t, z, p)
        q, v, w, x = self.split(z)
        zeros = jnp.zeros(self.m + self.n_mu)
        y = jnp.concatenate([q, v, lam, jnp.zeros(self.n_mu), w, x])
        yp = jnp.concatenate([v, a, zeros, zp[2 * self.nq:]])
        return y, yp


def build_mode(mf: ModeFunctions, parameter_names: tuple[str, ...]) -> JaxMode:
    """One mode's layout, its functions lambdified on first use (`JaxMode._functions`)."""
    size = {k: sl.stop - sl.start for k, sl in mf.index.items()}
    names = list(parameter_names)
    return JaxMode(name=mf.name, nq=size["q"], m=mf.m, nw=size["work"], ne=size["ext"], n_mu=size["mu"],
                   guard_names=tuple(mf.guard_names), guard_directions=tuple(mf.guard_directions),
                   alpha_index=names.index("baumgarte_alpha"), beta_index=names.index("baumgarte_beta"), source=mf,
                   parameter_names=tuple(parameter_names))


def _lambdified(mf: ModeFunctions, parameter_names: tuple[str, ...]) -> tuple[bool, Callable, Callable]:
    """Lambdify one mode's symbolic pieces (see module docstring): (ext_diagonal, KKT pieces, post pieces). sympy
    is imported here only: a process that loads its programs traced never imports it."""
    import sympy as sp

    from mechsim.dynamics.codegen import lambdify
    s = mf.symbolic
    t, q, v, lam, x, xp, params = s["t"], s["q"], s["v"], s["lam"], s["x"], s["xp"], s["params"]
    nq, m = len(q), len(lam)
    cd = s["constraints"]
    force = sp.Matrix(s["force"])
    lam_zero = {li: 0 for li in lam}
    Q0 = force.subs(lam_zero)
    Ql = force.jacobian(lam) if m else sp.zeros(nq, 0)
    M = sp.Matrix(s["mass"])
    kkt_exprs = (list(M) + (list(cd.G) if m else []) + list(Q0) + (list(Ql) if m else [])
                 + (list(cd.gamma) + list(cd.phi) + list(cd.phi_dot) if m else []))
    a_syms = [sp.Symbol(f"_acc_{i}", real=True) for i in range(nq)]
    acc_sub = dict(zip(s["guard_acc_symbols"], a_syms))
    powers = [sp.sympify(s["powers"][n]).subs(acc_sub) for n in s["work_names"]]
    guards = [sp.sympify(g).subs(acc_sub) for g in s["guards"]]
    ext_rows = sp.Matrix([sp.sympify(r).subs(acc_sub) for r in s["ext_rows"]]) if x else sp.zeros(0, 1)
    if x:
        A = ext_rows.jacobian(xp)
        if any(e.has(*xp) for e in A):
            raise ValueError(f"mode {mf.name!r}: extension rows are not linear in their rates")
        b = ext_rows.subs({xi: 0 for xi in xp})
        diagonal = all(A[i, j] == 0 for i in range(A.rows) for j in range(A.cols) if i != j)
        # a thermal network's rows are C x' + ...: only the diagonal is stored and divided by (82 states of a
        # 1-D mesh would otherwise stack 82^2 entries and solve densely at every evaluation)
        ext_exprs = ([A[i, i] for i in range(A.rows)] if diagonal else list(A)) + list(b)
    else:
        diagonal, ext_exprs = True, []
    for e in kkt_exprs + powers + guards + ext_exprs:
        stray = sp.sympify(e).free_symbols - set([t, *q, *v, *lam, *x, *a_syms, *params])
        if stray:
            raise ValueError(f"mode {mf.name!r}: unexpected symbols {sorted(map(str, stray))}")
    if (nq, m, len(powers), len(x)) != (mf.index["q"].stop - mf.index["q"].start, mf.m,
                                         mf.index["work"].stop - mf.index["work"].start,
                                         mf.index["ext"].stop - mf.index["ext"].start):
        raise ValueError(f"mode {mf.name!r}: its sympy pieces do not match its layout")
    return (diagonal,
            lambdify([t, list(q), list(v), list(x), list(params)], kkt_exprs, "jax"),
            lambdify([t, list(q), list(v), a_syms, list(lam), list(x), list(params)], powers + guards + ext_exprs,
                     "jax"))


@dataclass(frozen=True, eq=False)
class JaxModel:
    """Every mode of a derived model behind one switch on a (traced) mode index.

    All modes share the state layout z = [q, v, work, ext]; multipliers and guard values are padded to the
    largest mode (guards with 1.0), so one compiled solve serves every mode of a model structure.
    """

    modes: tuple[JaxMode, ...]

    @property
    def names(self) -> tuple[str, ...]:
        return tuple(jm.name for jm in self.modes)

    @property
    def nz(self) -> int:
        return self.modes[0].nz

    @property
    def nq(self) -> int:
        return self.modes[0].nq

    @property
    def m_max(self) -> int:
        return max(jm.m for jm in self.modes)

    @property
    def ng_max(self) -> int:
        return max(jm.ng for jm in self.modes)

    def index(self, name: str) -> int:
        return self.names.index(name)

    def _branch(self, jm: JaxMode):
        m_max, ng_max = self.m_max, self.ng_max
        evaluate = jm.traced_once

        def f(t, z, p):
            zp, a, lam, g = evaluate(t, z, p)
            return (zp, a, jnp.concatenate([lam, jnp.zeros(m_max - jm.m)]),
                    jnp.concatenate([g, jnp.ones(ng_max - jm.ng)]))
        return f

    def evaluate_mode(self, k: int) -> Callable:
        """evaluate(t, z, p) of mode number k (a python int), with the padding of `evaluate`."""
        return self._branch(self.modes[k])

    def evaluate(self, k, t, z, p):
        """(z', a, lam padded to m_max, guards padded to ng_max) in mode number k."""
        if len(self.modes) == 1:
            return self._branch(self.modes[0])(t, z, p)
        return jax.lax.switch(k, [self._branch(jm) for jm in self.modes], t, z, p)

    def rates(self, k, t, z, p):
        return self.evaluate(k, t, z, p)[0]

    def guards(self, k, t, z, p):
        return self.evaluate(k, t, z, p)[3]


def jax_mode(mf: ModeFunctions, parameter_names: tuple[str, ...]) -> JaxMode:
    """The JaxMode of a derived mode (one per mode structure and process, `dynamics/programs.py`)."""
    return program("jax_mode", mf, tuple(parameter_names), lambda: build_mode(mf, tuple(parameter_names)))[0]


def _build_model(model) -> JaxModel:
    modes = tuple(jax_mode(mf, model.parameter_names) for mf in model.modes.values())
    layouts = {(jm.nz, jm.nw, jm.ne) for jm in modes}
    if len(layouts) != 1:
        raise ValueError(f"modes of one model must share the state layout, got {layouts}")
    return JaxModel(modes)


def jax_model(model) -> JaxModel:
    """The JaxModel of a DerivedModel (one per model structure and process, `dynamics/programs.py`)."""
    return program("jax_model", model, (), lambda: _build_model(model))[0]
