"""Files a job writes, written atomically: each goes to a temporary name in the same directory and is renamed.

A job's ``summary.json`` is written last and names ``status``; a directory without a complete summary
holds no results the report would read, so a job killed at any moment leaves complete results or none.
"""

from __future__ import annotations

import json
import os
import secrets
from pathlib import Path
from typing import Any, Callable

import numpy as np

SUMMARY = "summary.json"
METRICS_CSV = "metrics.csv"
SEGMENTS_CSV = "segments.csv"
SERIES = "series.npz"
BANDS = "bands.npz"
CONFIG = "config.yaml"
PLOTS_DIR = "plots"

#: The headline metrics of a job (units and meanings in :data:`ddmr_cli.engine.catalog.METRICS`): its log lines,
#: the sweep's ``sweep_jobs.csv`` (``<metric>_mean``, ``<metric>_sd``) and the sweep's terminal summary.
HEADLINE = ("deviation_mae", "e_x_mae", "e_y_mae", "e_theta_mae", "chattering", "d_est_mae", "mean_voltage")


def unit_of(metric: str) -> str:
    """The unit of a run metric (docs/model.md §7), as :data:`ddmr_cli.engine.catalog.METRICS` defines it."""
    from ddmr_cli.engine.catalog import METRICS

    return METRICS[metric][0]


def atomic_write(path: Path, write: Callable[[str], None]) -> Path:
    """Call ``write(tmp_path)`` and rename the temporary file onto ``path``. The temporary file is created
    with mode 0666 less the umask (as ``open`` makes files), so outputs follow the user's umask."""
    path = Path(path)
    path.parent.mkdir(parents=True, exist_ok=True)
    tmp = str(path.parent / f".{path.name}.{os.getpid()}.{secrets.token_hex(4)}.tmp")
    open(tmp, "xb").close()
    try:
        write(tmp)
        os.replace(tmp, path)
    except BaseException as exc:
        if os.path.exists(tmp):
            os.unlink(tmp)
        if isinstance(exc, OSError) and exc.filename is None:  # e.g. a full disk inside a zip or csv writer
            raise OSError(exc.errno, exc.strerror or str(exc), str(path)) from exc
        raise
    return path


def write_text(path: Path, text: str) -> Path:
    def _write(tmp: str) -> None:
        with open(tmp, "w", encoding="utf-8") as fh:
            fh.write(text)

    return atomic_write(path, _write)


def yaml_text(container: dict) -> str:
    """A plain (resolved) config as YAML, as ``OmegaConf.to_yaml`` prints it (same text, tested), by PyYAML's C
    emitter when it is built (a tenth of the time: it is written by every job of a sweep)."""
    import yaml

    dumper = getattr(yaml, "CSafeDumper", yaml.SafeDumper)
    return yaml.dump(container, Dumper=dumper, sort_keys=False, allow_unicode=True, default_flow_style=False)


def _json_default(obj: Any):
    if isinstance(obj, np.generic):
        return obj.item()
    if isinstance(obj, np.ndarray):
        return obj.tolist()
    return str(obj)


def write_json(path: Path, data: Any) -> Path:
    return write_text(path, json.dumps(data, indent=2, default=_json_default, allow_nan=True) + "\n")


def write_csv(path: Path, frame, columns: list[str] | None = None) -> Path:
    """A pandas DataFrame, or a list or iterator of dicts with the same keys, or with ``columns`` the header and
    ``frame`` an iterable of row sequences in that order (both written with the csv module, no pandas, floats as
    ``repr``; an iterator is streamed, so its rows never all sit in memory)."""
    if columns is not None:
        return _write_rows(path, columns, frame)
    if not hasattr(frame, "to_csv"):
        import csv
        import itertools

        def _write(tmp: str) -> None:
            rows = iter(frame)
            first = next(rows, None)
            with open(tmp, "w", newline="", encoding="utf-8") as fh:
                writer = csv.DictWriter(fh, fieldnames=list(first) if first is not None else [])
                writer.writeheader()
                if first is not None:
                    writer.writerows({k: repr(v) if isinstance(v, float) else v for k, v in row.items()}
                                     for row in itertools.chain([first], rows))

        return atomic_write(path, _write)
    if not _csv_writes(frame):  # a column of a type the csv module would not write as pandas does
        return atomic_write(path, lambda tmp: frame.to_csv(tmp, index=False))
    rows = (row for first in range(0, len(frame), CSV_BLOCK_ROWS)
            for row in zip(*_csv_cells(frame.iloc[first:first + CSV_BLOCK_ROWS])))
    return _write_rows(path, frame.columns, rows, lineterminator=os.linesep)  # pandas' to_csv: os.linesep


def _write_rows(path: Path, columns, rows, lineterminator: str = "\r\n") -> Path:
    """The header ``columns`` and ``rows`` (sequences in that order, streamed) by the csv module, atomically."""
    import csv

    def _write(tmp: str) -> None:
        with open(tmp, "w", newline="", encoding="utf-8") as fh:
            writer = csv.writer(fh, lineterminator=lineterminator)
            writer.writerow(columns)
            writer.writerows(rows)

    return atomic_write(path, _write)


