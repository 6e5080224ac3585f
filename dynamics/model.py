"""Derive, once per model structure, every function the solvers need from a mechanism description.

For each mode this builds the residual F(t, y, y') of the chosen formulation with its exact Jacobian
dF/dy + cj dF/dy' (sympy), the guard functions, the pieces of the KKT system used to initialise
consistently, and vectorised read-outs. The hot-path functions (residual, Jacobian, guards) are emitted as
plain Python, the rest are numpy functions (both from dynamics/codegen.py).

State layout in a mode with m constraints (including a prescribed-speed drive constraint):
    y = [q (nq), v (nq), lam (m), mu (m, index2 only), work (nw), extra states (ne, e.g. temperatures)]
Work states integrate the power flows (drive, load, friction, damping) so energy balances close to the
integrator's tolerance rather than to a quadrature's.
"""
from __future__ import annotations

from dataclasses import dataclass, field
from functools import lru_cache
from typing import TYPE_CHECKING, Callable, Protocol, Sequence

from mechsim.dynamics.drives import DRIVE_PARAMETERS

if TYPE_CHECKING:      # sympy is imported where a model is derived: a model loaded from the disk cache needs none
    import sympy as sp

    from mechsim.mechanisms.base import Mechanism, Mode

SOLVER_PARAMETERS = ("baumgarte_alpha", "baumgarte_beta")


class StateExtension(Protocol):
    """States integrated alongside the mechanics (thermal model). Rows must be linear in their y'."""

    names: tuple[str, ...]
    parameter_names: tuple[str, ...]

    def structure_key(self) -> tuple: ...

    def parameter_values(self) -> dict[str, float]: ...

    def rows(self, x: Sequence[sp.Symbol], xp: Sequence[sp.Symbol], contact: dict[str, sp.Expr],
             p) -> list[sp.Expr]: ...


@dataclass
class ModeFunctions:
    """Compiled functions and layout of one mode."""

    name: str
    m: int
    ny: int
    index: dict[str, slice]
    algebraic: list[int]
    residual: object          # (t, y, yp, out, p)
    jacobian: object          # (t, y, yp, res, cj, JJ, p)
    events: object            # (t, y, yp, out, p)
    guard_names: list[str]
    guard_directions: list[int]
    phi: object               # (t, q, p) -> (m,)
    G: object                 # (t, q, p) -> (m, nq)
    phi_dot: object           # (t, q, v, p) -> (m,)
    mass: object              # (q, p) -> (nq, nq)
    force0: object            # (t, q, v, x, p) -> (nq,)   Q at lam = 0
    force_lam: object         # (t, q, v, x, p) -> (nq, m)
    gamma: object             # (t, q, v, p) -> (m,)
    readouts: dict[str, object] = field(default_factory=dict)   # vectorised (t, q, v, a, lam, x, p)
    readout_names: list[str] = field(default_factory=list)
    #: the KKT pieces as flat lists of entries, vectorised over output rows (dynamics/tables.py)
    kkt_flat: dict = field(default_factory=dict)
    #: (derivation key, mode name): identifies these expressions across processes (compiled_model's cache)
    cache_key: tuple = ()
    #: the sympy pieces (for the diffrax backend, the compiled callbacks, the sensitivities): see `symbolic`
    symbolic_pieces: dict = field(default_factory=dict, repr=False)
    #: where the functions were loaded from the disk cache (dynamics/derivation_cache.py): derives the sympy
    #: pieces on first use
    symbolic_source: Callable[[], dict] | None = field(default=None, repr=False, compare=False)

    @property
    def symbolic(self) -> dict:
        """The sympy pieces the functions were made from (derived now if the functions came from the cache)."""
        if not self.symbolic_pieces and self.symbolic_source is not None:
            self.symbolic_pieces = self.symbolic_source()
        return self.symbolic_pieces


@dataclass
class DerivedModel:
    """All modes of one (mechanism structure, drive kind, formulation, extension) combination."""

    coordinates: tuple[str, ...]
    parameter_names: tuple[str, ...]
    work_names: tuple[str, ...]
    extension_names: tuple[str, ...]
    modes: dict[str, ModeFunctions]
    formulation: str
    prescribed: bool
    key: tuple = ()      # the derivation key: the structure its compiled programs are kept under (dynamics/programs.py)
    #: (mechanism, formulation, prescribed, extension) it was derived from: what derives it again in another process
    #: (the default backend's background compilation where this process cannot fork: compiled_model.py)
    recipe: tuple | None = field(default=None, repr=False, compare=False)


