"""A DataFrame written by ddmr_cli.storage.io.write_csv: the bytes pandas' ``to_csv(index=False)`` writes, for every
column type it writes itself, and pandas' own writer for the others."""

from __future__ import annotations

import numpy as np
import pandas as pd
import pytest

from ddmr_cli.storage import io


def _frames():
    rng = np.random.default_rng(11)
    floats = rng.standard_normal(400) * 10.0 ** rng.integers(-20, 20, 400)
    floats[::7] = np.nan
    floats[:8] = [0.0, -0.0, np.inf, -np.inf, 1e16, 1e-5, 5e-324, 0.1]
    mixed = np.array(["a", None, 1.5, 7, True, float("nan"), "x,y", 'say "hi"'] * 50, dtype=object)
    yield "every type", pd.DataFrame({
        "f": floats, "i": rng.integers(-5, 5, 400), "u": rng.integers(0, 9, 400).astype(np.uint8),
        "b": rng.random(400) < 0.5, "o": mixed, "s": pd.array(["ok", None, "line\nbreak", ""] * 100, dtype="string"),
        "t": ["plain"] * 399 + [""]})
    yield "no rows", pd.DataFrame({"a": pd.Series([], dtype=float), "b": pd.Series([], dtype=object)})
    yield "one empty text", pd.DataFrame({"only": [""]})
    yield "read back", pd.read_csv(__import__("io").StringIO("job,seed,x,label\nj1,0,0.5,\nj2,1,,ok\n"))


@pytest.mark.parametrize("name,frame", list(_frames()), ids=[n for n, _ in _frames()])
def test_the_bytes_pandas_writes(tmp_path, monkeypatch, name, frame):
    monkeypatch.setattr(io, "CSV_BLOCK_ROWS", 7)  # blocks of rows that cross the frame's 400 rows unevenly
    ours = io.write_csv(tmp_path / "ours.csv", frame)
    frame.to_csv(tmp_path / "pandas.csv", index=False)
    assert io._csv_writes(frame)  # written by the csv module, not handed to pandas
    assert ours.read_bytes() == (tmp_path / "pandas.csv").read_bytes()


@pytest.mark.parametrize("column", [pd.Series([1.5, 2.5], dtype=np.float32), pd.Series([1, None], dtype="Int64"),
                                    pd.to_datetime(pd.Series(["2026-01-01", "2026-01-02"])),
                                    pd.Series(["a", "b"], dtype="category")], ids=["float32", "Int64", "date", "category"])
def test_other_column_types_are_written_by_pandas(tmp_path, column):
    frame = pd.DataFrame({"x": [0.25, 0.5], "other": column})
    assert not io._csv_writes(frame)
    ours = io.write_csv(tmp_path / "ours.csv", frame)
    frame.to_csv(tmp_path / "pandas.csv", index=False)
    assert ours.read_bytes() == (tmp_path / "pandas.csv").read_bytes()
