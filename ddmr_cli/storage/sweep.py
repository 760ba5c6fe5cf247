"""Sweeps: the plan of jobs, the state of a sweep dir, and the sweep-level tables written when a multirun ends.

The plan (``sweep_plan.json``: every job's dir and overrides) is computed by :mod:`ddmr_cli.config.plan` from what
Hydra carries; the Hydra callback :class:`ddmr_cli.cli.callbacks.SweepAggregator` writes it when the multirun
starts and calls :func:`aggregate` when it ends, in the launching process, whatever the launcher (joblib,
submitit, ray). Nothing is handed over in memory: the CLI reads the outcome from the sweep dir afterwards.
This module is storage only: no Hydra.

Tables written into the sweep dir: ``sweep_jobs.csv`` (one row per job: status, runs, diverged, mean and SD
of the headline metrics), ``sweep_metrics.csv`` (every job and seed) and ``sweep_segments.csv`` (every job,
seed, zone and phase). Every key whose value differs between the jobs (``controller.switching_gain=4,8,12``)
is a typed column of all three, and the rows are sorted by those values (numbers as numbers).
"""

from __future__ import annotations

import contextlib
import json
import logging
import os
import sys
from dataclasses import dataclass, field
from pathlib import Path
from typing import TYPE_CHECKING, Any, Callable, ContextManager, Iterable

from ddmr_cli.storage import io, jobdir

if TYPE_CHECKING:
    import pandas as pd

log = logging.getLogger("ddmr")

PLAN = "sweep_plan.json"
JOBS_CSV = "sweep_jobs.csv"
SWEEP_METRICS_CSV = "sweep_metrics.csv"
SWEEP_SEGMENTS_CSV = "sweep_segments.csv"
#: Columns every per-seed table has; a swept key of the same name (``controller``, ``scenario``) is not repeated.
_BASE_COLUMNS = ("job", "controller", "scenario")


def is_hydra_override(override: str) -> bool:
    """True for an override of Hydra's own settings (``hydra.*``, ``hydra/...``), which is not part of a job."""
    key = override.lstrip("+~").partition("=")[0]
    return key == "hydra" or key.startswith(("hydra.", "hydra/"))


TABLES = (JOBS_CSV, SWEEP_METRICS_CSV, SWEEP_SEGMENTS_CSV)


def read_plan(sweep_dir: Path) -> list[dict] | None:
    path = Path(sweep_dir) / PLAN
    if not path.is_file():
        return None
    try:
        return json.loads(path.read_text(encoding="utf-8"))["jobs"]
    except (OSError, ValueError, KeyError, TypeError):
        return None


def _recorded_tables(sweep_dir: Path) -> dict[str, dict]:
    """The sweep tables the plan file records as written by this sweep dir's sweeps, with their digests."""
    record = io.read_json(Path(sweep_dir) / PLAN)
    tables = record.get("tables") if isinstance(record, dict) else None
    return {k: v for k, v in tables.items() if k in TABLES} if isinstance(tables, dict) else {}


def check_dir(sweep_dir: Path) -> None:
    """Refuse a sweep dir whose ``sweep_plan.json`` or sweep tables ddmr did not write (a table the plan file
    does not record): the sweep would overwrite them. Raises ``FaultError`` (exit 1)."""
    from ddmr_cli.storage.jobdir import FaultError

    sweep_dir = Path(sweep_dir)
    plan = sweep_dir / PLAN
    if os.path.lexists(plan) and (plan.is_symlink() or read_plan(sweep_dir) is None):
        raise FaultError(plan, "in the way: not a sweep plan ddmr wrote; nothing was changed; move it away or "
                               "choose another output dir")
    recorded = _recorded_tables(sweep_dir)
    for name in TABLES:
        path = sweep_dir / name
        if os.path.lexists(path) and (name not in recorded or path.is_symlink()):
            raise FaultError(path, "in the way: ddmr did not write it (sweep_plan.json does not list it); nothing "
                                   "was changed; move it away or choose another output dir")


