"""What a report reads: the jobs of a sweep (or one run dir), their configs, per-seed metrics and segments.

Every table of the report is built from the jobs' own ``metrics.csv`` / ``segments.csv`` (not the sweep-level
CSVs, which a partial or resumed sweep may not have), so a report always matches the job dirs it lists.
"""

from __future__ import annotations

import json
import shlex
from dataclasses import dataclass, field
from functools import cached_property
from pathlib import Path
from typing import TYPE_CHECKING, Any

from ddmr_cli.storage import io
from ddmr_cli.errors import DDMRError
from ddmr_cli.paper import PAPER_SCENARIO
from ddmr_cli import display

if TYPE_CHECKING:
    import numpy as np
    import pandas as pd

#: The paper's reference. A job on another one (``trajectory=circle``) is reported under the scenario
#: ``<scenario>@<trajectory>`` (``paper_1@circle``): the reference is part of the scenario axis.
PAPER_TRAJECTORY = "line"
#: The paper's plant, the wheel-space model (8). A job on another plant (``plant=mujoco``, docs/model.md §13) is
#: reported under ``<scenario>@<plant>`` (``paper_1@mujoco``): the plant is part of the scenario axis, so each
#: plant gets its Table 4 and verdicts, side by side (:meth:`ReportData.plant_pairs`).
PAPER_PLANT = "wheel"
#: Override keys that do not tell two jobs apart (launcher, output dirs, plotting).
_IGNORED_KEYS = ("experiment", "launcher", "cluster", "run.plots", "run.progress")


def _override_key(override: str) -> str:
    return override.partition("=")[0].lstrip("+~")


def _ignored(override: str) -> bool:
    key = _override_key(override)
    return key.startswith(("hydra.", "cluster.")) or key in _IGNORED_KEYS


def flatten(cfg: Any, prefix: str = "") -> dict[str, Any]:
    """``{"a": {"b": 1}}`` -> ``{"a.b": 1}`` (lists kept as values)."""
    out: dict[str, Any] = {}
    if isinstance(cfg, dict):
        for k, v in cfg.items():
            out.update(flatten(v, f"{prefix}{k}."))
    else:
        out[prefix[:-1]] = cfg
    return out


@dataclass
class Job:
    """One complete job: a controller on a scenario over a batch of seeds."""

    dir: Path
    summary: dict
    config: dict
    key: str = ""        # controller, or controller[overrides] when several jobs share controller and scenario
    extra: list[str] = field(default_factory=list)
    variant: int = 0     # index among the jobs of the same controller (line style in figures)

    @property
    def controller(self) -> str:
        return str(self.summary.get("controller"))

    @cached_property
    def trajectory(self) -> str:
        """The trajectory option the job's overrides chose (the default, line, when none did)."""
        chosen = [o.partition("=")[2] for o in self.overrides if _override_key(o) == "trajectory"]
        return chosen[-1] if chosen else PAPER_TRAJECTORY

    @cached_property
    def plant(self) -> str:
        """The plant the job ran on: its saved config's ``plant.name`` (the wheel plant when it has none)."""
        return str(self.setting("plant.name", PAPER_PLANT))

    @cached_property
    def scenario_on_paper_plant(self) -> str:
        """The scenario's name, ``@<trajectory>`` appended on a reference other than the paper's line."""
        name = str(self.summary.get("scenario"))
        return name if self.trajectory == PAPER_TRAJECTORY else f"{name}@{self.trajectory}"

    @cached_property
    def scenario(self) -> str:
        """:attr:`scenario_on_paper_plant`, ``@<plant>`` appended on a plant other than the wheel plant."""
        name = self.scenario_on_paper_plant
        return name if self.plant == PAPER_PLANT else f"{name}@{self.plant}"

    @property
    def label(self) -> str:
        base = self.display.label
        return f"{base} ({', '.join(self.extra)})" if self.extra else base

    @cached_property
    def display(self) -> display.Display:
        """The controller's label, style and rank, from the job's saved config (:mod:`ddmr_cli.display`)."""
        return display.of_job(self.controller, self.config)

    @property
    def overrides(self) -> list[str]:
        return [str(o) for o in self.summary.get("overrides", [])]

    @property
    def series_seeds(self) -> list[int]:
        return [int(s) for s in self.summary.get("series_seeds", [])]

    @cached_property
    def flat_config(self) -> dict[str, Any]:
        """The config flattened to dotted keys (:func:`flatten`), once: a large report asks for settings often."""
        return flatten(self.config)

    def setting(self, dotted: str, default=None):
        return self.flat_config.get(dotted, default)


