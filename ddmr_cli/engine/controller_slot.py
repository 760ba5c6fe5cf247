"""The controller slot of the step loop: where :mod:`ddmr_cli.engine.stepper` takes the wheel controller's laws.

numba inlines the laws a compiled function calls, so the step loop is compiled once per controller module. The
template :mod:`ddmr_cli.engine.stepper` imports the four controller laws from this module::

    from ddmr_cli.engine.controller_slot import command as controller_command  # controller laws

and :mod:`ddmr_cli.engine.kernels` makes each controller's copy of the loop by pointing exactly those lines at
the controller's own module (``WheelController.laws``: ``ddmr_cli.control.smc``, or a user's module): nothing else
of the template changes. A controller without the optional ``estimates`` law keeps the open loop's default here.

The loop by blocks of runs (:mod:`ddmr_cli.engine.lanes`) takes the optional lanes laws (:data:`LANES_LAWS`) and
``start`` the same way.

Run as it stands (the template imported as a module, without a copy), the slot holds the open loop's laws, a
controller with no state: the contract's defaults (docs/extending.md).
"""

from __future__ import annotations

from ddmr_cli.control.open_loop import (LANE_STATE_ROWS, command, estimates, lanes_command, lanes_load, lanes_store,
                                        lanes_update, start, update)

#: the laws of a controller the loop calls, in the order the slot's import lines name them; ``estimates`` optional
LAWS = ("command", "estimates", "start", "update")
#: the laws of a controller the lanes loop (:mod:`ddmr_cli.engine.lanes`) calls besides ``start``
LANES_LAWS = ("LANE_STATE_ROWS", "lanes_command", "lanes_load", "lanes_store", "lanes_update")
#: the module whose law a controller that does not define an optional one keeps
DEFAULT_MODULE = "ddmr_cli.control.open_loop"

__all__ = ["LAWS", "LANES_LAWS", "DEFAULT_MODULE", "LANE_STATE_ROWS", "command", "estimates", "lanes_command",
           "lanes_load", "lanes_store", "lanes_update", "start", "update"]
