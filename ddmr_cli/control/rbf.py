"""RBF neural-network observer, the paper's (24)-(27) with the update law (25) (docs/model.md §6).

``d_hat_NN = W^T Phi(x)`` with ``x = w``, ``phi_j = exp(-||x - c_j||^2 / (2 sigma^2))``, centres
``c_j = (c, c)`` evenly spaced on ``[center_min, center_max]``, ``W`` (n x 2 per run, stored as one row of n
weights per wheel) starting at 0 and adapting by ``W' = -gamma Phi(x) s^T`` (25): the sign that makes (28)'s
``V' <= 0`` for ``s = w_d - w`` with ``d_hat`` subtracted in (17). Discretised by explicit Euler.
"""

from __future__ import annotations

import math
from typing import NamedTuple

import numpy as np

from ddmr_cli.compiled import law
from ddmr_cli.checks import compact, finite, integer, per_wheel, positive
from ddmr_cli.errors import ConfigError
from ddmr_cli.model.elementary import exp_neg


#: A state record holds the network in blocks of this many neurons (:func:`capacity`): numba types a record by its
#: fields' shapes and compiles a step loop per record layout (8-9 s each), so the sizes 1 to 16 (Table 3's 10 and
#: the sensitivity study's 5, 10 and 15) share one layout and one loop, 17 to 32 the next. The laws run over the
#: first ``n`` only. Blocks of 32 would take the study's 20 too, but raised a 10,000-seed run's peak by 3.4 MiB
#: (194.3 -> 197.7 MiB), enough to put ``ddmr bench``'s 197 MiB past its 200 MB target; blocks of 16 left it
#: unchanged (194.1 MiB; measured, issue 28).
NEURON_BLOCK = 16


