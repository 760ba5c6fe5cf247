"""Seeded noise: one generator per run, drawn in chunks, so a seed gives the same stream in any batch.

Each run owns ``numpy.random.default_rng(seed)``. It first draws the initial state of three unit-variance
Ornstein-Uhlenbeck processes (right-wheel roughness, left-wheel roughness, damping uncertainty) from their
stationary N(0, 1), then three standard normals per step, always all of them, so that the same seed sees the
same terrain whatever the scenario and controller ("same seed, same terrain"; docs/model.md §5). The step
loop turns the normals into the OU processes with :func:`ou_step`, the exact discretisation.
"""

from __future__ import annotations

import math
from typing import Sequence

import numpy as np

from ddmr_cli import bit_generators
from ddmr_cli.compiled import law

#: noise channels per run and step
CHANNELS = ("roughness_right", "roughness_left", "uncertainty")


def ou_coefficients(dt: float, correlation_time: float) -> tuple[float, float]:
    """Exact discretisation of a unit-variance OU process with correlation time ``tau`` [s]:
    ``n_k+1 = a n_k + b xi_k``, ``a = exp(-dt / tau)``, ``b = sqrt(1 - a^2)`` (docs/model.md §5)."""
    a = math.exp(-dt / correlation_time)
    return a, math.sqrt(1.0 - a * a)


@law
def ou_step(a, b, n, xi):
    """``n_k+1 = a n_k + b xi_k`` with ``xi_k ~ N(0, 1)``."""
    return b * xi + a * n


class NoiseStreams:
    """The standard normals of a batch of runs, one generator per run.

    Parameters
    ----------
    seeds : sequence of int
        One per run.
    spawn_key : tuple of int
        numpy's ``SeedSequence`` spawn key of every run's stream (``()``: ``default_rng(seed)`` itself).
    """

    #: normals per run and step
    channels = len(CHANNELS)

    def __init__(self, seeds: Sequence[int], spawn_key: tuple[int, ...] = ()) -> None:
        self.n_runs = len(seeds)
        if bit_generators.drawn_compiled():
            #: each run's ``PCG64`` of ``default_rng(SeedSequence(seed, spawn_key=spawn_key))``, one row a run
            #: (:func:`ddmr_cli.bit_generators.states`: seeded at once, drawn by compiled code), or None
            self.states = bit_generators.states(seeds, spawn_key)
            self.generators = None
        else:
            self.states = None
            #: the same generators as numpy objects, where the draws run as Python (numba missing or off), or None
            self.generators = bit_generators.generators(seeds, spawn_key)

    def streams(self):
        """Each run's stream as the step loop draws from it (:func:`ddmr_cli.bit_generators.stream_of`): the rows of
        :attr:`states` where the loop is compiled, else the generators themselves."""
        return self.states if self.states is not None else self.generators

    def initial_state(self) -> np.ndarray:
        """The OU processes' state before the first step, drawn from N(0, 1): shape ``(n_runs, 3)`` (each run's
        first three normals, drawn as a step's are)."""
        return self.next_chunk(1)[:, 0, :]

    def next_chunk(self, n_steps: int, out: np.ndarray | None = None, runs: tuple[int, int] | None = None
                   ) -> np.ndarray:
        """The next ``n_steps`` normals per run and channel, run-major: shape ``(n_runs, n_steps, channels)``.

        ``runs=(first, end)`` draws for those runs only, into their rows of ``out`` (which must then have the
        shape): the engine's worker threads each draw their own block (one compiled call that releases the GIL;
        numpy's own draw where numba is missing), and a run's numbers are the same whichever thread draws them."""
        shape = (self.n_runs, n_steps, self.channels)
        if out is None or out.shape != shape:
            if runs is not None:
                raise ValueError(f"out must have shape {shape} to be filled by blocks of runs")
            out = np.empty(shape)
        first, end = runs if runs is not None else (0, self.n_runs)
        if self.states is not None:  # one compiled call for the block, the GIL released: the same numbers
            bit_generators.standard_normals_of(self.states, out, first, end)
        else:
            for i in range(first, end):
                self.generators[i].standard_normal(out=out[i])
        return out


#: the spawn key that derives a run's sensor stream from its seed (child 1 of ``SeedSequence(seed)``)
SENSOR_STREAM = 1


class SensorNoise(NoiseStreams):
    """The sensor's standard normals (docs/model.md §10), one generator per run of its own:
    ``default_rng(SeedSequence(seed, spawn_key=(SENSOR_STREAM,)))``, independent of the seed's disturbance
    stream, which therefore stays the same whether or not a sensor is noisy. ``channels`` normals per plant
    step (:data:`ddmr_cli.model.sensor.NOISE_CHANNELS`), drawn only when a sensor is noisy.
    """

    def __init__(self, seeds: Sequence[int], channels: int) -> None:
        self.channels = int(channels)
        super().__init__(seeds, spawn_key=(SENSOR_STREAM,))
