"""What every wheel-speed controller is: a Python object holding its parameters, and a module of laws.

The engine (:mod:`ddmr_cli.engine.stepper`) runs a controller through three laws that its module defines, per
run and step, on both wheels (right, left):

``start(p, st, w0_R, w0_L)``
    Set the run's state record ``st`` at the first step, given the initial wheel speeds [rad/s].
``command(p, st, k, w_R, w_L, wd_R, wd_L, wdd_R, wdd_L)``
    At step ``k``, from the wheel speeds ``w``, their references ``w_d`` and ``w_d'``, return
    ``(u_R, u_L, s_R, s_L, dndo_R, dndo_L, dnn_R, dnn_L)``: the unsaturated voltage [V], the sliding variable
    (the speed error for controllers without a surface) [rad/s] and the disturbance estimates [rad/s^2] of an
    NDO-like observer and of a learning observer (0 where the controller has none).
``update(p, st, w_R, w_L, wd_R, wd_L, u_R, u_L, uc_R, uc_L, sat_R, sat_L)``
    Advance the state by one step, given the applied voltage ``u``, the command ``uc`` and whether each wheel
    saturated.

The laws run at the control instants (every plant step unless ``control.rate`` is set; docs/model.md §10) on the
measured wheel speeds, so their ``dt`` is the control period. ``p`` is the named tuple
:meth:`WheelController.law_parameters` returns and ``st`` one record of the structured
array whose fields :meth:`WheelController.state_fields` lists. Adding a controller is one module with a
subclass and its three laws, plus a YAML file in ``conf/controller`` (see docs/extending.md): the engine,
the compile cache, determinism and validation come with it.
"""

from __future__ import annotations

from types import ModuleType
from typing import Any, NamedTuple, Sequence

import numpy as np

from ddmr_cli.errors import ConfigError
from ddmr_cli.model.robot import NominalModel

#: Largest stable ``dt * rate`` of a first-order mode under the plant's integrator (explicit Euler: 2, RK4: 2.78)
STABILITY_LIMIT = {"euler": 2.0, "rk4": 2.78}


class StepRate(NamedTuple):
    """A first-order rate [1/s] the step ``dt`` must resolve, and what it is (for the error message)."""

    what: str
    rate: float


class WheelController:
    """Base class of the wheel-speed controllers (docs/model.md §6).

    Subclasses set :attr:`laws` to the module that defines their ``start``, ``command`` and ``update`` laws,
    and implement :meth:`law_parameters`, :meth:`state_fields` and :meth:`parameters`. Their constructors check
    every value (raising :class:`~ddmr_cli.errors.ConfigError` with the config key), and :meth:`check_step`
    refuses a step ``dt`` at which their own sampled loops are unstable.
    """

    #: short name used in tables and plots
    name: str = "controller"
    #: the module whose laws the engine runs for this controller
    laws: ModuleType

    def law_parameters(self, nominal: NominalModel, dt: float) -> NamedTuple:
        """The parameters as the laws take them (a named tuple of numbers, tuples and arrays)."""
        raise NotImplementedError

    def state_fields(self) -> list[tuple]:
        """The fields of one run's state record (a numpy structured dtype's field list)."""
        return [("unused", "f8")]

    def parameters(self) -> dict[str, object]:
        """The controller's parameters, for the report's Table 3."""
        return {}

    def estimators(self) -> tuple[str, ...]:
        """The disturbance estimators whose estimate of d the controller reports: its NDO and NN observers when it
        has them (the ``ndo`` and ``nn`` attributes), none by default. Without one, d-hat is 0 and the estimation
        MAE is only the mean |d|: the report leaves it out."""
        return tuple(name for name, observer in (("NDO", getattr(self, "ndo", None)), ("NN", getattr(self, "nn", None)))
                     if observer is not None)

    def step_rates(self, nominal: NominalModel) -> list[StepRate]:
        """First-order rates of the controller's own loops that ``dt * rate`` must keep below the
        integrator's stability limit (see :meth:`check_step`)."""
        return []

    def check_step(self, nominal: NominalModel, dt: float, integrator: str) -> None:
        """Raise ConfigError on ``simulation.dt`` when a loop of this controller is unstable at ``dt``."""
        limit = STABILITY_LIMIT[integrator]
        for what, rate in self.step_rates(nominal):
            if dt * rate >= limit:
                raise ConfigError("simulation.dt", dt,
                                  f"must be < {limit / rate:.3g} s for {integrator} with {what} = {rate:.3g} 1/s")

    def initial_state(self, n_runs: int) -> np.ndarray:
        """A zeroed state record per run (``start`` sets the initial values at the first step)."""
        return np.zeros(n_runs, dtype=np.dtype(self.state_fields()))


__all__ = ["WheelController", "StepRate", "STABILITY_LIMIT"]
