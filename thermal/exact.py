"""Integrate the thermal network where no DAE runs: prescribed speed, closed-form kinematics + the thermal ODE.

docs/architecture.md: "prescribed speed needs no DAE: closed-form kinematics + thermal ODE only". The heat inputs are the
same functions the DAE rows use (thermal/coupling.py, numpy flavour), evaluated on the closed form. The
network is linear with constant coefficients, so each output interval is integrated exactly in the state
(variation of constants) and by Gauss-Legendre quadrature in the input:

    y(t + h) = e^{Ah} y(t) + int_0^h e^{A(h - s)} (C^-1 s0) ds + sum_j h w_j e^{A h (1 - x_j)} C^-1 B u(t + h x_j),

with A = -C^-1 K; intervals are split where the contact switches (the input jumps there), so the quadrature
only ever sees a smooth input (error ~ h^12 u^(12)). The inputs at every node come from one vectorised call of
the closed form: exact for the linear network, and far cheaper than `LinearThermalSystem.integrate` with BDF and
a closed-form call per step (docs/benchmarks.md, "Costs behind the code").
The bookkeeping energies (generated, into the pin, convected) are integrated alongside (the convected one
exactly, from the modal integral of T), so the heat balance closes to round-off here too.
"""
from __future__ import annotations

import functools
import weakref
from typing import Callable

import numpy as np

from mechsim.thermal.coupling import ThermalExtension
from mechsim.thermal.linear import LinearThermalSystem

#: Gauss-Legendre nodes per (sub-)interval
QUADRATURE_NODES = 6
#: rows farther apart than this much drive angle have the contact's switches searched between them on instants
#: SWITCH_STEP_RAD apart (at most SWITCH_INSTANTS a run): an engagement spans tens of degrees, its switches (entry,
#: slip reversal, flank switch, exit) apart by as much, and every built-in's own rows lie within 0.61 degree
WIDEST_GAP_RAD = np.radians(1.0)
SWITCH_STEP_RAD = np.radians(0.5)
SWITCH_INSTANTS = 200_000
#: bisection halvings per closed-form call in switch_times
SEARCH_LEVELS = 6
#: rows per block of `ModalNetwork.constant`'s elementwise work
CONSTANT_BLOCK = 4096
#: `ModalNetwork.integrate_many` advances the starts of at most this many pieces together, in a network of at most
#: this many states (their elementwise products with the modes held at once); longer ones one by one
SHORT_PIECES = 8
SHORT_STATES = 32


def closed_form_columns(mech, angle0: float, speed: float) -> Callable[[np.ndarray], dict]:
    """Result columns (dict of arrays) of the closed form at arbitrary times t >= 0 (it counts from its first time)."""
    def columns(t) -> dict:
        t = np.atleast_1d(np.asarray(t, dtype=float))
        cols = mech.closed_form(np.concatenate([[0.0], t]), angle0, speed)
        cols.pop("powers", None)
        out = {k: np.asarray(v)[1:] for k, v in cols.items()}
        out["t_s"] = t
        return out
    return columns


def input_function(ext: ThermalExtension, mech, columns_fn) -> Callable[[np.ndarray], np.ndarray]:
    """u(t) = [network inputs, Q, gamma Q] at an array of times, shape (n_inputs + 2, len(t)); the contact from
    the mechanism's `contact_state` of the closed-form columns."""
    parameter = ext.numeric_parameter()

    def inputs(t) -> np.ndarray:
        contact = mech.contact_state(columns_fn(t))
        u, Q, gamma = ext.inputs_numeric(contact, parameter)
        return np.vstack([u, Q[None, :], (gamma * Q)[None, :]])
    return inputs


def contact_code(cols: dict) -> np.ndarray:
    """One integer per row that changes wherever the heat input is not smooth: mode changes (jumps), and sign
    changes of the slip (|u| kinks: slip reversal) and of the normal force (flank switch). cols: result columns,
    or a mechanism's `closed_form_contact` (a boolean `engaged` in place of `mode`)."""
    if "engaged" in cols:
        mode = cols["engaged"]
    else:           # the column's own == where it is one (pandas' strings through pyarrow), else numpy's
        mode = cols["mode"] if hasattr(cols["mode"], "dtype") else np.asarray(cols["mode"])
        mode = np.asarray(mode == "engaged", dtype=bool)
    code = 9 * mode.astype(int)
    for k, name in ((3, "slip_speed_m_s"), (1, "contact_force_N")):
        if name in cols:
            code = code + k * (np.sign(np.asarray(cols[name], dtype=float)).astype(int) + 1)
    return code


