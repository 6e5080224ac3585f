"""Turn a raw hybrid trajectory into the result tables (SI, `<quantity>_<unit>` columns)."""
from __future__ import annotations

import weakref
from collections.abc import Mapping
from typing import TYPE_CHECKING

import numpy as np
import pandas as pd

from mechsim.dynamics import kkt

if TYPE_CHECKING:      # the tables read a finished Trajectory; importing the loop would load sympy for nothing
    from mechsim.dynamics.hybrid import Trajectory


class TableColumns(Mapping):
    """A result table's columns as numpy arrays, each read from the frame once (a pandas column read is not free,
    and a run's summary and checks read the same columns several times); `names` in the frame's order.
    The arrays are the frame's own data (`Series.to_numpy`, no copy): use it while the frame is unchanged."""

    def __init__(self, frame: pd.DataFrame):
        self.frame = frame
        self.names: list[str] = frame.columns.tolist()
        self._known = set(self.names)
        self._read: dict[str, np.ndarray] = {}
        #: column positions, where the names are unique (else each read goes through the frame's own indexing)
        self._at = {n: i for i, n in enumerate(self.names)} if len(self._known) == len(self.names) else None

    def __getitem__(self, name: str) -> np.ndarray:
        values = self._read.get(name)
        if values is None:
            if name not in self._known:
                raise KeyError(name)
            values = self._read[name] = (self.frame[name].to_numpy() if self._at is None
                                         else column_values(self.frame, self._at[name]))
        return values

    def __contains__(self, name) -> bool:
        return name in self._known

    def __iter__(self):
        return iter(self.names)

    def __len__(self) -> int:
        return len(self.names)


#: pandas' internal column read (not public API: present in pandas 2 and 3); without it, the public path
_COLUMN_ARRAY = getattr(pd.DataFrame, "_get_column_array", None)


def column_values(frame: pd.DataFrame, i: int) -> np.ndarray:
    """frame.iloc[:, i].to_numpy() as Series.to_numpy gives it (a read-only view of a numpy column; an extension
    column, such as pandas' string dtype, through its own to_numpy with the same defaults), read from the frame's
    block directly, without building the Series first (docs/benchmarks.md, "Costs behind the code"). The block read is a
    pandas internal: if a pandas version lacks it or it fails, the column is read through the public Series."""
    try:
        values = _COLUMN_ARRAY(frame, i)
    except Exception:          # noqa: BLE001  (absent or changed internal: the public read below is the reference)
        return frame.iloc[:, i].to_numpy()
    if isinstance(values, np.ndarray):
        view = values.view()
        view.flags.writeable = False
        return view
    return values.to_numpy()


def coordinate_columns(name: str, is_angle: bool) -> tuple[str, str, str]:
    """Column names of a coordinate's position, speed and acceleration."""
    if is_angle:
        return f"{name}_angle_rad", f"{name}_speed_rad_s", f"{name}_accel_rad_s2"
    return f"{name}_position_m", f"{name}_speed_m_s", f"{name}_accel_m_s2"


def kkt_rows(mf, t: np.ndarray, q: np.ndarray, v: np.ndarray, x: np.ndarray, p: tuple):
    """Accelerations and multipliers from the KKT system at every output row (exact for the row's q, v).

    The index-2/3 forms keep multipliers out of IDA's error test (SolverSettings.multiplier_atol), so the
    multiplier states are not accurate enough to report forces from; the KKT solution at the integrated
    (q, v) is, in every formulation and backend.
    """
    return _kkt(mf, t, list(q.T), list(v.T), list(x.T), p)[1:]


