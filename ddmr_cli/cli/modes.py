"""The four things ``ddmr run`` can launch, one class each behind one small protocol.

=====================  ==========================================================  =================================
mode                   chosen when                                                 its jobs
=====================  ==========================================================  =================================
:class:`SingleRun`     no ``-m``                                                   one job in ``hydra.run.dir``
:class:`Sweep`         ``-m``                                                      Hydra's sweeper expands the plan
:class:`TuningStudy`   ``-m +tune=<controller>`` (a ``tuning`` node)               Optuna trials (Hydra's sweeper)
:class:`CalibrationSearch` ``-m +experiment=sensitivity_calibration``              Optuna trials of the study's box
=====================  ==========================================================  =================================

Each mode answers, before Hydra starts, :meth:`Mode.plan` (the jobs it will run, each composed and validated,
and the overrides that pin this session: raises ``ConfigError`` on a bad value), :meth:`Mode.preflight` (refuse
an output dir where it would overwrite what ddmr did not write: ``FaultError``), :meth:`Mode.before_launch`
(tidy what an interrupted launch left, under the dir's lock) and, after Hydra returns, :meth:`Mode.finish` (the
exit status from what is on disk). :mod:`ddmr_cli.cli.run` drives them.
"""

from __future__ import annotations

import os
import sys
from dataclasses import dataclass
from pathlib import Path
from typing import TYPE_CHECKING, Callable, ClassVar, NamedTuple, Sequence

from omegaconf import DictConfig

from ddmr_cli.cli.usage import EXIT_FAILED, UsageError

if TYPE_CHECKING:
    from ddmr_cli.config import JobComposer

#: composes one job's config from its overrides (``hydra_node``: with the ``hydra`` node)
Compose = Callable[..., DictConfig]


@dataclass
class Plan:
    """What a mode will run: the jobs (dir relative to the output dir, overrides) and the session's overrides."""

    jobs: list[dict]
    session: list[str]


class Validated(NamedTuple):
    """What :func:`_validate_jobs` found besides the refusals it raises."""

    #: the simulated run-steps of all the jobs (``run.n_runs`` times the steps of each)
    work: int
    #: one-line warnings, each once (an empty steady-state window)
    warnings: tuple[str, ...]


class Mode:
    """What ``ddmr run`` launches (see the module docstring)."""

    #: Hydra's ``--multirun``
    multirun: ClassVar[bool] = True
    #: the kind of lock the output dir is held with (:class:`ddmr_cli.storage.jobdir.DirLock`)
    lock_kind: ClassVar[str] = "sweep"
    #: :meth:`watch` draws a bar over the jobs (Hydra's INFO lines are then kept off the terminal)
    draws_bar: ClassVar[bool] = False

    def plan(self, base: DictConfig, overrides: list[str], parsed, composer: "JobComposer") -> Plan:
        """The jobs and the session's overrides, every job composed (by ``composer``) and validated (raises
        ConfigError)."""
        raise NotImplementedError

    def preflight(self, out_dir: Path, jobs: Sequence[dict]) -> None:
        """Refuse (``FaultError``) an output dir where this launch would overwrite what ddmr did not write."""

    #: one-line warnings from planning (:func:`_validate_jobs`), printed once the launch is not refused
    warnings: tuple[str, ...] = ()

    def before_launch(self, out_dir: Path, jobs: Sequence[dict]) -> None:
        """Under the output dir's lock, just before Hydra starts: the planning's warnings."""
        for warning in self.warnings:
            print(f"ddmr: warning: {warning}", file=sys.stderr)

    def finish(self, out_dir: Path, jobs: Sequence[dict]) -> int:
        """The exit status, read from the output dir as it is on disk."""
        raise NotImplementedError

    def watch(self, out_dir: Path, jobs: Sequence[dict], enabled: bool):
        """A context manager that shows the launch's progress while Hydra runs (nothing by default)."""
        import contextlib

        return contextlib.nullcontext()


