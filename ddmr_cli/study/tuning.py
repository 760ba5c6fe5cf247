"""Gain tuning through ddmr's Optuna sweeper (docs/model.md §9): the trial, the study's checks and its tables.

``ddmr run -m +tune=<controller>`` composes a study (conf/tune/<controller>.yaml: the search space as the
sweeper's ``hydra.sweeper.params``; conf/tuning/default.yaml: budget, seeds, scenarios, storage). Hydra's Optuna
sweeper asks the sampler for gains and launches each trial as one Hydra job through the configured launcher;
the job (:func:`run_trial`) simulates the tuning seeds in every scenario of ``tuning.scenarios`` and returns the
objective to the sweeper. Nothing here loops over trials: the sweeper does.

The objective (:func:`evaluate_gains`): the mean of :data:`OBJECTIVE_METRIC` over the runs that did not diverge,
averaged over the scenarios; with ``tuning.objective=pareto`` also the mean chattering (NSGA-II, a Pareto front).
Divergence and saturation are constraints handled by a penalty that is written into every trial's
``trial.json`` and the study's ``tuning_trials.csv``: a trial with a diverged run, a mean saturation fraction
above ``tuning.saturation_limit`` or gains whose discrete-time loop is unstable at ``simulation.dt`` is
infeasible and scores ``bound * (1 + violation)`` (``bound`` = ``simulation.divergence_bound`` for the
deviation, ``2 U_max / dt`` — the largest total variation per second the voltage can have — for the
chattering), above every feasible trial, and lower the smaller its violation. Never NaN.

The study lives in its sweep dir (``outputs/tune/<objective>/<controller>``, no time stamp): the Optuna storage
``study.db`` (SQLite), ``tuning.json`` (what the study is and its sessions), one dir per trial under ``trials/``
and, when a session ends, ``tuning_trials.csv`` and ``best.yaml``. Before Hydra starts, :func:`prepare_study`
checks the search space and the study settings (a bad one is a one-line ConfigError, exit 2), and for an
existing study counts the trials done so that the same command runs only the rest of the budget.
"""

from __future__ import annotations

import copy
import hashlib
import json
import logging
import math
import time
from dataclasses import asdict, dataclass, field
from pathlib import Path
from typing import Any

from omegaconf import DictConfig, OmegaConf, open_dict, read_write

from ddmr_cli.checks import integer, one_of
from ddmr_cli.storage import io
from ddmr_cli.engine.catalog import STEADY
from ddmr_cli.errors import ConfigError

log = logging.getLogger("ddmr")

#: The deviation metric the tuning minimises: the steady-state mean deviation (after ``metrics.settle_time``, so
#: the start-up transient from the offset pose, the same for every controller, does not decide the gains).
OBJECTIVE_METRIC = "deviation_mae" + STEADY
#: The second objective of ``tuning.objective=pareto``: the steady-state chattering (total variation of u / s).
CHATTERING_METRIC = "chattering" + STEADY
#: The constraint metric: fraction of steps with a wheel at +-U_max.
SATURATION_METRIC = "saturation_fraction"
OBJECTIVES = ("deviation", "pareto")

STUDY_FILE = "tuning.json"
STORAGE_FILE = "study.db"
TRIAL_FILE = "trial.json"
TRIALS_DIR = "trials"
TRIALS_CSV = "tuning_trials.csv"
BEST_FILE = "best.yaml"
#: Study settings that do not change what a trial computes (a study may be resumed with other values).
_BUDGET_KEYS = ("n_trials", "batch", "seed", "held_out")


def is_study(cfg: DictConfig) -> bool:
    """True when the composed config is a tuning study (``+tune=<controller>``)."""
    return cfg.get("tuning") is not None


# --- the trial ------------------------------------------------------------------------------------------------


@dataclass(frozen=True)
class TrialOutcome:
    """What one trial measured and what it returns to the sweeper (``values``)."""

    values: tuple[float, ...]
    feasible: bool
    violation: float
    reason: str
    deviation: float
    chattering: float
    saturation: float
    runs: int
    diverged: int
    per_scenario: dict = field(default_factory=dict)

    def as_dict(self) -> dict:
        return asdict(self)


