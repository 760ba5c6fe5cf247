"""Validation of every config value, before anything is run or written (issue: bad input).

Each rule raises :class:`~ddmr_cli.errors.ConfigError` naming the key, the value and the rule, which the CLI
prints as one line with exit status 2.
"""

from __future__ import annotations

import math
from typing import Any

import numpy as np
from omegaconf import DictConfig, ListConfig, OmegaConf

from ddmr_cli.control.base import SWITCHING_FUNCTIONS
from ddmr_cli.control.smc import SURFACES
from ddmr_cli.errors import ConfigError
from ddmr_cli.engine.simulation import ENGINES, INTEGRATORS
from ddmr_cli.cli.config.build import _check_targets
#: Largest stable dt * rate of a first-order mode under the step (explicit Euler: 2, RK4: 2.78)
STABILITY_LIMIT = {"euler": 2.0, "rk4": 2.78}


def _number(key: str, value: Any) -> float:
    if isinstance(value, bool) or not isinstance(value, (int, float)):
        raise ConfigError(key, value, "must be a number")
    if not math.isfinite(value):
        raise ConfigError(key, value, "must be finite")
    return float(value)


def positive(key: str, value: Any) -> float:
    v = _number(key, value)
    if v <= 0:
        raise ConfigError(key, value, "must be > 0")
    return v


def non_negative(key: str, value: Any) -> float:
    v = _number(key, value)
    if v < 0:
        raise ConfigError(key, value, "must be >= 0")
    return v


def finite(key: str, value: Any) -> float:
    return _number(key, value)


def per_wheel(key: str, value: Any, rule=non_negative) -> np.ndarray:
    """A number or a [right, left] pair, each checked by ``rule``."""
    if isinstance(value, (list, tuple, ListConfig)):
        items = list(value)
        if len(items) != 2:
            raise ConfigError(key, OmegaConf.to_container(value) if isinstance(value, ListConfig) else value,
                              "must be a number or a [right, left] pair")
        return np.array([rule(f"{key}[{i}]", v) for i, v in enumerate(items)])
    v = rule(key, value)
    return np.array([v, v])


def one_of(key: str, value: Any, options) -> str:
    if value not in options:
        raise ConfigError(key, value, f"must be one of {', '.join(options)}")
    return value


def integer(key: str, value: Any, minimum: int) -> int:
    if isinstance(value, bool) or not isinstance(value, int):
        raise ConfigError(key, value, "must be an integer")
    if value < minimum:
        raise ConfigError(key, value, f"must be >= {minimum}")
    return value


def _increasing_from_zero(key: str, items: DictConfig, what: str) -> None:
    if len(items) == 0:
        raise ConfigError(key, {}, f"needs at least one {what}")
    previous = None
    for name, item in items.items():
        start = non_negative(f"{key}.{name}.start", item.start)
        if previous is None and start != 0:
            raise ConfigError(f"{key}.{name}.start", item.start, f"the first {what} must start at 0")
        if previous is not None and start <= previous:
            raise ConfigError(f"{key}.{name}.start", item.start,
                              f"{what} starts must be increasing (previous one starts at {previous:g})")
        previous = start


def validate_robot(cfg: DictConfig) -> None:
    for key in ("mass", "wheel_radius", "track_width", "yaw_inertia", "wheel_inertia", "torque_constant",
                "back_emf_constant", "armature_resistance", "max_voltage"):
        positive(f"robot.{key}", cfg[key])
    non_negative("robot.viscous_friction", cfg.viscous_friction)


def validate_terrain(cfg: DictConfig) -> None:
    positive("terrain.correlation_time", cfg.correlation_time)
    _increasing_from_zero("terrain.zones", cfg.zones, "zone")
    for name, zone in cfg.zones.items():
        non_negative(f"terrain.zones.{name}.roughness", zone.roughness)
        non_negative(f"terrain.zones.{name}.mu", zone.mu)


