"""Thermal states in the same DAE as the mechanics: a state extension (the rows `dynamics/` appends to the
mechanics' residual) built from a linear thermal network.

The network is a `LinearThermalSystem` (thermal/linear.py), C T' = -K T + s + B u (lumped bulk bodies, optionally 1-D
track meshes; docs/theory.md §G5-6). Its inputs u are heat rates into the bodies, made from the contact
expressions a mode exposes (`Mode.heat`): the friction power Q = mu |N| |u_slip| (`heat_rate`, docs/theory.md §G4.1),
the pin's share gamma (Blok's partition, §4.6, of the band-source fit, §4.3) and, for per-track meshes, the
index of the track in contact (`track`). The same functions evaluate in sympy (IDA residual rows, exact
Jacobian derived from them) and numpy (closed-form kinematics path), so both paths integrate one model.

Three bookkeeping states close the heat balance exactly (the residual is linear in them):
heat_generated_J' = Q, heat_pin_J' = gamma Q, heat_convected_J' = sum_j loss_j T_j - sum_i s_i, where
loss = K^T 1 is what leaves the network to the surroundings. Summing C_i times the network rows gives
d/dt(sum C_i T_i) = Q - convected power, so generated = stored + convected to the integrator's round-off.

Heat share in the DAE (docs/thermal.md "Coupling"): gamma_pin = R_wheel/(R_pin + R_wheel), R_i = theta_fit(L_i)/(2 k_i)
with the smooth effective Peclet numbers L_i^2 = b^2 [U_i^2/(4 chi_i^2) + c^2/(chi_i t_ref)] and
b^2 = 4 R |N|/(pi l E*) + b0^2. The c^2/(chi t_ref) term is the transient floor of §4.6 for a source on for
t_ref (the longest a contact lasts), added in quadrature so it is smooth; b0 keeps L > 0 as N -> 0. Both keep
theta finite and every derivative finite; where they act the heat Q is zero or small.
"""
from __future__ import annotations

import functools
from dataclasses import dataclass, field
from typing import TYPE_CHECKING, Callable, Sequence

import numpy as np
import scipy.sparse as sps

from mechsim.thermal.band_source import band_fit
from mechsim.thermal.flash import TRANSIENT_FLOOR_COEFFICIENT
from mechsim.thermal.linear import LinearThermalSystem

if TYPE_CHECKING:      # sympy is imported by the functions that build residual rows (the numpy path needs none)
    import sympy as sp

#: Regularising half-width b0 (m): of the order of the roughness of ground steel (Rq 0.2-1 µm), below which a
#: smooth Hertz contact is not meaningful anyway; it changes b only for N below ~0.1 N (seed geometry).
HALF_WIDTH_FLOOR = 1e-6

BOOKKEEPING_STATES = ("heat_generated_J", "heat_pin_J", "heat_convected_J")

SHARE_PARAMETERS = ("th_R", "th_l", "th_Estar", "th_b0", "th_k_pin", "th_k_wheel", "th_chi_pin", "th_chi_wheel",
                    "th_t_ref")


@dataclass(frozen=True)
class ShareModel:
    """Numbers of the heat-share expression (SI): contact radius R and length l, contact modulus E*,
    conductivities and diffusivities of pin and wheel, floor time t_ref, flux distribution."""

    contact_radius: float
    contact_length: float
    modulus: float
    k_pin: float
    k_wheel: float
    chi_pin: float
    chi_wheel: float
    t_ref: float
    distribution: str = "semi-elliptic"
    b0: float = HALF_WIDTH_FLOOR

    def values(self) -> dict[str, float]:
        return {"th_R": self.contact_radius, "th_l": self.contact_length, "th_Estar": self.modulus,
                "th_b0": self.b0, "th_k_pin": self.k_pin, "th_k_wheel": self.k_wheel, "th_chi_pin": self.chi_pin,
                "th_chi_wheel": self.chi_wheel, "th_t_ref": self.t_ref}