def _validate_jobs(jobs: list[dict], base: DictConfig, multirun: bool, compose: Callable[[list[str]], DictConfig]):
    """Compose and validate every job (the model is built: derived numbers fail here); then the memory budget
    of the largest job times the jobs at once. A bad value raises UsageError naming the key, the value and the
    job's overrides. Returns the simulated run-steps in all and the warnings (each once): an empty steady-state
    window."""
    from ddmr_cli import progress
    from ddmr_cli.config import budget
    from ddmr_cli.config.validate import (check_additions, job_estimate, message, steady_state_warning,
                                          validate_config)
    from ddmr_cli.errors import ConfigError

    largest, work = None, 0
    warned: list[str] = []
    shown = multirun and bool(base.run.get("progress", True))
    for job in progress.each(jobs, len(jobs), "validating", "jobs", enabled=shown, leave=False,
                             delay=progress.delay_since_start()):
        current = job["overrides"]
        try:
            cfg = compose(current) if multirun else base
            check_additions(cfg, current)
            sim = validate_config(cfg)  # builds the model: derived numbers (J^-1, controller gains) fail here
        except ConfigError as exc:
            raise UsageError(message(exc, current)) from None
        except (MemoryError, OverflowError) as exc:  # a value too large to validate
            raise UsageError(f"{' '.join(current)}: too large to plan ({type(exc).__name__}); lower the largest "
                             f"value") from None
        warning = steady_state_warning(sim)
        if warning is not None and warning not in warned:  # once per distinct message, not once per job
            warned.append(warning)
        est = job_estimate(cfg, sim)
        largest = est if largest is None or est.total > largest.total else largest
        work += int(cfg.run.n_runs) * sim.n_steps * (EXTERNAL_PLANT_COST if sim.plant is not None else 1)
    if multirun and largest is not None:
        at_once = budget.at_once(str(base.hydra.launcher.get("_target_", "")), base.hydra.launcher.get("n_jobs"),
                                 len(jobs))
        budget.check(largest, base.run.get("max_memory_gb"), at_once, (base.get("cluster") or {}).get("mem_gb"))
    return Validated(work, tuple(warned))


def _compose_in_parallel(composer: "JobComposer", jobs: list[list[str]], shown: bool) -> None:
    """The sweep's sets of group choices that ddmr's cache lacks composed at once on every core
    (:meth:`~ddmr_cli.config.JobComposer.prefetch`: the first sweep after an edit of ``conf/``), with a status
    line meanwhile."""
    from ddmr_cli import progress
    from ddmr_cli.compiled import thread_count

    def composing(n_sets: int, n_processes: int):
        return progress.status(f"composing {n_sets} sets of group choices in {n_processes} processes (the first "
                               f"sweep of this config: kept for the next)", enabled=shown,
                               delay=progress.delay_since_start())

    composer.prefetch(jobs, thread_count(0), composing)


#: a sweep on the default launcher (``launcher=local``, joblib) of at most this many jobs and this many simulated
#: run-steps in all (a few seconds of one core) runs in this process on Hydra's basic launcher (``launcher=basic``):
#: worker start-up and a kernel load per worker cost more than the parallel simulation saves. table4 (8 jobs,
#: 6e6 run-steps), A/B over 5 pairs: 0.67x the CPU and 0.66x the wall time of the joblib launcher (issue 28).
SMALL_SWEEP_JOBS = 16
SMALL_SWEEP_RUN_STEPS = 20_000_000
#: a run-step on an external plant counts as this many on the wheel plant: a MuJoCo step of the paper's robot took
#: about 40 us against the compiled wheel loop's 0.2 us (issue 30), so a physics sweep runs in parallel processes
EXTERNAL_PLANT_COST = 200


def small_local_sweep(base: DictConfig, parsed, n_jobs: int, work: int) -> bool:
    """True when a sweep should run in this process (see :data:`SMALL_SWEEP_JOBS`): few jobs, little simulation,
    and the launcher is the default one, neither chosen nor configured (``cluster.*``) on the command line.

    Never a sensitivity study's stage: its jobs are chunks of samples (``study.chunks``, one per core), each
    validating, building and simulating a configuration per sample, work that runs in parallel only in processes
    (in this process, the default study took 369 s against 267 s on joblib's workers: measured, 2 cores)."""
    chosen = any(o.key_or_group.lstrip("+~") in ("launcher", "hydra/launcher")
                 or o.key_or_group.lstrip("+~").startswith(("cluster.", "hydra.launcher.")) for o in parsed)
    default = str((base.hydra.runtime.get("choices") or {}).get("launcher")) == "local"
    study_stage = base.get("study") is not None
    return (not chosen and default and not study_stage and n_jobs <= SMALL_SWEEP_JOBS
            and work <= SMALL_SWEEP_RUN_STEPS)