def _kkt(mf, t, qT, vT, xT, p):
    """(M, a, lam) at every row: `kkt_rows` with the mass matrix it solved with (the kinetic energy's): on a long
    stack as the lambdified entries (nq lists of nq: arrays over the rows, or scalars every row shares), the
    system solved entry by entry (`kkt.solve_entries`); on a short one stacked (rows, nq, nq), solved by LAPACK.
    qT, vT, xT: a list of each variable's rows (the generated functions unpack them: a list unpacks at a tenth of
    an array's cost)."""
    f = mf.kkt_flat
    n, nq, m = len(t), len(qT), mf.m
    mass = f["mass"](qT, p)
    Q0 = f["force0"](t, qT, vT, xT, p)
    if not kkt.long_stack(n, nq + m):     # a short stack: LAPACK's (M kept stacked)
        if m == 0:
            return kkt.solve_short(n, mass, [], [], Q0, [])
        return kkt.solve_short(n, mass, f["G"](t, qT, p), f["force_lam"](t, qT, vT, xT, p), Q0,
                               f["gamma"](t, qT, vT, p))
    M = [mass[i * nq:(i + 1) * nq] for i in range(nq)]
    if m == 0:
        return (M,) + kkt.solve_entries(n, M, [], [[] for _ in range(nq)], Q0, [])
    G, Ql = f["G"](t, qT, p), f["force_lam"](t, qT, vT, xT, p)
    return (M,) + kkt.solve_entries(n, M, [G[k * nq:(k + 1) * nq] for k in range(m)],
                                    [Ql[i * m:(i + 1) * m] for i in range(nq)], Q0,
                                    [-np.asarray(g, dtype=float) for g in f["gamma"](t, qT, vT, p)])


def _quadratic_form(v: np.ndarray, M) -> np.ndarray:
    """v_r^T M_r v_r of every row r, v as (rows, nq) and M as (rows, nq, nq) or nq lists of nq entries (arrays over
    the rows, or scalars): numpy.einsum("ri,rij,rj->r") on M stacked, whose sum over many rows takes the terms
    (v_i M_ij) v_j in order of i, then j; that sum an entry at a time (the same values to the last bit, several
    times faster on a few coordinates). A short stack goes to einsum itself (on one row it orders the sum
    otherwise)."""
    rows, nq = v.shape
    stacked = isinstance(M, np.ndarray)       # (rows, nq, nq), or entries
    if rows < 64:               # (v in C order, as einsum was given it from the rows of states)
        v = np.ascontiguousarray(v)
        return np.einsum("ri,rij,rj->r", v, M if stacked else kkt.stack_entries([e for row in M for e in row], rows,
                                                                                (nq, nq)), v)
    v = v.T
    total = None
    for i in range(nq):
        for j in range(nq):
            term = v[i] * (M[:, i, j] if stacked else M[i][j]) * v[j]
            total = term if total is None else total + term
    return total


def _mode_params(pieces) -> tuple:
    """The parameters of a mode's pieces, row-aligned with their stacked rows: a value every piece shares as
    that scalar, one that changes from piece to piece (a re-based drive angle, a restart time) as a per-row array,
    so each lambdified read-out is called once on all of the mode's rows. Values are compared as numpy compares
    them as floats (a NaN differs from itself)."""
    first = pieces[0].params
    if all(p.params == first for p in pieces[1:]):
        return first
    counts = np.array([len(p.t) for p in pieces])
    params = list(first)
    P = np.array([p.params for p in pieces], dtype=float)        # (pieces, parameters)
    for j in np.flatnonzero(~(P == P[0]).all(axis=0)).tolist():  # a parameter over the pieces (a NaN never shared)
        params[j] = np.repeat(P[:, j], counts)
    return tuple(params)


def _constraint_values(mf, t: np.ndarray, q: np.ndarray, p: tuple, qT: list | None = None) -> np.ndarray:
    """Phi(t, q) as (rows, m): one call on all rows (qT: q's rows as a list, if at hand); row by row where an entry
    does not broadcast (a constant constraint entry makes the lambdified matrix ragged)."""
    try:
        phi = np.asarray(mf.phi(t, q.T if qT is None else qT, p), dtype=float)
        if phi.ndim == 3 and phi.shape[:2] == (mf.m, 1) and phi.shape[2] == len(t):
            return phi[:, 0, :].T
    except (ValueError, TypeError):
        pass
    rows = [(ti, qi, tuple(pj if np.ndim(pj) == 0 else pj[r] for pj in p)) for r, (ti, qi) in enumerate(zip(t, q))]
    return np.asarray([np.ravel(mf.phi(ti, qi, pr)) for ti, qi, pr in rows]).reshape(len(t), mf.m)


def _kept_rows(t: np.ndarray) -> np.ndarray | None:
    """Rows to keep where an instant repeats (the later one, the state after a mode change), as
    DataFrame.drop_duplicates(subset="t_s", keep="last"); None where every row is kept."""
    if len(t) > 1 and (t[1:] > t[:-1]).all():        # strictly increasing: nothing repeats
        return None
    d = np.diff(t)
    if np.all(d >= 0):              # time order (every backend's): repeats are neighbours
        keep = np.append(d != 0, True)
    else:
        keep = ~pd.Series(t).duplicated(keep="last").to_numpy()
    return None if keep.all() else keep


