"""What the motor gets: the controller's voltage through PWM quantisation, a delay and a driver lag (docs/model.md §10).

At each control instant the controller's command ``u_c`` is saturated to ``+-U_max`` (the driver's limit,
:func:`ddmr_cli.model.dynamics.saturate`) and written as a PWM duty of ``bits`` bits: ``u_s = du round(u / du)``,
``du = U_max / (2^bits - 1)`` (:func:`pwm`; sign and magnitude, so 0 V is a level). ``u_s`` is what the controller
believes it applied (its observers are fed with it). It is held until the next control instant (zero-order hold),
reaches the driver ``delay`` seconds later (a whole number of plant steps; :func:`delay_line`) and the motor
voltage follows it through a first-order lag of time constant ``tau`` (:func:`driver_lag`), exact for a
held input: ``u_k = u_in + a (u_k-1 - u_in)``, ``a = exp(-dt / tau)``. Before the first command has come through,
the driver applies the first command.

The delay line is one array per run beside the engine's run record (:func:`delay_lines`), not a field of it: its
length is the delay, and the shape of a record's field is part of the compiled step loop's type, so a line in the
record made every delay value a loop of its own, compiled anew (7-8 s each on a 2-core machine: the realism
table's five delays compiled five loops per controller, 20 for its four).
"""

from __future__ import annotations

import math
from typing import NamedTuple

import numpy as np

from ddmr_cli.checks import integer, non_negative
from ddmr_cli.compiled import law
from ddmr_cli.errors import ConfigError

#: the largest PWM resolution accepted [bits]
MAX_PWM_BITS = 32


#: the per-run actuator state in the engine's run record: the driver's output [V]
ACTUATOR_FIELDS = [("u_drive", "f8", 2)]


def delay_lines(n_runs: int, delay_steps: int) -> np.ndarray:
    """Every run's delay line, ``(n_runs, delay_steps + 1, 2)`` [V]: the held commands of the last
    ``delay_steps + 1`` plant steps per wheel, a ring buffer (:func:`delay_line`). One array type whatever the
    delay, so one compiled loop serves every delay."""
    return np.zeros((n_runs, delay_steps + 1, 2))


class ActuatorParameters(NamedTuple):
    """The actuator as its laws take it (built by :meth:`Actuator.law_parameters`)."""

    pwm: bool  # quantise the voltage
    pwm_step: float  # du = U_max / (2^bits - 1) [V]
    delay_steps: int  # delay in plant steps
    lagged: bool  # first-order driver lag on
    lag_a: float  # exp(-dt / tau)


@law
def pwm(u, step):
    """The nearest PWM level, ``du round(u / du)`` [V]."""
    return step * math.floor(u / step + 0.5)


@law
def driver_lag(u_prev, u_in, a):
    """The driver's output one plant step on, ``u_in + a (u_prev - u_in)``, ``a = exp(-dt / tau)`` [V]."""
    return u_in + a * (u_prev - u_in)


@law
def start(p, run, line, u_R, u_L):
    """At the first control instant: the run's delay line ``line`` and the driver's output hold the first
    command."""
    for i in range(line.shape[0]):
        line[i, 0] = u_R
        line[i, 1] = u_L
    run["u_drive"][0] = u_R
    run["u_drive"][1] = u_L


@law
def delay_line(line, k, u_R, u_L):
    """Write the held command at plant step ``k`` into the ring buffer ``line`` (``delay_steps + 1`` rows) and
    return the one written ``delay_steps`` steps earlier [V]."""
    n = line.shape[0]
    line[k % n, 0] = u_R
    line[k % n, 1] = u_L
    i = (k + 1) % n  # == (k - delay_steps) mod n
    return line[i, 0], line[i, 1]


@law
def apply(p, run, line, k, u_R, u_L):
    """The voltage on the motor at plant step ``k`` given the held command ``u`` [V]: delayed (the run's delay
    line ``line``), then lagged."""
    if p.delay_steps > 0:
        u_R, u_L = delay_line(line, k, u_R, u_L)
    if p.lagged:
        u_R = driver_lag(run["u_drive"][0], u_R, p.lag_a)
        u_L = driver_lag(run["u_drive"][1], u_L, p.lag_a)
        run["u_drive"][0] = u_R
        run["u_drive"][1] = u_L
    return u_R, u_L


class Actuator:
    """The motor driver between the controller and the plant (module docstring; docs/model.md §10).

    Parameters
    ----------
    delay : float
        Transport delay [s] from the controller's output to the driver; a whole number of plant steps.
    lag : float
        Time constant tau [s] of the driver's first-order lag; 0: none.
    pwm_bits : int
        PWM resolution [bits] of the voltage magnitude; 0: none (a continuous voltage).
    """

    def __init__(self, *, delay: float, lag: float, pwm_bits: int) -> None:
        self.delay = non_negative("actuator.delay", delay)
        self.lag = non_negative("actuator.lag", lag)
        self.pwm_bits = integer("actuator.pwm_bits", pwm_bits, 0)
        if self.pwm_bits > MAX_PWM_BITS:
            raise ConfigError("actuator.pwm_bits", pwm_bits, f"must be <= {MAX_PWM_BITS} (0: no quantisation)")

    def delay_steps(self, dt: float) -> int:
        """The delay in plant steps; ConfigError unless it is a whole number of steps ``dt``."""
        ratio = self.delay / dt
        n = int(round(ratio))
        if abs(ratio - n) > 1e-9 * max(1.0, ratio):
            raise ConfigError("actuator.delay", self.delay, f"must be a whole number of plant periods "
                                                            f"(simulation.dt = {dt:g} s); {ratio:.6g} periods is not")
        return n

    def law_parameters(self, dt: float, max_voltage: float) -> ActuatorParameters:
        """The parameters at plant step ``dt`` [s] and supply voltage ``max_voltage`` [V]."""
        return ActuatorParameters(
            pwm=self.pwm_bits > 0, pwm_step=max_voltage / (2.0 ** self.pwm_bits - 1.0) if self.pwm_bits else 1.0,
            delay_steps=self.delay_steps(dt), lagged=self.lag > 0.0,
            lag_a=math.exp(-dt / self.lag) if self.lag > 0.0 else 0.0)

    @property
    def ideal(self) -> bool:
        return not (self.delay > 0.0 or self.lag > 0.0 or self.pwm_bits > 0)


__all__ = ["Actuator", "ActuatorParameters", "ACTUATOR_FIELDS", "delay_lines", "pwm", "driver_lag", "start",
           "delay_line", "apply", "MAX_PWM_BITS"]