def _is_sympy(xp) -> bool:
    """Whether the array namespace `xp` is sympy (told by name, so that the numpy path never imports it)."""
    return getattr(xp, "__name__", "") == "sympy"


def _abs(x, xp):
    return xp.Abs(x) if _is_sympy(xp) else xp.abs(x)


def opaque_function(name: str, expr: sp.Expr, args: tuple[sp.Symbol, ...],
                    origin: tuple | None = None) -> type[sp.Function]:
    """`expr(args)` as an opaque sympy function whose derivatives are opaque functions too (made on demand).

    sympy's Jacobian and common-subexpression passes then see one call instead of nested powers and logs
    (for the heat share this cut the model derivation several times: docs/benchmarks.md, "Costs behind the
    code"); every code printer (plain Python, numpy, jax, lambdify) prints the explicit expression with the call's
    arguments substituted. `origin`: how `opaque_class` makes the class again in another process (a class made at
    run time has no name pickle can find it by: dynamics/derivation_cache.py keeps the sympy pieces that hold it);
    its derivatives' origins are its own with the argument's index appended.
    """
    import sympy as sp
    cache: dict[int, type[sp.Function]] = {}

    def fdiff(self, argindex=1):
        i = argindex - 1
        if i not in cache:
            cache[i] = opaque_function(f"{name}_d{i}", sp.diff(expr, args[i]), args,
                                       None if origin is None else (*origin, i))
        return cache[i](*self.args)

    def printer_method(self, printer, **kwargs):      # parenthesised: the caller treats a call as an atom
        return "(" + printer._print(expr.xreplace(dict(zip(args, self.args)))) + ")"

    return type(name, (sp.Function,), {"nargs": len(args), "fdiff": fdiff, "_pythoncode": printer_method,
                                       "_lambdacode": printer_method, "_numpycode": printer_method,
                                       "opaque_origin": origin})


def opaque_class(origin: tuple) -> type[sp.Function]:
    """The opaque function class of `origin` (`opaque_function`): ("share", distribution, i, j, ...) is the heat
    share's function differentiated in its arguments i, then j, ... This process's own class, the one a
    derivation here would use."""
    kind, distribution, *indices = origin
    if kind != "share":
        raise ValueError(f"unknown opaque function origin {origin!r}")
    cls, args = _share_function(distribution)
    for i in indices:
        cls = cls(*args).fdiff(i + 1).func
    return cls


@functools.lru_cache(maxsize=None)
def _share_function(distribution: str) -> tuple[type[sp.Function], tuple[sp.Symbol, ...]]:
    """gamma_pin(N, U_pin, U_wheel, share parameters) as one opaque sympy function (see `heat_share_pin`)."""
    import sympy as sp
    N, u_pin, u_wheel = sp.symbols("N U_pin U_wheel", real=True)
    params = sp.symbols(SHARE_PARAMETERS, positive=True)
    by_name = dict(zip(SHARE_PARAMETERS, params))
    contact = {"normal_force": N, "source_speed_driver": u_pin, "source_speed_driven": u_wheel}
    expr = _share_expression(contact, by_name.__getitem__, distribution, sp)
    args = (N, u_pin, u_wheel) + params
    name = f"heat_share_pin_{distribution.replace('-', '_')}"
    return opaque_function(name, expr, args, ("share", distribution)), args


def _share_expression(contact: dict, P: Callable[[str], object], distribution: str, xp=np):
    """The explicit share expression (sympy or numpy)."""
    N = contact["normal_force"]
    U_pin, U_wheel = contact["source_speed_driver"], contact["source_speed_driven"]
    b2 = 4 * P("th_R") * _abs(N, xp) / (xp.pi * P("th_l") * P("th_Estar")) + P("th_b0") ** 2
    c2 = TRANSIENT_FLOOR_COEFFICIENT ** 2
    L2_pin = b2 * (U_pin ** 2 / (4 * P("th_chi_pin") ** 2) + c2 / (P("th_chi_pin") * P("th_t_ref")))
    L2_wheel = b2 * (U_wheel ** 2 / (4 * P("th_chi_wheel") ** 2) + c2 / (P("th_chi_wheel") * P("th_t_ref")))
    r_pin = band_fit(xp.sqrt(L2_pin), distribution, "max", xp) / (2 * P("th_k_pin"))
    r_wheel = band_fit(xp.sqrt(L2_wheel), distribution, "max", xp) / (2 * P("th_k_wheel"))
    return r_wheel / (r_pin + r_wheel)