def contact_columns(mech, angle0: float, speed: float, columns_fn, part: str = "closed_form_contact"
                    ) -> Callable[[np.ndarray], dict]:
    """What contact_code (part = 'closed_form_contact') or the mechanism's contact_state (part =
    'closed_form_heat') reads of the closed form at times t >= 0: the mechanism's own method `part` where it has
    one (the same numbers, counted from t = 0 as closed_form_columns counts, without the other columns), else
    columns_fn itself."""
    own = getattr(mech, part, None)
    if own is None:
        return columns_fn

    def contact(t) -> dict:
        t = np.atleast_1d(np.asarray(t, dtype=float))
        return {k: np.asarray(v)[1:] for k, v in own(np.concatenate([[0.0], t]), angle0, speed).items()}
    return contact


def switch_times(columns_fn, t_grid: np.ndarray, tol: float = 1e-13, levels: int = SEARCH_LEVELS,
                 grid_columns=None, known: np.ndarray | None = None) -> list[float]:
    """Times where the closed form's contact changes (see contact_code), by bisection between output rows, so
    that every quadrature interval sees a smooth input.

    All brackets are bisected together, `levels` halvings per closed-form call: each call evaluates the whole
    tree of midpoints the next `levels` halvings can visit (2^levels - 1 per bracket, each computed as the
    bisection computes it, 0.5 (a + b) of its own parents), then the halvings walk down that tree. About 36
    halvings take 6 calls instead of 36 (a call's fixed cost dominates the cost of a point);
    each bracket stops on its own tolerance, so the times are those of one-at-a-time bisection, to the bit.
    grid_columns: columns_fn(t_grid) when already at hand (the run's closed-form table), to save that call.
    known: instants known already (the run's events, sorted): a bracket holding one is not searched."""
    t_grid = np.asarray(t_grid, dtype=float)
    _, times = _bracket_switches(columns_fn, t_grid, tol, levels, grid_columns, known)
    return sorted(times.tolist())


def _unknown(idx: np.ndarray, t_grid: np.ndarray, known: np.ndarray | None) -> np.ndarray:
    """Which brackets (t_grid[i], t_grid[i + 1]] of `idx` hold none of the sorted instants `known`."""
    if known is None or not len(known) or not len(idx):
        return np.ones(len(idx), dtype=bool)
    return known.searchsorted(t_grid[idx]) == known.searchsorted(t_grid[idx + 1], side="right")


def _bracket_switches(columns_fn, t_grid: np.ndarray, tol: float, levels: int, grid_columns, known
                      ) -> tuple[np.ndarray, np.ndarray]:
    """`switch_times`' brackets (the rows i where the contact's code changes between i and i + 1, those holding a
    known instant left out) and each one's switch time, in the brackets' order."""
    code = contact_code(columns_fn(t_grid) if grid_columns is None else grid_columns)
    idx = np.flatnonzero(code[1:] != code[:-1])
    idx = idx[_unknown(idx, t_grid, known)]
    if not len(idx):
        return idx, np.zeros(0)
    a, b, ca = t_grid[idx].copy(), t_grid[idx + 1].copy(), code[idx]
    active = b - a > tol * np.maximum(1.0, np.abs(b))
    while np.any(active):
        j = np.flatnonzero(active)
        lo, hi = a[j, None], b[j, None]
        mids = []                                    # mids[l]: (brackets, 2^l) midpoints of the level-l nodes
        for level in range(levels):
            mid = 0.5 * (lo + hi)
            mids.append(mid)                         # children of node p: 2p = [lo, mid], 2p + 1 = [mid, hi]
            if level == levels - 1:                  # the last level's children are not evaluated
                break
            lo2, hi2 = np.empty((len(j), 2 * mid.shape[1])), np.empty((len(j), 2 * mid.shape[1]))
            lo2[:, 0::2], lo2[:, 1::2], hi2[:, 0::2], hi2[:, 1::2] = lo, mid, mid, hi
            lo, hi = lo2, hi2
        codes = contact_code(columns_fn(np.concatenate([m.ravel() for m in mids])))
        node, start, rows, cj = np.zeros(len(j), dtype=int), 0, np.arange(len(j)), ca[j]
        for mid in mids:
            width = mid.shape[1]
            same = codes[start:start + len(j) * width].reshape(len(j), width)[rows, node] == cj
            start += len(j) * width
            m = mid[rows, node]
            go = active[j]                           # a bracket that met its tolerance stops where it is
            up, down = go & same, go & ~same
            a[j[up]] = m[up]
            b[j[down]] = m[down]
            node = 2 * node + same
            active = b - a > tol * np.maximum(1.0, np.abs(b))
    return idx, 0.5 * (a + b)


