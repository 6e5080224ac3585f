"""dynamics/tables.py `timeseries` evaluates every read-out once per mode on all of that mode's rows (pieces
stacked, parameters that differ between pieces as per-row arrays) and builds one frame. The reference here is the
evaluation it replaces: one frame per output piece with that piece's own parameters, the constraint function
called row by row, then concat and the later row kept at a repeated time. Both evaluate the same expressions on
the same numbers, elementwise, so the tables agree to round-off (the batched KKT solve and the einsum of the
kinetic energy may group their operations differently); the columns' names, order and dtypes are equal."""
import numpy as np
import pandas as pd
import pytest

import mechsim
from mechsim.dynamics.tables import coordinate_columns, events_table, kkt_rows, timeseries
from mechsim.scenarios import runner


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


def _reference(traj, angle_coordinates) -> pd.DataFrame:
    model = traj.model
    frames = []
    for piece in traj.pieces:
        mf = model.modes[piece.mode]
        ix = mf.index
        t, y, p = piece.t, piece.y, piece.params
        q, v, x = y[:, ix["q"]], y[:, ix["v"]], y[:, ix["ext"]]
        q_out = piece.coordinates(ix["q"])
        a, lam = kkt_rows(mf, t, q, v, x, p)
        cols = {"t_s": t, "mode": np.full(len(t), piece.mode, dtype=object)}
        for i, name in enumerate(model.coordinates):
            pos, spd, acc = coordinate_columns(name, i in angle_coordinates)
            cols[pos], cols[spd], cols[acc] = q_out[:, i], v[:, i], a[:, i]
        for name, val in zip(mf.readout_names, mf.readouts["_all"](t, q.T, v.T, a.T, lam.T, x.T, p)):
            cols[name] = np.broadcast_to(np.asarray(val, dtype=float), t.shape).copy()
        cols["kinetic_energy_J"] = _kinetic_energy(mf.mass, q, v, p)
        for j, name in enumerate(model.work_names):
            cols[f"work_{name}_J"] = y[:, ix["work"]][:, j]
        n_mech = mf.m - (1 if model.prescribed else 0)
        phi = np.asarray([np.ravel(mf.phi(ti, qi, p)) for ti, qi in zip(t, q)]).reshape(len(t), mf.m)
        cols["constraint_residual_m"] = np.max(np.abs(phi[:, :n_mech]), axis=1) if n_mech > 0 else np.zeros(len(t))
        for j, name in enumerate(model.extension_names):
            cols[name] = x[:, j]
        frames.append(pd.DataFrame(cols))
    df = pd.concat(frames, ignore_index=True)
    return df.drop_duplicates(subset="t_s", keep="last").reset_index(drop=True)


def _reference_events(traj) -> pd.DataFrame:
    df = pd.DataFrame(traj.events)
    df["energy_lost_J"] = df["kinetic_energy_before_J"] - df["kinetic_energy_after_J"]
    return df


CASES = {
    # an engaged mode whose pieces differ in a parameter (the slide direction): per-row parameter arrays
    "geneva-motor": ("geneva-motor", ["duration=0.5 s"]),
    "geneva-lc1-motor-lumped": ("geneva-lc1", ["duration=0.5 s", 'drive.type="motor"', "drive.stall_torque=40 N*m",
                                               "drive.no_load_speed=8 rad/s"]),
    "geneva-lc1-dae-prescribed": ("geneva-lc1", ["duration=0.3 s", 'solver.method="dae"', 'thermal.model="none"']),
    "chain-mech2-torque": ("chain-mech2-torque", ["duration=0.5 s"]),
    "rolling-a-torque": ("rolling-a-torque", ["duration=0.2 s"]),      # no sliding contact: no thermal model
}


