"""Cycle-averaged bulk temperatures in closed form and array-neutral (numpy or jax.numpy), so that jax can
differentiate them for the design sensitivities (docs/sensitivity.md): `dense_turn_bulk` for a turn read on the
window's solution (a DAE run's, its input polynomial on pieces fixed by the turn and its events), `turn_bulk` for a
turn read on its output rows (its input linear between them, as a closed-form cycle's derivatives trace it). The
rest of this docstring describes the latter; `dense_turn_bulk` says what it changes.

The model is thermal/cycle.py's (docs/theory.md §G5): the last full crank turn [a, b) of the mechanics (its ends
where the drive angle passes angle0 + 2 pi m, linearly interpolated between output rows, `turn_boundaries`) gives
the cycle-mean heat Q = dE_gen/P and pin share gamma = dE_pin/dE_gen (`cycle_means_from_energies`); from the
resolved states T(a) (linear between the rows around a) the linear network C T' = -K T + s + B u, its input the
turn repeated, is T = M + T_p with
- T_p the periodic response to the zero-mean remainder u(t) - mean(u) of the turn's input u (the rows' network
  inputs, linearly interpolated between output rows, `ThermalPlan._period_input`), and
- M the mean curve, the response to the constant input u_bar = [gamma Q, (1 - gamma) Q] from T(a) - T_p(a), exact
  in the network's modes (`ModalNetwork.constant`).

Here the ripple is exact for that piecewise-linear input: over an interval of length h with end values g0, g1
(modal coordinates, eigenvalue lambda, x = lambda h) the zero-state response is
h [(phi1(x) - phi2(x)) g0 + phi2(x) g1], phi1 = (e^x - 1)/x, phi2 = (e^x - 1 - x)/x^2, and the mean of the input
is the trapezoid sum; thermal/cycle.py's `bulk_response` reaches the same by Gauss-Legendre quadrature on finer
pieces (tested equal to that quadrature's error). The periodic start is (I - e^{AP})^-1 Z(P).

The temperatures are evaluated at the times t_k + m_k P, the last repetition of each of the turn's rows t_k in the
run (`TurnLayout.periods`, thermal/cycle.py `last_repetitions`): the very rows the run's continuation writes there,
so that the periodic turn's peak is the run's (docs/sensitivity.md, "Cycle averaging").
"""
from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

#: below this |x| phi1 and phi2 are evaluated by their series (their closed forms lose digits to cancellation)
SERIES_BELOW = 0.1


def phi1(x, xp=np):
    """(e^x - 1)/x, 1 at x = 0 (series below SERIES_BELOW; safe for differentiation at 0)."""
    small = xp.abs(x) < SERIES_BELOW
    safe = xp.where(small, 1.0, x)
    series = 1.0 + x * (1 / 2 + x * (1 / 6 + x * (1 / 24 + x * (1 / 120 + x * (1 / 720 + x * (1 / 5040 + x * (
        1 / 40320 + x / 362880)))))))
    return xp.where(small, series, xp.expm1(safe) / safe)


def phi2(x, xp=np):
    """(e^x - 1 - x)/x^2, 1/2 at x = 0 (series below SERIES_BELOW: truncation < 1e-14 relative)."""
    small = xp.abs(x) < SERIES_BELOW
    safe = xp.where(small, 1.0, x)
    series = 1 / 2 + x * (1 / 6 + x * (1 / 24 + x * (1 / 120 + x * (1 / 720 + x * (1 / 5040 + x * (
        1 / 40320 + x * (1 / 362880 + x / 3628800)))))))
    return xp.where(small, series, (xp.expm1(safe) - safe) / (safe * safe))


def modes(capacity, conductance, xp=np):
    """(lambda, V, V^-1) of A = -C^-1 K = V diag(lambda) V^-1 from the symmetric -C^-1/2 K C^-1/2 (as
    thermal/exact.py `ModalNetwork`)."""
    d = 1.0 / xp.sqrt(capacity)
    lam, Q = xp.linalg.eigh(-(d[:, None] * conductance * d[None, :]))
    return lam, d[:, None] * Q, Q.T / d[None, :]