def write_plan(sweep_dir: Path, plan: list[dict]) -> None:
    """Write the plan, keeping the record of the tables an earlier sweep into this dir wrote."""
    tables = _recorded_tables(sweep_dir)
    io.write_json(Path(sweep_dir) / PLAN, {"jobs": plan, **({"tables": tables} if tables else {})})


def _install_tables(sweep_dir: Path, staged: Path) -> None:
    """Replace the tables of an earlier sweep into this dir by the staged ones: the old ones go (only those the
    plan file records), the new ones' digests are recorded in the plan file, then they are moved in,
    ``sweep_jobs.csv`` last (the CLI takes a sweep without it as failed)."""
    from ddmr_cli.storage.jobdir import digest

    plan = read_plan(sweep_dir)
    _remove_tables(sweep_dir)  # no table of an earlier sweep stays beside this one's
    names = [n for n in (SWEEP_METRICS_CSV, SWEEP_SEGMENTS_CSV, JOBS_CSV) if (staged / n).is_file()]
    if plan is not None:
        io.write_json(Path(sweep_dir) / PLAN, {"jobs": plan, "tables": {n: digest(staged / n) for n in names}})
    for name in names:
        os.replace(staged / name, Path(sweep_dir) / name)


def _remove_tables(sweep_dir: Path) -> None:
    """Remove the sweep tables this dir's plan records (a table changed since is kept as ``<name>.changed``)."""
    from ddmr_cli.storage.jobdir import _set_aside, digest

    for name, want in _recorded_tables(sweep_dir).items():
        path = Path(sweep_dir) / name
        if not path.is_file() or path.is_symlink():
            continue
        if digest(path) == {"size": want.get("size"), "sha256": want.get("sha256")}:
            path.unlink()
        else:
            log.warning("kept %s as %s: it differs from what the sweep wrote", path, _set_aside(path).name)


@dataclass
class SweepState:
    """What a sweep dir holds: complete, failed and missing jobs (``unplanned``: job dirs of an earlier sweep
    into the same dir that this sweep's plan does not list, the foreign jobs, left alone). A job whose files
    differ from the digests its summary records counts as failed (status ``corrupt``)."""

    sweep_dir: Path
    complete: list[tuple[Path, dict]] = field(default_factory=list)
    failed: list[tuple[Path, dict]] = field(default_factory=list)
    missing: list[dict] = field(default_factory=list)
    unplanned: list[str] = field(default_factory=list)

    @property
    def ok(self) -> bool:
        return not self.failed and not self.missing


def read_state(sweep_dir: Path, plan: list[dict] | None = None, every_dir: bool = False) -> SweepState:
    """The state of a sweep dir (or a single run dir) on disk.

    With a plan (``plan``, else the dir's ``sweep_plan.json``) the state covers exactly the planned jobs: a
    planned job with a summary is complete or failed, one without is missing; other job dirs are listed in
    ``unplanned``. ``every_dir=True`` (or no plan) takes every job dir with a summary, plus the planned ones
    without."""
    sweep_dir = Path(sweep_dir)
    state = SweepState(sweep_dir)
    if io.read_summary(sweep_dir) is not None:  # a single run dir
        candidates = [sweep_dir]
    elif sweep_dir.is_dir():
        candidates = sorted(d for d in sweep_dir.iterdir() if d.is_dir() and not d.name.startswith("."))
    else:
        candidates = []
    plan = read_plan(sweep_dir) if plan is None else plan
    planned = {job["dir"]: job for job in plan or []}
    if plan is not None and not every_dir and candidates != [sweep_dir]:
        state.unplanned = [d.name for d in candidates if d.name not in planned and io.read_summary(d) is not None]
        candidates = [sweep_dir / job["dir"] for job in plan]
    else:
        state.missing = [job for name, job in planned.items() if not (sweep_dir / name).is_dir()]
    for job_dir in candidates:
        summary = io.read_summary(job_dir)
        if summary is None:
            if job_dir.name in planned or (job_dir / ".hydra").is_dir():
                state.missing.append(planned.get(job_dir.name, {"dir": job_dir.name, "overrides": []}))
            continue
        if summary.get("status") == "complete":
            problem = _changed(job_dir, summary)
            if problem is None:
                state.complete.append((job_dir, summary))
                continue
            summary = {**summary, "status": "corrupt", "error": f"files changed since the job finished: {problem}"}
        state.failed.append((job_dir, summary))
    return state