#: the contact switches found per closed form and output rows (`contact_switches`): (the mechanism, by weak
#: reference, its brackets and their times) by (its identity, start angle, speed, the rows)
_SWITCHES: dict = {}


def contact_switches(mech, angle0: float, speed: float, t_grid: np.ndarray, grid_columns=None,
                     known: np.ndarray | None = None) -> list[float]:
    """`switch_times` of the closed form's contact (`contact_columns`) on the output rows `t_grid`, searched once for
    a run: its thermal integration (`integrate_closed_form`) and its located peaks (scenarios/peaks.py
    `_contact_switches`, with the events `known`) search the same brackets. The brackets holding a known instant
    are left out afterwards, as `switch_times` leaves them out before (each bracket's bisection is its own: the
    same times to the bit). Rows more than WIDEST_GAP_RAD of drive angle apart are searched on instants
    SWITCH_STEP_RAD apart between them (`_switch_grid`): a gap holding an engagement's entry, slip reversal and exit
    shows the same code at both its rows."""
    t_grid = np.asarray(t_grid, dtype=float)
    finer = _switch_grid(t_grid, speed)
    if finer is not None:
        t_grid, grid_columns = finer, None
    key = (id(mech), float(angle0), float(speed), len(t_grid), hash(t_grid.tobytes()))
    hit = _SWITCHES.get(key)
    if hit is None or hit[0]() is not mech:
        columns = contact_columns(mech, angle0, speed, closed_form_columns(mech, angle0, speed))
        idx, times = _bracket_switches(columns, t_grid, 1e-13, SEARCH_LEVELS, grid_columns, None)
        if len(_SWITCHES) >= 16:
            _SWITCHES.clear()
        hit = _SWITCHES[key] = (weakref.ref(mech), idx, times)
    _, idx, times = hit
    return sorted(times[_unknown(idx, t_grid, known)].tolist())


def _switch_grid(t: np.ndarray, speed: float) -> np.ndarray | None:
    """The rows with each gap wider than WIDEST_GAP_RAD of drive angle (at the prescribed speed) cut into equal
    parts of at most SWITCH_STEP_RAD (coarser where that would make more than SWITCH_INSTANTS instants), the rows
    themselves kept exactly (`dynamics.quadrature.split_gaps`); None where no gap is that wide."""
    from mechsim.dynamics.quadrature import split_gaps
    pace = abs(float(speed))
    if len(t) < 2 or not (pace > 0.0 and np.isfinite(pace)) or not np.max(np.diff(t)) * pace > WIDEST_GAP_RAD:
        return None
    return split_gaps(t, SWITCH_STEP_RAD / pace, SWITCH_INSTANTS)[0]


@functools.lru_cache(maxsize=8)
def _gauss_legendre(nodes: int) -> tuple[np.ndarray, np.ndarray]:
    """Gauss-Legendre nodes and weights on [0, 1] (numpy's leggauss on [-1, 1] mapped; kept once per node
    count, read-only)."""
    x, w = np.polynomial.legendre.leggauss(nodes)
    x, w = 0.5 * (x + 1.0), 0.5 * w
    x.setflags(write=False)
    w.setflags(write=False)
    return x, w


def _phi1(x: np.ndarray) -> np.ndarray:
    """(e^x - 1)/x, 1 at x = 0 (stable for small |x|)."""
    x = np.asarray(x, dtype=float)
    small = np.abs(x) < 1e-8
    if not small.any():                              # the quotient alone (what the selection below picks)
        return np.expm1(x) / x
    safe = np.where(small, 1.0, x)
    return np.where(small, 1.0 + 0.5 * x, np.expm1(safe) / safe)


def _interior_points(cuts: np.ndarray, max_piece: float) -> np.ndarray:
    """The interior points of each interval [cuts_i, cuts_i+1] split into k_i = ceil(length / max_piece) equal
    pieces: np.linspace(a, b, k + 1)[1:-1] for every interval at once, by linspace's own operations
    (a + j (b - a)/k, j = 1..k-1), so the same floats."""
    return _gap_points(cuts[:-1], cuts[1:], max_piece)[0]


