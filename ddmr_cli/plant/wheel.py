"""The wheel plant: the paper's 2x2 wheel-space model (docs/model.md §1, eq. (8)), the default ``plant=wheel``.

Its laws live where the model names them and run inlined in the compiled step loop, so the default plant costs
nothing per step and its numbers are the regression fixture's:

- :func:`ddmr_cli.model.dynamics.wheel_acceleration`: the acceleration (8) and the true lumped disturbance d under
  the applied voltages, the terrain's torques and scenario 2's damping scale;
- :func:`ddmr_cli.model.integrators.euler` and :func:`~ddmr_cli.model.integrators.rk4`: the wheel speeds and the
  pose (4) one plant step on;
- :func:`ddmr_cli.model.dynamics.disturbance`: the terrain's torques (5).

It is therefore not an :class:`~ddmr_cli.plant.base.ExternalPlant` object: the engine's compiled loop is its
implementation of the same contract (state, step with applied voltages and damping scale, true d, divergence by
the deviation bound). This module names it and lists its parts, so that a reader looking for "the plant" finds it.
"""

from __future__ import annotations

from ddmr_cli.model.dynamics import disturbance, wheel_acceleration

#: the name of the default plant (``plant.name`` of conf/plant/wheel.yaml)
NAME = "wheel"
#: the model's laws that make the wheel plant (the step loop integrates them with model/integrators.py)
LAWS = (wheel_acceleration, disturbance)

__all__ = ["NAME", "LAWS"]