def scenario_config(cfg: DictConfig, name: str) -> DictConfig:
    """A copy of a study config whose ``scenario`` is ``tuning.scenarios.<name>`` (replaced, not merged)."""
    out = copy.deepcopy(cfg)
    with read_write(out), open_dict(out):
        out.scenario = copy.deepcopy(cfg.tuning.scenarios[name])
    return out


def _mean(values) -> float:
    values = [float(v) for v in values if not math.isnan(float(v))]
    return math.fsum(values) / len(values) if values else float("nan")


def ceilings(cfg: DictConfig) -> tuple[float, float]:
    """The penalty scales: the divergence bound [m] and the largest chattering ``2 U_max / dt`` [V/s]."""
    return float(cfg.simulation.divergence_bound), 2.0 * float(cfg.robot.max_voltage) / float(cfg.simulation.dt)


def penalised(cfg: DictConfig, violation: float) -> tuple[float, float]:
    """The (deviation, chattering) an infeasible trial scores, docs/model.md §9 [9c]: ``bound (1 + v)``, above
    every feasible trial, growing with the violation ``v`` (the fraction of runs diverged plus the saturation
    fraction beyond the limit; 1 for gains unstable at the step)."""
    bound, chattering = ceilings(cfg)
    return bound * (1.0 + violation), chattering * (1.0 + violation)


def evaluate_gains(cfg: DictConfig, threads: int = 0) -> TrialOutcome:
    """Simulate a study config's tuning seeds in every scenario of ``tuning.scenarios``; the objective values
    with the constraints applied: docs/model.md §9, the deviation [9a], the chattering [9b], the violation and
    penalty [9c] (:func:`penalised`)."""
    from ddmr_cli.config import seeds_of, validate_config
    from ddmr_cli.engine.simulation import simulate

    two = str(cfg.tuning.objective) == "pareto"
    try:
        sims = {name: validate_config(scenario_config(cfg, name)) for name in cfg.tuning.scenarios}
    except ConfigError as exc:  # gains whose discrete-time loop is unstable at this step: infeasible
        values = penalised(cfg, 1.0)
        return TrialOutcome(values if two else values[:1], False, 1.0, f"unstable: {exc}", float("nan"),
                            float("nan"), float("nan"), 0, 0)
    seeds = seeds_of(cfg)
    per, devs, chats, sats = {}, [], [], []
    runs = diverged = 0
    for name, sim in sims.items():
        result = simulate(sim, seeds, keep_series=[], threads=threads)
        ok = ~result.diverged
        dev = _mean(result.metric(OBJECTIVE_METRIC)[ok])
        chat = _mean(result.metric(CHATTERING_METRIC)[ok])
        sat = _mean(result.metric(SATURATION_METRIC)[ok])
        n_div = int(result.diverged.sum())
        per[name] = {OBJECTIVE_METRIC: dev, CHATTERING_METRIC: chat, SATURATION_METRIC: sat, "diverged": n_div}
        devs.append(dev), chats.append(chat), sats.append(sat)
        runs, diverged = runs + len(seeds), diverged + n_div
    deviation, chattering, saturation = _mean(devs), _mean(chats), _mean(sats)
    excess = max(0.0, saturation - float(cfg.tuning.saturation_limit)) if not math.isnan(saturation) else 0.0
    violation = diverged / runs + excess
    reasons = []
    if not math.isfinite(deviation) and diverged < runs:  # cannot happen after check_study: settle < duration
        reasons.append(f"no finite {OBJECTIVE_METRIC}")
        violation = max(violation, 1.0)
    if diverged:
        reasons.append(f"{diverged}/{runs} runs diverged")
    if excess > 0.0:
        reasons.append(f"saturation {saturation:.4f} > limit {float(cfg.tuning.saturation_limit):g}")
    feasible = not reasons
    values = (deviation, chattering) if feasible else penalised(cfg, violation)
    return TrialOutcome(values if two else values[:1], feasible, violation, "; ".join(reasons), deviation,
                        chattering, saturation, runs, diverged, per)


