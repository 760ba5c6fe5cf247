"""The calibration search of the sensitivity study through ddmr's Optuna sweeper (docs/model.md §11, stage
``calibration``): the reading of the box nearest the paper's Table 4.

``ddmr run -m +experiment=sensitivity_calibration`` runs ddmr's Optuna sweeper with a seeded TPE sampler, as the
gain tuning does (docs/model.md §9; :mod:`ddmr_cli.study.tuning`): the sweeper asks ``study.calibration.batch``
trials at a time, :func:`suggest_reading` (the sweeper's ``custom_search_space``) draws each trial's reading from
the box (``+study.reading.<parameter>=value``: log axes log-uniform, choices categorical, ``study.vary``
respected), the configured launcher runs each trial as one study job (:func:`ddmr_cli.study.task.execute_study`:
4 controllers x 2 scenarios x ``run.n_runs`` seeds, the same row of ``study.csv`` as any sample) and the job
returns :func:`objective` of its row to the sweeper. Nothing here loops over trials: the sweeper does.

Before Hydra starts, :func:`prepare_search` checks the settings (one-line ConfigError, exit 2), refuses a sweep
dir holding a search of another config, and plans the session (the rest of the budget, the sampler seeded
``seed + trials done``: :class:`ddmr_cli.study.tuning.Session`). When a search starts from scratch,
:func:`warm_start` enqueues the ``study.calibration.warm_start`` best readings of a Latin-hypercube stage's
``study.csv`` (``study.calibration.warm_start_from``; ``ddmr sensitivity`` passes its ``lhs`` stage's), so the
search begins where the uniform sample ended and the two are compared on the same seeds.
"""

from __future__ import annotations

import hashlib
import json
import math
import time
from pathlib import Path
from typing import TYPE_CHECKING, Any, Mapping

import numpy as np
from omegaconf import DictConfig, OmegaConf

from ddmr_cli.storage import io
from ddmr_cli.study import claims as claim_stats
from ddmr_cli.study.space import READING, reading_of, Box
from ddmr_cli.study.stages import STAGES

if TYPE_CHECKING:
    import pandas as pd

    from ddmr_cli.study.tuning import Session

STAGE = "calibration"
#: a trial's sampled value of parameter p is the Hydra override ``+study.reading.<p>=value``
PREFIX = f"+{READING}."
SEARCH_FILE = "search.json"
#: settings that do not change what a trial computes: a search may be resumed with other values
BUDGET_KEYS = ("trials", "batch", "seed", "warm_start", "warm_start_from")
#: study settings of the other stages (their sizes, SALib's seed, the named readings): not the search's
OTHER_STAGES = tuple(s for s in STAGES if s != STAGE) + ("calibrated", "sampler_seed", "chunk")
#: largest |log(ours / paper)| a number counts with in the objective (a factor 100); a missing number counts it
LOG_CAP = math.log(100.0)


def is_search(cfg: DictConfig) -> bool:
    """True when the composed config is the calibration search (``+experiment=sensitivity_calibration``)."""
    study = cfg.get("study")
    return study is not None and str(study.get("stage")) == STAGE


def search_names(study: DictConfig) -> list[str]:
    """The parameters the search varies: the box's global ones (``study.vary`` restricts them)."""
    box = Box.from_config(study)
    vary = study.get("vary")
    return box.restricted(None if vary is None else [str(n) for n in vary]).global_names()


def suggest_reading(cfg: DictConfig, trial) -> None:
    """The Optuna sweeper's ``custom_search_space``: one value per searched parameter on the trial, named as the
    override that sets it (:data:`PREFIX`): ``suggest_float`` on the parameter's axis (log or linear; integers
    ``suggest_int``), ``suggest_categorical`` for a choice."""
    box = Box.from_config(cfg.study)
    for name in search_names(cfg.study):
        p = box[name]
        key = PREFIX + name
        if p.is_choice:
            trial.suggest_categorical(key, list(p.options))
        elif p.integer:
            trial.suggest_int(key, int(math.ceil(p.low)), int(math.floor(p.high)), log=p.scale == "log")
        else:
            trial.suggest_float(key, float(p.low), float(p.high), log=p.scale == "log")


