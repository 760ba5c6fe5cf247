"""``hydra/sweeper=ddmr_optuna``: an Optuna (>= 4) study whose trials are Hydra jobs.

Written for ddmr against Hydra's public sweeper interface (:class:`hydra.plugins.sweeper.Sweeper`) and Optuna's
public ask-and-tell API, after the behaviour of Hydra's ``hydra-optuna-sweeper`` (MIT), whose every release pins
``optuna < 3`` (its main branch has moved to Optuna 4 but is unreleased). What a user knows from that plugin holds:

- the search space ``hydra.sweeper.params`` (and the sweep overrides of the command line, which replace a param of
  the same key): ``interval(a, b)`` a float (int when both ends are ints), ``tag(log, interval(a, b))`` on a log
  scale, ``choice(...)`` categorical, ``range(start, stop[, step])`` the values Hydra's ``range`` names (``stop``
  excluded, as in Hydra's basic sweeper; hydra-optuna-sweeper 1.x also sampled ``stop``), ``shuffle(...)`` of a
  range categorical; any other override is passed to every trial unchanged;
- ``custom_search_space``: a dotted path to ``f(config, trial)`` that suggests more parameters on each trial;
- ``sampler`` (``hydra/sweeper/sampler=tpe|nsgaii|random|cmaes|gp|qmc|grid``), ``direction`` (one, or a list for
  several objectives), ``storage`` (e.g. ``sqlite:///study.db``) and ``study_name``: an existing study of that
  name in the storage is loaded and continued, so re-running the same command resumes it; ``n_trials`` trials in
  batches of ``n_jobs`` (asked together, launched together through the configured launcher);
- a job's return value is the objective (a float, or a sequence of one float per direction); a job that raised
  or returned something else is a FAIL trial, and more than ``max_failure_rate`` failures in a batch stop the
  sweep with the job's own error;
- ``optimization_results.yaml`` in the sweep dir: the best trial, or the Pareto front.

Differences: a trial's parameters are suggested with ``trial.suggest_*`` (no private Optuna API), the launcher's
job numbers are the Optuna trial numbers (unique across resumed sessions), and the sampler configs are those of
Optuna >= 4 (:mod:`.config`).

A study in a storage is worked on in memory and recorded in the storage as it goes (:class:`StoredTrials`): the
sampler asks and is told in an in-memory copy of the stored study, and each trial is written to the storage twice,
in one transaction each: when it is launched (RUNNING, with its parameters) and when it ends (its state and
values). Optuna writes each suggested parameter in a transaction of its own: 2.3 ms each in SQLite, 7 s of the
sensitivity study's calibration (128 trials of 24 parameters), with the launcher's workers idle. The storage holds
what it held before at every trial's start and end, with the same numbers; a killed sweep leaves its running
trials RUNNING, as before. A batch's RUNNING records are written in a thread while the launcher starts its jobs
(:meth:`DdmrOptunaSweeper._launch`), and are complete before any of its trials is told.

A batch is validated as Hydra's sweepers validate one (every trial's config composed before any runs), except
that a trial whose overrides have the form of one already composed in this sweep is not composed again
(:func:`override_form`: the same names, numbers of the same types, the same texts).
"""

from __future__ import annotations

import logging
from concurrent.futures import ThreadPoolExecutor, wait
from typing import Any, Callable, Dict, List, Optional

from hydra.core.plugins import Plugins
from hydra.plugins.sweeper import Sweeper
from hydra.types import HydraContext, TaskFunction
from hydra.utils import get_method, instantiate
from omegaconf import DictConfig, OmegaConf

from ._space import Dimension, directions, objective_values, search_space

log = logging.getLogger(__name__)

RESULTS_FILE = "optimization_results.yaml"


def override_form(params: Dict[str, Any]) -> tuple:
    """What Hydra's composition of a trial's overrides (``name=value`` each, :meth:`DdmrOptunaSweeper._trial_overrides`)
    depends on beyond its numbers: each parameter's name and, for a number, its type (int or float: Hydra's override
    grammar parses every value of one type alike, and a config's schema checks types, not values); any other value
    (a text, such as a config group's option, or a boolean) whole. Trials of one form compose alike, or fail alike."""
    return tuple((name, type(value).__name__) if isinstance(value, (int, float)) and not isinstance(value, bool)
                 else (name, repr(value)) for name, value in params.items())