def run_trial(cfg: DictConfig, place, keys: list[str]) -> float | list[float]:
    """A trial of the study (the Hydra task, :mod:`ddmr_cli.cli.hydra_main`): evaluate the gains the sweeper
    sampled (``keys``, its ``hydra.sweeper.params``), write ``trial.json`` into ``place.out``, return the
    objective."""
    out = Path(place.out)
    params = {k: OmegaConf.to_container(v) if isinstance(v := OmegaConf.select(cfg, k), DictConfig) else v
              for k in keys}
    threads = int(cfg.run.threads) or 1  # trials run in parallel processes: one thread each unless asked
    started = time.perf_counter()
    outcome = evaluate_gains(cfg, threads)
    io.write_json(out / TRIAL_FILE, {"params": params, "overrides": list(place.overrides), "metric": OBJECTIVE_METRIC,
                                     **outcome.as_dict(), "wall_time": time.perf_counter() - started})
    shown = ", ".join(f"{k.rsplit('.', 1)[-1]}={v:.4g}" for k, v in params.items())
    state = "feasible" if outcome.feasible else f"infeasible ({outcome.reason})"
    log.info("trial %s: %s -> %s %s", out.name, shown, ", ".join(f"{v:.6g}" for v in outcome.values), state)
    return list(outcome.values) if len(outcome.values) > 1 else outcome.values[0]


# --- checks before Hydra starts -------------------------------------------------------------------------------


@dataclass(frozen=True)
class Interval:
    """One dimension of a search space: ``[low, high]``, log-uniform or uniform (or a list of choices)."""

    key: str
    low: float = float("nan")
    high: float = float("nan")
    log: bool = False
    choices: tuple = ()


def space_texts(cfg: DictConfig, overrides=()) -> dict[str, str]:
    """The search space as text, key -> sweep: the study's ``hydra.sweeper.params``, then the sweep overrides of
    the command line (``'controller.kp=tag(log, interval(1, 20))'``), which the Optuna sweeper adds to them."""
    from hydra.core.override_parser.overrides_parser import OverridesParser

    texts = {str(k): str(v) for k, v in (cfg.hydra.sweeper.get("params") or {}).items()}
    for o in OverridesParser.create().parse_overrides([str(o) for o in overrides]):
        if o.is_sweep_override():
            texts[o.get_key_element().lstrip("+~")] = o.input_line.split("=", 1)[1]
    return texts


def search_space(cfg: DictConfig, overrides=()) -> list[Interval]:
    """The study's search space (:func:`space_texts`), checked: every key a key of the composed config, every
    interval finite with low < high (and low > 0 on a log scale). Raises ConfigError naming the key."""
    from hydra.core.override_parser.overrides_parser import OverridesParser
    from hydra.core.override_parser.types import ChoiceSweep, IntervalSweep
    from hydra.errors import HydraException

    params = space_texts(cfg, overrides)
    if not params:
        raise ConfigError("hydra.sweeper.params", None, "the study has no search space (conf/tune/<controller>.yaml)")
    parser = OverridesParser.create()
    space = []
    for key, text in params.items():
        where = key if key in overrides_keys(overrides) else f"hydra.sweeper.params.{key}"
        if OmegaConf.select(cfg, str(key), default=None) is None:
            raise ConfigError(where, text, f"{key} is not a key of the composed config")
        try:
            value = parser.parse_override(f"{key}={text}").value()
        except HydraException as exc:
            raise ConfigError(where, text, f"cannot parse ({str(exc).splitlines()[0]})") from None
        if isinstance(value, ChoiceSweep):
            if not value.list:
                raise ConfigError(where, text, "empty choice")
            space.append(Interval(str(key), choices=tuple(value.list)))
            continue
        if not isinstance(value, IntervalSweep):
            raise ConfigError(where, text, "must be interval(low, high), tag(log, interval(low, high)) or choice(...)")
        low, high, log_scale = float(value.start), float(value.end), "log" in value.tags
        if not (math.isfinite(low) and math.isfinite(high)):
            raise ConfigError(where, text, "the range must be finite")
        if not low < high:
            raise ConfigError(where, text, f"empty or inverted range: low {low:g} must be < high {high:g}")
        if log_scale and low <= 0.0:
            raise ConfigError(where, text, f"a log-scale range needs low > 0 (low {low:g})")
        space.append(Interval(str(key), low, high, log_scale))
    return space