#: weights of the objective's two terms (docs/model.md §11): Table 4's 16 means, and its 4 across-seed SDs, which
#: no reading of the box reaches (the paper's 0.2-4.5 mm against our 0.7-1 mm: the model's seeds vary less than
#: the paper's runs did); with weight 0 the SDs are reported beside the fit but do not steer it
MEAN_WEIGHT, SD_WEIGHT = 1.0, 0.0


def _capped_log_ratios(row: Mapping[str, Any]) -> dict[str, float]:
    paper = claim_stats.paper_table4()
    ours = {k: float(row.get(k, math.nan)) for k in paper}
    r = claim_stats.log_residuals(ours)
    return {k: float(np.clip(v, -LOG_CAP, LOG_CAP)) if np.isfinite(v) else LOG_CAP for k, v in r.items()}


def objective_terms(row: Mapping[str, Any]) -> dict[str, float]:
    """The objective's two terms: the RMS of the capped log ratios over Table 4's means, and over its SDs."""
    r = _capped_log_ratios(row)
    sds = np.array([v for k, v in r.items() if k.endswith(":deviation_sd")])
    means = np.array([v for k, v in r.items() if not k.endswith(":deviation_sd")])
    return {"means": float(np.sqrt(np.mean(means ** 2))), "sds": float(np.sqrt(np.mean(sds ** 2)))}


def objective(row: Mapping[str, Any]) -> float:
    """What a trial returns to the sweeper: ``sqrt(w_m T_m^2 + w_s T_s^2) / sqrt(w_m + w_s)``, ``T_m`` and ``T_s``
    the RMS of ``log(ours / paper)`` over Table 4's 16 means and its 4 SDs (:func:`objective_terms`), weights
    :data:`MEAN_WEIGHT` and :data:`SD_WEIGHT` (the SDs reported, not fitted); each log ratio capped at
    +-:data:`LOG_CAP` and a missing number (a failed sample, every run diverged) counted at the cap, so it is never
    NaN; a failed trial scores the largest value, :data:`LOG_CAP`."""
    t = objective_terms(row)
    return float(math.sqrt((MEAN_WEIGHT * t["means"] ** 2 + SD_WEIGHT * t["sds"] ** 2) / (MEAN_WEIGHT + SD_WEIGHT)))


def objective_of(summary: Mapping[str, Any]) -> float:
    """A trial job's objective from its summary (a failed job, without one: :data:`LOG_CAP`)."""
    value = summary.get("objective")
    return float(value) if value is not None and math.isfinite(float(value)) else LOG_CAP


# --- before Hydra starts --------------------------------------------------------------------------------------


def search_hash(cfg: DictConfig) -> str:
    """What a trial computes: the result config without the hydra node, the search budget, the reading and the
    other stages' settings."""
    from ddmr_cli.config.build import result_config

    container = result_config(OmegaConf.masked_copy(cfg, [k for k in cfg if k != "hydra"]))
    study = container.get("study") or {}
    for key in ("reading", *OTHER_STAGES):
        study.pop(key, None)
    for key in BUDGET_KEYS:
        (study.get("calibration") or {}).pop(key, None)
    return hashlib.sha256(json.dumps(container, sort_keys=True, default=str).encode()).hexdigest()[:16]