def _changed(job_dir: Path, summary: dict) -> str | None:
    """Why a complete job's files are not the ones its summary records (None: they are, or the summary
    predates digests). Dropped series and plots are allowed (:func:`ddmr_cli.storage.jobdir.verify`)."""
    from ddmr_cli.storage.jobdir import verify

    return verify(job_dir, summary, strict=False) if "digests" in summary else None


def load_sweep(sweep_dir: Path) -> SweepState:
    """The jobs of a sweep dir as :mod:`ddmr_cli.report.data` reads them: the planned jobs of its
    ``sweep_plan.json`` (foreign job dirs of an earlier sweep into the same dir left out), or every job dir
    when it has no plan. The public ``ddmr_cli.load_sweep`` is :func:`load_table`."""
    return read_state(sweep_dir)


# --- swept keys ---------------------------------------------------------------------------------------------


def _typed_lines(lines: Iterable[str]) -> dict[str, tuple[str, Any]]:
    """Each distinct override line (``hydra.*`` left out) -> its key and its value, typed as Hydra parses them (int,
    float, bool, str, list, ...): ``"controller.switching_gain=4"`` -> ``("controller.switching_gain", 4)``. One
    parse of each distinct line (Hydra's parser takes about 0.1 ms a line; a sweep's jobs share most of theirs)."""
    from hydra.core.override_parser.overrides_parser import OverridesParser

    distinct = [line for line in dict.fromkeys(lines) if not is_hydra_override(line)]
    parsed = OverridesParser.create().parse_overrides(distinct) if distinct else []
    return {line: (o.get_key_element().lstrip("+~"), o.value()) for line, o in zip(distinct, parsed)}


def swept_values(jobs: dict[str, list[str]]) -> tuple[list[str], dict[str, dict[str, Any]]]:
    """The keys whose value differs between jobs (in override order) and each job's typed values of them.

    ``jobs`` maps a job's dir name to its overrides."""
    lines = _typed_lines(line for overrides in jobs.values() for line in overrides)
    typed = {name: dict(lines[line] for line in overrides if line in lines) for name, overrides in jobs.items()}
    keys: list[str] = []
    for values in typed.values():
        keys.extend(k for k in values if k not in keys)
    varying = [k for k in keys if len({repr(v.get(k, "<unset>")) for v in typed.values()}) > 1]
    return varying, {name: {k: values.get(k) for k in varying} for name, values in typed.items()}


def _cell(value: Any) -> Any:
    """A table cell: numbers, strings, booleans and None as they are, anything else (a list) as text."""
    if value is None or isinstance(value, (bool, int, float, str)):
        return value
    from omegaconf import OmegaConf

    return OmegaConf.to_yaml(value).strip() if isinstance(value, dict) else json.dumps(value)


def _sort_key(column: "pd.Series") -> "pd.Series":
    """Numbers sort as numbers (4, 8, 12), anything else as text; empty cells last."""
    import pandas as pd

    if pd.api.types.is_numeric_dtype(column.dtype) and not pd.api.types.is_bool_dtype(column.dtype):
        return column
    numeric = pd.to_numeric(column, errors="coerce")
    if numeric.notna().sum() == column.notna().sum() and not column.map(lambda v: isinstance(v, bool)).any():
        return numeric
    return column.map(lambda v: None if v is None or v != v else str(v))


