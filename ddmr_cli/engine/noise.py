"""Seeded noise: one generator per run, drawn in chunks, so a seed gives the same stream in any batch.

Each run owns ``numpy.random.default_rng(seed)``. Per step it consumes three standard normals
(right-wheel roughness, left-wheel roughness, damping uncertainty), always all of them, so that the same seed
sees the same terrain whatever the scenario and controller ("same seed, same terrain"). The streams are
turned into OU processes with an exact discretisation, in chunks whose size does not change the numbers.
"""

from __future__ import annotations

from typing import Sequence

import numpy as np

from ddmr_cli.engine.kernel import _jit
from ddmr_cli.model.terrain import ou_coefficients



@_jit
def ou_filter(xi, a, b, state, out):
    """``out[r, j, c] = a[c] out[r, j-1, c] + b[c] xi[r, j, c]``, starting from ``state[r, c]``; updates ``state``."""
    n_runs, n_steps, n_ch = xi.shape
    for r in range(n_runs):
        for c in range(n_ch):
            y = state[r, c]
            for j in range(n_steps):
                y = b[c] * xi[r, j, c] + a[c] * y
                out[r, j, c] = y
            state[r, c] = y


class OUStreams:
    """Unit-variance OU processes per run and channel, produced chunk by chunk.

    Parameters
    ----------
    seeds : sequence of int
        One per run.
    dt : float
        Step [s].
    correlation_times : sequence of float
        One per channel [s].
    """

    def __init__(self, seeds: Sequence[int], dt: float, correlation_times: Sequence[float]) -> None:
        self.generators = [np.random.default_rng(int(s)) for s in seeds]
        coeffs = [ou_coefficients(dt, tc) for tc in correlation_times]
        self.a = np.array([c[0] for c in coeffs])
        self.b = np.array([c[1] for c in coeffs])
        n_runs, n_ch = len(self.generators), len(coeffs)
        # The state before the first step is drawn from the stationary distribution N(0, 1).
        self.state = np.empty((n_runs, n_ch))
        for i, rng in enumerate(self.generators):
            rng.standard_normal(out=self.state[i])

    def next_chunk(self, n_steps: int) -> np.ndarray:
        """The next ``n_steps`` values, run-major: shape ``(n_runs, n_steps, channels)``."""
        n_runs, n_ch = self.state.shape
        xi = np.empty((n_runs, n_steps, n_ch))
        for i, rng in enumerate(self.generators):
            rng.standard_normal(out=xi[i])
        out = np.empty((n_runs, n_steps, n_ch))
        ou_filter(xi, self.a, self.b, self.state, out)
        return out