def heat_share_pin(contact: dict, P: Callable[[str], object], distribution: str, xp=np):
    """gamma_pin of the DAE (module docstring): Blok partition of the band fit at smooth, floored Peclet numbers.

    `contact` holds normal_force, source_speed_driver (over the pin), source_speed_driven (over the wheel) (sympy expressions or numpy arrays);
    P(name) gives the SHARE_PARAMETERS (symbols or numbers). With xp = sympy the result is one opaque call
    (`opaque_function`) of the same expression. docs/theory.md §G4.3 (fit), §4.6 (partition, transient floor).
    """
    if not _is_sympy(xp):
        return _share_expression(contact, P, distribution, xp)
    fn, _ = _share_function(distribution)
    return fn(contact["normal_force"], contact["source_speed_driver"], contact["source_speed_driven"],
              *(P(name) for name in SHARE_PARAMETERS))


@dataclass(frozen=True)
class HeatInput:
    """One network input: the heat rate into `body` ('pin' or 'wheel'); with `tracks` > 0 only while the contact's
    track index is congruent to `track` modulo `tracks` (per-slot meshes)."""

    body: str
    track: int = 0
    tracks: int = 0


def heat_inputs(contact: dict, P: Callable[[str], object], inputs: Sequence[HeatInput], distribution: str,
                xp=np) -> tuple[list, object, object]:
    """(input heat rates u, Q, gamma_pin) from the contact expressions; sympy or numpy alike."""
    if "heat_rate" not in contact:
        raise KeyError("the mode's `heat` must expose 'heat_rate' (the friction power) for thermal states")
    Q = contact["heat_rate"]
    gamma = heat_share_pin(contact, P, distribution, xp)
    out = []
    for spec in inputs:
        rate = gamma * Q if spec.body == "pin" else (1 - gamma) * Q
        if spec.tracks:
            track = contact.get("track", 0)
            if _is_sympy(xp):
                on = xp.Piecewise((1, xp.Eq(xp.Mod(track, spec.tracks), spec.track)), (0, True))
            else:
                on = np.where(np.mod(np.rint(np.asarray(track, dtype=float)), spec.tracks) == spec.track, 1.0, 0.0)
            rate = rate * on
        out.append(rate)
    return out, Q, gamma


def _pattern(matrix) -> list[tuple[int, int]]:
    m = sps.coo_matrix(matrix)
    return sorted({(int(i), int(j)) for i, j, v in zip(m.row, m.col, m.data) if v != 0})


