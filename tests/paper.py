"""The packaged config's values (conf/, the one place defaults live) as model objects for tests, with chosen
values replaced: ``make_smc(lam=10.0)`` is conf/controller/smc.yaml with lambda = 10."""

from __future__ import annotations

import dataclasses

from omegaconf import OmegaConf

from ddmr_cli import (PID, SMC, NonlinearDisturbanceObserver, RBFNetworkObserver, Terrain, paper_config, paper_robot,
                      paper_simulation)


def _values(option: str, node: str = "controller") -> dict:
    values = OmegaConf.to_container(paper_config(option)[node], resolve=True)
    values.pop("_target_", None)
    values.pop("display", None)  # the report's label and style, not a constructor argument
    return values


def make_smc(**values) -> SMC:
    """conf/controller/smc.yaml (no observers) with ``values`` replaced (``ndo=``, ``nn=`` take objects)."""
    return SMC(**{**_values("controller=smc"), **values})


def make_pid(**values) -> PID:
    return PID(**{**_values("controller=pid"), **values})


def make_ndo(**values) -> NonlinearDisturbanceObserver:
    return NonlinearDisturbanceObserver(**{**_values("controller=smc_ndo")["ndo"], **values})


def make_rbf(**values) -> RBFNetworkObserver:
    nn = _values("controller=smc_ndo_nno")["nn"]
    nn.pop("_target_", None)
    return RBFNetworkObserver(**{**nn, **values})


def make_robot(**values):
    """conf/robot/paper.yaml with ``values`` replaced."""
    return dataclasses.replace(paper_robot(), **values)


def make_simulation(**fields):
    """The packaged config on flat ground without roughness or rolling resistance (terrain=none), scenario 1,
    with ``fields`` of the Simulation replaced."""
    return paper_simulation("terrain=none", **fields)


def make_terrain(*zones, correlation_time: float | None = None):
    """A Terrain of ``zones`` with the packaged paper terrain's correlation time unless given."""
    tc = paper_config().terrain.correlation_time if correlation_time is None else correlation_time
    return Terrain(zones=zones, correlation_time=tc)