def overrides_keys(overrides) -> set[str]:
    return {str(o).lstrip("+~").partition("=")[0] for o in overrides}


def check_study(cfg: DictConfig, overrides=()) -> list[Interval]:
    """Check a composed study config (with its ``hydra`` node): the tuning settings, the search space, and the
    config at its own (paper) gains. Returns the search space. Raises ConfigError naming the key."""
    from ddmr_cli.checks import finite
    from ddmr_cli.config import validate_config

    from ddmr_cli.compat import require_optuna

    require_optuna()
    t = cfg.tuning
    one_of("tuning.objective", t.objective, OBJECTIVES)
    integer("tuning.n_trials", t.n_trials, 1)
    integer("tuning.batch", t.batch, 1)
    integer("tuning.seed", t.seed, 0)
    limit = finite("tuning.saturation_limit", t.saturation_limit)
    if not 0.0 <= limit < 1.0:
        raise ConfigError("tuning.saturation_limit", limit, "must be >= 0 and < 1")
    if not t.scenarios:
        raise ConfigError("tuning.scenarios", {}, "at least one scenario")
    integer("tuning.held_out.base_seed", t.held_out.base_seed, 0)
    integer("tuning.held_out.n_runs", t.held_out.n_runs, 1)
    first, last = int(cfg.run.base_seed), int(cfg.run.base_seed) + int(cfg.run.n_runs) - 1
    h_first, h_last = int(t.held_out.base_seed), int(t.held_out.base_seed) + int(t.held_out.n_runs) - 1
    if h_first <= last and first <= h_last:
        raise ConfigError("tuning.held_out.base_seed", h_first, f"the held-out seeds {h_first}-{h_last} overlap the "
                                                                f"tuning seeds {first}-{last} (run.base_seed, run.n_runs)")
    settle, duration = float(cfg.metrics.settle_time), float(cfg.simulation.duration)
    if OBJECTIVE_METRIC.endswith(STEADY) and not settle < duration:
        raise ConfigError("metrics.settle_time", settle, f"must be < simulation.duration ({duration:g} s): the "
                                                         f"objective {OBJECTIVE_METRIC} counts the steps after it")
    space = search_space(cfg, overrides)
    _check_sampler(cfg)
    for name in t.scenarios:
        validate_config(scenario_config(cfg, name))
    return space


def _check_sampler(cfg: DictConfig) -> None:
    """The Optuna sampler the sweeper will instantiate exists (else Hydra fails after the sweep dir is made)."""
    import importlib

    sampler = cfg.hydra.sweeper.get("sampler") if "sweeper" in cfg.get("hydra", {}) else None
    target = sampler.get("_target_") if sampler is not None else None
    if target is None:
        return
    module, _, name = str(target).rpartition(".")
    try:
        if not isinstance(getattr(importlib.import_module(module), name), type):
            raise TypeError(target)
    except (ImportError, AttributeError, TypeError, ValueError):
        raise ConfigError("hydra.sweeper.sampler._target_", str(target), "no such Optuna sampler (e.g. "
                          "optuna.samplers.TPESampler, optuna.samplers.NSGAIISampler)") from None


def study_hash(cfg: DictConfig, overrides=()) -> str:
    """What a trial computes (the result config without the budget settings, plus the search space): a study
    may be resumed only with the same hash."""
    from ddmr_cli.config.build import result_config

    container = result_config(OmegaConf.masked_copy(cfg, [k for k in cfg if k != "hydra"]))
    for key in _BUDGET_KEYS:
        container.get("tuning", {}).pop(key, None)
    container["search_space"] = space_texts(cfg, overrides)
    text = json.dumps(container, sort_keys=True, default=str)
    return hashlib.sha256(text.encode()).hexdigest()[:16]