def _as_list(x) -> list:
    return list(x) if x is not None else []


def _build_mode(mech: Mechanism, mode: Mode, formulation: str, prescribed: bool,
                ext: StateExtension | None, params: tuple[sp.Symbol, ...], P) -> ModeFunctions:
    import sympy as sp

    from mechsim.dynamics.codegen import emit, lambdify
    from mechsim.dynamics.derivation_cache import TARGETS
    from mechsim.dynamics.formulation import differentiate_constraints, mechanical_residual
    s = mech.symbols
    t, q, v, a = s.t, list(s.q), list(s.v), list(s.a)
    nq = len(q)
    k = mech.drive_coordinate
    constraints = list(mode.constraints)
    if prescribed:
        constraints.append(q[k] - (P("drive_angle0") + P("drive_speed") * (t - P("drive_time0"))))
    m = len(constraints)
    lam = [sp.Symbol(f"lam_{i}", real=True) for i in range(m)]
    mu = [sp.Symbol(f"mu_{i}", real=True) for i in range(m)] if formulation == "index2" else []
    # the mechanism's lam symbols are its own constraints' multipliers; the drive multiplier is appended
    lam_sub = {s.lam[i]: lam[i] for i in range(len(mode.constraints))}

    force = sp.Matrix([sp.sympify(f).subs(lam_sub) for f in mode.force])
    drive_power = sp.Integer(0)
    if prescribed:
        drive_torque = -lam[-1]
    else:
        drive_torque = P("drive_T0") - P("drive_slope") * v[k]
        force[k] += drive_torque
    drive_power = drive_torque * v[k]
    powers = {"drive": drive_power}
    powers.update({name: sp.sympify(e).subs(lam_sub) for name, e in mode.powers.items()})
    work_names = tuple(powers)

    x = [sp.Symbol(f"x_{n}", real=True) for n in (ext.names if ext else ())]
    contact = {key: sp.sympify(e).subs(lam_sub) for key, e in mode.heat.items()}

    # IDA state symbols
    qp = [sp.Symbol(f"qp_{c}", real=True) for c in mech.coordinates]
    vp = [sp.Symbol(f"vp_{c}", real=True) for c in mech.coordinates]
    lamp = [sp.Symbol(f"lamp_{i}", real=True) for i in range(m)]
    mup = [sp.Symbol(f"mup_{i}", real=True) for i in range(len(mu))]
    W = [sp.Symbol(f"W_{n}", real=True) for n in work_names]
    Wp = [sp.Symbol(f"Wp_{n}", real=True) for n in work_names]
    xp = [sp.Symbol(f"xp_{n}", real=True) for n in (ext.names if ext else ())]
    y_syms = q + v + lam + mu + W + x
    yp_syms = qp + vp + lamp + mup + Wp + xp

    M = mech.mass_matrix()
    cd = differentiate_constraints(constraints, t, q, v, vp)
    rows = mechanical_residual(formulation, M, force, cd, q, v, qp, vp, lam, mu,
                               (P("baumgarte_alpha"), P("baumgarte_beta")))
    rows += [Wp[i] - powers[n] for i, n in enumerate(work_names)]
    if ext:
        rows += ext.rows(x, xp, contact, P)
    ny = len(y_syms)
    assert len(rows) == ny, (len(rows), ny)

    index = {}
    pos = 0
    for name, n in (("q", nq), ("v", nq), ("lam", m), ("mu", len(mu)), ("work", len(W)), ("ext", len(x))):
        index[name] = slice(pos, pos + n)
        pos += n
    algebraic = list(range(index["lam"].start, index["mu"].stop))

    cj = sp.Symbol("cj", real=True)
    J = _residual_jacobian(rows, y_syms, yp_syms, cj)
    unpack = [("y", y_syms), ("yp", yp_syms), ("p", params)]
    residual = emit(f"residual_{mode.name}", ["t", "y", "yp", "out", "p"], unpack,
                    [(f"out[{i}]", r) for i, r in enumerate(rows)])
    jac_out = [(f"JJ[{i}, {j}]", J[i, j]) for i in range(ny) for j in range(ny) if J[i, j] != 0]
    jacobian = emit(f"jacobian_{mode.name}", ["t", "y", "yp", "res", "cj", "JJ", "p"],
                    [("y", y_syms), ("yp", yp_syms), ("p", params)], jac_out, prologue=["JJ.fill(0.0)"])
    guards = [sp.sympify(g.expr).subs(lam_sub) for g in mode.guards]
    if any(g.has(*lam, *a) for g in guards):
        guards = _guards_on_kkt(guards, M, force, cd, lam, a, vp, nq, m)
    events = emit(f"events_{mode.name}", ["t", "y", "yp", "out", "p"], unpack,
                  [(f"out[{i}]", g) for i, g in enumerate(guards)])

    def lamb(args, expr):
        return lambdify(args, expr, TARGETS["lambdified"])

    lam_zero = {li: 0 for li in lam}
    fmat = force
    force_lam = fmat.jacobian(lam) if m else sp.zeros(nq, 0)
    zeros_m = sp.zeros(m, 1)

    ro_names = list(mode.readouts)
    ro_exprs = [sp.sympify(e).subs(lam_sub) for e in mode.readouts.values()]
    ro_names += ["drive_torque_N_m"]
    ro_exprs += [drive_torque]
    ro_fn = lamb([t, q, v, a, lam, x, params], ro_exprs)

    return ModeFunctions(
        name=mode.name, m=m, ny=ny, index=index, algebraic=algebraic,
        residual=residual, jacobian=jacobian, events=events,
        guard_names=[g.name for g in mode.guards], guard_directions=[g.direction for g in mode.guards],
        phi=lamb([t, q, params], cd.phi if m else zeros_m),
        G=lamb([t, q, params], cd.G),
        phi_dot=lamb([t, q, v, params], cd.phi_dot if m else zeros_m),
        mass=lamb([q, params], M),
        force0=lamb([t, q, v, x, params], fmat.subs(lam_zero)),
        force_lam=lamb([t, q, v, x, params], force_lam),
        gamma=lamb([t, q, v, params], cd.gamma if m else zeros_m),
        readouts={"_all": ro_fn}, readout_names=ro_names,
        kkt_flat=dict(
            mass=lamb([q, params], list(M)),
            force0=lamb([t, q, v, x, params], list(fmat.subs(lam_zero))),
            G=lamb([t, q, params], list(cd.G)) if m else None,
            force_lam=lamb([t, q, v, x, params], list(force_lam)) if m else None,
            gamma=lamb([t, q, v, params], list(cd.gamma)) if m else None,
        ),
        symbolic_pieces=dict(t=t, q=q, v=v, lam=lam, x=x, xp=xp, params=params, mass=M, force=force,
                      constraints=cd, powers=powers, work_names=work_names, guards=guards,
                      guard_acc_symbols=vp, ext_rows=rows[len(rows) - len(x):] if x else [],
                      readout_exprs=ro_exprs, residual_rows=rows, residual_jacobian=J, y=y_syms, yp=yp_syms,
                      cj=cj),
    )