def capacity(n_neurons: int) -> int:
    """The neurons a state record holds for a network of ``n_neurons``: ``n`` rounded up to a whole
    :data:`NEURON_BLOCK` (the weights' and the basis's length; the entries past ``n`` stay 0 and are never read)."""
    return -(-int(n_neurons) // NEURON_BLOCK) * NEURON_BLOCK


class RBFParameters(NamedTuple):
    """The network's constants, all scalars: an array here would be reference-counted at every call of the laws
    that take these parameters, and made SMC's step (which never uses the network) 2x slower."""

    n_neurons: int  # n
    center_min: float  # c_1 [rad/s]
    center_max: float  # c_n [rad/s]
    center_step: float  # (c_n - c_1) / (n - 1) [rad/s]; 0 for one neuron
    width: float  # sigma [rad/s]
    learning_rate: tuple  # gamma per wheel (right, left)


@law
def center(p, j):
    """``c_j`` [rad/s], evenly spaced on ``[c_1, c_n]`` (docs/model.md §6): ``c_1 + j step``, the last one exactly
    ``c_n`` (the numbers ``numpy.linspace`` gives)."""
    if j == p.n_neurons - 1 and j > 0:
        return p.center_max
    return j * p.center_step + p.center_min


@law
def exponent(p, j, w_R, w_L):
    """The exponent of (27) for neuron ``j``: ``-||x - c_j||^2 / (2 sigma^2)``."""
    c = center(p, j)
    return ((w_R - c) ** 2 + (w_L - c) ** 2) * (-0.5 / (p.width * p.width))


@law
def activation(p, j, w_R, w_L):
    """(27) for neuron ``j``: ``phi_j = exp(-||x - c_j||^2 / (2 sigma^2))`` (:func:`basis`)."""
    return exp_neg(exponent(p, j, w_R, w_L))


@law
def basis(p, phi, w_R, w_L):
    """(27): ``phi_j = exp(-||x - c_j||^2 / (2 sigma^2))`` for ``x = (w_R, w_L)``, ``c_j = (c_j, c_j)``, into ``phi``.

    The exp is :func:`~ddmr_cli.model.elementary.exp_neg` (arithmetic, not libm's call): compiled, the loop over
    the neurons is vectorised, and a neuron far from ``x`` (exactly 0 below
    :data:`~ddmr_cli.model.elementary.EXP_ZERO`; at the paper's 33 rad/s, 3 of the 10) costs what the others cost,
    where libm's exp takes a slow underflow path."""
    for j in range(p.n_neurons):
        phi[j] = activation(p, j, w_R, w_L)


@law
def estimate(p, weights, phi, w_R, w_L):
    """(24): ``d_hat_NN = W^T Phi(x)`` [rad/s^2] over the ``n`` neurons (the record may hold more:
    :func:`capacity`); leaves ``Phi(x)`` in ``phi`` for :func:`update`."""
    basis(p, phi, w_R, w_L)
    d_R = 0.0
    d_L = 0.0
    for j in range(p.n_neurons):
        d_R += weights[0, j] * phi[j]
        d_L += weights[1, j] * phi[j]
    return d_R, d_L


@law
def learning_steps(p, dt, s_R, s_L):
    """The factors of (25)'s Euler step per wheel, ``dt gamma s``."""
    return (dt * p.learning_rate[0]) * s_R, (dt * p.learning_rate[1]) * s_L


@law
def learned(weight, step, phi_j):
    """(25) for one weight: ``w_j - dt gamma s phi_j`` (``step`` from :func:`learning_steps`)."""
    return weight - step * phi_j


@law
def update(p, dt, weights, phi, s_R, s_L):
    """(25), one Euler step: ``W <- W - dt gamma Phi(x) s^T`` for the ``n`` neurons."""
    step_R, step_L = learning_steps(p, dt, s_R, s_L)
    for j in range(p.n_neurons):
        weights[0, j] = learned(weights[0, j], step_R, phi[j])
        weights[1, j] = learned(weights[1, j], step_L, phi[j])


class RBFNetworkObserver:
    """The RBF network observer of the paper's section 3.3 (docs/model.md §6).

    Parameters
    ----------
    n_neurons : int
        Hidden neurons n (Table 3: 10).
    width : float
        RBF width sigma [rad/s] (eq. 25 / Table 3 reading: 2; text reading: 50).
    learning_rate : float or (float, float)
        gamma per wheel (eq. 25 / Table 3 reading: 50; text reading: 2).
    center_min, center_max : float
        Range of the centres [rad/s] (docs/model.md §6: -40, 40).
    """

    def __init__(self, *, n_neurons: int, width: float, learning_rate, center_min: float, center_max: float) -> None:
        self.n_neurons = integer("controller.nn.n_neurons", n_neurons, 1)
        self.width = positive("controller.nn.width", width)
        square = self.width * self.width
        if not (square > 0.0 and math.isfinite(0.5 / square)):  # (27)'s 1 / (2 sigma^2): a zero division compiled
            raise ConfigError("controller.nn.width", width, "is too small: 1 / (2 width^2) overflows")
        self.learning_rate = per_wheel("controller.nn.learning_rate", learning_rate, positive)
        self.center_min = finite("controller.nn.center_min", center_min)
        self.center_max = finite("controller.nn.center_max", center_max)
        if self.center_max <= self.center_min and self.n_neurons > 1:
            raise ConfigError("controller.nn.center_max", center_max,
                              f"must be > controller.nn.center_min ({self.center_min:g})")

    @property
    def centers(self) -> np.ndarray:
        """The centres ``c_j`` [rad/s], shape (n,) (the laws compute them: :func:`center`)."""
        return np.linspace(self.center_min, self.center_max, self.n_neurons)

    def law_parameters(self) -> RBFParameters:
        n, low, high = self.n_neurons, self.center_min, self.center_max
        step = (high - low) / (n - 1) if n > 1 else 0.0  # as numpy.linspace computes it
        return RBFParameters(n, low, high, step, self.width, self.learning_rate)

    def parameters(self) -> dict[str, object]:
        return {"n": self.n_neurons, "sigma": self.width, "gamma": compact(self.learning_rate),
                "centres": f"[{self.center_min:g}, {self.center_max:g}]"}