def storage_url(sweep_dir: Path) -> str:
    return f"sqlite:///{Path(sweep_dir) / STORAGE_FILE}"


def load_study(sweep_dir: Path, study_name: str):
    """The Optuna study stored in a sweep dir."""
    import optuna

    optuna.logging.set_verbosity(optuna.logging.WARNING)
    return optuna.load_study(study_name=study_name, storage=storage_url(sweep_dir))


def close_killed_trials(study) -> int:
    """Mark the trials a killed session left RUNNING as FAIL (user attribute ``killed``); returns how many."""
    from optuna.trial import TrialState

    from ddmr_cli.compat import mark_killed

    stale = study.get_trials(deepcopy=False, states=(TrialState.RUNNING,))
    for t in stale:
        mark_killed(study, t)
    return len(stale)


def trials_done(study) -> int:
    """Trials that count against the budget: every trial that returned its objective."""
    from optuna.trial import TrialState

    return sum(1 for t in study.get_trials(deepcopy=False) if t.state == TrialState.COMPLETE)


def prepare_study(cfg: DictConfig, overrides=()) -> Session:
    """Check a study before Hydra starts and plan this session (:class:`Session`: its overrides run the rest of
    the budget, ``hydra.sweeper.n_trials``, with the sampler seeded ``tuning.seed + trials done``).

    ``overrides``: the command line's (its sweep overrides extend the search space).
    Raises ConfigError on a bad setting, or when the sweep dir holds a study of another config."""
    check_study(cfg, overrides)
    sweep_dir = Path(str(cfg.hydra.sweep.dir))
    budget, seed = int(cfg.tuning.n_trials), int(cfg.tuning.seed)
    info = read_study_info(sweep_dir)
    digest = study_hash(cfg, overrides)
    if info is not None and info.get("hash") != digest:
        raise ConfigError("hydra.sweep.dir", str(sweep_dir), f"holds a study of another config (hash {info.get('hash')}"
                          f", this one {digest}); choose another hydra.sweep.dir or remove it")
    return plan_session(sweep_dir, str(cfg.hydra.sweeper.study_name), budget, seed)


class StorageError(OSError):
    """The study's storage file exists but cannot be read as an Optuna study database (a fault: exit 1)."""


@dataclass(frozen=True)
class Session:
    """A session of the Optuna study ``study_name`` stored in ``sweep_dir`` (none yet, or resumed), as planned
    before the sweep dir's lock is taken: read from the storage, nothing written (a second ``ddmr run`` on a dir in
    use is refused by the lock and must leave the running session's trials as they are). Shared by the gain tuning
    and the sensitivity study's calibration search (docs/model.md §9, "Storage and resumption"; §11)."""

    sweep_dir: Path
    study_name: str
    budget: int
    seed: int
    done: int = 0      # trials complete (:func:`trials_done`)
    stored: bool = False  # the storage holds the study

    @property
    def overrides(self) -> list[str]:
        """The Hydra overrides of the session: the rest of the budget (``hydra.sweeper.n_trials``) with the sampler
        seeded ``seed + trials done``."""
        return [f"hydra.sweeper.n_trials={max(0, self.budget - self.done)}",
                f"hydra.sweeper.sampler.seed={self.seed + self.done}"]

    def start(self) -> None:
        """Under the sweep dir's lock, just before Hydra starts: the trials a killed session left RUNNING marked
        failed, and the resumption said. A study whose trials changed since planning (a session that ended in
        between) is refused (exit 1: run the command again)."""
        if not self.stored:
            return
        study = load_study(self.sweep_dir, self.study_name)
        done = trials_done(study)
        if done != self.done:
            from ddmr_cli.storage.jobdir import FaultError

            raise FaultError(Path(self.sweep_dir) / STORAGE_FILE, f"the study's trials changed while this session was "
                             f"planned ({self.done} complete, now {done}); run the command again")
        killed = close_killed_trials(study)
        print(f"ddmr: resuming study {study.study_name}: {self.done}/{self.budget} trials done"
              + (f" ({killed} left running by a killed session marked failed)" if killed else ""), flush=True)