def controller_rank(controller: str) -> tuple[float, str]:
    """Sort key of a controller known by name: its packaged ``display.rank`` (after the ranked ones when it has
    none), then its name."""
    return display.rank(controller)


@dataclass
class ReportData:
    """Everything the report is built from."""

    path: Path
    single_run: bool
    jobs: list[Job]
    failed: list[tuple[Path, dict]]
    missing: list[dict]
    metrics: "pd.DataFrame"
    segments: "pd.DataFrame"
    multirun: dict | None = None
    plan: list[dict] | None = None
    #: the lock record of the ddmr process still writing the dir when the report was made (a sweep in progress:
    #: its missing jobs may still come), else None (:func:`ddmr_cli.storage.jobdir.running_holder`)
    running: dict | None = None
    _series: dict = field(default_factory=dict, repr=False)
    _bands: dict = field(default_factory=dict, repr=False)
    _ok: dict = field(default_factory=dict, repr=False)

    def ok_metrics(self, job: Job) -> "pd.DataFrame":
        """The job's per-seed metrics of the seeds that did not diverge, indexed by seed (made once: the verdicts
        read each job's for every claim and metric)."""
        if job.dir not in self._ok:
            m = self.metrics
            self._ok[job.dir] = m[(m["job"] == job.dir.name) & (m["status"] == "ok")].set_index("seed")
        return self._ok[job.dir]

    def series(self, job: Job, seed: int) -> dict:
        """One kept seed's time series of a job (read once)."""
        if job.dir not in self._series:
            self._series[job.dir] = io.read_series(job.dir / io.SERIES)
        return self._series[job.dir][seed]

    def all_series(self, job: Job) -> dict[int, dict]:
        """Every kept seed's time series of a job (empty when it kept none)."""
        if not (job.dir / io.SERIES).is_file():
            return {}
        if job.dir not in self._series:
            self._series[job.dir] = io.read_series(job.dir / io.SERIES)
        return self._series[job.dir]

    def bands(self, job: Job) -> Bands | None:
        """The job's across-seed bands (``bands.npz``) when it wrote them, else None."""
        if job.dir not in self._bands:
            self._bands[job.dir] = read_bands(job.dir / BANDS)
        return self._bands[job.dir]

    @property
    def scenarios(self) -> list[str]:
        names = sorted({j.scenario for j in self.jobs})
        return ([PAPER_SCENARIO] if PAPER_SCENARIO in names else []) + [n for n in names if n != PAPER_SCENARIO]

    def plant_pairs(self) -> list[tuple[str, str, str]]:
        """``(scenario on the wheel plant, the same scenario on another plant, that plant)`` for every scenario the
        jobs ran on both, in :attr:`scenarios` order."""
        on_paper = {j.scenario for j in self.jobs if j.plant == PAPER_PLANT}
        pairs = {(j.scenario_on_paper_plant, j.scenario, j.plant) for j in self.jobs
                 if j.plant != PAPER_PLANT and j.scenario_on_paper_plant in on_paper}
        order = self.scenarios
        return sorted(pairs, key=lambda p: (order.index(p[0]), p[2]))

    def keys(self, scenario: str | None = None) -> list[str]:
        """Controller keys in the paper's order."""
        seen: dict[str, Job] = {}
        for j in self.jobs:
            if scenario is None or j.scenario == scenario:
                seen.setdefault(j.key, j)
        return sorted(seen, key=lambda k: (seen[k].display.order, seen[k].variant, k))

    def job(self, scenario: str, key: str) -> Job | None:
        return next((j for j in self.jobs if j.scenario == scenario and j.key == key), None)

    def label(self, key: str) -> str:
        return next(j.label for j in self.jobs if j.key == key)

    def displays(self) -> dict[str, display.Display]:
        """Per controller, its display (label, style, rank) from its first job's config."""
        out: dict[str, display.Display] = {}
        for j in self.jobs:
            out.setdefault(j.controller, j.display)
        return out

    def controller_of(self, key: str) -> str:
        return next(j.controller for j in self.jobs if j.key == key)

    # --- how to regenerate ---------------------------------------------------------------------------------
    def run_command(self) -> str:
        """The ``ddmr run`` line that (re)creates this sweep or run in the same dir."""
        where = shlex.quote(str(self.path))
        if self.single_run:
            ovs = [o for o in self.jobs[0].overrides if not o.startswith("hydra.run.dir=")]
            return " ".join(["ddmr run", *map(shlex.quote, ovs), f"hydra.run.dir={where}"])
        overrides: list[str] | None = None
        if self.multirun is not None:
            ovs = (self.multirun.get("hydra") or {}).get("overrides") or {}
            extra_hydra = [o for o in ovs.get("hydra") or [] if not o.startswith(("hydra.mode=", "hydra.sweep.dir="))]
            overrides = list(ovs.get("task") or []) + extra_hydra
        if overrides is None:  # no multirun.yaml: rebuild the sweep from the planned (or finished) jobs
            job_lists = [job["overrides"] for job in self.plan] if self.plan else [j.overrides for j in self.jobs]
            values: dict[str, list[str]] = {}
            for job in job_lists:
                for o in job:
                    if o.startswith("hydra.sweep.dir="):
                        continue
                    key, _, value = o.partition("=")
                    if value not in values.setdefault(key, []):
                        values[key].append(value)
            overrides = [f"{k}={','.join(v)}" for k, v in values.items()]
        return " ".join(["ddmr run -m", *map(shlex.quote, overrides), f"hydra.sweep.dir={where}"])


