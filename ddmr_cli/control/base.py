"""What every wheel-speed controller is: a Python object holding its parameters, and a module of laws.

The engine (:mod:`ddmr_cli.engine.stepper`) runs a controller through the laws that its module defines, per
run and step, on both wheels (right, left):

``start(p, st, w0_R, w0_L)``
    Set the run's state record ``st`` at the first step, given the initial wheel speeds [rad/s].
``command(p, st, k, w_R, w_L, wd_R, wd_L, wdd_R, wdd_L)``
    At step ``k``, from the wheel speeds ``w``, their references ``w_d`` and ``w_d'``, return the unsaturated
    voltages ``(u_R, u_L)`` [V], and write the controller's diagnostic channels into ``st["diagnostics"]``.
``estimates(p, st, w_R, w_L, u_R, u_L)`` (optional)
    Given the applied voltage ``u`` (after the driver's limit and PWM), write the estimate channels that depend
    on it (ADRC's ESO); a controller without it keeps what ``command`` wrote.
``update(p, st, w_R, w_L, wd_R, wd_L, u_R, u_L, uc_R, uc_L, sat_R, sat_L)``
    Advance the state by one step, given the applied voltage ``u``, the command ``uc`` and whether each wheel
    saturated.

Diagnostic channels. A controller declares what it reports besides ``u`` (:meth:`WheelController.diagnostics`):
a tuple of :class:`Diagnostic` (a name, a kind and a description). Row ``c`` of the ``(n, 2)`` array
``st["diagnostics"]`` (the engine adds the field to the controller's state record) holds channel ``c``'s value
for the right and left wheel, written by the laws at every control instant and held in between. The engine
records, bands and sums the channels by kind, never by name (docs/model.md §6, "The controller contract"):

``SURFACE``
    The sliding variable (or, for a controller without a surface, the speed error ``w_d - w``) [rad/s]; at most
    one. Recorded as ``s_right``/``s_left``, banded, and its mean ``|s|`` is the metric ``s_mae``.
``ESTIMATE``
    An estimate of the lumped disturbance d of (8) [rad/s^2] (an NDO, a learning observer, an ESO). Recorded as
    ``d_hat_<name>_right``/``_left``; the estimation metrics compare the true d with the sum of a set of them
    (:data:`ddmr_cli.engine.metrics.ESTIMATION_METRICS`).
``SIGNAL``
    Anything else worth a look (an adapted gain): recorded as ``<name>_right``/``_left`` only.

The laws run at the control instants (every plant step unless ``control.rate`` is set; docs/model.md §10) on the
measured wheel speeds, so their ``dt`` is the control period. ``p`` is the named tuple
:meth:`WheelController.law_parameters` returns and ``st`` one record of the structured
array whose fields :meth:`WheelController.state_fields` lists. Adding a controller is one module with a
subclass and its laws, plus a YAML file in ``conf/controller`` (see docs/extending.md): the engine,
the compile cache, determinism and validation come with it.

Lanes (optional). A controller whose module also defines the four laws below runs by blocks of runs stepped
together, the runs as a vectorised inner axis (:mod:`ddmr_cli.engine.lanes`), with any sensor, actuator, control
rate and integrator. The block's per-run values sit in rows ``(row, lane)`` of
two arrays: ``L``, the engine's, whose first rows (:data:`LANE_ROWS`) the contract fixes, and ``C``, the
controller's own, of ``LANE_STATE_ROWS`` rows (a constant of the controller's module). The laws compute what
``command`` and ``update`` do, through the same per-run definitions, for lanes ``0 .. nb - 1``:

``lanes_load(p, st, C, l)`` / ``lanes_store(p, st, C, l)``
    Copy run record ``st`` into lane ``l`` of ``C``, and back.
``lanes_command(p, C, L, nb, k)``
    ``command`` for every lane at control instant ``k``: reads ``L[W_R]`` ... ``L[WDD_L]`` (``W``: the measured
    wheel speeds), writes ``L[UC_R]``, ``L[UC_L]`` and the
    diagnostic channels, channel ``c`` in rows ``L[DIAGNOSTICS + 2 c]`` (right) and ``+ 1`` (left).
``lanes_update(p, C, L, nb)``
    ``estimates`` (when the controller has one) and ``update`` for every lane: also reads ``L[U_R]``, ``L[U_L]``
    (applied) and ``L[SAT_R]``, ``L[SAT_L]`` (1.0/0.0).
"""

