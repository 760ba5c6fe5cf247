"""``hydra/sweeper=ddmr`` (ddmr's default): Hydra's basic sweeper, whose jobs compose from one composition per set
of group choices instead of two full compositions each (one to validate the job, one in the launcher).

The sweep itself (the cartesian product, batches, ``hydra.sweeper.params``) and every launcher (joblib,
submitit, Ray) are Hydra's; the only change is the config loader handed to them,
:class:`ddmr_cli.config.compose_once.SweepConfigLoader`, which gives the same configs. It lives in
``hydra_plugins`` because Hydra instantiates sweepers only from there; ``ddmr run`` registers it explicitly
(``Plugins.register``), since Hydra's plugin scan does not see packages of an editable install.
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import Dict, Optional

from hydra.core.config_store import ConfigStore
from hydra.plugins.sweeper import Sweeper
from hydra.types import HydraContext, TaskFunction
from omegaconf import DictConfig


@dataclass
class DdmrSweeperConf:
    _target_: str = "hydra_plugins.ddmr_sweeper.ddmr_sweeper.DdmrSweeper"
    max_batch_size: Optional[int] = None
    params: Optional[Dict[str, str]] = None


ConfigStore.instance().store(group="hydra/sweeper", name="ddmr", node=DdmrSweeperConf, provider="ddmr")


class DdmrSweeper(Sweeper):
    """Hydra's :class:`BasicSweeper` with :class:`~ddmr_cli.config.compose_once.SweepConfigLoader`.

    It wraps a basic sweeper rather than subclassing it: Hydra's plugin scan re-executes the module of its core
    plugins, so the class ``BasicSweeper`` names inside its own methods is not the one a subclass was made from."""

    def __init__(self, max_batch_size: Optional[int] = None, params: Optional[Dict[str, str]] = None) -> None:
        from ddmr_cli.compat import basic_sweeper

        super().__init__()
        self.basic = basic_sweeper(max_batch_size, params)

    def setup(self, *, hydra_context: HydraContext, task_function: TaskFunction, config: DictConfig) -> None:
        from ddmr_cli.config.compose_once import SweepConfigLoader

        context = HydraContext(config_loader=SweepConfigLoader(hydra_context.config_loader),
                               callbacks=hydra_context.callbacks)
        self.basic.setup(hydra_context=context, task_function=task_function, config=config)

    def sweep(self, arguments: list[str]):
        """Hydra's basic sweep. Its check that each batch's jobs compose (``validate_batch_is_legal``: a composition
        per job, before the batch is launched; 200 one-seed jobs waited 0.6 s for it) composes, of the jobs ddmr's
        plan composed and validated in this process (:func:`ddmr_cli.config.compose_once.validated_jobs`: ``ddmr run
        -m`` validates every job before launching), only the first of each set of group choices: that composition
        is the skeleton the launcher's workers derive the set's jobs from (they would compose it again each
        otherwise), and it is what leaves Hydra's config store holding the launcher's config class that its module
        now defines, which loky pickles by reference (checking no job at all, a joblib sweep failed: "Can't pickle
        JobLibLauncherConf: it's not the same object"). A job ddmr did not validate is checked as Hydra checks it."""
        from ddmr_cli.config.compose_once import validated_jobs

        validated, check = validated_jobs(), self.basic.validate_batch_is_legal
        loader, master, seen = self.basic.hydra_context.config_loader, self.basic.config, set()

        def first_of_its_skeleton(job) -> bool:  # a job composed in full (no skeleton) counts as a first
            skeleton = loader.skeleton_of(master, list(job))
            if skeleton in seen:
                return False
            if skeleton is not None:
                seen.add(skeleton)
            return True

        def validate_batch_is_legal(batch) -> None:
            check([job for job in batch if tuple(job) not in validated or first_of_its_skeleton(job)])

        self.basic.validate_batch_is_legal = validate_batch_is_legal
        return self.basic.sweep(arguments)