def _residual_jacobian(rows, y_syms, yp_syms, cj) -> sp.Matrix:
    """dF/dy + cj dF/dy', differentiating each row only by the symbols it contains (same result as
    Matrix.jacobian, but linear in the number of nonzeros instead of rows x states: matters for 1-D meshes)."""
    import sympy as sp
    J = sp.zeros(len(rows), len(y_syms))
    col_y = {s: j for j, s in enumerate(y_syms)}
    col_yp = {s: j for j, s in enumerate(yp_syms)}
    for i, row in enumerate(rows):
        row = sp.sympify(row)
        for s in row.free_symbols:
            if s in col_y:
                J[i, col_y[s]] += sp.diff(row, s)
            if s in col_yp:
                J[i, col_yp[s]] += cj * sp.diff(row, s)
    return J


def _guards_on_kkt(guards, M, force, cd, lam, a, vp, nq, m):
    """Guards that read multipliers or accelerations use their exact KKT values as functions of (t, q, v).

    In the index-2/3 forms the multipliers are kept out of IDA's error test (see SolverSettings), so the
    state's lam is too noisy to root-find on; the KKT solution is exact for the current (q, v). Solved
    symbolically for small systems; larger ones fall back to the state's lam and v'.
    """
    import sympy as sp

    from mechsim.dynamics import kkt
    if nq + m > 6:
        return [g.subs({a[i]: vp[i] for i in range(nq)}) for g in guards]
    Ql = force.jacobian(lam) if m else sp.zeros(nq, 0)
    Q0 = force.subs({li: 0 for li in lam})
    acc, mult = kkt.solve_symbolic(M, cd.G if m else sp.zeros(0, nq), Ql, Q0, -cd.gamma if m else [])
    sub = {a[i]: acc[i] for i in range(nq)}
    sub.update({lam[j]: mult[j] for j in range(m)})
    return [g.subs(sub, simultaneous=True) for g in guards]