def validate_scenario(cfg: DictConfig) -> None:
    _increasing_from_zero("scenario.phases", cfg.phases, "phase")
    u = cfg.uncertainty
    positive("scenario.uncertainty.correlation_time", u.correlation_time)
    non_negative("scenario.uncertainty.std", u.std)
    low, high = finite("scenario.uncertainty.low", u.low), finite("scenario.uncertainty.high", u.high)
    if low <= -1.0:
        raise ConfigError("scenario.uncertainty.low", u.low, "must be > -1 (the true damping must stay positive)")
    if high <= low:
        raise ConfigError("scenario.uncertainty.high", u.high, f"must be > scenario.uncertainty.low ({low:g})")


def validate_controller(cfg: DictConfig) -> None:
    target = str(cfg.get("_target_", ""))
    kind = target.rsplit(".", 1)[-1]
    if kind == "PID":
        for key in ("kp", "ki", "kd"):
            per_wheel(f"controller.{key}", cfg[key])
    elif kind == "SMC":
        per_wheel("controller.lam", cfg.lam, positive)
        per_wheel("controller.switching_gain", cfg.switching_gain)
        positive("controller.boundary_layer", cfg.boundary_layer)
        one_of("controller.surface", cfg.surface, SURFACES)
        one_of("controller.switching", cfg.switching, tuple(SWITCHING_FUNCTIONS))
        if cfg.get("ndo") is not None:
            per_wheel("controller.ndo.gain", cfg.ndo.gain, positive)
        if cfg.get("nn") is not None:
            nn = cfg.nn
            integer("controller.nn.n_neurons", nn.n_neurons, 1)
            positive("controller.nn.width", nn.width)
            per_wheel("controller.nn.learning_rate", nn.learning_rate, positive)
            lo, hi = finite("controller.nn.center_min", nn.center_min), finite("controller.nn.center_max", nn.center_max)
            if hi <= lo and nn.n_neurons > 1:
                raise ConfigError("controller.nn.center_max", nn.center_max, f"must be > controller.nn.center_min ({lo:g})")
    elif kind == "OpenLoop":
        per_wheel("controller.voltage", cfg.voltage, finite)


def validate_trajectory(cfg: DictConfig) -> None:
    for key in ("speed", "heading", "x0", "y0"):
        if key in cfg:
            finite(f"trajectory.{key}", cfg[key])
    for key in ("radius", "amplitude", "period"):
        if key in cfg:
            positive(f"trajectory.{key}", cfg[key])


def _pd_spectral_radius(dt_g_kp: float, g_kd: float) -> float:
    """Largest |root| of the sampled wheel-speed loop under PD with a backward-difference derivative:
    ``e_k+1 = (1 - dt g K_p - g K_d) e_k + g K_d e_k-1`` (the integral term is slow and left out).

    The roots of ``z^2 - a z - b`` in closed form (no LAPACK, so the verdict is the same on every CPU):
    real ``(a +- sqrt(a^2 + 4 b)) / 2``, or a complex pair of modulus ``sqrt(-b)``."""
    a, b = 1.0 - dt_g_kp - g_kd, g_kd
    disc = a * a + 4.0 * b
    if disc >= 0.0:
        root = math.sqrt(disc)
        return max(abs(0.5 * (a + root)), abs(0.5 * (a - root)))
    return math.sqrt(-b)