def plan_session(sweep_dir: Path, study_name: str, budget: int, seed: int) -> Session:
    """The :class:`Session` of the study ``study_name`` in ``sweep_dir`` (read only: see :class:`Session`)."""
    if not (Path(sweep_dir) / STORAGE_FILE).is_file():
        return Session(Path(sweep_dir), study_name, budget, seed)
    try:
        study = load_study(sweep_dir, study_name)
    except KeyError:  # a storage without this study
        return Session(Path(sweep_dir), study_name, budget, seed)
    except Exception as exc:  # SQLAlchemy/Optuna errors of a file that is not a readable study database
        raise StorageError(f"{Path(sweep_dir) / STORAGE_FILE}: not a readable Optuna study database "
                           f"({type(exc).__name__}); nothing was changed; move it away to start afresh") from None
    return Session(Path(sweep_dir), study_name, budget, seed, trials_done(study), stored=True)


# --- the study's files ----------------------------------------------------------------------------------------


def read_study_info(sweep_dir: Path) -> dict | None:
    """A study dir's ``tuning.json``, or None."""
    return io.read_json(Path(sweep_dir) / STUDY_FILE)


def _task_overrides(config: DictConfig) -> list[str]:
    from ddmr_cli.storage.sweep import is_hydra_override

    return [str(o) for o in config.hydra.overrides.task if not is_hydra_override(str(o))]


def trial_dirs(sweep_dir: Path) -> list[tuple[frozenset, Path, dict]]:
    """Every trial dir with a ``trial.json``: its job's overrides (the sampled gains and the fixed ones), dir, record."""
    out = []
    for path in sorted((Path(sweep_dir) / TRIALS_DIR).glob(f"*/{TRIAL_FILE}")):
        record = io.read_json(path)
        if record is not None:
            out.append((frozenset(record.get("overrides", [])), path.parent, record))
    return out


def trial_record(records, params: dict) -> tuple[Path | None, dict]:
    """The dir and record of the job the sweeper launched with these sampled values (its overrides hold them as
    the sweeper wrote them, ``key=repr(value)``)."""
    wanted = {f"{k}={v}" for k, v in params.items()}
    return next(((d, r) for overrides, d, r in records if wanted <= overrides), (None, {}))


def trials_table(sweep_dir: Path, study) -> "pd.DataFrame":
    """One row per Optuna trial: number, state, objective values, the sampled gains, and the trial's own record
    (feasible, violation and why, deviation, chattering, saturation, diverged runs, its dir)."""
    import pandas as pd

    from ddmr_cli.compat import KILLED_ATTR

    records = trial_dirs(sweep_dir)
    rows = []
    for t in study.get_trials(deepcopy=False):
        job_dir, rec = trial_record(records, t.params)
        row = {"number": t.number, "state": t.state.name, "killed": bool(t.user_attrs.get(KILLED_ATTR, False))}
        values = t.values or []
        row.update({f"value_{i}": v for i, v in enumerate(values)})
        row.update({k: v for k, v in t.params.items()})
        row.update({"feasible": rec.get("feasible"), "violation": rec.get("violation"), "reason": rec.get("reason"),
                    OBJECTIVE_METRIC: rec.get("deviation"), CHATTERING_METRIC: rec.get("chattering"),
                    SATURATION_METRIC: rec.get("saturation"), "runs": rec.get("runs"), "diverged": rec.get("diverged"),
                    "started": t.datetime_start.isoformat() if t.datetime_start else None,
                    "duration_s": t.duration.total_seconds() if t.duration else None,
                    "dir": job_dir.relative_to(sweep_dir).as_posix() if job_dir else None})
        rows.append(row)
    return pd.DataFrame(rows)


def best_trials(study) -> list:
    """The best trial (one objective) or the Pareto front (two), as Optuna reports them."""
    if len(study.directions) > 1:
        return list(study.best_trials)
    try:
        return [study.best_trial]
    except ValueError:  # no complete trial
        return []