#: rows of a DataFrame :func:`write_csv` turns into Python values at a time (a table's rows never all sit in memory
#: twice)
CSV_BLOCK_ROWS = 4096


def _csv_kind(dtype) -> str | None:
    """How :func:`_csv_cells` hands a column of ``dtype`` to the csv module: ``"float"`` (float64: NaN empty),
    ``"plain"`` (integers and booleans as they are), ``"object"`` (text and objects: missing values empty), or None
    for a type pandas writes otherwise (float32, dates, categories, nullable integers)."""
    import pandas as pd

    if isinstance(dtype, np.dtype) and dtype == np.float64:
        return "float"
    if isinstance(dtype, np.dtype) and dtype.kind in "iub":
        return "plain"
    return "object" if dtype == object or isinstance(dtype, pd.StringDtype) else None


def _csv_writes(frame) -> bool:
    """Whether every column of a DataFrame is of a type :func:`_csv_cells` hands the csv module as pandas does."""
    return all(_csv_kind(t) is not None for t in frame.dtypes)


def _csv_cells(frame) -> list[list]:
    """The columns of a DataFrame (of the types :func:`_csv_writes` accepts) as the values that
    ``frame.to_csv(index=False)`` hands the csv module, so that the csv module writes the same text
    (tests/test_csv_frames.py: the same bytes), at about 0.6x its time (pandas turns every float into text through
    numpy first): float64 numbers as floats (written by ``repr``, the text numpy gives them) with NaN empty,
    integers and booleans as they are, text and other objects with every missing value empty. Other types
    (float32, dates, categories, nullable integers) are pandas' to write."""
    import pandas as pd

    out = []
    for _, column in frame.items():
        kind = _csv_kind(column.dtype)
        if kind == "float":
            out.append([v if v == v else "" for v in column.to_numpy().tolist()])
        elif kind == "plain":
            out.append(column.to_numpy().tolist())
        else:
            values = column.to_numpy(dtype=object)
            out.append(["" if missing else v for v, missing in zip(values.tolist(), pd.isna(values).tolist())])
    return out


def write_series(path: Path, series: dict[int, dict[str, np.ndarray]]) -> Path:
    """Time series of the kept seeds, uncompressed (deflate shrank the paper's run from 3.5 to 3.3 MB and took
    0.1 s of a 1 s run): key ``seed<k>/<channel>``."""
    arrays = {f"seed{seed}/{name}": arr for seed, channels in series.items() for name, arr in channels.items()}

    def _write(tmp: str) -> None:
        with open(tmp, "wb") as fh:
            np.savez(fh, **arrays)

    return atomic_write(path, _write)


def write_bands(path: Path, bands: dict[str, np.ndarray]) -> Path:
    """Across-seed bands (:meth:`ddmr_cli.engine.bands.BandAccumulator.arrays`), uncompressed: key ``t`` and
    ``<channel>/mean|p05|p95``."""

    def _write(tmp: str) -> None:
        with open(tmp, "wb") as fh:
            np.savez(fh, **bands)

    return atomic_write(path, _write)


def seal(summary: dict) -> str:
    """SHA-256 of a summary as JSON (sorted keys, without its ``seal``), computed on the summary as it reads back
    from its file: a summary whose seal does not match was changed after the job wrote it."""
    import hashlib

    body = {k: v for k, v in summary.items() if k != "seal"}
    canonical = json.loads(json.dumps(body, default=_json_default, allow_nan=True))
    return hashlib.sha256(json.dumps(canonical, sort_keys=True, allow_nan=True).encode()).hexdigest()


def write_summary(job_dir: Path, summary: dict) -> dict:
    """Write a job's ``summary.json`` with its :func:`seal`; returns the summary as written."""
    summary = {**{k: v for k, v in summary.items() if k != "seal"}, "seal": seal(summary)}
    write_json(Path(job_dir) / SUMMARY, summary)
    return json.loads(json.dumps(summary, default=_json_default, allow_nan=True))


def read_series(path: Path, channels=None) -> dict[int, dict[str, np.ndarray]]:
    """Inverse of :func:`write_series`; only the named ``channels`` when given (the others are not read)."""
    out: dict[int, dict[str, np.ndarray]] = {}
    with np.load(path) as data:
        for key in data.files:
            seed, name = key.split("/", 1)
            if channels is None or name in channels:
                out.setdefault(int(seed[4:]), {})[name] = data[key]
    return out


def read_json(path: Path) -> dict | None:
    """A JSON file, or None when it is missing or cannot be read."""
    try:
        return json.loads(Path(path).read_text(encoding="utf-8"))
    except (OSError, ValueError):
        return None


def read_summary(job_dir: Path) -> dict | None:
    """A job's summary, or None when it has none (not run, or killed before it finished)."""
    path = Path(job_dir) / SUMMARY
    if not path.is_file():
        return None
    return read_json(path)