#: Optional per-job file: the 5-95 % band and the mean over all seeds of each channel at each time step.
BANDS = "bands.npz"


@dataclass
class Bands:
    """``t`` and, per channel, the mean and the 5th and 95th percentiles over the seeds at each step."""

    t: "np.ndarray"
    mean: dict
    p05: dict
    p95: dict

    def __contains__(self, channel: str) -> bool:
        return channel in self.mean and channel in self.p05 and channel in self.p95

    def on(self, t: "np.ndarray") -> "Bands | None":
        """The bands on the time axis ``t`` of a kept series (linear interpolation from the band's grid of every
        few steps, docs/model.md §7), or None when the grid does not span ``t``."""
        import numpy as np

        if len(self.t) == len(t) and np.allclose(self.t, t):
            return self
        step = float(self.t[1] - self.t[0]) if len(self.t) > 1 else 0.0
        if len(self.t) < 2 or self.t[0] > t[0] + 1e-9 or self.t[-1] < t[-1] - step - 1e-9:
            return None
        out = Bands(np.asarray(t), {}, {}, {})
        for stat in ("mean", "p05", "p95"):
            for channel, arr in getattr(self, stat).items():
                getattr(out, stat)[channel] = np.interp(t, self.t, arr)
        return out


def read_bands(path: Path) -> Bands | None:
    """``bands.npz`` (keys ``t`` and ``<channel>/mean``, ``<channel>/p05``, ``<channel>/p95``), or None when the job
    has none or it is unreadable."""
    import numpy as np

    if not Path(path).is_file():
        return None
    try:
        with np.load(path) as z:
            arrays = {k: z[k] for k in z.files}
    except (OSError, ValueError):
        return None
    if "t" not in arrays:
        return None
    out = Bands(arrays["t"], {}, {}, {})
    for key, arr in arrays.items():
        channel, _, stat = key.rpartition("/")
        if channel and stat in ("mean", "p05", "p95") and arr.shape == arrays["t"].shape:
            getattr(out, stat)[channel] = arr
    return out