class StoredTrials:
    """A study kept in a storage (an Optuna RDB URL) and worked on in an in-memory copy (module docstring).

    :attr:`study` is the in-memory study: the stored study's trials, in order, then the trials asked of it.
    :meth:`launched` records asked trials in the storage (RUNNING, with their parameters; an enqueued trial the
    copy took from the storage's WAITING ones is that trial, updated), :meth:`ended` records their state and values.
    The storage's trial numbers are the copy's: a trial numbered otherwise there (another process wrote into the
    same study) stops the sweep."""

    def __init__(self, url: str, study_name: Optional[str], sampler: Any, directions: List[str]) -> None:
        import optuna

        self.storage = optuna.storages.RDBStorage(url)
        stored = optuna.create_study(study_name=study_name, storage=self.storage, directions=directions,
                                     load_if_exists=True)
        self.study_id = self.storage.get_study_id_from_name(stored.study_name)
        self.study = optuna.create_study(study_name=stored.study_name, sampler=sampler, directions=directions)
        copied = stored.get_trials(deepcopy=False)
        self.study.add_trials(copied)
        #: trials the storage holds as WAITING (enqueued): number -> stored id, updated when the copy asks them
        self._waiting = {t.number: self.storage.get_trial_id_from_study_id_trial_number(self.study_id, t.number)
                         for t in copied if t.state == optuna.trial.TrialState.WAITING}
        self._ids: Dict[int, int] = {}

    def launched(self, trials) -> None:
        """Record asked trials (:class:`optuna.Trial` of :attr:`study`, their parameters suggested) as RUNNING."""
        from optuna.trial import TrialState

        frozen = self.study.get_trials(deepcopy=False)
        for trial in trials:
            t = frozen[trial.number]
            if t.number in self._waiting:
                trial_id = self._waiting.pop(t.number)
                self.storage.set_trial_state_values(trial_id, TrialState.RUNNING)
                for name, value in t.params.items():
                    dist = t.distributions[name]
                    self.storage.set_trial_param(trial_id, name, dist.to_internal_repr(value), dist)
            else:
                trial_id = self.storage.create_new_trial(self.study_id, template_trial=t)
            number = self.storage.get_trial_number_from_id(trial_id)
            if number != t.number:
                raise RuntimeError(f"Optuna study {self.study.study_name}: trial {t.number} was stored as trial "
                                   f"{number}; another process is writing into the same study")
            self._ids[t.number] = trial_id

    def ended(self, trial) -> None:
        """Record a told trial's state and values."""
        t = self.study.get_trials(deepcopy=False)[trial.number]
        self.storage.set_trial_state_values(self._ids.pop(t.number), t.state, t.values)