def validate_step(cfg: DictConfig) -> None:
    """dt small enough for the integrator and the fastest loop (plant, observer, sliding surface, PID)."""
    from ddmr_cli.model.robot import Robot
    from ddmr_cli.cli.config.build import build_robot

    sim = cfg.simulation
    dt = positive("simulation.dt", sim.dt)
    limit = STABILITY_LIMIT[sim.integrator]
    robot: Robot = build_robot(cfg.robot)
    try:
        derived = (*robot.inverse_inertia.eigenvalues, robot.damping, robot.voltage_gain)
    except (ValueError, ArithmeticError) as exc:
        raise ConfigError("robot", OmegaConf.to_container(cfg.robot),
                          f"gives no usable inertia matrix J ({' '.join(str(exc).split())})") from None
    if not all(math.isfinite(v) for v in derived):
        raise ConfigError("robot", OmegaConf.to_container(cfg.robot),
                          "gives a non-finite J^-1, damping B or voltage gain K_u (values too extreme)")
    b_max = 1.0 + (max(0.0, float(cfg.scenario.uncertainty.high)) if any(
        p.uncertainty for p in cfg.scenario.phases.values()) else 0.0)
    rates = {"the plant's fastest pole": max(robot.drift.eigenvalues) * b_max}
    ctrl = cfg.controller
    kind = str(ctrl.get("_target_", "")).rsplit(".", 1)[-1]
    g_max = max(robot.input_gain.eigenvalues)
    if kind == "SMC":
        rates["controller.lam + switching_gain/boundary_layer"] = float(
            np.max(per_wheel("controller.lam", ctrl.lam, positive))
            + np.max(per_wheel("controller.switching_gain", ctrl.switching_gain)) / float(ctrl.boundary_layer))
        if ctrl.get("ndo") is not None:
            rates["controller.ndo.gain"] = float(np.max(per_wheel("controller.ndo.gain", ctrl.ndo.gain, positive)))
    for what, rate in rates.items():
        if dt * rate >= limit:
            raise ConfigError("simulation.dt", sim.dt,
                              f"must be < {limit / rate:.3g} s for {sim.integrator} with {what} = {rate:.3g} 1/s")
    if kind == "PID":
        kp = float(np.max(per_wheel("controller.kp", ctrl.kp)))
        kd = float(np.max(per_wheel("controller.kd", ctrl.kd)))
        if _pd_spectral_radius(dt * g_max * kp, g_max * kd) >= 1.0:
            stable = [h for h in np.geomspace(dt, dt * 1e-3, 61) if _pd_spectral_radius(h * g_max * kp, g_max * kd) < 1]
            bound = f"must be < {stable[0]:.3g} s" if stable else "has no stable value"
            raise ConfigError("simulation.dt", sim.dt, f"{bound}: the sampled PD loop (controller.kp={kp:g}, "
                                                       f"controller.kd={kd:g}) is unstable at this step")


def validate_config(cfg: DictConfig) -> None:
    """Check every value of a composed config; raise ConfigError on the first bad one."""
    _check_targets(cfg.get("controller"), "controller")
    _check_targets(cfg.get("trajectory"), "trajectory")
    validate_robot(cfg.robot)
    validate_terrain(cfg.terrain)
    validate_scenario(cfg.scenario)
    validate_controller(cfg.controller)
    validate_trajectory(cfg.trajectory)
    for key in ("k_x", "k_y", "k_theta"):
        non_negative(f"outer_loop.{key}", cfg.outer_loop[key])
    sim = cfg.simulation
    one_of("simulation.integrator", sim.integrator, INTEGRATORS)
    duration = positive("simulation.duration", sim.duration)
    dt = positive("simulation.dt", sim.dt)
    if dt > duration:
        raise ConfigError("simulation.dt", sim.dt, f"must be <= simulation.duration ({duration:g})")
    if len(sim.initial_pose) != 3:
        raise ConfigError("simulation.initial_pose", OmegaConf.to_container(sim.initial_pose), "must be [x, y, theta]")
    for i, v in enumerate(sim.initial_pose):
        finite(f"simulation.initial_pose[{i}]", v)
    wheel = sim.initial_wheel_speeds
    if isinstance(wheel, str):
        one_of("simulation.initial_wheel_speeds", wheel, ("reference", "rest"))
    else:
        per_wheel("simulation.initial_wheel_speeds", wheel, finite)
    positive("simulation.divergence_bound", sim.divergence_bound)
    one_of("simulation.engine", sim.engine, ENGINES)
    validate_step(cfg)
    run = cfg.run
    integer("run.n_runs", run.n_runs, 1)
    integer("run.base_seed", run.base_seed, 0)
    integer("run.threads", run.threads, 0)
    for i, seed in enumerate(run.keep_series):
        integer(f"run.keep_series[{i}]", seed, 0)