def _gap_points(a: np.ndarray, b: np.ndarray, max_piece: float) -> tuple[np.ndarray, np.ndarray]:
    """(`_interior_points` of the gaps [a_i, b_i], each gap's index of each point)."""
    delta = b - a
    k = np.maximum(1, np.ceil(delta / max_piece).astype(int))
    gaps = np.flatnonzero(k > 1)
    a, b, delta, k = a[gaps], b[gaps], delta[gaps], k[gaps]
    step = delta / k
    count = k - 1
    if np.any(step == 0):                            # linspace's denormal branch: not worth reproducing
        return (np.concatenate([np.linspace(x, y, n + 1)[1:-1] for x, y, n in zip(a, b, k)] + [a[:0]]),
                np.repeat(gaps, count))
    first = np.cumsum(count) - count                 # where each interval's points start
    j = np.arange(int(count.sum())) - np.repeat(first, count) + 1
    return j * np.repeat(step, count) + np.repeat(a, count), np.repeat(gaps, count)


def _distinct(values: np.ndarray, segment: np.ndarray, origin: np.ndarray) -> tuple[np.ndarray, ...]:
    """The values of each segment sorted and distinct (as np.unique of each segment's alone), segment after segment:
    (values, their segments, each original value's position among them: origin[q] is where values' entry q came
    from, -1 for none)."""
    order = np.lexsort((values, segment))
    values, segment, origin = values[order], segment[order], origin[order]
    keep = np.ones(len(values), bool)
    keep[1:] = (segment[1:] != segment[:-1]) | (values[1:] != values[:-1])
    position = np.cumsum(keep) - 1                   # the first of each run of equal values
    at = np.full(int(origin.max(initial=-1)) + 1, -1, dtype=np.int64)
    mine = origin >= 0
    at[origin[mine]] = position[mine]
    return values[keep], segment[keep], at


def _pieces(T: np.ndarray, t_first: np.ndarray, known: np.ndarray, max_piece: float | None
            ) -> tuple[np.ndarray, ...]:
    """Every start's cuts, all in one pass of whole-array work: (cuts, first, where), start j's cuts
    cuts[first[j]:first[j + 1]] (its instants T[t_first[j]:t_first[j + 1]] (ascending), the `known` breaks strictly
    between its first and last, and with max_piece each gap longer split into equal pieces, `_interior_points`: the
    same floats as np.unique of those of each start alone), and where each instant lies among its start's cuts
    (`ModalNetwork.integrate_flat`)."""
    S = len(t_first) - 1
    seg = np.repeat(np.arange(S), np.diff(t_first))
    i0 = known.searchsorted(T[t_first[:-1]], side="right")
    nb = np.maximum(known.searchsorted(T[t_first[1:] - 1], side="left") - i0, 0)
    nth = np.arange(int(nb.sum())) - np.repeat(np.cumsum(nb) - nb, nb)
    cut, cseg, where = _distinct(np.concatenate([T, known[np.repeat(i0, nb) + nth]]),
                                 np.concatenate([seg, np.repeat(np.arange(S), nb)]),
                                 np.concatenate([np.arange(len(T)), np.full(int(nb.sum()), -1)]))
    if max_piece is not None and len(cut) > 1:
        inner = cseg[1:] == cseg[:-1]                # the gaps between a start's own cuts
        gaps = np.flatnonzero(inner)
        if len(gaps) and (cut[gaps + 1] - cut[gaps]).max() > max_piece:
            points, of = _gap_points(cut[gaps], cut[gaps + 1], max_piece)
            if len(points):
                cut, cseg, at = _distinct(np.concatenate([cut, points]), np.concatenate([cseg, cseg[gaps[of]]]),
                                          np.concatenate([np.arange(len(cut)), np.full(len(points), -1)]))
                where = at[where]
    first = np.searchsorted(cseg, np.arange(S + 1))
    return cut, first, where - first[seg]