def write_tables(sweep_dir: Path, study_name: str) -> dict:
    """Write ``tuning_trials.csv`` and ``best.yaml``; returns the best record."""
    study = load_study(sweep_dir, study_name)
    table = trials_table(sweep_dir, study)
    io.write_csv(Path(sweep_dir) / TRIALS_CSV, table)
    best = [{"number": t.number, "values": list(t.values), "params": dict(t.params)} for t in best_trials(study)]
    record = {"study": study_name, "trials_done": trials_done(study), "best": best}
    io.write_text(Path(sweep_dir) / BEST_FILE, OmegaConf.to_yaml(OmegaConf.create(record)))
    return record


def start_session(config: DictConfig) -> None:
    """A tuning study's session starts (:class:`ddmr_cli.cli.callbacks.StudyCallback`): records the study and its
    sessions (``tuning.json``) and creates the dir the SQLite storage lives in before the sweeper opens it."""
    logging.getLogger("alembic").setLevel(logging.WARNING)  # its plugin set-up lines when Optuna imports it
    import optuna

    optuna.logging.set_verbosity(optuna.logging.WARNING)
    sweep_dir = Path(str(config.hydra.sweep.dir))
    sweep_dir.mkdir(parents=True, exist_ok=True)
    info = read_study_info(sweep_dir) or {
        "study_name": str(config.hydra.sweeper.study_name), "controller": str(config.tuning.controller),
        "objective": str(config.tuning.objective), "hash": study_hash(config, config.hydra.overrides.task),
        "metric": OBJECTIVE_METRIC,
        "overrides": _task_overrides(config), "sessions": []}
    info["budget"] = int(config.tuning.n_trials)
    info["search_space"] = space_texts(config, config.hydra.overrides.task)
    info["sessions"].append({"started": time.time(), "n_trials": int(config.hydra.sweeper.n_trials),
                             "sampler_seed": config.hydra.sweeper.sampler.get("seed"),
                             "launcher": str(config.hydra.launcher.get("_target_", "")).rsplit(".", 1)[-1]})
    io.write_json(sweep_dir / STUDY_FILE, info)
    log.info("study %s: %d trials this session -> %s", info["study_name"], config.hydra.sweeper.n_trials, sweep_dir)


def end_session(config: DictConfig) -> None:
    """A tuning study's session ends: its wall time recorded, the study's tables written and its best printed."""
    sweep_dir = Path(str(config.hydra.sweep.dir))
    info = read_study_info(sweep_dir)
    if info and info["sessions"]:
        session = info["sessions"][-1]
        session["wall_time"] = time.time() - session["started"]
        io.write_json(sweep_dir / STUDY_FILE, info)
    record = write_tables(sweep_dir, str(config.hydra.sweeper.study_name))
    print(f"\nddmr study {record['study']}: {record['trials_done']}/{config.tuning.n_trials} trials -> {sweep_dir}")
    for b in record["best"]:
        gains = ", ".join(f"{k}={v:.4g}" for k, v in b["params"].items())
        print(f"  trial {b['number']}: {', '.join(f'{v:.6g}' for v in b['values'])}  {gains}")
    print(f"  tables: {TRIALS_CSV}, {BEST_FILE}; held-out evaluation and report: ddmr report {sweep_dir}")


def finish(sweep_dir: Path) -> int:
    """The exit status of a study session: 0 when the storage holds the whole budget of complete trials."""
    info = read_study_info(sweep_dir)
    if info is None or not (Path(sweep_dir) / STORAGE_FILE).is_file():
        return 1
    return 0 if trials_done(load_study(sweep_dir, info["study_name"])) >= int(info["budget"]) else 1


__all__ = ["OBJECTIVE_METRIC", "TrialOutcome", "evaluate_gains", "run_trial", "search_space", "check_study",
           "prepare_study", "Session", "plan_session", "study_hash", "load_study", "trials_table", "write_tables", "start_session", "end_session", "finish",
           "is_study", "scenario_config"]


# --- held-out evaluation at tuned gains (ddmr report on a study) ---------------------------------------------

HELD_OUT_DIR = "heldout"
GAINS = ("paper", "tuned")