def _sorted(frame: "pd.DataFrame", keys: list[str], then: Iterable[str] = ()) -> "pd.DataFrame":
    by = [c for c in [*keys, *then] if c in frame.columns]
    if not by or frame.empty:
        return frame.reset_index(drop=True)
    return frame.sort_values(by=by, key=_sort_key, kind="mergesort", na_position="last").reset_index(drop=True)


def _job_overrides(state: SweepState) -> dict[str, list[str]]:
    jobs = {d.name: list(s.get("overrides") or []) for d, s in state.complete + state.failed}
    jobs.update({job["dir"]: list(job.get("overrides") or []) for job in state.missing})
    return jobs


def _per_seed(state: SweepState, keys: list[str], values: dict[str, dict], segments: bool) -> "pd.DataFrame":
    """Every complete job's per-seed rows (``metrics.csv``, or ``segments.csv``), its dir's name and the swept
    values it lacks as columns, sorted by the swept values and then the seed.

    Jobs whose files share one header are parsed as one text (:func:`_read_together`): one ``read_csv`` for the
    sweep instead of one a job (200 one-seed jobs: 0.65 -> 0.06 s, their segments 0.78 -> 0.09 s, measured). Anything
    else is read job by job (:func:`_read_each`); tests/test_sweep_columns.py holds the two to the same table."""
    import pandas as pd

    name = io.SEGMENTS_CSV if segments else io.METRICS_CSV
    if not state.complete:
        return pd.DataFrame(columns=["job", "controller", "scenario", *[k for k in keys if k not in _BASE_COLUMNS]])
    table = _read_together(state, keys, values, name)
    if table is None:
        table = _read_each(state, keys, values, name)
    return _sorted(table, keys, then=("seed",))


def _read_each(state: SweepState, keys: list[str], values: dict[str, dict], name: str) -> "pd.DataFrame":
    """The jobs' rows read job by job, each job's columns added to its own rows, then concatenated."""
    import pandas as pd

    frames = []
    for job_dir, _ in state.complete:
        frame = pd.read_csv(job_dir / name)
        frame.insert(0, "job", job_dir.name)
        after = frame.columns.get_loc("scenario") + 1 if "scenario" in frame.columns else 1
        for i, key in enumerate(k for k in keys if k not in frame.columns):
            frame.insert(after + i, key, [_cell(values[job_dir.name][key])] * len(frame))
        frames.append(frame)
    return pd.concat(frames, ignore_index=True)


#: the most text :func:`_read_together` parses at once: a sweep's rows are parsed in groups of jobs, so that its
#: text and its table are not both held whole (table4's segments, 2.2 MB of text: three parses)
READ_TOGETHER_BYTES = 2**20


def _read_together(state: SweepState, keys: list[str], values: dict[str, dict], name: str) -> "pd.DataFrame | None":
    """The table :func:`_read_each` makes, from one parse of many jobs' rows under their common header (groups of
    about :data:`READ_TOGETHER_BYTES`); None when the headers differ, a row spans lines (a job's row count is its
    line count) or a cell is empty (a job's missing values are then typed within that job alone; ddmr's own rows
    write a missing number as ``nan``). The added columns are concatenated from one constant column a job, as each
    job's own frame holds them, so that their types come out as in :func:`_read_each` (a number in one job and none
    in another stays as it was there)."""
    import io as text_io

    import pandas as pd

    jobs, counts, frames, group, size, header = [], [], [], [], 0, None

    def parse() -> bool:
        table = pd.read_csv(text_io.StringIO(header + "\n" + "".join(group)))
        frames.append(table)
        return len(table) == sum(counts[len(counts) - len(group):])

    for job_dir, _ in state.complete:
        text = (job_dir / name).read_text(encoding="utf-8")
        first, newline, body = text.partition("\n")
        header = first if header is None else header
        if first != header or not newline or (body and not body.endswith("\n")) or _has_empty_cell(body):
            return None
        jobs.append(job_dir.name)
        counts.append(body.count("\n"))
        group.append(body)
        size += len(body)
        if size >= READ_TOGETHER_BYTES:
            if not parse():
                return None
            group, size = [], 0
    if group and not parse():
        return None
    table = pd.concat(frames, ignore_index=True)

    def per_job(cell) -> "pd.Series":
        return pd.concat([pd.Series([cell(job)] * n) for job, n in zip(jobs, counts)], ignore_index=True)

    table.insert(0, "job", per_job(lambda job: job))
    after = table.columns.get_loc("scenario") + 1 if "scenario" in table.columns else 1
    for i, key in enumerate(k for k in keys if k not in table.columns):
        table.insert(after + i, key, per_job(lambda job, key=key: _cell(values[job][key])))
    return table


