"""What a plant is to the engine: the contract of a plant stepped from outside the compiled loop (issue 27).

Two kinds of plant drive the same control laws, sensor and actuator models, series and metrics:

The wheel plant (:mod:`ddmr_cli.plant.wheel`, ``plant=wheel``, the default)
    The paper's 2x2 wheel-space model with its disturbance torques (docs/model.md §1, §5: eq. (8)), inlined in
    the compiled step loop (:mod:`ddmr_cli.engine.stepper`: ``wheel_acceleration`` and the integrators). It is not
    an object behind this contract: inlined, it costs nothing per step, and its numbers are the regression
    fixture's.
An external plant (:class:`ExternalPlant`, e.g. :class:`ddmr_cli.plant.mujoco.MujocoPlant`, ``plant=mujoco``)
    Anything stepped from Python (a rigid-body engine releasing the GIL). It advances a batch of ``n`` runs in
    lockstep; the engine reads the true state, runs the control instant for every run on it, and hands the
    applied voltages back.

The contract, in the order the engine calls it per batch (arrays: one row per run, wheels ordered right, left):

``reset(seeds, pose0, w0)``
    Start the batch: ``seeds`` ``(n,)`` ints (each run's own randomness, e.g. its ground, drawn from its seed:
    same seed, same plant), ``pose0`` ``(n, 3)`` x [m], y [m], theta [rad] of the axle midpoint, ``w0`` ``(n, 2)``
    wheel speeds [rad/s].
``state()``
    The true state now: a mapping with ``x``, ``y``, ``theta``, ``distance`` ``(n,)`` [m, m, rad, m] and ``w``
    ``(n, 2)`` [rad/s]. The sensor models read it as they read the wheel plant's state.
``step(u, damping_scale)``
    Advance every run by one plant step ``dt`` with the applied motor voltages ``u`` ``(n, 2)`` [V] (after the
    driver's limit, PWM, delay and lag: docs/model.md §10) and scenario 2's damping scale ``b`` ``(n,)`` [1]
    (1 where the uncertainty is off), both held over the step.
``true_disturbance()``
    The lumped disturbance d of eq. (8) over the last step ``(n, 2)`` [rad/s^2]: the part of the wheel
    acceleration the nominal model does not explain, ``(w_k+1 - w_k)/dt - (f(w_k) + g u_k)``; the estimation
    metrics compare the controllers' estimates with it. NaN for a diverged run.
``diverged()``
    ``(n,)`` bool: the run has left the plant's valid region (tipped over, left the ground, non-finite). A
    diverged run is a result: it is no longer stepped, its metrics stop where the engine's divergence rule stops
    them, never an exception.
``dt``
    The plant step [s] (``simulation.dt``).

The engine (:func:`ddmr_cli.engine.simulation.simulate`) drives it step by step: the compiled control half of
every run (``external_control`` of the step loop), :meth:`step`, then the compiled accounting half on
:meth:`state` and :meth:`true_disturbance` (``external_account``), and marks the runs :meth:`diverged` flags.

A second plant is one module ``ddmr_cli.plant.<name>`` implementing this protocol with a ``factory(config)`` that
returns a callable ``(simulation, threads) -> plant`` (:func:`ddmr_cli.plant.mujoco.factory`) and optionally a
``check(config, simulation)`` that config validation calls before anything runs, plus one
``conf/plant/<name>.yaml`` whose ``name`` is the module's; the engine, the
metrics, the report and the determinism rules (same seed, same numbers, whatever the thread count) come with it.
"""

from __future__ import annotations

from typing import Mapping, Protocol, runtime_checkable

import numpy as np

#: the keys of :meth:`ExternalPlant.state`
STATE_KEYS = ("x", "y", "theta", "distance", "w")


@runtime_checkable
class ExternalPlant(Protocol):
    """A batch of runs of a plant stepped from Python (the module docstring gives each method's contract)."""

    dt: float

    def reset(self, seeds: np.ndarray, pose0: np.ndarray, w0: np.ndarray) -> None: ...

    def state(self) -> Mapping[str, np.ndarray]: ...

    def step(self, u: np.ndarray, damping_scale: np.ndarray) -> None: ...

    def true_disturbance(self) -> np.ndarray: ...

    def diverged(self) -> np.ndarray: ...


def check_state(state: Mapping[str, np.ndarray], n: int) -> None:
    """Raise ValueError unless ``state`` has every key of :data:`STATE_KEYS` with the contract's shapes for ``n``
    runs (a plant's own test calls this: an implementation that drifts from the contract fails by name)."""
    missing = [k for k in STATE_KEYS if k not in state]
    if missing:
        raise ValueError(f"plant state lacks {', '.join(missing)}")
    for key in STATE_KEYS:
        shape = (n, 2) if key == "w" else (n,)
        if np.shape(state[key]) != shape:
            raise ValueError(f"plant state {key} has shape {np.shape(state[key])}, not {shape}")


__all__ = ["ExternalPlant", "STATE_KEYS", "check_state"]