#: what is derived once from a model's or a mode's structure (`_kept`): (weak reference to it, the value) by key
_DERIVED: dict = {}


def _kept(owner, key, build):
    """build(), kept for (owner, key) while owner lives: a table's layout and the rows each part of a mode's block
    fills follow from the model's structure alone, and deriving them again was a fixed cost of every read-out, most
    of it on a located peak's few rows. Keyed by identity (the model and its modes are dataclasses: compared by
    value, not hashable); a weak reference, so a model that goes leaves nothing behind that answers for another."""
    k = (id(owner), key)
    hit = _DERIVED.get(k)
    if hit is not None and hit[0]() is owner:
        return hit[1]
    value = build()
    if len(_DERIVED) >= 512:
        _DERIVED.clear()
    _DERIVED[k] = (weakref.ref(owner), value)
    return value


def _layout(model, angle_coordinates: tuple[int, ...], modes: list[str], residual: bool = True) -> tuple[str, ...]:
    """The table's columns: time, coordinates (position, speed, acceleration each), the first mode's read-outs,
    kinetic energy, works, constraint residual, extension states, then a read-out only a later mode has (as
    pandas' concat of per-piece frames put them); "mode" goes in second place."""
    return _kept(model, ("layout", tuple(angle_coordinates), tuple(modes), residual),
                 lambda: _derive_layout(model, angle_coordinates, modes, residual))


def _derive_layout(model, angle_coordinates, modes, residual) -> tuple[str, ...]:
    names = ["t_s"]
    for i, name in enumerate(model.coordinates):
        names += coordinate_columns(name, i in angle_coordinates)
    first = list(model.modes[modes[0]].readout_names) if modes else []
    names += first + ["kinetic_energy_J"] + [f"work_{w}_J" for w in model.work_names] + \
        (["constraint_residual_m"] if residual else []) + list(model.extension_names)
    later = [nm for mode in modes for nm in model.modes[mode].readout_names]
    return tuple(names + list(dict.fromkeys(nm for nm in later if nm not in names)))


class _Slots:
    """The rows of a mode's block (`_mode_block`, columns `names`) that each of its parts fills: its read-outs,
    kinetic energy (works after it), constraint residual, extension states; `missing`, the read-outs of other
    modes, left NaN (None where there are none)."""

    def __init__(self, model, mf, names: tuple[str, ...], residual: bool):
        at = {nm: i for i, nm in enumerate(names)}
        ncoord = len(model.coordinates)
        fixed = set(names[:1 + 3 * ncoord]) | {"kinetic_energy_J", "constraint_residual_m"} | set(
            model.extension_names) | {f"work_{w}_J" for w in model.work_names}
        own = set(mf.readout_names)
        missing = [i for i, nm in enumerate(names) if nm not in own and nm not in fixed]
        self.missing = np.array(missing, dtype=np.intp) if missing else None
        self.readouts = [at[nm] for nm in mf.readout_names]
        self.ke = at["kinetic_energy_J"]
        self.works = slice(self.ke + 1, self.ke + 1 + len(model.work_names))
        self.residual = self.works.stop if residual else None
        start = self.works.stop + (1 if residual else 0)
        self.ext = slice(start, start + len(model.extension_names))
        self.n_mech = mf.m - (1 if model.prescribed else 0)


def _unwrapped(out: np.ndarray, q: np.ndarray, pieces) -> None:
    """The positions unwrapped into out (coordinates, rows): q is in each piece's re-based frame, plus the piece's
    offset where it has one (`Piece.coordinates`, for all pieces at once; the same sums)."""
    offsets = [pc.offset for pc in pieces]
    if all(o is None for o in offsets):
        out[...] = q.T
        return
    if all(o is offsets[0] for o in offsets):          # one piece, or pieces of one call: one offset
        np.add(q.T, np.asarray(offsets[0], dtype=float)[:, None], out=out)
        return
    counts = [len(pc.t) for pc in pieces]
    shift = np.repeat(np.array([np.zeros(q.shape[1]) if o is None else o for o in offsets], dtype=float).T, counts,
                      axis=1)
    if all(o is not None for o in offsets):
        np.add(q.T, shift, out=out)
        return
    out[...] = q.T
    np.add(out, shift, out=out, where=np.repeat([o is not None for o in offsets], counts))