class SingleRun(Mode):
    """One job (no ``-m``): its config composed and validated, its dir cleared of nothing ddmr did not write."""

    multirun = False
    lock_kind = "run"

    def plan(self, base, overrides, parsed, composer):
        jobs = [{"dir": "", "overrides": list(overrides)}]
        self.warnings = _validate_jobs(jobs, base, False, composer.compose).warnings
        return Plan(jobs, [])

    def preflight(self, out_dir, jobs):
        from ddmr_cli.storage import jobdir

        jobdir.check_clear(out_dir)

    def finish(self, out_dir, jobs):
        from ddmr_cli.storage import io

        summary = io.read_summary(out_dir)
        return 0 if summary and summary.get("status") == "complete" else EXIT_FAILED


class Sweep(Mode):
    """A sweep (``-m``): Hydra's sweeper expands the overrides into jobs; every job is composed and validated
    before anything is written, and none may write into another's dir or outside the sweep dir."""

    draws_bar = True

    def plan(self, base, overrides, parsed, composer):
        from ddmr_cli.config.compose_once import record_validated_jobs
        from ddmr_cli.config.plan import plan_jobs

        jobs = plan_jobs(overrides, base)
        if not jobs:
            empty = next((o.input_line for o in parsed if o.is_sweep_override() and not list(o.sweep_string_iterator())),
                         "hydra.sweeper.params")
            raise UsageError(f"{empty}: the sweep has no jobs (an empty range or list); nothing to run")
        subdir = [o for o in overrides if o.startswith("hydra.sweep.subdir=")]
        _refuse_escapes(jobs, subdir)
        _refuse_shared_dirs(jobs, subdir)
        # a small sweep's jobs are validated as Hydra's sweeper will compose them (launcher=basic last), so both
        # share one composition per set of group choices; the launcher is left out of the job dirs' names and of
        # the config hash: the same dirs, the same numbers
        session = ["launcher=basic"] if small_local_sweep(base, parsed, len(jobs), 0) else []
        _compose_in_parallel(composer, [[*job["overrides"], *session] for job in jobs],
                             bool(base.run.get("progress", True)))
        work, self.warnings = _validate_jobs(jobs, base, True, lambda job: composer.compose([*job, *session]))
        session = session if small_local_sweep(base, parsed, len(jobs), work) else []
        # as Hydra's sweeper will list them (the session's overrides last): it need not compose them again to check
        record_validated_jobs([*job["overrides"], *session] for job in jobs)
        return Plan(jobs, session)

    def preflight(self, out_dir, jobs):
        from ddmr_cli.storage import jobdir, sweep

        sweep.check_dir(out_dir)
        for job in jobs:
            job_dir = out_dir / job["dir"]
            if not os.path.lexists(job_dir):
                continue
            if not jobdir.inside(job_dir, out_dir):
                raise jobdir.FaultError(job_dir, f"resolves to {job_dir.resolve()}, outside the sweep dir; a job "
                                                 "writes only inside its sweep dir; remove the link or choose "
                                                 "another dir")
            jobdir.check_clear(job_dir)

    def before_launch(self, out_dir, jobs):
        from ddmr_cli.storage import jobdir

        jobdir.clean_leftovers(out_dir, [job["dir"] for job in jobs])
        print(f"ddmr: sweep of {len(jobs)} jobs validated -> {out_dir}", file=sys.stderr)
        super().before_launch(out_dir, jobs)

    def watch(self, out_dir, jobs, enabled):
        """A bar over the jobs, advanced as their summaries appear (:class:`ddmr_cli.progress.SweepWatch`)."""
        from ddmr_cli.progress import SweepWatch
        from ddmr_cli.storage import io

        return SweepWatch(out_dir, [job["dir"] for job in jobs], io.SUMMARY, enabled)

    def finish(self, out_dir, jobs):
        from ddmr_cli.storage import sweep
        from ddmr_cli.study.setup import STUDY_CSV

        state = sweep.read_state(out_dir, plan=list(jobs))
        # a sweep writes its tables; a sensitivity-study stage (+experiment=sensitivity_*) writes its study table
        tables = (out_dir / sweep.JOBS_CSV).is_file() or (out_dir / STUDY_CSV).is_file()
        status = 0 if state.ok and tables else EXIT_FAILED
        faults = [s["fault"] for _, s in state.failed if isinstance(s.get("fault"), dict)]
        if faults:
            more = f" ({len(faults)} jobs failed on file-system faults)" if len(faults) > 1 else ""
            print(f"ddmr: error: {faults[0]['path']}: {faults[0]['reason']}{more}", file=sys.stderr)
        return status


