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
        return self.basic.sweep(arguments)
