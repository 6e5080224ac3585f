"""Turn a raw hybrid trajectory into the result tables (SI, `<quantity>_<unit>` columns)."""
from __future__ import annotations

from collections.abc import Mapping
from typing import TYPE_CHECKING

import numpy as np
import pandas as pd

from mechsim.dynamics import kkt

if TYPE_CHECKING:      # the tables read a finished Trajectory; importing the loop would load sympy for nothing
    from mechsim.dynamics.hybrid import Trajectory


class TableColumns(Mapping):
    """A result table's columns as numpy arrays, each read from the frame once (a pandas column read costs ~20 us
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
    block directly: ~0.6 us instead of ~11 us for building the Series first (pandas 3). The block read is a
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


def _kinetic_energy(mass, q: np.ndarray, v: np.ndarray, p: tuple) -> np.ndarray:
    """1/2 v^T M(q) v row by row (M evaluated on the whole array where it broadcasts; a configuration-dependent
    M with constant entries does not form one numpy array, so it is then evaluated row by row)."""
    n = q.shape[1]
    rows = len(q)
    Mb = np.empty((rows, n, n))
    try:
        M = mass(q.T, p)
    except ValueError:
        for r in range(rows):
            Mb[r] = np.asarray(mass(q[r], p), dtype=float)
        return 0.5 * np.einsum("ri,rij,rj->r", v, Mb, v)
    for i in range(n):
        for j in range(n):
            Mb[:, i, j] = np.broadcast_to(np.asarray(M[i][j], dtype=float), (rows,))
    return 0.5 * np.einsum("ri,rij,rj->r", v, Mb, v)


def _rows(entries, n: int, shape: tuple[int, ...]) -> np.ndarray:
    """Flat lambdified entries (arrays over the rows, or scalars) as an (n, *shape) array."""
    return np.stack([np.broadcast_to(np.asarray(e, dtype=float), (n,)) for e in entries], axis=1).reshape(n, *shape)


def kkt_rows(mf, t: np.ndarray, q: np.ndarray, v: np.ndarray, x: np.ndarray, p: tuple):
    """Accelerations and multipliers from the KKT system at every output row (exact for the row's q, v).

    The index-2/3 forms keep multipliers out of IDA's error test (SolverSettings.multiplier_atol), so the
    multiplier states are not accurate enough to report forces from; the KKT solution at the integrated
    (q, v) is, in every formulation and backend.
    """
    f = mf.kkt_flat
    n, nq, m = len(t), q.shape[1], mf.m
    M = _rows(f["mass"](q.T, p), n, (nq, nq))
    Q0 = _rows(f["force0"](t, q.T, v.T, x.T, p), n, (nq,))
    if m == 0:
        return kkt.solve(M, np.zeros((n, 0, nq)), np.zeros((n, nq, 0)), Q0, np.zeros((n, 0)))
    G = _rows(f["G"](t, q.T, p), n, (m, nq))
    Ql = _rows(f["force_lam"](t, q.T, v.T, x.T, p), n, (nq, m))
    gamma = _rows(f["gamma"](t, q.T, v.T, p), n, (m,))
    return kkt.solve(M, G, Ql, Q0, -gamma)


def piece_columns(model, piece, angle_coordinates: tuple[int, ...], residual: bool = True) -> dict[str, np.ndarray]:
    """The table's columns over one piece's rows, read-outs evaluated with the piece's mode and parameters
    (residual=False: without constraint_residual_m, a Python loop over the rows)."""
    mf = model.modes[piece.mode]
    ix = mf.index
    t, y = piece.t, piece.y
    q, v, x = y[:, ix["q"]], y[:, ix["v"]], y[:, ix["ext"]]
    q_out = piece.coordinates(ix["q"])       # unwrapped: q is in the mode's re-based frame
    a, lam = kkt_rows(mf, t, q, v, x, piece.params)
    cols: dict[str, np.ndarray] = {"t_s": t, "mode": np.full(len(t), piece.mode, dtype=object)}
    for i, name in enumerate(model.coordinates):
        pos, spd, acc = coordinate_columns(name, i in angle_coordinates)
        cols[pos], cols[spd], cols[acc] = q_out[:, i], v[:, i], a[:, i]
    values = mf.readouts["_all"](t, q.T, v.T, a.T, lam.T, x.T, piece.params)
    for name, val in zip(mf.readout_names, values):
        cols[name] = np.broadcast_to(np.asarray(val, dtype=float), t.shape).copy()
    cols["kinetic_energy_J"] = _kinetic_energy(mf.mass, q, v, piece.params)
    for j, name in enumerate(model.work_names):
        cols[f"work_{name}_J"] = y[:, ix["work"]][:, j]
    if residual:
        phi = np.asarray([np.ravel(mf.phi(ti, qi, piece.params)) for ti, qi in zip(t, q)]) if mf.m else \
            np.zeros((len(t), 1))
        n_mech = mf.m - (1 if model.prescribed else 0)
        cols["constraint_residual_m"] = np.max(np.abs(phi[:, :max(n_mech, 1)]), axis=1) if n_mech else \
            np.zeros(len(t))
    for j, name in enumerate(model.extension_names):
        cols[name] = x[:, j]
    return cols


def timeseries(traj: Trajectory, angle_coordinates: tuple[int, ...]) -> pd.DataFrame:
    """One row per output instant, read-outs evaluated with the mode and parameters of that instant."""
    frames = [pd.DataFrame(piece_columns(traj.model, piece, angle_coordinates)) for piece in traj.pieces]
    df = pd.concat(frames, ignore_index=True)
    return df.drop_duplicates(subset="t_s", keep="last").reset_index(drop=True)


def events_table(traj: Trajectory) -> pd.DataFrame:
    cols = ["t_s", "from_mode", "to_mode", "kind", "guard", "kinetic_energy_before_J", "kinetic_energy_after_J",
            "message"]
    df = pd.DataFrame(traj.events)
    if df.empty:
        return pd.DataFrame(columns=cols)
    df["energy_lost_J"] = df["kinetic_energy_before_J"] - df["kinetic_energy_after_J"]
    return df