class ModalNetwork:
    """Exact linear algebra of a reciprocal network C T' = -K T + s + B u in its modes.

    K is symmetric, so A = -C^-1 K = V diag(lambda) V^-1 with V = C^-1/2 Q, V^-1 = Q^T C^1/2 and (lambda, Q) the
    eigenpairs of the symmetric -C^-1/2 K C^-1/2 (numpy eigh): e^{At} is then elementwise. (scipy's expm was ~1000x
    slower than this on a loaded 2-core machine, where its BLAS threads wait for cores.)
    `loss` = K^T 1 gives the convected power loss . T - sum(s); `source=False` drops s (for the ripple).
    """

    def __init__(self, system: LinearThermalSystem, loss: np.ndarray | None = None, source: bool = True):
        K = np.asarray(system.dense_conductance(), dtype=float)
        if not np.allclose(K, K.T, rtol=1e-12, atol=1e-14 * np.abs(K).max()):
            raise ValueError("ModalNetwork needs a symmetric (reciprocal) conductance matrix")
        d = 1.0 / np.sqrt(system.capacity)
        lam, Q = np.linalg.eigh(-(d[:, None] * K * d[None, :]))
        self.lam = lam
        self.V = d[:, None] * Q
        self.Vinv = Q.T / d[None, :]
        self.s = system.source if source else np.zeros(system.size)
        self.b0 = self.Vinv @ (self.s / system.capacity)               # modal source
        self.Bm = self.Vinv @ (system.input_matrix / system.capacity[:, None])
        self.loss = np.zeros(system.size) if loss is None else np.asarray(loss, dtype=float)
        self.loss_m = self.loss @ self.V                               # convected power in modal coordinates
        self.n = system.size

    def exp(self, t, x: np.ndarray) -> np.ndarray:
        """e^{At} x for an array of times (rows)."""
        t = np.atleast_1d(np.asarray(t, dtype=float))
        return (np.exp(self.lam[None, :] * t[:, None]) * (self.Vinv @ x)[None, :]) @ self.V.T

    def resolvent_periodic(self, x: np.ndarray, period: float) -> np.ndarray:
        """(I - e^{AP})^-1 x (needs every mode to decay: lambda < 0)."""
        return self.V @ ((self.Vinv @ x) / (-np.expm1(self.lam * period)))

    def constant(self, T0: np.ndarray, u: np.ndarray, times, energy: bool = True
                 ) -> tuple[np.ndarray, np.ndarray | None]:
        """(T(t), convected energy E_conv(t)) from T0 at t = 0 under a constant input u: exact. energy=False: the
        states only (None for the energy), for callers that discard it (an hour of rows: a third of the work)."""
        t = np.atleast_1d(np.asarray(times, dtype=float))[:, None]
        z0, g = self.Vinv @ np.asarray(T0, dtype=float), self.b0 + self.Bm @ np.asarray(u, dtype=float)
        if not energy:
            # the modal states block by block (the same operations per element; blocks that stay in the cache
            # instead of a dozen passes over an hour of rows), then mapped back in one product as before
            z = np.empty((len(t), self.n))
            for k in range(0, len(t), CONSTANT_BLOCK):
                tk = t[k:k + CONSTANT_BLOCK]
                lt = self.lam[None, :] * tk
                z[k:k + CONSTANT_BLOCK] = np.exp(lt) * z0 + tk * _phi1(lt) * g
            return z @ self.V.T, None
        lt = self.lam[None, :] * t
        p1 = _phi1(lt)
        z = np.exp(lt) * z0 + t * p1 * g
        # int_0^t z = t phi1 z0 + t^2 phi2 g, phi2(x) = (phi1(x) - 1)/x (series near 0)
        small = np.abs(lt) < 1e-6
        phi2 = np.where(small, 0.5 + lt / 6.0, (p1 - 1.0) / np.where(small, 1.0, lt))
        integral = t * p1 * z0 + t * t * phi2 * g
        return z @ self.V.T, integral @ self.loss_m - t[:, 0] * float(np.sum(self.s))

    def integrate(self, inputs: Callable[[np.ndarray], np.ndarray], t_out: np.ndarray, y0: np.ndarray,
                  breaks: list[float], nodes: int = QUADRATURE_NODES, max_piece: float | None = None) -> np.ndarray:
        """States [T, E_gen, E_pin, E_conv] at t_out from y0 at t_out[0]; inputs(t) -> [u..., Q, gamma Q] rows.
        max_piece: intervals longer than this are split into equal pieces (so that the quadrature's error does not
        grow with the spacing of t_out).

        Per interval h (split at the breaks): z <- e^{lambda h} z + sum_j h w_j e^{lambda h (1 - x_j)} g_j, and
        int z = h phi1(lambda h) z + sum_j h w_j h (1 - x_j) phi1(lambda h (1 - x_j)) g_j, g_j the modal forcing.
        """
        return self.integrate_many(inputs, [(t_out, y0)], breaks, nodes, max_piece)[0]

    def integrate_many(self, inputs: Callable[[np.ndarray], np.ndarray], starts: list[tuple[np.ndarray, np.ndarray]],
                       breaks: list[float], nodes: int = QUADRATURE_NODES, max_piece: float | None = None
                       ) -> list[np.ndarray]:
        """`integrate` of each (t_out, y0) of `starts`, each on its own pieces (its states do not depend on the
        other starts): `integrate_flat` of them all."""
        sizes = np.array([len(t_out) for t_out, _ in starts], dtype=np.int64)
        t_first = np.concatenate([[0], np.cumsum(sizes)])
        states = self.integrate_flat(inputs, np.concatenate([np.asarray(t, dtype=float) for t, _ in starts]),
                                     t_first, np.array([y0 for _, y0 in starts], dtype=float).reshape(
                                         len(starts), self.n + 3), breaks, nodes, max_piece)
        return [states[t_first[j]:t_first[j + 1]] for j in range(len(starts))]

    def integrate_flat(self, inputs: Callable[[np.ndarray], np.ndarray], t_out: np.ndarray, t_first: np.ndarray,
                       y0: np.ndarray, breaks: list[float], nodes: int = QUADRATURE_NODES,
                       max_piece: float | None = None) -> np.ndarray:
        """The states at t_out of several starts, start j from y0[j] at t_out[t_first[j]] over its instants
        t_out[t_first[j]:t_first[j + 1]] (ascending), each on its own pieces as `integrate` (its states do not
        depend on the other starts): every start's pieces found in one pass of whole-array work (`_pieces`), the
        heat input evaluated at all their quadrature nodes in one call (an input's evaluation, the closed form's,
        has a fixed cost that dominates a short integration's), each piece's decay and forcing in one pass; the
        recurrence and the sums over each start's own pieces then start by start (`_advanced`) for a long start,
        and for the short ones (a reading from the row before it: a piece or two) all together, piece index by
        piece index (`_advanced_short`: the same operations per element, the products with the modes as
        elementwise sums)."""
        x, w = _gauss_legendre(nodes)
        S = len(y0)
        cut, first, where = _pieces(t_out, t_first, np.sort(np.asarray(breaks, dtype=float)), max_piece)
        count = np.diff(first) - 1                                      # pieces of each start
        lo = np.ones(len(cut), bool)
        lo[first[1:] - 1] = False                                       # a start's last cut begins no piece
        h = (cut[1:] - cut[:-1])[lo[:-1]]                               # every start's pieces, start after start
        U = np.asarray(inputs((cut[lo][:, None] + h[:, None] * x[None, :]).ravel()), dtype=float)
        u = U.reshape(U.shape[0], len(h), nodes)
        m = self.Bm.shape[1]
        g = self.b0[:, None, None] + np.einsum("im,mkj->ikj", self.Bm, u[:m])         # (n, K, nodes)
        lam = self.lam[:, None]
        decay = np.exp(lam * h[None, :])                                               # (n, K)
        rest = h[None, :, None] * (1.0 - x[None, None, :])                             # time left after node j
        weights = h[None, :, None] * w[None, None, :]
        lam_rest = lam[:, :, None] * rest
        forcing = np.sum(weights * np.exp(lam_rest) * g, axis=2)
        forcing_int = np.sum(weights * rest * _phi1(lam_rest) * g, axis=2)
        carry_int = h[None, :] * _phi1(lam * h[None, :])
        if u.shape[0] >= m + 2:
            q_int = np.sum(w[None, :] * u[m], axis=1) * h, np.sum(w[None, :] * u[m + 1], axis=1) * h
        else:                                                      # no heat rows: no bookkeeping energies
            q_int = np.zeros(len(h)), np.zeros(len(h))
        piece0 = first[:-1] - np.arange(S)                              # each start's first piece
        out = np.empty((len(t_out), self.n + 3))
        short = (count <= SHORT_PIECES) & (self.n <= SHORT_STATES)
        for j in np.flatnonzero(~short).tolist():
            k = slice(piece0[j], piece0[j] + count[j])
            mine = slice(t_first[j], t_first[j + 1])
            out[mine] = self._advanced(t_out[mine], y0[j], cut[first[j]:first[j + 1]], h[k], decay[:, k],
                                       forcing[:, k], forcing_int[:, k], carry_int[:, k], (q_int[0][k], q_int[1][k]))
        if short.any():
            ids = np.flatnonzero(short)
            got = self._advanced_short(y0[ids], piece0[ids], count[ids], h, decay, forcing, forcing_int, carry_int,
                                       q_int)
            sizes = np.diff(t_first)
            rows = np.repeat(ids, sizes[ids])                           # each short start's instants, in order
            nth = np.arange(len(rows)) - np.repeat(np.cumsum(sizes[ids]) - sizes[ids], sizes[ids])
            at = t_first[rows] + nth
            out[at] = got[np.repeat(np.arange(len(ids)), sizes[ids]), where[at]]
        return out

    def _advanced_short(self, y0: np.ndarray, piece0: np.ndarray, count: np.ndarray, h: np.ndarray,
                        decay: np.ndarray, forcing: np.ndarray, forcing_int: np.ndarray, carry_int: np.ndarray,
                        q_int: tuple) -> np.ndarray:
        """`_advanced` of several starts (their states y0, first piece and piece count among the pieces' arrays),
        each at every one of its cuts: (starts, most pieces + 1, n + 3), a start's cuts past its last its last
        state. The recurrence piece index by piece index over all the starts at once, and each product with the
        modes an elementwise sum over them, so that a start's states are the same in any batch."""
        n, S, P = self.n, len(y0), int(count.max(initial=0))
        k = np.minimum(piece0[:, None] + np.minimum(np.arange(P)[None, :], np.maximum(count - 1, 0)[:, None]),
                       max(len(h) - 1, 0))                                    # (S, P): a held start reads any
        live = np.arange(P)[None, :] < count[:, None]
        Z = np.empty((S, P + 1, n))
        Z[:, 0] = (self.Vinv[None, :, :] * y0[:, None, :n]).sum(axis=2)
        D, F = decay.T[k], forcing.T[k]                                                 # (S, P, n)
        for p in range(P):                           # past a start's last piece its state is held
            Z[:, p + 1] = np.where(live[:, p, None], D[:, p] * Z[:, p] + F[:, p], Z[:, p])
        z_int = carry_int.T[k] * Z[:, :-1] + forcing_int.T[k]                          # (S, P, n)
        conv = (z_int * self.loss_m).sum(axis=2) - float(np.sum(self.s)) * h[k]
        out = np.empty((S, P + 1, n + 3))
        out[:, :, :n] = (Z[:, :, None, :] * self.V[None, None, :, :]).sum(axis=3)
        out[:, 0] = y0
        for j, inc in enumerate((q_int[0][k], q_int[1][k], conv)):
            column = out[:, :, n + j]
            for p in range(P):                       # cumsum's order: one addition a piece
                column[:, p + 1] = np.where(live[:, p], column[:, p] + inc[:, p], column[:, p])
        return out

    def _advanced(self, t_out: np.ndarray, y0: np.ndarray, cuts: np.ndarray, h: np.ndarray, decay: np.ndarray,
                  forcing: np.ndarray, forcing_int: np.ndarray, carry_int: np.ndarray, q_int: tuple) -> np.ndarray:
        """`integrate`'s states at t_out from y0 over the pieces h between the cuts, from each piece's modal decay
        and forcing, their integrals over it (n, pieces) and the heat inputs' (`integrate_many`)."""
        y = np.asarray(y0, dtype=float)
        # the modal recurrence z_{k+1} = decay_k z_k + forcing_k is the only sequential part: per mode, over Python
        # floats (the same IEEE operations as numpy's, faster than a loop of length-n array steps, and a plain loop
        # faster than itertools.accumulate with a lambda); the rest is whole-array work. cumsum adds in
        # order, as the step-by-step sum did.
        Z = np.empty((len(cuts), self.n))
        for i, z in enumerate((self.Vinv @ y[:self.n]).tolist()):
            column = [z]
            append = column.append
            for d, f in zip(decay[i].tolist(), forcing[i].tolist()):
                z = d * z + f
                append(z)
            Z[:, i] = column
        z_int = carry_int.T * Z[:-1] + forcing_int.T                                   # (K, n)
        conv = z_int @ self.loss_m - float(np.sum(self.s)) * h
        out = np.empty((len(cuts), self.n + 3))
        out[:, :self.n] = Z @ self.V.T
        out[0] = y
        for j, inc in enumerate((q_int[0], q_int[1], conv)):
            out[:, self.n + j] = np.cumsum(np.concatenate([[y[self.n + j]], inc]))
        return out[np.searchsorted(cuts, t_out)]