def _mode_block(model, pieces, names: tuple[str, ...], residual: bool = True) -> np.ndarray:
    """The columns `names` over the rows of one mode's pieces, stacked, as (len(names), rows): read-outs, the
    KKT solution, kinetic energy and constraint residual evaluated once on all rows (parameters that differ
    between pieces as per-row arrays); a read-out this mode lacks is NaN."""
    mf = model.modes[pieces[0].mode]
    ix, ncoord = mf.index, len(model.coordinates)
    slots = _kept(mf, ("slots", names, residual), lambda: _Slots(model, mf, names, residual))
    block = np.empty((len(names), sum(len(pc.t) for pc in pieces)))
    # the states a variable a row (contiguous: every evaluation below reads them elementwise)
    if len(pieces) == 1:
        t = block[0] = pieces[0].t
        yT = np.ascontiguousarray(pieces[0].y.T)
    else:
        t = np.concatenate([pc.t for pc in pieces], out=block[0])
        yT = np.concatenate([pc.y.T for pc in pieces], axis=1)
    if slots.missing is not None:
        block[slots.missing] = np.nan
    qT, vT, xT = yT[ix["q"]], yT[ix["v"]], yT[ix["ext"]]
    ql, vl, xl = list(qT), list(vT), list(xT)          # (the generated functions unpack lists cheaper)
    p = _mode_params(pieces)
    M, a, lam = _kkt(mf, t, ql, vl, xl, p)
    block[2:1 + 3 * ncoord:3] = vT
    block[3:1 + 3 * ncoord:3] = a.T
    _unwrapped(block[1:1 + 3 * ncoord:3], qT.T, pieces)
    # (a read-out with a pole where a mode's event lies, the chain's coupler force at its crank stop, is inf on a
    # row at that event exactly: the value, which the peaks report as unbounded (docs/theory.md §K5), not a fault)
    with np.errstate(divide="ignore"):
        values = mf.readouts["_all"](t, ql, vl, list(a.T), list(lam.T), xl, p)
    for row, val in zip(slots.readouts, values):
        block[row] = val                               # a scalar read-out broadcasts over the rows
    np.multiply(0.5, _quadratic_form(vT.T, M), out=block[slots.ke])          # 1/2 v^T M v with the KKT's M
    block[slots.works] = yT[ix["work"]]
    if residual:
        n_mech = slots.n_mech
        if n_mech == 1:         # (the largest of one: that one)
            np.abs(_constraint_values(mf, t, qT.T, p, ql)[:, 0], out=block[slots.residual])
        elif n_mech > 1:
            np.max(np.abs(_constraint_values(mf, t, qT.T, p, ql)[:, :n_mech]), axis=1, out=block[slots.residual])
        else:
            block[slots.residual] = 0.0
    block[slots.ext] = xT
    return block


def state_column(model, pieces: list, angle_coordinates: tuple[int, ...], name: str) -> np.ndarray | None:
    """The column `name` over the rows of one mode's pieces (stacked) where it is a state, read without the
    read-out: a coordinate's position (its piece's offset added) or speed, a work; None for any other column.
    The same values as `_mode_block` puts there (the same additions): a reader that needs only these (the drive's
    turns located, scenarios/turns.py) pays no KKT solve."""
    mf = model.modes[pieces[0].mode]
    ix = mf.index
    for i, coordinate in enumerate(model.coordinates):
        position, speed, _ = coordinate_columns(coordinate, i in angle_coordinates)
        if name == speed:
            return np.concatenate([pc.y[:, ix["v"]][:, i] for pc in pieces])
        if name == position:
            return np.concatenate([pc.y[:, ix["q"]][:, i] if pc.offset is None else
                                   pc.y[:, ix["q"]][:, i] + np.asarray(pc.offset, dtype=float)[i] for pc in pieces])
    works = [f"work_{w}_J" for w in model.work_names]
    if name in works:
        return np.concatenate([pc.y[:, ix["work"]][:, works.index(name)] for pc in pieces])
    return None


def piece_columns(model, piece, angle_coordinates: tuple[int, ...], residual: bool = True) -> dict[str, np.ndarray]:
    """The table's columns over one piece's rows (or over a list of one mode's pieces, stacked: one evaluation for
    all), read-outs evaluated with the piece's mode and parameters, as `timeseries` evaluates them (residual=False:
    without constraint_residual_m)."""
    pieces = piece if isinstance(piece, list) else [piece]
    names = _layout(model, angle_coordinates, [pieces[0].mode], residual)
    block = _mode_block(model, pieces, names, residual)
    mode = np.empty(block.shape[1], dtype=object)
    mode.fill(pieces[0].mode)                # (np.full converts the name to a numpy string for every row)
    cols = {"t_s": block[0], "mode": mode}
    cols.update(zip(names[1:], block[1:]))
    return cols