def _read_yaml(path: Path) -> dict:
    import yaml

    try:
        data = yaml.load(path.read_text(encoding="utf-8"), Loader=getattr(yaml, "CSafeLoader", yaml.SafeLoader))
    except (OSError, yaml.YAMLError):
        return {}
    return data if isinstance(data, dict) else {}


def _assign_keys(jobs: list[Job]) -> None:
    """A job's key is its controller, plus the overrides that set it apart when a controller has several jobs
    on one scenario (e.g. a gain sweep)."""
    per_job = {id(j): [o for o in j.overrides if not _ignored(o)
                       and _override_key(o) not in ("controller", "scenario", "trajectory", "plant")] for j in jobs}
    common = set.intersection(*(set(v) for v in per_job.values())) if per_job else set()
    groups: dict[tuple[str, str], list[Job]] = {}
    for j in jobs:
        groups.setdefault((j.controller, j.scenario), []).append(j)
    clash = {c for (c, _), js in groups.items() if len(js) > 1}
    for j in jobs:
        j.extra = [o for o in per_job[id(j)] if o not in common] if j.controller in clash else []
        j.key = j.controller + (f"[{','.join(j.extra)}]" if j.extra else "")
    for controller in {j.controller for j in jobs}:
        keys = sorted({j.key for j in jobs if j.controller == controller})
        for j in jobs:
            if j.controller == controller:
                j.variant = keys.index(j.key)


def load(path) -> ReportData:
    """Read a sweep dir or a single run dir; raises DDMRError when there is nothing to report."""
    import pandas as pd

    from ddmr_cli.storage.jobdir import running_holder
    from ddmr_cli.storage.sweep import PLAN, load_sweep

    path = Path(path).expanduser().resolve()
    if not path.is_dir():
        raise DDMRError(f"{path}: no such directory (expected a sweep dir from `ddmr run -m` or a run dir)")
    running = running_holder(path)  # read before the jobs: a sweep that ends meanwhile is reported as running
    single = io.read_summary(path) is not None
    state = load_sweep(path)
    if not (state.complete or state.failed or state.missing):
        raise DDMRError(f"{path}: not a sweep or run dir (no {io.SUMMARY}, {PLAN} or job dirs with results)")
    if not state.complete:
        names = [d.name for d, _ in state.failed] + [m["dir"] for m in state.missing]
        raise DDMRError(f"{path}: no complete job to report ({len(state.failed)} failed, {len(state.missing)} "
                        f"missing: {', '.join(names[:5])}{' ...' if len(names) > 5 else ''})")
    jobs, metric_frames, segment_frames = [], [], []
    for job_dir, summary in state.complete:
        job = Job(job_dir, summary, _read_yaml(job_dir / io.CONFIG))
        try:
            metrics = pd.read_csv(job_dir / io.METRICS_CSV)
            segments = pd.read_csv(job_dir / io.SEGMENTS_CSV)
        except (OSError, ValueError) as exc:
            state.failed.append((job_dir, {**summary, "status": "unreadable", "error": f"{type(exc).__name__}: {exc}"}))
            continue
        jobs.append(job)
        metric_frames.append(metrics.assign(job=job_dir.name))
        segment_frames.append(segments.assign(job=job_dir.name))
    if not jobs:
        raise DDMRError(f"{path}: no job with readable results")
    _assign_keys(jobs)
    key_of = {j.dir.name: j.key for j in jobs}
    metrics = pd.concat(metric_frames, ignore_index=True)
    segments = pd.concat(segment_frames, ignore_index=True)
    metrics["key"] = metrics["job"].map(key_of)
    segments["key"] = segments["job"].map(key_of)
    multirun = _read_yaml(path / "multirun.yaml") if (path / "multirun.yaml").is_file() else None
    plan = None
    if (path / PLAN).is_file():
        try:
            plan = json.loads((path / PLAN).read_text(encoding="utf-8")).get("jobs")
        except (OSError, ValueError):
            plan = None
    return ReportData(path, single, jobs, list(state.failed), list(state.missing), metrics, segments,
                      multirun, plan, running)