def check_search(cfg: DictConfig) -> None:
    """The search settings and the box; raises ConfigError naming the key."""
    from ddmr_cli.checks import integer
    from ddmr_cli.errors import ConfigError

    from ddmr_cli.compat import require_optuna

    require_optuna()
    c = cfg.study.calibration
    integer("study.calibration.trials", c.trials, 1)
    integer("study.calibration.batch", c.batch, 1)
    integer("study.calibration.seed", c.seed, 0)
    integer("study.calibration.warm_start", c.warm_start, 0)
    source = c.get("warm_start_from")
    if source is not None and int(c.warm_start) > 0 and not Path(str(source)).is_file():
        raise ConfigError("study.calibration.warm_start_from", source, "no such file (a lhs stage's study.csv)")
    if int(cfg.study.get("chunks", 1)) != 1:
        raise ConfigError("study.chunks", cfg.study.chunks, "must be 1 in the calibration search (a trial is one "
                                                            "reading; hydra.sweeper.n_jobs runs trials at once)")
    if not search_names(cfg.study):
        raise ConfigError("study.vary", OmegaConf.to_container(cfg.study.vary), "no global parameter to search")
    reading_of(cfg.study, Box.from_config(cfg.study))


def prepare_search(cfg: DictConfig) -> "Session":
    """Check a search before Hydra starts and plan this session (:class:`ddmr_cli.study.tuning.Session`: its
    overrides run the rest of the budget with the sampler seeded ``study.calibration.seed + trials done``).
    Raises ConfigError on a bad setting, or when the sweep dir holds a search of another config."""
    from ddmr_cli.config import validate_config
    from ddmr_cli.study.tuning import plan_session
    from ddmr_cli.errors import ConfigError
    from ddmr_cli.study.setup import study_setup

    check_search(cfg)
    study_setup(cfg)  # every parameter a key of a study config
    validate_config(cfg)
    sweep_dir = Path(str(cfg.hydra.sweep.dir))
    info = io.read_json(sweep_dir / SEARCH_FILE)
    digest = search_hash(cfg)
    if info is not None and info.get("hash") != digest:
        raise ConfigError("hydra.sweep.dir", str(sweep_dir), f"holds a calibration search of another config (hash "
                          f"{info.get('hash')}, this one {digest}); choose another dir or remove it")
    c = cfg.study.calibration
    return plan_session(sweep_dir, str(cfg.hydra.sweeper.study_name), int(c.trials), int(c.seed))


# --- the session ----------------------------------------------------------------------------------------------


def warm_readings(rows: "pd.DataFrame", names: list[str], k: int) -> list[dict[str, Any]]:
    """The ``k`` readings of a study table with the smallest objective (ties: the earlier sample), restricted to
    the searched parameters: the first trials of a new search."""
    if k <= 0 or rows.empty or "distance" not in rows:
        return []
    scored = rows.assign(_objective=[objective(r) for r in rows.to_dict("records")])
    best = scored.sort_values(["_objective", "sample"], kind="mergesort").head(k)
    return [{n: _plain(r[n]) for n in names} for r in best.to_dict("records")]


def _plain(value):
    if isinstance(value, np.integer):
        return int(value)
    if isinstance(value, np.floating):
        return float(value)
    return value