class _OptunaStudy(Mode):
    """A mode whose session is an Optuna study stored in the sweep dir (:class:`ddmr_cli.study.tuning.Session`):
    planned read only, started under the dir's lock (the trials a killed session left RUNNING marked failed)."""

    draws_bar = True

    def _prepare(self, base, overrides):
        """The planned :class:`~ddmr_cli.study.tuning.Session` (checks the study's settings first)."""
        raise NotImplementedError

    def plan(self, base, overrides, parsed, composer):
        self.session = self._prepare(base, overrides)  # read only: the lock is not held yet
        return Plan([], self.session.overrides)

    def before_launch(self, out_dir, jobs):
        super().before_launch(out_dir, jobs)
        self.session.start()  # under the lock

    def _trial_marker(self) -> str:
        """The file a trial's job writes when it ends."""
        raise NotImplementedError

    def watch(self, out_dir, jobs, enabled):
        """A bar over the session's trials, advanced as their :meth:`_trial_marker` files appear
        (:class:`ddmr_cli.progress.TrialWatch`)."""
        from ddmr_cli.progress import TrialWatch

        return TrialWatch(out_dir, self.session.budget - self.session.done, self._trial_marker(), enabled)


class TuningStudy(_OptunaStudy):
    """A gain-tuning study (``+tune=<controller>``, docs/model.md §9): Optuna's trials through Hydra's sweeper,
    resumed from its SQLite storage; this session runs the rest of the budget."""

    def _prepare(self, base, overrides):
        from ddmr_cli.study import tuning

        return tuning.prepare_study(base, overrides)

    def _trial_marker(self):
        from ddmr_cli.study.tuning import TRIAL_FILE

        return TRIAL_FILE

    def finish(self, out_dir, jobs):
        from ddmr_cli.study import tuning

        return tuning.finish(out_dir)


class CalibrationSearch(_OptunaStudy):
    """The sensitivity study's calibration search (``+experiment=sensitivity_calibration``, docs/model.md §11)."""

    def _prepare(self, base, overrides):
        from ddmr_cli.study import search

        return search.prepare_search(base)

    def _trial_marker(self):  # a trial is a study job
        from ddmr_cli.storage.io import SUMMARY

        return SUMMARY

    def finish(self, out_dir, jobs):
        from ddmr_cli.study import search

        return search.finish(out_dir)


def mode_of(base: DictConfig, multirun: bool) -> Mode:
    """The mode the composed config and ``-m`` choose (see the module docstring)."""
    if not multirun:
        return SingleRun()
    from ddmr_cli.study import search, tuning

    if search.is_search(base):
        return CalibrationSearch()
    if tuning.is_study(base):
        return TuningStudy()
    return Sweep()


def _refuse_shared_dirs(plan: list[dict], subdir: list[str]) -> None:
    """Two jobs of one plan that would write into one dir: refused, naming the ``hydra.sweep.subdir`` override
    or the keys that tell them apart (left out of the dir names)."""
    from ddmr_cli.config.plan import shared_dir

    clash = shared_dir(plan)
    if clash is None:
        return
    a, b = clash
    differ = sorted({ov.lstrip("+~").partition("=")[0] for ov in set(a["overrides"]) ^ set(b["overrides"])})
    raise UsageError(f"{subdir[-1] if subdir else ', '.join(differ) or 'hydra.sweep.subdir'}: jobs {' '.join(a['overrides'])!r} and "
                     f"{' '.join(b['overrides'])!r} would write into one job dir {a['dir']!r}; sweep a key that names "
                     f"the dir (not one of hydra.job.config.override_dirname.exclude_keys) or give hydra.sweep.subdir "
                     f"a per-job value")


def _refuse_escapes(plan: list[dict], subdir: list[str]) -> None:
    """A planned job dir that is not a path strictly inside the sweep dir (``hydra.sweep.subdir=../x``, an
    absolute path, ``.``): refused, naming the ``hydra.sweep.subdir`` override."""
    for job in plan:
        norm = os.path.normpath(job["dir"])
        if os.path.isabs(norm) or norm == "." or norm.split(os.sep)[0] == "..":
            raise UsageError(f"{subdir[-1] if subdir else 'hydra.sweep.subdir'}: job {' '.join(job['overrides'])!r} "
                             f"would write into {job['dir']!r}, not a dir inside the sweep dir; give "
                             f"hydra.sweep.subdir a relative path below it")


__all__ = ["SMALL_SWEEP_JOBS", "SMALL_SWEEP_RUN_STEPS", "EXTERNAL_PLANT_COST", "small_local_sweep", "Mode", "Plan", "SingleRun", "Sweep", "TuningStudy", "CalibrationSearch", "mode_of"]