def timeseries(traj: Trajectory, angle_coordinates: tuple[int, ...]) -> pd.DataFrame:
    """One row per output instant, read-outs evaluated with the mode and parameters of that instant.

    The read-outs, the KKT solution, the kinetic energy and the constraint residual are evaluated once per mode on
    all of that mode's rows (`_mode_block`), whose pieces are joined in time order into one block, from which the
    frame is built once (columns: `_layout`; NaN where a mode lacks a read-out); a later instant replaces an
    earlier one at the same time (the state after a mode change)."""
    model = traj.model
    pieces = [pc for pc in traj.pieces if len(pc.t)] or list(traj.pieces[:1])
    by_mode: dict[str, list[int]] = {}
    for k, pc in enumerate(pieces):
        by_mode.setdefault(pc.mode, []).append(k)
    names = _layout(model, angle_coordinates, list(by_mode))
    counts = [len(pc.t) for pc in pieces]
    parts = [None] * len(pieces)          # each piece's columns: a view of its mode's block
    for ks in by_mode.values():
        block = _mode_block(model, [pieces[k] for k in ks], names)
        offset = 0
        for k in ks:
            parts[k] = block[:, offset:offset + counts[k]]
            offset += counts[k]
    # one mode: its block is the table already (its pieces in order); else the pieces' columns joined in time order
    out = block if len(by_mode) == 1 else np.concatenate(parts, axis=1)
    keep = _kept_rows(out[0])
    if keep is not None:
        out = out[:, keep]
        counts = np.bincount(np.repeat(np.arange(len(pieces)), counts)[keep], minlength=len(pieces)).tolist()
    code = {mode: i for i, mode in enumerate(by_mode)}
    return _frame(out, names, _mode_column(tuple(by_mode), [code[pc.mode] for pc in pieces], counts))


def _mode_column(modes: tuple[str, ...], codes: list[int], counts: list[int]):
    """modes[codes[k]] repeated counts[k] times, k in order, as the column pandas infers for those names (the
    names typed once each, `_typed_names`, then taken row by row)."""
    return _typed_names(modes).take(np.repeat(np.asarray(codes, dtype=np.intp), counts))


def _typed_names(names: tuple[str, ...]):
    """The names as the array pandas infers for them in a column (its string dtype), inferred once per set of names
    and pandas' string options (`_inferred`); never itself put in a frame (a frame gets `_mode_column`'s array)."""
    return _inferred(("typed", names), lambda: pd.Series(np.asarray(names, dtype=object)).array)


def _columns_index(names: list[str]) -> pd.Index:
    """pd.Index(names), inferred once per names and pandas' string options (`_inferred`); each frame gets its own
    shallow copy (an Index's name is settable: frames never share one)."""
    return _inferred(("index", tuple(names)), lambda: pd.Index(names)).copy()


#: what `_inferred` keeps: pandas' inference of a set of names, by the names and pandas' string options
_INFERRED: dict = {}
#: pandas' own switch of string inference (a pandas internal, pandas 2.1+); without it nothing inferred is kept
_USING_STRING_DTYPE = getattr(getattr(pd, "_config", None), "using_string_dtype", None)


def _inferred(key: tuple, build):
    """build(): what pandas infers for a set of names, kept per key and pandas' string options (whether it infers
    its string dtype, and the storage), so that a change of them infers anew; built every time where the options
    cannot be read."""
    try:
        options = None if _USING_STRING_DTYPE is None else (bool(_USING_STRING_DTYPE()),
                                                            pd.get_option("mode.string_storage"))
    except Exception:      # noqa: BLE001  (a changed internal: inferred every time)
        options = None
    if options is None:
        return build()
    key += (options,)
    value = _INFERRED.get(key)
    if value is None:
        if len(_INFERRED) >= 512:
            _INFERRED.clear()
        value = _INFERRED[key] = build()
    return value


#: pandas' constructor of a frame from its blocks (pandas.api.internals, pandas 3); without it, `_frame` inserts
_FROM_BLOCKS = getattr(getattr(pd.api, "internals", None), "create_dataframe_from_blocks", None)