from __future__ import annotations

from types import ModuleType
from typing import Any, NamedTuple, Sequence

import numpy as np

from ddmr_cli.errors import ConfigError
from ddmr_cli.model.robot import NominalModel

#: Largest stable ``dt * rate`` of a first-order mode under the plant's integrator (explicit Euler: 2, RK4: 2.78)
STABILITY_LIMIT = {"euler": 2.0, "rk4": 2.78}


#: the rows of a block of runs that the lanes laws share with the engine (module docstring, "Lanes"), then up to
#: :data:`LANE_CHANNELS` diagnostic channels from row DIAGNOSTICS
W_R, W_L, WD_R, WD_L, WDD_R, WDD_L, UC_R, UC_L, U_R, U_L, SAT_R, SAT_L, DIAGNOSTICS = range(13)
#: runs of a block (the rows' length): 32 ran as fast as 64 and 10 % faster than 8 in the reference kernel's lanes
#: layout (ddmr_cli.bench.reference)
LANES = 32
LANE_CHANNELS = 4
LANE_ROWS = DIAGNOSTICS + 2 * LANE_CHANNELS

#: kinds of diagnostic channel (see the module docstring)
SURFACE, ESTIMATE, SIGNAL = "surface", "estimate", "signal"
KINDS = (SURFACE, ESTIMATE, SIGNAL)
#: the field of the state record that holds the diagnostic channels (added by the engine)
DIAGNOSTICS_FIELD = "diagnostics"
#: the series prefix of an ESTIMATE channel (``d_hat_<name lower-case>_right``/``_left``)
ESTIMATE_PREFIX = "d_hat_"


class Diagnostic(NamedTuple):
    """One diagnostic channel a controller reports, per wheel (see the module docstring).

    Attributes
    ----------
    name : str
        ``NDO``, ``NN``, ``ESO``, ``s``, ... (an estimate's series is ``d_hat_<name lower-case>_right``).
    kind : {'surface', 'estimate', 'signal'}
    description : str
        What it is, with its unit.
    """

    name: str
    kind: str
    description: str


def series_name(channel: Diagnostic) -> str:
    """The series prefix a channel is recorded under: ``s`` for the surface, ``d_hat_<name>`` for an estimate, else
    ``<name>`` (each followed by ``_right``/``_left``)."""
    if channel.kind == SURFACE:
        return "s"
    if channel.kind == ESTIMATE:
        return f"{ESTIMATE_PREFIX}{channel.name.lower()}"
    return channel.name.lower()


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

    def diagnostics(self) -> tuple[Diagnostic, ...]:
        """The diagnostic channels the laws write into ``st["diagnostics"]``, in row order (none by default)."""
        return ()

    def estimators(self) -> tuple[str, ...]:
        """The names of the controller's :data:`ESTIMATE` channels, in row order. Without one, d-hat is 0 and the
        estimation MAE is only the mean |d|: the report leaves it out."""
        return tuple(c.name for c in self.diagnostics() if c.kind == ESTIMATE)

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

    def runs_in_lanes(self) -> bool:
        """True when the controller's module defines the lanes laws (module docstring) and its channels fit."""
        laws = ("LANE_STATE_ROWS", "lanes_load", "lanes_store", "lanes_command", "lanes_update")
        return (all(hasattr(self.laws, name) for name in laws)
                and len(self.diagnostics()) <= LANE_CHANNELS)

    def initial_state(self, n_runs: int) -> np.ndarray:
        """A zeroed state record per run (``start`` sets the initial values at the first step): the fields of
        :meth:`state_fields` and the diagnostic channels, ``(max(1, n), 2)`` (one unused row when there are none)."""
        rows = max(1, len(self.diagnostics()))
        return np.zeros(n_runs, dtype=np.dtype(self.state_fields() + [(DIAGNOSTICS_FIELD, "f8", (rows, 2))]))


__all__ = ["DIAGNOSTICS", "LANES", "LANE_CHANNELS", "LANE_ROWS", "SAT_L", "SAT_R", "UC_L", "UC_R", "U_L", "U_R", "WDD_L",
           "WDD_R", "WD_L", "WD_R", "W_L", "W_R", "DIAGNOSTICS_FIELD", "Diagnostic", "ESTIMATE", "ESTIMATE_PREFIX",
           "KINDS", "SIGNAL", "STABILITY_LIMIT", "SURFACE", "StepRate", "WheelController", "series_name"]