@dataclass
class Study:
    """A study dir as the report reads it: ``tuning.json``, the Optuna study, its trials table."""

    dir: Path
    info: dict
    study: Any

    @property
    def controller(self) -> str:
        return str(self.info["controller"])

    @property
    def objective(self) -> str:
        return str(self.info["objective"])

    @property
    def overrides(self) -> list[str]:
        """The study's command-line overrides without its sweeps (what composes its config)."""
        from hydra.core.override_parser.overrides_parser import OverridesParser

        parsed = OverridesParser.create().parse_overrides(list(self.info["overrides"]))
        return [o.input_line for o in parsed if not o.is_sweep_override()]

    def best(self) -> list:
        return best_trials(self.study)

    def config(self, params: dict | None = None, extra=()) -> DictConfig:
        """The study's composed config, at ``params`` (e.g. a trial's gains) and ``extra`` overrides."""
        from ddmr_cli.config import compose_config

        return compose_config([*self.overrides, *(f"{k}={v!r}" for k, v in (params or {}).items()), *extra])


def find_studies(path: Path) -> list[Study]:
    """The studies in ``path``: the dir itself, or every dir below it with a ``tuning.json`` (sorted)."""
    path = Path(path)
    dirs = [path] if (path / STUDY_FILE).is_file() else sorted(
        p.parent for p in path.rglob(STUDY_FILE) if HELD_OUT_DIR not in p.relative_to(path).parts)
    studies = []
    for d in dirs:
        info = read_study_info(d)
        if info is None or not (d / STORAGE_FILE).is_file():
            continue
        studies.append(Study(d, info, load_study(d, info["study_name"])))
    return studies


def held_out_config(study: Study, scenario: str, gains: str) -> tuple[DictConfig, list[str]]:
    """The config of one held-out job: the study's config at its paper (``gains='paper'``) or best gains, on
    the held-out seeds, in one scenario of ``tuning.scenarios``; a plain job config (``tuning`` null)."""
    base = study.config()
    h = base.tuning.held_out
    extra = [f"run.base_seed={int(h.base_seed)}", f"run.n_runs={int(h.n_runs)}", f"run.keep_series=[{int(h.base_seed)}]",
             "run.plots=false", "run.progress=false"]
    params = dict(study.best()[0].params) if gains == "tuned" else {}
    cfg = scenario_config(study.config(params, extra), scenario)
    with read_write(cfg), open_dict(cfg):
        cfg.tuning = None
    overrides = [*study.overrides, *(f"{k}={v!r}" for k, v in params.items()), *extra, f"scenario={scenario}"]
    return cfg, overrides


def run_held_out(studies: list[Study], root: Path) -> Path:
    """Run every single-objective study's controller at its paper and its tuned gains on the held-out seeds in
    every scenario: standard job dirs ``<root>/heldout/<gains>/<controller>-<scenario>`` (complete jobs with the
    same config hash are kept). Returns ``<root>/heldout``. Raises ConfigError when two studies tune the same
    controller."""
    from ddmr_cli.job import JobPlace, execute
    from ddmr_cli.config import config_hash, validate_config

    single = [s for s in studies if s.objective == "deviation" and s.best()]
    seen: dict[str, Path] = {}
    for s in single:
        if s.controller in seen:
            raise ConfigError("path", str(root), f"two studies tune {s.controller} ({seen[s.controller]}, {s.dir}); "
                                                 f"report one of them")
        seen[s.controller] = s.dir
    out_root = Path(root) / HELD_OUT_DIR
    for s in single:
        for gains in GAINS:
            for scenario in s.config().tuning.scenarios:
                cfg, overrides = held_out_config(s, str(scenario), gains)
                out = out_root / gains / f"{s.controller}-{scenario}"
                digest = config_hash(cfg)
                previous = io.read_summary(out)
                if previous and previous.get("status") == "complete" and previous.get("config_hash") == digest:
                    continue
                print(f"ddmr: held-out {s.controller} at {gains} gains, {scenario}: seeds "
                      f"{int(cfg.run.base_seed)}-{int(cfg.run.base_seed) + int(cfg.run.n_runs) - 1}", flush=True)
                execute(cfg, JobPlace(out, tuple(overrides)), digest, validate_config(cfg))
    return out_root