def states_between_rows(network: ModalNetwork, inputs: Callable, breaks: list[float], t_rows: np.ndarray,
                        rows: np.ndarray, times: np.ndarray, max_piece: float | None = None) -> np.ndarray:
    """The states [T, E_gen, E_pin, E_conv] at any instants from the states `rows` at the rows t_rows: each
    integrated exactly in the modes (`ModalNetwork.integrate`, split at the breaks) from the row at or before it (the
    first row for an instant before it), as the rows themselves were: so a reading between rows is the solution
    the rows sample, whatever the rows' spacing (to the quadrature's error on the pieces between them)."""
    return states_between_rows_many(network, inputs, breaks, t_rows, rows, [times], max_piece)[0]


def states_between_rows_many(network: ModalNetwork, inputs: Callable, breaks: list[float], t_rows: np.ndarray,
                             rows: np.ndarray, times: list[np.ndarray], max_piece: float | None = None
                             ) -> list[np.ndarray]:
    """`states_between_rows` of each array of instants in `times`, each on its own (the same states as one at a
    time): an array's instants after one row integrated together from it, and every such integration of every
    array run together (`ModalNetwork.integrate_flat`: one evaluation of the input)."""
    outs, places, t_out, sizes, y0 = [], [], [], [], []
    for ts in times:
        ts = np.asarray(ts, dtype=float)
        at = np.clip(np.searchsorted(t_rows, ts, side="right") - 1, 0, len(t_rows) - 1)
        out = rows[at]                  # (an instant at a row, or before the first, is that row's)
        outs.append(out)
        ahead = np.flatnonzero(ts > t_rows[at])
        if not len(ahead):
            continue
        r, t = at[ahead], ts[ahead]
        order = np.lexsort((t, r))      # each row's later instants, distinct and ascending: a start per row
        r, t = r[order], t[order]
        keep = np.ones(len(t), bool)
        keep[1:] = (r[1:] != r[:-1]) | (t[1:] != t[:-1])
        position = np.empty(len(t), dtype=np.int64)
        position[order] = np.cumsum(keep) - 1
        r, t = r[keep], t[keep]
        new = np.ones(len(r), bool)
        new[1:] = r[1:] != r[:-1]
        row = r[new]
        # each start's instants: its row's, then the later ones (a place for the row's instant before each group)
        group = np.cumsum(new) - 1
        slot = np.arange(len(t)) + group + 1
        instants = np.empty(len(t) + len(row))
        instants[slot] = t
        instants[slot[new] - 1] = t_rows[row]
        t_out.append(instants)
        sizes.append(np.bincount(group, minlength=len(row)) + 1)
        y0.append(rows[row])
        places.append((out, ahead, slot[position]))
    if t_out:
        sizes = np.concatenate(sizes)
        states = network.integrate_flat(inputs, np.concatenate(t_out), np.concatenate([[0], np.cumsum(sizes)]),
                                        np.concatenate(y0), breaks, max_piece=max_piece)
        a = 0
        for (out, ahead, slots), instants in zip(places, t_out):
            out[ahead] = states[a + slots]
            a += len(instants)
    return outs


def integrate_closed_form(ext: ThermalExtension, mech, angle0: float, speed: float, t_out: np.ndarray,
                          y0: np.ndarray, table=None, max_piece: float | None = None
                          ) -> tuple[np.ndarray, Callable, list[float]]:
    """Thermal states [T..., E_gen, E_pin, E_conv] at t_out for the closed-form motion; also the input function
    and the contact switch times (for reuse by the cycle-averaged model). table: the closed form's columns at
    t_out, if already computed (the run's table). max_piece: the longest quadrature piece (`ModalNetwork.integrate`)."""
    columns = closed_form_columns(mech, angle0, speed)
    inputs = input_function(ext, mech, contact_columns(mech, angle0, speed, columns, "closed_form_heat"))
    breaks = contact_switches(mech, angle0, speed, t_out, grid_columns=table)
    return ModalNetwork(ext.system, ext.loss).integrate(inputs, t_out, y0, breaks, max_piece=max_piece), inputs, breaks