def periodic_response(lam, sigma, g, period, xp=np):
    """Modal periodic response (nodes x n) at the nodes sigma (0 = sigma_0 <= ... <= sigma_N = period) to the input
    that is linear between nodes with modal values g (nodes x n): z_k = e^{lambda sigma_k} z_0 + Z_k, Z the
    zero-state response, z_0 = Z_N / (1 - e^{lambda P}). Z_k = sum_{j<k} e^{lambda (sigma_k - sigma_{j+1})} f_j with
    f_j the interval's response (module docstring), summed as e^{lambda (sigma_k - P)} cumsum(e^{lambda (P - sigma_{j+1})}
    f_j): every weight <= 1 for decaying modes (needs |lambda| P < 700)."""
    h = sigma[1:] - sigma[:-1]
    x = lam[None, :] * h[:, None]
    p2 = phi2(x, xp)
    f = h[:, None] * ((phi1(x, xp) - p2) * g[:-1] + p2 * g[1:])
    weights = xp.exp(lam[None, :] * (period - sigma[1:, None]))
    cs = xp.cumsum(weights * f, axis=0)
    Z = xp.concatenate([xp.zeros((1, lam.shape[0])), xp.exp(lam[None, :] * (sigma[1:, None] - period)) * cs], axis=0)
    z0 = Z[-1] / (-xp.expm1(lam * period))
    return xp.exp(lam[None, :] * sigma[:, None]) * z0[None, :] + Z


def mean_response(lam, V, Vinv, capacity, source, input_matrix, u_bar, start, times, xp=np):
    """Network states (rows = times, from 0) from the states `start` at time 0 under the constant input u_bar:
    z = e^{lambda t} z0 + t phi1(lambda t) g (thermal/exact.py `ModalNetwork.constant`)."""
    z0 = Vinv @ start
    g = Vinv @ ((source + input_matrix @ u_bar) / capacity)
    lt = lam[None, :] * times[:, None]
    return (xp.exp(lt) * z0[None, :] + times[:, None] * phi1(lt, xp) * g[None, :]) @ V.T


def _linear(x, x0, x1, y0, y1):
    """The straight line through (x0, y0), (x1, y1) at x (np.interp between two rows)."""
    return y0 + (y1 - y0) * ((x - x0) / (x1 - x0))


#: the turn's inner rows are padded to a multiple of this (zero-length intervals), so that a compiled evaluation
#: serves every design whose turn has about as many rows
PAD = 256