@lru_cache(maxsize=64)
def _derive_cached(key, mech_ref, formulation, prescribed, ext_ref):
    """One model per derivation key and process: from the disk cache where it holds the key (the sympy pieces
    then derived on first use), else derived and stored there (dynamics/derivation_cache.py)."""
    from mechsim.dynamics import derivation_cache
    mech, ext = mech_ref.obj, (ext_ref.obj if ext_ref else None)
    fresh: dict = {}

    def symbolic_of(mode: str) -> dict:
        if "pieces" not in fresh:
            fresh["pieces"] = derivation_cache.load_symbolic(key)
            if fresh["pieces"] is None or set(fresh["pieces"]) != set(model.modes):
                derived = _derive_fresh(key, mech, formulation, prescribed, ext)
                fresh["pieces"] = {name: mf.symbolic for name, mf in derived.modes.items()}
                derivation_cache.store_symbolic(key, fresh["pieces"])
        return fresh["pieces"][mode]

    model = derivation_cache.load(key, symbolic_of)
    if model is None:
        model = _derive_fresh(key, mech, formulation, prescribed, ext)
        derivation_cache.store(key, model)
        derivation_cache.store_symbolic(key, {name: mf.symbolic for name, mf in model.modes.items()})
    model.recipe = (mech, formulation, prescribed, ext)
    return model


def _derive_fresh(key, mech, formulation, prescribed, ext) -> DerivedModel:
    """Every mode's functions derived from the mechanism's sympy description."""
    import sympy as sp
    pnames = tuple(mech.parameter_names) + DRIVE_PARAMETERS + SOLVER_PARAMETERS + (
        tuple(ext.parameter_names) if ext else ())
    existing = {s.name: s for s in mech.symbols.params}
    params = tuple(existing.get(n) or sp.Symbol(n, real=True) for n in pnames)
    by_name = dict(zip(pnames, params))

    def P(name):
        return by_name[name]

    modes = {name: _build_mode(mech, mode, formulation, prescribed, ext, params, P)
             for name, mode in mech.modes().items()}
    for name, mf in modes.items():
        mf.cache_key = (key, name)
    work_names = tuple(n for n in _work_names(mech))
    return DerivedModel(coordinates=mech.coordinates, parameter_names=pnames, work_names=work_names,
                        extension_names=tuple(ext.names) if ext else (), modes=modes,
                        formulation=formulation, prescribed=prescribed, key=key)


def _work_names(mech: Mechanism) -> tuple[str, ...]:
    first = next(iter(mech.modes().values()))
    return ("drive",) + tuple(first.powers)


class _Ref:
    """Hashable-by-key wrapper so lru_cache keys on the structure, not the instance."""

    def __init__(self, obj, key):
        self.obj, self.key = obj, key

    def __hash__(self):
        return hash(self.key)

    def __eq__(self, other):
        return isinstance(other, _Ref) and self.key == other.key


def derive(mech: Mechanism, formulation: str, prescribed: bool, ext: StateExtension | None = None) -> DerivedModel:
    """The derived model for this mechanism structure (cached: one derivation per process)."""
    key = (mech.structure_key(), formulation, prescribed, ext.structure_key() if ext else None)
    return _derive_cached(key, _Ref(mech, mech.structure_key()), formulation, prescribed,
                          _Ref(ext, ext.structure_key()) if ext else None)