class DdmrOptunaSweeper(Sweeper):
    """An Optuna study run as batches of Hydra jobs (see the module docstring)."""

    def __init__(self, sampler: Any, direction: Any, storage: Optional[Any], study_name: Optional[str],
                 n_trials: int, n_jobs: int, max_failure_rate: float = 0.0,
                 custom_search_space: Optional[str] = None, params: Optional[DictConfig] = None) -> None:
        super().__init__()
        if not 0.0 <= float(max_failure_rate) <= 1.0:
            raise ValueError(f"hydra.sweeper.max_failure_rate={max_failure_rate!r}: must be in [0, 1]")
        if int(n_jobs) < 1:
            raise ValueError(f"hydra.sweeper.n_jobs={n_jobs!r}: must be >= 1")
        self.sampler_config = sampler
        self.directions = directions(direction)
        self.storage = None if storage is None else str(storage)
        self.study_name = None if study_name is None else str(study_name)
        self.n_trials, self.n_jobs = int(n_trials), int(n_jobs)
        self.max_failure_rate = float(max_failure_rate)
        self.extend: Optional[Callable[[DictConfig, Any], None]] = \
            get_method(custom_search_space) if custom_search_space else None
        self.params = params
        self.config: Optional[DictConfig] = None
        self.launcher = None

    def setup(self, *, hydra_context: HydraContext, task_function: TaskFunction, config: DictConfig) -> None:
        """The launcher, given Hydra's config loader wrapped by ddmr's
        :class:`~ddmr_cli.config.compose_once.SweepConfigLoader`: the trials differ only in values, so each is a
        copy of one composition with its values applied (the same config as Hydra's, composed once a sweep, in
        this process: :meth:`sweep` validates each batch before launching it)."""
        from ddmr_cli.config.compose_once import SweepConfigLoader

        hydra_context = HydraContext(config_loader=SweepConfigLoader(hydra_context.config_loader),
                                     callbacks=hydra_context.callbacks)
        self.hydra_context = hydra_context
        self.config = config
        self.launcher = Plugins.instance().instantiate_launcher(config=config, hydra_context=hydra_context,
                                                                task_function=task_function)

    def _sampler(self, dims: Dict[str, Dimension]):
        sampler = self.sampler_config  # Hydra instantiates the sweeper's nested nodes with it
        if isinstance(sampler, (DictConfig, dict)):
            sampler = instantiate(sampler)
        if callable(sampler) and getattr(sampler, "func", None) is not None:  # the grid: a partial of GridSampler
            grid = {name: d.grid() for name, d in dims.items()}
            sampler = sampler(grid)
            size = 1
            for values in grid.values():
                size *= len(values)
            if size < self.n_trials:
                log.info("the grid has %d points: %d trials instead of %d", size, size, self.n_trials)
                self.n_trials = size
        return sampler

    def _trial_overrides(self, trial, dims: Dict[str, Dimension], fixed: List[str]) -> List[str]:
        for dim in dims.values():
            dim.suggest(trial)
        if self.extend is not None:
            self.extend(self.config, trial)
        return [f"{name}={value}" for name, value in trial.params.items()] + fixed

    def _validate(self, trials, overrides: List[List[str]], validated: set) -> None:
        """Hydra's ``validate_batch_is_legal`` on the trials of a batch whose overrides differ in form
        (:func:`override_form`) from every trial validated before in this sweep (``validated``, updated): a trial of
        a form already composed composes too. The sensitivity study's calibration validated 128 trials of 24
        numbers each, 37 ms each in this process with the launcher's workers idle; its forms are one."""
        new = {}
        for trial, trial_overrides in zip(trials, overrides):
            form = override_form(trial.params)
            if form not in validated and form not in new:
                new[form] = trial_overrides
        if new:
            self.validate_batch_is_legal(list(new.values()))
            validated.update(new)

    def sweep(self, arguments: List[str]) -> None:
        import optuna

        assert self.config is not None and self.launcher is not None, "setup() first"
        params = [f"{k}={v}" for k, v in (OmegaConf.to_container(self.params) if isinstance(self.params, DictConfig)
                                          else (self.params or {})).items()]
        dims, fixed = search_space([*params, *arguments])
        stored = None
        if self.storage is None:
            study = optuna.create_study(study_name=self.study_name, sampler=self._sampler(dims),
                                        directions=self.directions)
        else:
            stored = StoredTrials(self.storage, self.study_name, self._sampler(dims), self.directions)
            study = stored.study
        log.info("Optuna study %s (%s, %s, %s): %d trials in batches of %d", study.study_name, self.storage or "memory",
                 type(study.sampler).__name__, ", ".join(self.directions), self.n_trials, self.n_jobs)
        recorder = ThreadPoolExecutor(1, thread_name_prefix="ddmr-optuna-storage") if stored is not None else None
        try:
            self._batches(study, stored, dims, fixed, recorder)
        finally:
            if recorder is not None:
                recorder.shutdown(wait=True)
        self._write_results(study)

    def _launch(self, trials, overrides: List[List[str]], stored: Optional[StoredTrials], recorder):
        """Launch a batch; with a storage, its trials are recorded RUNNING (:meth:`StoredTrials.launched`) in
        ``recorder``'s thread while the launcher starts the jobs, and the records are complete before this returns
        or raises (a killed sweep leaves them RUNNING, as before). The records are Optuna's SQL transactions, about
        60 ms a trial of 24 parameters: 7.7 s of the study's calibration (128 trials), which the main thread spent
        before each launch with the launcher's workers idle."""
        if stored is None:
            return self.launcher.launch(overrides, initial_job_idx=trials[0].number)
        recording = recorder.submit(stored.launched, trials)
        try:
            returns = self.launcher.launch(overrides, initial_job_idx=trials[0].number)
        finally:
            wait([recording])
        recording.result()  # its error (another process writing into the study) stops the sweep
        return returns

    def _batches(self, study, stored: Optional[StoredTrials], dims, fixed: List[str], recorder) -> None:
        """Ask, validate, launch and tell batches of :attr:`n_jobs` trials until :attr:`n_trials` are done."""
        import optuna

        to_go, validated = self.n_trials, set()
        while to_go > 0:
            trials = [study.ask() for _ in range(min(to_go, self.n_jobs))]
            overrides = [self._trial_overrides(t, dims, fixed) for t in trials]
            # as Hydra's sweepers: every trial's config composes before any runs (a bad override stops the sweep
            # here); the composition the trials share is then made here, once, and travels to the launcher's workers
            self._validate(trials, overrides, validated)
            returns = self._launch(trials, overrides, stored, recorder)
            failures = 0
            for trial, ret in zip(trials, returns):
                try:
                    values = objective_values(ret.return_value, len(self.directions))
                except Exception as exc:  # the job raised (JobReturn re-raises it) or returned no objective
                    study.tell(trial, state=optuna.trial.TrialState.FAIL)
                    log.warning("trial %d failed: %s", trial.number, exc)
                    failures += 1
                else:
                    try:
                        study.tell(trial, values)
                    except RuntimeError as exc:  # the grid sampler's Study.stop once the grid is done: told, raised
                        if "Study.stop" not in str(exc):
                            raise
                if stored is not None:
                    stored.ended(trial)
            if failures / len(returns) > self.max_failure_rate:
                log.error("%d of %d trials failed (hydra.sweeper.max_failure_rate=%g)", failures, len(returns),
                          self.max_failure_rate)
                for ret in returns:
                    ret.return_value  # re-raises the job's own error
                raise RuntimeError(f"{failures} of {len(returns)} trials returned no objective")
            to_go -= len(trials)

    def _write_results(self, study) -> None:
        import optuna

        done = [t for t in study.get_trials(deepcopy=False, states=(optuna.trial.TrialState.COMPLETE,))]
        if not done:
            return
        if len(self.directions) == 1:
            best = study.best_trial
            results = {"name": "optuna", "best_params": best.params, "best_value": best.value}
        else:
            results = {"name": "optuna", "solutions": [{"params": t.params, "values": t.values}
                                                       for t in study.best_trials]}
        OmegaConf.save(OmegaConf.create(results), f"{self.config.hydra.sweep.dir}/{RESULTS_FILE}")


__all__ = ["DdmrOptunaSweeper", "RESULTS_FILE", "StoredTrials", "override_form"]