@pytest.mark.parametrize("case", list(CASES))
def test_per_mode_table_equals_per_piece_table(case, monkeypatch):
    caught = {}

    def keep(traj, angle_coordinates):
        caught["args"] = (traj, angle_coordinates)
        return timeseries(traj, angle_coordinates)

    monkeypatch.setattr(runner, "timeseries", keep)
    name, overrides = CASES[case]
    mechsim.run(name, set=overrides)
    traj, angles = caught["args"]
    got, want = timeseries(*caught["args"]), _reference(traj, angles)
    assert len(got) > 10
    if case == "geneva-motor":      # a mode stacked from pieces of different parameters is covered
        by_mode: dict = {}
        for pc in traj.pieces:
            by_mode.setdefault(pc.mode, set()).add(pc.params)
        assert any(len(ps) > 1 for ps in by_mode.values())
    assert got.columns.tolist() == want.columns.tolist()
    assert got.dtypes.tolist() == want.dtypes.tolist()
    assert got["mode"].tolist() == want["mode"].tolist()
    for c in got.columns.drop("mode"):
        w = want[c].to_numpy(float)
        scale = max(float(np.nanmax(np.abs(w), initial=0.0)), 1e-300)
        np.testing.assert_allclose(got[c].to_numpy(float), w, rtol=0, atol=1e-13 * scale, err_msg=c)
    if traj.events:                 # the events table, its loss column made with the records: the same frame
        pd.testing.assert_frame_equal(events_table(traj), _reference_events(traj), check_exact=True)


@pytest.mark.parametrize("records", [
    [{"t_s": 0.1, "kind": "entry", "x": 1.0}, {"t_s": 0.2, "kind": "exit", "x": float("nan")}],
    [{"t_s": 0.1, "kind": "", "message": "2020-01-01", "x": -0.0}],
    [{"only": 1.0}, {"only": 2.0}],
    [{"only": "text"}],
    [{"t_s": 0.1, "kind": "a"}, {"kind": "b", "t_s": 0.2}],           # keys in another order
    [{"t_s": 0.1, "kind": "a"}, {"t_s": 0.2}],                          # a key missing
    [{"t_s": 0.1, "kind": None}], [{"t_s": 1, "kind": "a"}], [{"t_s": True, "kind": "a"}],
    [{"t_s": np.float64(0.1), "kind": "a"}],
])
def test_events_frame_from_its_blocks_is_pandas_frame_of_the_records(records):
    """The events table's frame built from its blocks where the records allow it (same keys, floats or strings
    only) is the frame pandas builds from the records: columns, dtypes, blocks and values."""
    from mechsim.dynamics.tables import _records_frame
    got, want = _records_frame(records), pd.DataFrame(records)
    pd.testing.assert_frame_equal(got, want, check_exact=True)
    assert got.columns.dtype == want.columns.dtype
    assert [type(b).__name__ for b in got._mgr.blocks] == [type(b).__name__ for b in want._mgr.blocks]


@pytest.mark.parametrize("storage", ["auto", "python"])
def test_frames_follow_pandas_string_options(storage):
    """The timeseries' mode names and the frames' column indexes are inferred once per set of names and kept; a
    change of pandas' string options infers them anew: under each option the tables' dtypes are what pandas infers
    then, and no two frames share a column index (its name is settable)."""
    from mechsim.dynamics.tables import _frame, _records_frame, _typed_names
    names = ["t_s", "x_m"]
    out = np.arange(6.0).reshape(2, 3)
    with pd.option_context("mode.string_storage", storage):
        frames = [_frame(out, names, _typed_names(("dwell", "engaged")).take(np.array([0, 1, 1]))) for _ in range(2)]
        want = pd.DataFrame({"t_s": out[0], "mode": ["dwell", "engaged", "engaged"], "x_m": out[1]})
        records = [{"t_s": 0.1, "kind": "entry"}, {"t_s": 0.2, "kind": "exit"}]
        events = [_records_frame(records) for _ in range(2)]
        pd.testing.assert_frame_equal(events[0], pd.DataFrame(records), check_exact=True)
    for got in frames:
        pd.testing.assert_frame_equal(got, want, check_exact=True)
        assert got.columns.dtype == want.columns.dtype
    for a, b in (frames, events):
        assert a.columns is not b.columns
        a.columns.name = "renamed"
        assert b.columns.name is None