def _has_empty_cell(body: str) -> bool:
    """Whether CSV rows (each ending in a line break) hold an empty cell."""
    return body.startswith(",") or any(pair in body for pair in (",,", ",\n", ",\r", "\n,"))


def load_table(path, segments: bool = False) -> "pd.DataFrame":
    """The tidy per-seed table of a sweep dir (or a run dir): one row per job and seed (``segments=True``: per
    job, seed and terrain zone / scenario phase), every swept key a typed column, rows sorted by the swept
    values (numbers as numbers), then by seed. Complete jobs only. This is ``ddmr_cli.load_sweep``."""
    path = Path(path).expanduser()
    if not path.is_dir():
        raise FileNotFoundError(f"{path}: no such directory (expected a sweep dir from `ddmr run -m` or a run dir)")
    state = read_state(path)
    keys, values = swept_values(_job_overrides(state))
    return _per_seed(state, keys, values, segments)


# --- aggregation --------------------------------------------------------------------------------------------


def jobs_table(state: SweepState, keys: list[str], values: dict[str, dict]) -> "pd.DataFrame":
    """One row per job: its swept values, status, runs, diverged, mean and SD of the headline metrics."""
    import pandas as pd

    rows = []
    for job_dir, summary in state.complete + state.failed:
        stats = summary.get("statistics", {})
        row = {"job": job_dir.name, "controller": summary.get("controller"), "scenario": summary.get("scenario")}
        row.update({k: _cell(values[job_dir.name][k]) for k in keys if k not in _BASE_COLUMNS})
        row.update({"status": summary.get("status"), "runs": stats.get("runs"), "diverged": stats.get("diverged")})
        for m in io.HEADLINE:
            row[f"{m}_mean"], row[f"{m}_sd"] = stats.get(f"{m}_mean"), stats.get(f"{m}_sd")
        row.update({"wall_time": summary.get("wall_time"), "error": summary.get("error", "")})
        rows.append(row)
    for job in state.missing:
        # a missing job has no summary: its swept group choices (controller=smc) stand for its names
        rows.append({"job": job["dir"], **{k: _cell(values[job["dir"]][k]) for k in keys}, "status": "missing"})
    frame = pd.DataFrame(rows)
    if not frame.empty and "runs" in frame:
        for column in ("runs", "diverged"):
            frame[column] = frame[column].astype("Int64")
    return _sorted(frame, keys, then=("job",))


def _fmt(value: Any) -> str:
    if value is None or (isinstance(value, float) and value != value):
        return "-"
    if isinstance(value, float):
        return f"{value:.4g}"
    return str(value)


