"""TableColumns reads a frame's columns from its blocks (dynamics/tables.py `column_values`): the same arrays as
Series.to_numpy (values, dtype, read-only), for every dtype a result table holds, and frames with repeated names."""
import numpy as np
import pandas as pd
import pytest

from mechsim.dynamics.tables import TableColumns, column_values


def _frame():
    n = 7
    return pd.DataFrame({"t_s": np.linspace(0.0, 0.3, n), "mode": ["dwell", "engaged", "dwell", "engaged",
                                                                       "engaged", "dwell", None],
                         "events": np.arange(n), "engaged": np.arange(n) % 2 == 0,
                         "force_N": [1.5, np.nan, -2.0, 0.0, -0.0, np.inf, 3.0],
                         "kind": pd.Categorical(list("abcabca"))})


@pytest.mark.parametrize("name", ["t_s", "mode", "events", "engaged", "force_N", "kind"])
def test_each_column_equals_series_to_numpy(name):
    df = _frame()
    expected = df[name].to_numpy()
    got = column_values(df, df.columns.get_loc(name))
    assert got.dtype == expected.dtype and got.shape == expected.shape
    assert [repr(x) for x in got] == [repr(x) for x in expected]
    if isinstance(got, np.ndarray) and got.dtype != object:
        assert not got.flags.writeable            # as Series.to_numpy: a view the reader cannot write through


def test_table_columns_with_repeated_names_read_through_the_frame():
    df = pd.concat([_frame()[["t_s", "force_N"]], _frame()[["force_N"]]], axis=1)
    cols = TableColumns(df)
    assert cols["force_N"].shape == (7, 2)      # as df["force_N"].to_numpy()
    np.testing.assert_array_equal(cols["t_s"], df["t_s"].to_numpy())
    with pytest.raises(KeyError):
        cols["missing"]



def test_public_read_when_pandas_lacks_the_block_read(monkeypatch):
    """A pandas without the internal block read (or one that changed it) gets the same arrays through the Series."""
    import mechsim.dynamics.tables as tables
    monkeypatch.setattr(tables, "_COLUMN_ARRAY", None)
    df = _frame()
    for name in df.columns:
        got, expected = column_values(df, df.columns.get_loc(name)), df[name].to_numpy()
        assert got.dtype == expected.dtype
        assert [repr(x) for x in got] == [repr(x) for x in expected]