@dataclass
class ThermalExtension:
    """A linear thermal network plus the bookkeeping states, as rows of the mechanics' IDA residual.

    Every nonzero of C, K, s, B and of the loss vector is a parameter (so one derivation serves every scenario
    with the same network structure); the structure key is the sparsity pattern, the inputs and the distribution.
    """

    system: LinearThermalSystem
    inputs: tuple[HeatInput, ...]
    share: ShareModel
    names: tuple[str, ...] = field(init=False)
    parameter_names: tuple[str, ...] = field(init=False)

    def __post_init__(self) -> None:
        sysm = self.system
        if sysm.input_matrix.shape[1] != len(self.inputs):
            raise ValueError("ThermalExtension: one HeatInput per network input")
        self.names = tuple(sysm.state_names) + BOOKKEEPING_STATES
        K = sps.csr_matrix(sysm.conductance)
        self._K = _pattern(K)
        self._B = _pattern(sysm.input_matrix)
        self._s = [i for i, v in enumerate(sysm.source) if v != 0]
        self.loss = np.asarray(K.sum(axis=0)).ravel()              # K^T 1: conductance to the surroundings
        self._loss = [j for j, v in enumerate(self.loss) if v != 0]
        n = sysm.size
        self.parameter_names = SHARE_PARAMETERS + tuple(
            [f"th_C_{i}" for i in range(n)] + [f"th_K_{i}_{j}" for i, j in self._K]
            + [f"th_s_{i}" for i in self._s] + [f"th_B_{i}_{k}" for i, k in self._B]
            + [f"th_loss_{j}" for j in self._loss])

    def structure_key(self) -> tuple:
        return ("thermal-network", tuple(self.system.state_names), tuple(self._K), tuple(self._B), tuple(self._s),
                tuple(self._loss), self.inputs, self.share.distribution)

    def parameter_values(self) -> dict[str, float]:
        sysm = self.system
        # K's entries read from its stored ones (an element read K[i, j] of a sparse matrix is slow): each stored
        # once, in canonical CSR (a copy put in that form otherwise), as K[i, j] gives them
        K = sysm.conductance
        if not (sps.issparse(K) and K.format == "csr" and K.has_canonical_format):
            K = sps.csr_matrix(K, copy=True)
            K.sum_duplicates()
        rows = np.repeat(np.arange(K.shape[0]), np.diff(K.indptr))
        entry = dict(zip(zip(rows.tolist(), K.indices.tolist()), K.data.tolist()))
        values = dict(self.share.values())
        values.update({f"th_C_{i}": float(c) for i, c in enumerate(sysm.capacity)})
        values.update({f"th_K_{i}_{j}": float(entry.get((i, j), 0.0)) for i, j in self._K})
        values.update({f"th_s_{i}": float(sysm.source[i]) for i in self._s})
        values.update({f"th_B_{i}_{k}": float(sysm.input_matrix[i, k]) for i, k in self._B})
        values.update({f"th_loss_{j}": float(self.loss[j]) for j in self._loss})
        return values

    def rows(self, x: Sequence[sp.Symbol], xp: Sequence[sp.Symbol], contact: dict, P) -> list[sp.Expr]:
        import sympy as sp
        n = self.system.size
        T, Tp = list(x[:n]), list(xp[:n])
        u, Q, gamma = heat_inputs(contact, P, self.inputs, self.share.distribution, sp)
        rows = [P(f"th_C_{i}") * Tp[i] for i in range(n)]
        for i in self._s:
            rows[i] -= P(f"th_s_{i}")
        for i, j in self._K:
            rows[i] += P(f"th_K_{i}_{j}") * T[j]
        for i, k in self._B:
            rows[i] -= P(f"th_B_{i}_{k}") * u[k]
        e_gen, e_pin, e_conv = xp[n:n + 3]
        convected = sum((P(f"th_loss_{j}") * T[j] for j in self._loss), sp.Integer(0)) - sum(
            (P(f"th_s_{i}") for i in self._s), sp.Integer(0))
        rows += [e_gen - Q, e_pin - gamma * Q, e_conv - convected]
        return rows

    # -- the same model in numpy, for the closed-form path and post-processing ------------------------------
    def numeric_parameter(self) -> Callable[[str], float]:
        values = self.parameter_values()
        return values.__getitem__

    def inputs_numeric(self, contact: dict, parameter: Callable[[str], float] | None = None
                       ) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        """(u (n_inputs, n_times), Q, gamma) from contact arrays; parameter: `numeric_parameter()` where a caller
        that reads many times keeps it."""
        P = self.numeric_parameter() if parameter is None else parameter
        u, Q, gamma = heat_inputs(contact, P, self.inputs, self.share.distribution, np)
        shape = np.shape(Q)
        return np.array([np.broadcast_to(v, shape) for v in u]), np.asarray(Q, float), np.asarray(gamma, float)

    def augmented(self) -> tuple[np.ndarray, np.ndarray, object, np.ndarray]:
        """(C, source, K, loss) of the network, for integrators of y = [T, E_gen, E_pin, E_conv]."""
        return self.system.capacity, self.system.source, self.system.conductance, self.loss
