"""A sweep's plan: the jobs Hydra's sweeper will launch, each with its overrides and its job dir (Hydra glue).

The same function computes the plan for the CLI's validation before launching and for the sweep's
``sweep_plan.json`` (:class:`ddmr_cli.cli.callbacks.SweepAggregator`), from the sweep's task overrides and
``hydra.sweeper.params``.
"""

from __future__ import annotations

from typing import Any, Callable, Iterable

from omegaconf import DictConfig

from ddmr_cli.storage.sweep import is_hydra_override

def expand_jobs(overrides: Iterable[str], sweeper_params: dict[str, Any]) -> list[list[str]]:
    """The job override lists Hydra's basic sweeper will launch (sweeper params first, then the command line);
    ``hydra.*`` overrides are not part of a job's overrides (Hydra keeps them apart) and are left out."""
    from hydra.core.override_parser.overrides_parser import OverridesParser

    from ddmr_cli.compat import split_sweep

    params = [f"{k}={v}" for k, v in sweeper_params.items()] + [o for o in overrides if not is_hydra_override(o)]
    parsed = OverridesParser.create().parse_overrides(params)
    return split_sweep(parsed)


def job_dirname(job_overrides: list[str], exclude_keys, item_sep: str = ",", kv_sep: str = "=",
                parse: Callable[[list[str]], list] | None = None) -> str:
    """Hydra's ``hydra.job.override_dirname`` of a job's overrides (made safe by the ``ddmr.jobdir`` resolver of
    the default ``hydra.sweep.subdir``, :func:`ddmr_cli.storage.jobdir.safe_name`); ``parse``: Hydra's override
    parser, or one that remembers the lines it parsed (:class:`~ddmr_cli.config.compose_once.OverrideParser`)."""
    from hydra.core.override_parser.overrides_parser import OverridesParser

    from ddmr_cli.compat import overrides_dirname

    parsed = (parse or OverridesParser.create().parse_overrides)(list(job_overrides))
    return overrides_dirname(parsed, exclude_keys, item_sep, kv_sep)


def _subdir(scratch: DictConfig, dirname: str, num: int) -> str:
    """A job's ``hydra.sweep.subdir`` as Hydra will resolve it in the job (override_dirname and num set), on
    ``scratch``, a plain copy of the sweep's config whose ``hydra.job`` this sets."""
    from omegaconf import OmegaConf

    from ddmr_cli.storage.jobdir import safe_name

    scratch.hydra.job.override_dirname, scratch.hydra.job.num, scratch.hydra.job.id = dirname, num, str(num)
    try:
        return str(OmegaConf.select(scratch, "hydra.sweep.subdir", throw_on_missing=True))
    except Exception:  # noqa: BLE001  (an interpolation only Hydra's job runtime can resolve)
        return safe_name(dirname)


def plan_jobs(overrides: Iterable[str], cfg: DictConfig) -> list[dict]:
    """The planned jobs of a sweep, ``[{"dir": ..., "overrides": [...]}, ...]``, from its overrides and the
    composed config (its ``hydra`` node: sweeper params, override_dirname settings, ``hydra.sweep.subdir``).
    ``cfg`` may also be the ``hydra`` node alone."""
    from omegaconf import OmegaConf

    root = cfg if "hydra" in cfg else OmegaConf.create({"hydra": OmegaConf.to_container(cfg, resolve=False)})
    hydra_cfg = root.hydra
    od = hydra_cfg.job.config.override_dirname
    jobs = expand_jobs(overrides, dict(hydra_cfg.sweeper.get("params") or {}))
    scratch = OmegaConf.create(OmegaConf.to_container(root, resolve=False))  # one copy for every job's subdir
    if "job" not in scratch.hydra:
        scratch.hydra.job = {}
    from ddmr_cli.config.compose_once import OverrideParser

    parse = OverrideParser().parse  # a sweep's jobs share most override lines: each is parsed once
    return [{"dir": _subdir(scratch, job_dirname(job, od.exclude_keys, od.item_sep, od.kv_sep, parse), num),
             "overrides": job} for num, job in enumerate(jobs)]


def shared_dir(plan: list[dict]) -> tuple[dict, dict] | None:
    """The first two planned jobs that would write into one dir, or None."""
    seen: dict[str, dict] = {}
    for job in plan:
        if job["dir"] in seen:
            return seen[job["dir"]], job
        seen[job["dir"]] = job
    return None


__all__ = ["expand_jobs", "is_hydra_override", "job_dirname", "plan_jobs", "shared_dir"]