def summary_lines(jobs: "pd.DataFrame", keys: list[str], units: dict[str, str]) -> list[str]:
    """The terminal summary: one row per job, swept keys and headline metrics, units in the header; a job that did
    not complete shows its status and error in the last column. Aligned by pandas ``DataFrame.to_markdown`` in
    tabulate's ``plain`` format (text left, numbers right, the cells as formatted here)."""
    import pandas as pd

    label_keys = ["controller", "scenario", *[k for k in keys if k not in _BASE_COLUMNS]]
    header = [*(f"{k} [{units[k]}]" if units.get(k) else k for k in label_keys), "runs", "diverged"]
    metric_header = [f"{m} [{io.unit_of(m)}]" for m in io.HEADLINE]
    header += [f"{metric_header[0]} (mean +- sd)", *metric_header[1:], ""]
    rows = []
    for _, job in jobs.iterrows():
        cells = [_fmt(job.get(k)) for k in label_keys]
        if job["status"] != "complete":
            error = job.get("error") if isinstance(job.get("error"), str) else ""
            rows.append(cells + [""] * (len(header) - len(cells) - 1) + [f"{job['status']} {error}".strip()])
            continue
        first = io.HEADLINE[0]
        rows.append(cells + [_fmt(int(job["runs"])), _fmt(int(job["diverged"])),
                             f"{_fmt(job[f'{first}_mean'])} +- {_fmt(job[f'{first}_sd'])}",
                             *(_fmt(job[f"{m}_mean"]) for m in io.HEADLINE[1:]), ""])
    numeric = [k in jobs and pd.api.types.is_numeric_dtype(jobs[k].dtype) for k in label_keys]
    right = numeric + [True] * (len(header) - len(label_keys) - 1) + [False]
    text = pd.DataFrame(rows, columns=range(len(header))).to_markdown(
        index=False, headers=header, tablefmt="plain", disable_numparse=True,
        colalign=["right" if r else "left" for r in right])
    return ["  " + line.rstrip() for line in text.splitlines()]


def aggregate(sweep_dir: Path, unit_of: Callable[[str], str | None] | None = None,
              while_writing: Callable[[], ContextManager] = contextlib.nullcontext) -> SweepState:
    """Write the sweep-level tables and print the summary of the planned jobs; returns the sweep's state.
    ``unit_of`` gives the unit of a swept key (None when unknown); ``while_writing()`` is entered while the jobs are
    read and the tables written, and left before anything is printed (the sweep's callback: a status line, 1-3 s
    for the per-seed tables of 72 jobs of 50 seeds)."""
    with while_writing():
        state = read_state(sweep_dir)
        keys, values = swept_values(_job_overrides(state))
        jobs = jobs_table(state, keys, values)
        try:
            check_dir(state.sweep_dir)  # a table ddmr did not write is never replaced
            with jobdir.Stage(state.sweep_dir / jobdir.TABLES_STAGE, create=False) as stage:
                if state.complete:
                    io.write_csv(stage.path / SWEEP_METRICS_CSV, _per_seed(state, keys, values, segments=False))
                    io.write_csv(stage.path / SWEEP_SEGMENTS_CSV, _per_seed(state, keys, values, segments=True))
                io.write_csv(stage.path / JOBS_CSV, jobs)
                _install_tables(state.sweep_dir, stage.path)
            fault = None
        except OSError as exc:
            fault = jobdir.fault(exc)
    if fault is not None:
        staged = str(jobdir.Stage(state.sweep_dir / jobdir.TABLES_STAGE).path)
        print(f"ddmr: error: {fault.path.replace(staged, str(state.sweep_dir))}: {fault.reason}", file=sys.stderr)
        return state
    units = {key: unit for key in keys if unit_of is not None and (unit := unit_of(key)) is not None}
    print(f"\nddmr sweep: {len(state.complete)} complete, {len(state.failed)} failed, {len(state.missing)} missing "
          f"-> {state.sweep_dir}")
    if not jobs.empty:
        print("\n".join(summary_lines(jobs, keys, units)))
    if state.unplanned:
        names = ", ".join(state.unplanned[:3]) + (" ..." if len(state.unplanned) > 3 else "")
        print(f"  foreign: {len(state.unplanned)} job dirs of an earlier sweep into this dir ({names}) are not in "
              f"this sweep's plan; left alone, not in its tables")
    print(f"  tables: {JOBS_CSV}, {SWEEP_METRICS_CSV}, {SWEEP_SEGMENTS_CSV}; report: ddmr report {state.sweep_dir}")
    return state