def start_session(config: DictConfig) -> None:
    """At the start of a session (the stage callback, inside the sweep dir's lock, before the sweeper opens the
    storage): the dir, ``search.json`` (what the search is, its sessions), and for a new search the warm start
    enqueued in the storage."""
    import logging

    logging.getLogger("alembic").setLevel(logging.WARNING)
    import optuna

    optuna.logging.set_verbosity(optuna.logging.WARNING)
    sweep_dir = Path(str(config.hydra.sweep.dir))
    sweep_dir.mkdir(parents=True, exist_ok=True)
    c = config.study.calibration
    name = str(config.hydra.sweeper.study_name)
    study = optuna.create_study(study_name=name, storage=str(config.hydra.sweeper.storage), direction="minimize",
                                load_if_exists=True)
    info = io.read_json(sweep_dir / SEARCH_FILE) or {"study_name": name, "hash": search_hash(config),
                                                   "parameters": search_names(config.study), "warm_start": [],
                                                   "sessions": []}
    if not study.get_trials(deepcopy=False) and int(c.warm_start) > 0 and c.get("warm_start_from"):
        import pandas as pd

        rows = pd.read_csv(str(c.warm_start_from))
        readings = warm_readings(rows, info["parameters"], int(c.warm_start))
        for reading in readings:
            study.enqueue_trial({PREFIX + n: v for n, v in reading.items()})
        info["warm_start"] = [{"source": str(c.warm_start_from), "reading": r} for r in readings]
    info["budget"] = int(c.trials)
    info["sessions"].append({"started": time.time(), "n_trials": int(config.hydra.sweeper.n_trials),
                             "sampler_seed": config.hydra.sweeper.sampler.get("seed"), "batch": int(c.batch),
                             "launcher": str(config.hydra.launcher.get("_target_", "")).rsplit(".", 1)[-1]})
    io.write_json(sweep_dir / SEARCH_FILE, info)


def end_session(sweep_dir: Path) -> None:
    info = io.read_json(Path(sweep_dir) / SEARCH_FILE)
    if info and info["sessions"]:
        info["sessions"][-1]["wall_time"] = time.time() - info["sessions"][-1]["started"]
        io.write_json(Path(sweep_dir) / SEARCH_FILE, info)


def trial_rows(sweep_dir: Path, rows: "pd.DataFrame", complete) -> "pd.DataFrame":
    """The study table of a search: each complete Optuna trial's row (found by its sampled overrides among the
    complete jobs ``complete``, ``[(dir, summary)]``), ``sample`` = the trial number, ``objective`` = what the
    sweeper was told, ``warm_start`` = 1 for an enqueued trial; in trial order. Job dirs of no trial are left out."""
    import pandas as pd

    from ddmr_cli.study.tuning import load_study, trial_record

    info = io.read_json(Path(sweep_dir) / SEARCH_FILE)
    if info is None or rows.empty:
        return rows.iloc[:0]
    from optuna.trial import TrialState

    from ddmr_cli.compat import was_enqueued

    records = [(frozenset(s.get("overrides", [])), d, s) for d, s in complete]
    out = []
    for t in load_study(sweep_dir, info["study_name"]).get_trials(deepcopy=False):
        if t.state != TrialState.COMPLETE:
            continue
        job_dir, _ = trial_record(records, t.params)
        if job_dir is None:
            continue
        row = rows[rows["job"] == job_dir.name]
        if row.empty:
            continue
        row = row.iloc[[0]].copy()
        row["sample"] = t.number
        row["objective"] = float(t.values[0])
        row["warm_start"] = int(was_enqueued(t))
        out.append(row)
    return pd.concat(out, ignore_index=True) if out else rows.iloc[:0]


def finish(sweep_dir: Path) -> int:
    """The exit status of a search session: 0 when the storage holds the whole budget of complete trials, every
    trial job is complete and the study table is written."""
    from ddmr_cli.storage.sweep import read_state
    from ddmr_cli.study.tuning import STORAGE_FILE, load_study, trials_done
    from ddmr_cli.study.setup import STUDY_CSV

    sweep_dir = Path(sweep_dir)
    info = io.read_json(sweep_dir / SEARCH_FILE)
    if info is None or not (sweep_dir / STORAGE_FILE).is_file() or not (sweep_dir / STUDY_CSV).is_file():
        return 1
    if read_state(sweep_dir).failed:
        return 1
    return 0 if trials_done(load_study(sweep_dir, info["study_name"])) >= int(info["budget"]) else 1


__all__ = ["is_search", "search_names", "suggest_reading", "reading_of", "objective", "objective_of",
           "prepare_search", "check_search", "search_hash", "warm_readings", "start_session", "end_session",
           "trial_rows", "finish", "STAGE", "PREFIX", "SEARCH_FILE", "LOG_CAP"]