def _frame(out: np.ndarray, names: list[str], modes) -> pd.DataFrame:
    """The frame of the float block `out` (len(names), rows) with the column "mode" in second place: the block as
    the frame's float block (no copy) and the modes as its string block, put together at once; the same frame as
    pd.DataFrame(out.T, columns=names, copy=False) with "mode" inserted, which that does where pandas lacks the
    block constructor or infers no string dtype (an insert costs more than the rest of the frame: it rebuilds the
    column index's engine)."""
    if _FROM_BLOCKS is not None and isinstance(modes.dtype, pd.StringDtype):     # a string (extension) block
        try:
            place = np.arange(1, len(names) + 1)               # 0, 2, 3, ...: "mode" is column 1
            place[0] = 0
            columns = _columns_index([names[0], "mode", *names[1:]])
            return _FROM_BLOCKS([(out, place), (modes, np.array([1]))], index=pd.RangeIndex(out.shape[1]),
                                columns=columns)
        except Exception:      # noqa: BLE001  (a changed internal: the public construction below is the reference)
            pass
    df = pd.DataFrame(out.T, columns=list(names), copy=False)
    df.insert(1, "mode", modes)
    return df


def _records_frame(records: list[dict]) -> pd.DataFrame:
    """pd.DataFrame(records). Where every record has the same keys in the same order and each column holds only
    floats or only strings (Python's own types), the frame pandas infers is known: one float block of the float
    columns and a string block per string column; it is built from those blocks at once (pandas' inference on a
    list of records, column by column, costs more than the rest of the events table). Otherwise pandas builds it."""
    keys = list(records[0])
    kinds = [type(value) for value in records[0].values()]
    if _FROM_BLOCKS is None or any(k is not float and k is not str for k in kinds) or any(
            list(r) != keys or [type(value) for value in r.values()] != kinds for r in records[1:]):
        return pd.DataFrame(records)
    floats = [j for j, k in enumerate(kinds) if k is float]
    texts = [j for j, k in enumerate(kinds) if k is str]
    n = len(records)
    rows = [list(r.values()) for r in records]
    blocks = [(np.array([[row[j] for row in rows] for j in floats], dtype=float).reshape(len(floats), n),
               np.array(floats, dtype=np.intp))] if floats else []
    if texts:      # every string column typed in one inference, then cut into its columns
        strings = tuple(row[j] for j in texts for row in rows)

        def cut():        # the columns, kept per their strings (`_inferred`): a run repeated has the same events
            typed = pd.Series(np.asarray(strings, dtype=object)).array
            return [typed[i * n:(i + 1) * n] for i in range(len(texts))], isinstance(typed.dtype, pd.StringDtype)
        columns, typed_ok = _inferred(("event strings", len(texts), strings), cut)
        if not typed_ok:
            return pd.DataFrame(records)
        # each frame its own shallow copies of the (immutable) typed arrays
        blocks += [(column.copy(), np.array([j], dtype=np.intp)) for column, j in zip(columns, texts)]
    try:
        return _FROM_BLOCKS(blocks, index=pd.RangeIndex(n), columns=_columns_index(keys))
    except Exception:      # noqa: BLE001  (a changed internal: pandas' own construction is the reference)
        return pd.DataFrame(records)


def events_table(traj: Trajectory) -> pd.DataFrame:
    cols = ["t_s", "from_mode", "to_mode", "kind", "guard", "kinetic_energy_before_J", "kinetic_energy_after_J",
            "message"]
    events = traj.events
    if not events:
        return pd.DataFrame(columns=cols)
    before, after = "kinetic_energy_before_J", "kinetic_energy_after_J"
    if all(isinstance(e.get(before), float) and isinstance(e.get(after), float) for e in events):
        # the loss added to each record: one frame built, no column inserted afterwards
        # an impact may state its own loss (with a prescribed motion the kinetic energy's change is not all lost:
        # transitions.impact_split)
        return _records_frame([{**e, "energy_lost_J": e.get("energy_lost_J", e[before] - e[after])} for e in events])
    df = pd.DataFrame(events)
    own = df["energy_lost_J"] if "energy_lost_J" in df else None
    df["energy_lost_J"] = df[before] - df[after]
    if own is not None:
        df["energy_lost_J"] = own.where(own.notna(), df["energy_lost_J"])
    return df