@dataclass(frozen=True)
class TurnLayout:
    """Which output rows make up the last full turn, and the run's whole periods after it (discrete: fixed for a
    derivative). t: the rows' times; ia, ib: the rows just before the turn's ends a, b (a, b in [t[i], t[i+1]));
    inner: the rows strictly inside (a, b); targets: the drive angles at a and b (angle0 + 2 pi m); periods: m_k
    per inner row, the whole periods to its last repetition t_k + m_k P <= duration in the run (thermal/cycle.py
    `last_repetitions`; the rows near the turn's end may have one less)."""

    t: np.ndarray
    ia: int
    ib: int
    inner: np.ndarray
    targets: tuple[float, float]
    periods: np.ndarray

    @property
    def rows(self) -> np.ndarray:
        """The rows whose values the turn uses: both boundary pairs and the inner rows."""
        return np.unique(np.concatenate([[self.ia, self.ia + 1, self.ib, self.ib + 1], self.inner]))

    @property
    def edges(self) -> np.ndarray:
        """The rows around the turn's ends: ia, ia + 1, ib, ib + 1."""
        return np.array([self.ia, self.ia + 1, self.ib, self.ib + 1])

    @property
    def pad(self) -> int:
        """How many copies of the first inner row precede it in `padded`."""
        return PAD * -(-len(self.inner) // PAD) - len(self.inner)

    @property
    def padded(self) -> np.ndarray:
        """The inner rows padded in front to a multiple of PAD by copies of the first (zero-length intervals): row
        k of the turn is row k + pad of `turn_bulk`'s result."""
        return np.concatenate([np.full(self.pad, self.inner[0]), self.inner])

    def data(self) -> dict:
        """The layout as arrays (what `turn_bulk` needs besides the traced values)."""
        periods = np.concatenate([np.full(self.pad, self.periods[0]), self.periods]).astype(float)
        return {"t_edges": self.t[self.edges], "t_inner": self.t[self.padded], "targets": np.asarray(self.targets),
                "periods": periods}

    @classmethod
    def of(cls, t: np.ndarray, angle: np.ndarray, duration: float) -> "TurnLayout | None":
        """The layout of a run's rows (thermal/cycle.py `turn_boundaries` on the drive angle from its first row);
        None with fewer than two boundaries (no full turn)."""
        from mechsim.thermal.cycle import last_repetitions, turn_boundaries, turn_rows
        bounds = turn_boundaries(t, angle, angle[0])
        if len(bounds) < 2:
            return None
        a, b = float(bounds[-2]), float(bounds[-1])
        m = len(bounds)
        targets = (float(angle[0] + 2 * np.pi * (m - 1)), float(angle[0] + 2 * np.pi * m))
        ia, ib = (int(np.clip(np.searchsorted(angle, x, side="right") - 1, 0, len(t) - 2)) for x in targets)
        P = b - a
        inner = turn_rows(t, a, P)
        periods = last_repetitions(t[inner], P, duration)
        return cls(t, ia, ib, inner, targets, periods)


def turn_ends(t_edges, targets, angle_edges) -> tuple:
    """(a, b): the turn's ends where the drive angle passes the targets, linear between the rows around them
    (thermal/cycle.py `turn_boundaries`); *_edges: the values at rows ia, ia + 1, ib, ib + 1."""
    return tuple(_linear(targets[k], angle_edges[2 * k], angle_edges[2 * k + 1], t_edges[2 * k], t_edges[2 * k + 1])
                 for k in (0, 1))


def turn_means(t_edges, targets, angle_edges, gen_edges, pin_edges) -> dict:
    """a, P, Q_bar, gamma_bar of the turn from the drive angle and the generated and pin energies at the rows
    around its ends (thermal/cycle.py `cycle_means_from_energies` written out on them)."""
    a, b = turn_ends(t_edges, targets, angle_edges)
    G = [_linear(x, t_edges[2 * k], t_edges[2 * k + 1], gen_edges[2 * k], gen_edges[2 * k + 1])
         for k, x in enumerate((a, b))]
    Pn = [_linear(x, t_edges[2 * k], t_edges[2 * k + 1], pin_edges[2 * k], pin_edges[2 * k + 1])
          for k, x in enumerate((a, b))]
    energy = G[1] - G[0]
    return {"t_start": a, "period": b - a, "heat_mean": energy / (b - a), "share_mean": (Pn[1] - Pn[0]) / energy}


def turn_bulk(data: dict, angle_edges, gen_edges, pin_edges, u_edges, u_inner, network: dict, start_edges, xp=np):
    """Network states (rows = the padded inner rows, `TurnLayout.padded`) of the cycle-averaged solution at their
    last repetitions t_k + m_k P (data["periods"]), and the turn's means. data: `TurnLayout.data()`; *_edges: values
    at the rows around the turn's ends (start_edges: the network states there, of which the first two rows give
    T(a)); u_edges (4 x m), u_inner (padded rows x m): the rows' network inputs; network: capacity C, conductance K
    (dense), source s, input_matrix B."""
    t_edges, t_inner = data["t_edges"], data["t_inner"]
    means = turn_means(t_edges, data["targets"], angle_edges, gen_edges, pin_edges)
    a, P = means["t_start"], means["period"]
    Q, gamma = means["heat_mean"], means["share_mean"]
    u_bar = xp.stack([gamma * Q, (1.0 - gamma) * Q])
    u_a = _linear(a, t_edges[0], t_edges[1], u_edges[0], u_edges[1])
    u_b = _linear(a + P, t_edges[2], t_edges[3], u_edges[2], u_edges[3])
    T_a = _linear(a, t_edges[0], t_edges[1], start_edges[0], start_edges[1])
    sigma = xp.concatenate([xp.zeros(1), t_inner - a, xp.reshape(P, (1,))])
    U = xp.concatenate([u_a[None, :], u_inner, u_b[None, :]], axis=0)
    C, K, s, B = network["capacity"], network["conductance"], network["source"], network["input_matrix"]
    lam, V, Vinv = modes(C, K, xp)
    h = sigma[1:] - sigma[:-1]
    mean_u = xp.sum(0.5 * h[:, None] * (U[1:] + U[:-1]), axis=0) / P       # exact for the piecewise-linear input
    g = (U - mean_u[None, :]) @ (Vinv @ (B / C[:, None])).T
    Tp = periodic_response(lam, sigma, g, P, xp)
    since = t_inner + data["periods"] * P - a
    mean = mean_response(lam, V, Vinv, C, s, B, u_bar, T_a - V @ Tp[0], since, xp)
    return mean + Tp[1:-1] @ V.T, means


def phis(x, count: int, xp=np) -> list:
    """[phi_1(x), ..., phi_count(x)], phi_k(x) = sum_m x^m / (m + k)! = int_0^1 e^{x (1 - s)} s^(k-1)/(k-1)! ds: by
    their series below SERIES_BELOW, else phi_1 = (e^x - 1)/x and phi_(k+1) = (phi_k - 1/k!)/x (Hochbruck &
    Ostermann 2010, "Exponential integrators", Acta Numerica 19, eq. (2.10))."""
    small = xp.abs(x) < SERIES_BELOW
    safe = xp.where(small, 1.0, x)
    out, closed, fact = [], xp.expm1(safe) / safe, 1.0
    for k in range(1, count + 1):
        series, term = 0.0, 1.0
        for m in range(14):
            term_k = term / math.factorial(m + k)
            series = series + term_k * x ** m if m else series + term_k
        out.append(xp.where(small, series, closed))
        fact *= k
        closed = (closed - 1.0 / fact) / safe
    return out


def lagrange_monomials(nodes: np.ndarray) -> np.ndarray:
    """L with l_i(s) = sum_j L[i, j] s^j the Lagrange basis through `nodes` (l_i(nodes[k]) = delta_ik)."""
    return np.linalg.inv(np.vander(np.asarray(nodes, float), increasing=True).T)


def dense_turn_bulk(x: dict, data: dict, network: dict, u_nodes, xp=np):
    """Network states (rows = the instants data["times"] of the periodic turn, each at data["periods"] whole periods
    later) of the cycle-averaged solution whose turn input is read on the window's solution (thermal/plan.py
    `ThermalPlan._read_input`): polynomial through its values at the Gauss-Legendre nodes (data["nodes"] on [0, 1]) of
    each piece between x["edges"] (the pieces fixed by the turn and its events, `input_pieces`), and the turn's means.

    x: ends [a, b] (where the drive passes its start angle), gen, pin (the generated and pin energies there), start
    (the network's states at a), edges (the pieces' ends in time, padded at b by zero-length pieces); u_nodes (pieces
    x nodes x inputs): the input there; network: capacity C, conductance K (dense), source s, input_matrix B.

    As `turn_bulk`, T = M + T_p with the mean curve M from T(a) - T_p(a) under the cycle-mean input, exact in the
    modes, and the ripple T_p the periodic response to u - mean(u): for a piece of length h with modal input
    sum_j c_j s^j (s in [0, 1]) the zero-state response after theta h is h sum_j c_j j! theta^(j+1) phi_(j+1)(lambda h
    theta) (`phis`), so the ripple is exact for the polynomial input and the mean is its Gauss-Legendre sum, as
    thermal/cycle.py `bulk_response` integrates the same input to its quadrature error."""
    a, b = x["ends"][0], x["ends"][1]
    gen, pin = x["gen"], x["pin"]
    P = b - a
    energy = gen[1] - gen[0]
    Q, gamma = energy / P, (pin[1] - pin[0]) / energy
    u_bar = xp.stack([gamma * Q, (1.0 - gamma) * Q])
    C, K, s, B = network["capacity"], network["conductance"], network["source"], network["input_matrix"]
    lam, V, Vinv = modes(C, K, xp)
    sigma = x["edges"] - a
    h = sigma[1:] - sigma[:-1]
    weights = xp.asarray(data["weights"])
    mean_u = xp.sum(h[:, None] * xp.einsum("i,kim->km", weights, u_nodes), axis=0) / P
    g = (u_nodes - mean_u[None, None, :]) @ (Vinv @ (B / C[:, None])).T                # pieces x nodes x modes
    c = xp.einsum("ij,kin->kjn", xp.asarray(data["lagrange"]), g)                        # monomial coefficients
    count = c.shape[1]
    factorial = [float(math.factorial(j)) for j in range(count)]
    xs = lam[None, :] * h[:, None]
    ph = phis(xs, count, xp)
    f = h[:, None] * sum(c[:, j, :] * factorial[j] * ph[j] for j in range(count))
    weights_end = xp.exp(lam[None, :] * (P - sigma[1:, None]))
    Z = xp.concatenate([xp.zeros((1, lam.shape[0])),
                        xp.exp(lam[None, :] * (sigma[1:, None] - P)) * xp.cumsum(weights_end * f, axis=0)], axis=0)
    z = xp.exp(lam[None, :] * sigma[:, None]) * (Z[-1] / (-xp.expm1(lam * P)))[None, :] + Z
    k = xp.asarray(data["piece"])
    hk = h[k]
    theta = (data["times"] - a - sigma[k]) / hk
    xt = lam[None, :] * (hk * theta)[:, None]
    pt = phis(xt, count, xp)
    ripple = xp.exp(xt) * z[k] + hk[:, None] * sum(
        c[k, j, :] * factorial[j] * theta[:, None] ** (j + 1) * pt[j] for j in range(count))
    since = data["times"] + data["periods"] * P - a
    mean = mean_response(lam, V, Vinv, C, s, B, u_bar, x["start"] - V @ z[0], since, xp)
    return mean + ripple @ V.T, {"t_start": a, "period": P, "heat_mean": Q, "share_mean": gamma}
