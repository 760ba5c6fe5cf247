"""Typed config schemas (dataclasses registered in Hydra's ConfigStore); the values live in ``conf/`` YAML.

Each YAML file of a group starts from its schema (``defaults: [/schema_<name>@_here_]``), so a
misspelt key or a wrong type is refused when the config is composed. Per-wheel gains accept a number or a
``[right, left]`` pair, hence ``Any``; :mod:`ddmr_cli.config.validate` checks the values.
"""

from __future__ import annotations

from dataclasses import dataclass, field
from types import MappingProxyType
from typing import Any, Callable, Dict, List, Optional

from hydra.core.config_store import ConfigStore
from omegaconf import MISSING

from ddmr_cli.display import RULES as DISPLAY_RULES


def param(default: Any = MISSING, *, unit: str, help: str, range: str = "", model: int | None = None,
          paper: str = "", factory: Callable[[], Any] | None = None, entries: dict | None = None) -> Any:
    """A schema field with its documentation, the one place a key's meaning lives.

    ``unit`` (``"1"`` dimensionless, ``""`` not a number), ``help`` (one line), ``range`` (the valid values, as
    text; :mod:`ddmr_cli.config.validate` enforces them), ``model`` (section of docs/model.md), ``paper``
    (where the paper states it), ``entries`` (documentation of the keys of a free-form dict field).
    ``ddmr run --help`` and ``ddmr explain KEY`` print them."""
    metadata = {"unit": unit, "help": help, "range": range, "model": model, "paper": paper, "entries": entries}
    if factory is not None:
        return field(default_factory=factory, metadata=metadata)
    return field(default=default, metadata=metadata)


TARGET_HELP = ("class instantiated from this node (ddmr_cli.* classes; for controller also a WheelController "
               "subclass of the user's own module on PYTHONPATH, docs/extending.md)")
PER_WHEEL = "a number or a [right, left] pair"


@dataclass
class RobotConfig:
    """Paper Table 2 plus motor constants (docs/model.md §1). Fields as :class:`ddmr_cli.model.robot.Robot`."""

    mass: float = param(unit="kg", help="robot mass m", range="> 0", model=1, paper="Table 2")
    wheel_radius: float = param(unit="m", help="wheel radius R", range="> 0", model=1, paper="Table 2")
    track_width: float = param(unit="m", help="distance between the wheels 2L", range="> 0", model=1,
                               paper="Table 2")
    yaw_inertia: float = param(unit="kg m^2", help="yaw moment of inertia I_z of the robot", range="> 0", model=1,
                               paper="Table 2")
    wheel_inertia: float = param(unit="kg m^2", help="moment of inertia I_w of a wheel", range="> 0", model=1,
                                 paper="Table 2")
    torque_constant: float = param(unit="N m/A", help="motor torque constant k_t, at the wheel", range="> 0",
                                   model=1, paper="not given (docs/model.md §1 Resolution)")
    back_emf_constant: float = param(unit="V s/rad", help="motor back-EMF constant k_e, at the wheel", range="> 0",
                                     model=1, paper="not given (docs/model.md §1 Resolution)")
    armature_resistance: float = param(unit="ohm", help="armature resistance R_a", range="> 0", model=1,
                                       paper="not given (docs/model.md §1 Resolution)")
    viscous_friction: float = param(unit="N m s/rad", help="viscous friction b_v per wheel", range=">= 0", model=1,
                                    paper="not given (docs/model.md §1 Resolution)")
    max_voltage: float = param(unit="V", help="supply voltage U_max: u is saturated to [-U_max, U_max]",
                               range="> 0", model=1, paper="4.1")


@dataclass
class ZoneConfig:
    start: float = param(unit="m", help="distance travelled at which the zone begins",
                         range=">= 0; the first zone starts at 0, starts increasing", model=5, paper="Fig. 3")
    roughness: float = param(unit="rad/s^2", help="scale of the zone's unit Ornstein-Uhlenbeck roughness n(t) in d",
                             range=">= 0", model=5, paper="Fig. 3 (flat 0.1, slightly rough 5, very rough 100)")
    mu: float = param(unit="1", help="rolling-resistance coefficient of the zone", range=">= 0", model=5,
                      paper="Fig. 3 (flat 0.02, slightly rough 0.05, very rough 0.10)")


@dataclass
class TerrainConfig:
    name: str = param(unit="", help="label of the terrain", model=5)
    correlation_time: float = param(unit="s", help="correlation time tau_c of the roughness process",
                                    range="> 0", model=5)
    zones: Dict[str, ZoneConfig] = param(unit="", help="zones along the distance travelled: name -> {start, "
                                         "roughness, mu}", range="at least one zone", model=5, factory=dict)


@dataclass
class PhaseConfig:
    start: float = param(unit="m or s", help="distance travelled (scenario.phase_clock=distance) or time (time) "
                         "at which the phase begins",
                         range=">= 0; the first phase starts at 0, starts increasing", model=5, paper="Fig. 10")
    roughness: bool = param(unit="", help="terrain roughness on in this phase (rolling resistance is always "
                            "on)", range="true | false", model=5, paper="Fig. 10")
    uncertainty: bool = param(unit="", help="damping uncertainty B(t) = B_nom (1 + delta(t)) on in this "
                              "phase", range="true | false", model=5, paper="Fig. 10")


@dataclass
class UncertaintyConfig:
    correlation_time: float = param(unit="s", help="correlation time of the OU process delta(t)", range="> 0",
                                    model=5)
    std: float = param(unit="1", help="standard deviation of delta(t), relative to B_nom", range=">= 0",
                       model=5)
    low: float = param(unit="1", help="lower clip of delta(t)", range="> -1 (the true damping stays positive)",
                       model=5)
    high: float = param(unit="1", help="upper clip of delta(t)", range="> scenario.uncertainty.low", model=5)
    form: str = param(unit="", help="ou: delta(t) an OU process in time; constant: one value per run from the same "
                      "stationary law, held (a fixed unknown parameter; correlation_time unused)",
                      range="ou, constant", model=5)


@dataclass
class ScenarioConfig:
    name: str = param(unit="", help="label of the scenario in tables and figures", model=5)
    phases: Dict[str, PhaseConfig] = param(unit="", help="phases by time: name -> {start, roughness, uncertainty}",
                                           range="at least one phase", model=5, paper="Fig. 10", factory=dict)
    uncertainty: UncertaintyConfig = param(unit="", help="the damping uncertainty delta(t) of uncertain phases "
                                           "(conf/scenario/uncertainty)", model=5, factory=UncertaintyConfig)
    phase_clock: str = param(unit="", help="what phase starts are measured along: the distance the robot has "
                             "travelled [m] (the terrain zones' axis) or time [s]", range="distance | time", model=5,
                             paper="Fig. 10 (in s, at 1 m/s)")


@dataclass
class NDOConfig:
    _target_: str = param("ddmr_cli.control.NonlinearDisturbanceObserver", unit="", help=TARGET_HELP, model=6)
    gain: Any = param(unit="1/s", help="observer gain L (Gamma = L I) of the nonlinear disturbance observer",
                      range=f"> 0; {PER_WHEEL}; dt * L below the integrator's stability limit", model=6,
                      paper="3.2, eqs. (21)-(22), Table 3")


@dataclass
class NNConfig:
    _target_: str = param("ddmr_cli.control.RBFNetworkObserver", unit="", help=TARGET_HELP, model=6)
    n_neurons: int = param(unit="1", help="number of RBF neurons n", range="integer >= 1", model=6,
                           paper="3.3, Table 3")
    width: float = param(unit="rad/s", help="RBF width sigma", range="> 0", model=6,
                         paper="3.3, Table 3 vs text (two readings)")
    learning_rate: Any = param(unit="1/s^2", help="learning rate gamma of W' = -gamma Phi(x) s^T",
                               range=f"> 0; {PER_WHEEL}", model=6, paper="eq. (25), Table 3 vs text (two readings)")
    center_min: float = param(unit="rad/s", help="lowest RBF centre c (centres (c, c), evenly spaced)",
                              range="finite", model=6, paper="3.3")
    center_max: float = param(unit="rad/s", help="highest RBF centre c",
                              range="> controller.nn.center_min when n_neurons > 1", model=6, paper="3.3")


@dataclass
class DisplayConfig:
    """How the report shows a controller (ddmr_cli/report/display.py); every key optional (null: the report's
    default: the name, a free style, after the ranked controllers). Not passed to the controller, not hashed."""

    label: Optional[str] = param(None, unit="", help="label in tables and figures", range=DISPLAY_RULES["label"])
    colour: Optional[str] = param(None, unit="", help="line colour", range=DISPLAY_RULES["colour"])
    dash: Optional[str] = param(None, unit="", help="dash pattern", range=DISPLAY_RULES["dash"])
    marker: Optional[str] = param(None, unit="", help="marker on the line", range=DISPLAY_RULES["marker"])
    width: Optional[float] = param(None, unit="pt", help="line width", range=DISPLAY_RULES["width"])
    rank: Optional[int] = param(None, unit="1", help="order in tables and figures", range=DISPLAY_RULES["rank"])


DISPLAY_HELP = "how the report shows the controller: label, colour, dash, marker, width, rank (null: its defaults)"


@dataclass
class PIDConfig:
    _target_: str = param("ddmr_cli.control.PID", unit="", help=TARGET_HELP, model=6)
    kp: Any = param(unit="V s/rad", help="proportional gain K_p on the wheel-speed error e = w_d - w",
                    range=f">= 0; {PER_WHEEL}; the sampled PD loop must be stable at simulation.dt", model=6,
                    paper="Table 3")
    ki: Any = param(unit="V/rad", help="integral gain K_i", range=f">= 0; {PER_WHEEL}", model=6,
                    paper="Table 3")
    kd: Any = param(unit="V s^2/rad", help="derivative gain K_d (backward difference)",
                    range=f">= 0; {PER_WHEEL}; the sampled PD loop must be stable at simulation.dt", model=6,
                    paper="Table 3")
    anti_windup: bool = param(unit="", help="clamp the integrator while the voltage is saturated",
                              range="true | false", model=6)
    display: Optional[DisplayConfig] = param(None, unit="", help=DISPLAY_HELP)


@dataclass
class SMCConfig:
    _target_: str = param("ddmr_cli.control.SMC", unit="", help=TARGET_HELP, model=6)
    name: str = param(unit="", help="label of the controller in tables and figures", model=6)
    lam: Any = param(unit="1/s", help="lambda: linear term of the reaching law (integral surface: "
                     "s = e + lambda int e)", range=f"> 0; {PER_WHEEL}; dt * (lam + switching_gain/boundary_layer) "
                     "below the integrator's stability limit", model=6, paper="3.1, eq. (17), Table 3")
    switching_gain: Any = param(unit="rad/s^2", help="switching gain K of K sat(s/Phi)",
                                range=f">= 0; {PER_WHEEL}; dt * (lam + switching_gain/boundary_layer) below the "
                                "integrator's stability limit", model=6, paper="3.1, eq. (17), Table 3")
    boundary_layer: float = param(unit="rad/s", help="boundary layer Phi of sat(s/Phi) and tanh(s/Phi)",
                                  range="> 0", model=6, paper="Table 3")
    surface: str = param(unit="", help="sliding surface: s = e (eq. 10) or s = e + lambda int e",
                         range="proportional | integral", model=6, paper="eq. (10)")
    switching: str = param(unit="", help="switching function of the reaching law", range="sign | sat | tanh",
                           model=6, paper="3.1")
    ndo: Optional[NDOConfig] = param(None, unit="", help="nonlinear disturbance observer (null: none)", model=6,
                                     paper="3.2")
    nn: Optional[NNConfig] = param(None, unit="", help="RBF neural-network observer (null: none)", model=6,
                                   paper="3.3")
    display: Optional[DisplayConfig] = param(None, unit="", help=DISPLAY_HELP)


@dataclass
class AdaptiveSMCConfig(SMCConfig):
    _target_: str = param("ddmr_cli.control.AdaptiveSMC", unit="", help=TARGET_HELP, model=6)
    switching_gain: Any = param(unit="rad/s^2", help="initial switching gain K(0) of the adapted K(t)",
                                range=f"in [gain_min, gain_max]; {PER_WHEEL}", model=6)
    adaptation_rate: Any = param(unit="1/s^2", help="gamma of K' = gamma |s| - sigma K (outside the dead zone)",
                                 range=f"> 0; {PER_WHEEL}", model=6)
    leakage: float = param(unit="1/s", help="sigma of K' = gamma |s| - sigma K: K relaxes towards gamma |s| / sigma",
                           range=">= 0", model=6)
    dead_zone: float = param(unit="rad/s", help="eps: K is held while |s| < eps", range=">= 0", model=6)
    gain_min: float = param(unit="rad/s^2", help="K_min: lower clip of K", range=">= 0", model=6)
    gain_max: float = param(unit="rad/s^2", help="K_max: upper clip of K",
                            range=">= controller.gain_min; dt * (lam + gain_max/boundary_layer) below the "
                            "integrator's stability limit", model=6)


@dataclass
class STAConfig:
    _target_: str = param("ddmr_cli.control.SuperTwisting", unit="", help=TARGET_HELP, model=6)
    name: str = param(unit="", help="label of the controller in tables and figures", model=6)
    k1: Any = param(unit="(rad/s)^(1/2)/s", help="super-twisting gain k1 of k1 |s|^(1/2) sign(s) (s = w_d - w)",
                    range=f"> 0; {PER_WHEEL}; sufficient with |(d - d_hat)'| <= L: k1^2 >= 4 L (k2 + L) / (k2 - L) "
                    "(the default is the common 1.5 sqrt(L), docs/model.md §6)", model=6)
    k2: Any = param(unit="rad/s^3", help="super-twisting gain k2 of v' = k2 sign(s)",
                    range=f"> 0; {PER_WHEEL}; k2 > L, the bound on |(d - d_hat)'|", model=6)
    anti_windup: bool = param(unit="", help="hold v (the integral of k2 sign(s)) while the wheel is saturated and "
                              "sign(s) pushes further in", range="true | false", model=6)
    ndo: Optional[NDOConfig] = param(None, unit="", help="nonlinear disturbance observer (null: none)", model=6,
                                     paper="3.2")
    display: Optional[DisplayConfig] = param(None, unit="", help=DISPLAY_HELP)


@dataclass
class ADRCConfig:
    _target_: str = param("ddmr_cli.control.ADRC", unit="", help=TARGET_HELP, model=6)
    name: str = param(unit="", help="label of the controller in tables and figures", model=6)
    bandwidth: float = param(unit="1/s", help="controller bandwidth w_c: u = (w_c (w_d - z1) + w_d' - z2) / b0",
                             range="> 0; dt * w_c below the integrator's stability limit", model=6)
    observer_bandwidth: float = param(unit="1/s", help="ESO bandwidth w_o (double observer pole at -w_o)",
                                      range="> 0; dt * w_o < 2 (Euler ESO); 3-10 x bandwidth advised", model=6)
    display: Optional[DisplayConfig] = param(None, unit="", help=DISPLAY_HELP)


@dataclass
class OpenLoopConfig:
    _target_: str = param("ddmr_cli.control.OpenLoop", unit="", help=TARGET_HELP, model=6)
    voltage: Any = param(unit="V", help="constant voltage, no feedback (plant checks)",
                         range=f"finite; {PER_WHEEL}", model=6)
    display: Optional[DisplayConfig] = param(None, unit="", help=DISPLAY_HELP)


@dataclass
class LineConfig:
    _target_: str = param("ddmr_cli.model.trajectory.StraightLine", unit="", help=TARGET_HELP, model=3)
    speed: float = param(unit="m/s", help="reference speed v_r along the line", range="finite", model=3,
                         paper="4.2")
    heading: float = param(unit="rad", help="direction of the line", range="finite", model=3)
    x0: float = param(unit="m", help="x of the reference at t = 0", range="finite", model=3)
    y0: float = param(unit="m", help="y of the reference at t = 0", range="finite", model=3)


@dataclass
class CircleConfig:
    _target_: str = param("ddmr_cli.model.trajectory.Circle", unit="", help=TARGET_HELP, model=3)
    speed: float = param(unit="m/s", help="reference speed along the circle", range="finite", model=3)
    radius: float = param(unit="m", help="radius of the circle", range="> 0", model=3)


@dataclass
class FigureEightConfig:
    _target_: str = param("ddmr_cli.model.trajectory.FigureEight", unit="", help=TARGET_HELP, model=3)
    amplitude: float = param(unit="m", help="half-width of the figure eight (lemniscate of Gerono)",
                             range="> 0", model=3)
    period: float = param(unit="s", help="time for one figure eight", range="> 0", model=3)


@dataclass
class SinusoidConfig:
    _target_: str = param("ddmr_cli.model.trajectory.Sinusoid", unit="", help=TARGET_HELP, model=3)
    amplitude: float = param(unit="m", help="lateral amplitude A of the lane change y = A sin(2 pi x / lambda)",
                             range="finite", model=3)
    wavelength: float = param(unit="m", help="wavelength lambda of the lane change", range="> 0", model=3)
    speed: float = param(unit="m/s", help="constant speed v_r along the path", range="> 0", model=3)


@dataclass
class OuterLoopConfig:
    """Kanayama gains (docs/model.md §3)."""

    k_x: float = param(unit="1/s", help="Kanayama gain on the longitudinal error e_x", range=">= 0", model=3)
    k_y: float = param(unit="1/m^2", help="Kanayama gain on the lateral error e_y", range=">= 0", model=3)
    k_theta: float = param(unit="1/m", help="Kanayama gain on sin(e_theta) (critically damped: "
                           "2 sqrt(k_y))", range=">= 0", model=3)


@dataclass
class SimulationConfig:
    dt: float = param(unit="s", help="fixed time step of plant, controllers and metrics",
                      range="> 0; <= simulation.duration; small enough that the sampled plant, observer, sliding "
                      "surface and PID loops are stable (checked)", model=4)
    duration: float = param(unit="s", help="simulated time of each run", range="> 0", model=4, paper="4.2")
    integrator: str = param(unit="", help="integration of the plant over a step", range="euler | rk4",
                            model=4)
    initial_pose: List[float] = param(unit="m, m, rad", help="initial pose [x, y, theta] of the robot",
                                      range="3 finite numbers", model=3, paper="4.2")
    initial_wheel_speeds: Any = param(unit="rad/s", help="initial wheel speeds: reference (rolling "
                                      "at v_r), rest, or [w_R, w_L]", range="reference | rest | [w_R, w_L]",
                                      model=4)
    divergence_bound: float = param(unit="m", help="deviation beyond which a run is stopped and marked "
                                    "diverged", range="> 0", model=7)


@dataclass
class MetricsConfig:
    settle_time: float = param(unit="s", help="steady-state metrics (<metric>_ss) count the steps from this time "
                               "on (after the start-up transient of the initial pose offset)",
                               range=">= 0 (from simulation.duration on: no steady step, NaN)", model=7)
    zone_settle_time: float = param(unit="s", help="per zone and phase, steady-state metrics also skip this long "
                                    "after the robot entered it", range=">= 0", model=7)


@dataclass
class SensorConfig:
    """What the controller measures (docs/model.md §10). Fields as :class:`ddmr_cli.model.sensor.Sensor`."""

    kind: str = param(unit="", help="ideal: the truth; encoder: quantised wheel angles, speed by finite difference; "
                      "noisy: truth + Gaussian noise", range="ideal | encoder | noisy", model=10,
                      paper="conclusion (measurement noise named as a limit)")
    counts_per_rev: int = param(unit="1", help="encoder counts per wheel revolution N (sensor.kind=encoder)",
                                range="integer >= 1", model=10)
    speed_filter: float = param(unit="s", help="time constant of the first-order low-pass on the encoder speed "
                                "(0: none)", range=">= 0", model=10)
    pose: str = param(unit="", help="pose of an encoder sensor: dead reckoning of the quantised wheels, or the true "
                      "pose + noise (position_std, heading_std)", range="odometry | noisy", model=10)
    speed_std: float = param(unit="rad/s", help="std of the Gaussian noise on each measured wheel speed",
                             range=">= 0; 0 for sensor.kind=ideal", model=10)
    position_std: float = param(unit="m", help="std of the Gaussian noise on the measured x and y",
                                range=">= 0; 0 for sensor.kind=ideal", model=10)
    heading_std: float = param(unit="rad", help="std of the Gaussian noise on the measured heading",
                               range=">= 0; 0 for sensor.kind=ideal", model=10)


@dataclass
class ActuatorConfig:
    """Between the controller and the motor (docs/model.md §10). Fields as :class:`ddmr_cli.model.actuator.Actuator`."""

    delay: float = param(unit="s", help="transport delay from the controller's output to the motor driver",
                         range=">= 0; a whole number of plant periods simulation.dt", model=10,
                         paper="conclusion (delay named as a limit)")
    lag: float = param(unit="s", help="time constant of the motor driver's first-order lag (0: none)",
                       range=">= 0", model=10)
    pwm_bits: int = param(unit="bit", help="PWM resolution of the voltage magnitude, levels U_max/(2^bits - 1) "
                          "apart (0: a continuous voltage)", range="integer 0 .. 32", model=10)


@dataclass
class ControlConfig:
    rate: Optional[float] = param(unit="Hz", help="rate of the controller, sensor and outer loop (zero-order hold "
                                  "between control instants); null: every plant step (1/simulation.dt)",
                                  range="null or > 0, <= 1/simulation.dt and dividing it; the controller's loops "
                                  "stable at the control period", model=10,
                                  paper="conclusion (real-time implementation named as a limit)")


@dataclass
class RunConfig:
    n_runs: int = param(unit="1", help="seeds per job; Table 4 statistics are across them",
                        range="integer >= 1", model=7, paper="Table 4 (50 runs)")
    base_seed: int = param(unit="1", help="first seed: a job runs seeds base_seed .. base_seed + n_runs - 1",
                           range="integer >= 0", model=5)
    keep_series: Any = param(unit="1", help="runs whose full time series are saved (series.npz, figures): "
                             "first:N (the job's first N seeds, any base_seed), all, none, or a list of seeds",
                             range="first:N | all | none | [seeds among base_seed .. base_seed + n_runs - 1]")
    max_memory_gb: Optional[float] = param(unit="GB", help="memory budget: a job (the jobs of a sweep running at "
                                           "once) whose estimate exceeds it is refused before it starts",
                                           range="null (80% of the available memory) or > 0")
    plots: bool = param(unit="", help="PNG plots of the first kept seed in each job dir",
                        range="true | false")
    progress: bool = param(unit="", help="progress lines on the terminal and in the log",
                           range="true | false")
    bands: bool = param(unit="", help="mean and 5-95 % band over all seeds of deviation, pose errors, u and s at "
                        "every grid step (bands.npz, drawn in the report's time-series figures)",
                        range="true | false", model=7)
    threads: int = param(unit="1", help="threads of the compiled engine (0: all cores for a single run or a sweep "
                         "whose jobs run one after another in this process, launcher=basic; 1 per job of a sweep in "
                         "parallel processes)", range="integer >= 0")


@dataclass
class ReportConfig:
    auto: bool = param(unit="", help="write the report (ddmr report) when the run or sweep ends; "
                       "report=true is short for report.auto=true", range="true | false")
    margin: Optional[str] = param(unit="m or %", help="practical margin of the report's verdicts, with its unit: "
                                  "a paired difference whose 95% CI lies inside it refutes a claimed improvement "
                                  "(null: 0.1 mm or 5% of the reference's mean, whichever is smaller, for metrics "
                                  "in metres; 5% for the others)",
                                  range="null, a length with its unit (0.05mm, 50um, 5e-5m) or a percentage (2%); "
                                        "a bare number is refused", model=7)


@dataclass
class HeldOutConfig:
    base_seed: int = param(unit="1", help="first held-out seed of the tuned-gains evaluation (ddmr report on a study)",
                           range="integer >= 0; the held-out seeds must not overlap the tuning seeds", model=9)
    n_runs: int = param(unit="1", help="held-out seeds per controller and scenario", range="integer >= 1", model=9)


@dataclass
class TuningConfig:
    """A gain-tuning study (``ddmr run -m +tune=<controller>``; docs/model.md §9). The search space is the Optuna
    sweeper's ``hydra.sweeper.params``; the trial's seeds are ``run.base_seed .. + run.n_runs - 1``."""

    controller: str = param(unit="", help="the controller option tuned (conf/controller/<name>.yaml)", model=9)
    objective: str = param(unit="", help="deviation: minimise the mean deviation (TPE); pareto: deviation against "
                           "chattering (NSGA-II), a Pareto front", range="deviation | pareto", model=9)
    n_trials: int = param(unit="1", help="the study's budget: trials in all (a resumed study runs the rest)",
                          range="integer >= 1", model=9)
    batch: int = param(unit="1", help="trials asked of the sampler at once and launched together (the launcher runs "
                       "them in parallel); fixed, so the sampled gains do not depend on the launcher",
                       range="integer >= 1", model=9)
    seed: int = param(unit="1", help="seed of the Optuna sampler (a resumed study continues with seed + trials done)",
                      range="integer >= 0", model=9)
    saturation_limit: float = param(unit="1", help="constraint: mean fraction of steps with a wheel at +-U_max; a "
                                    "trial above it (or with a diverged run) is infeasible and penalised",
                                    range="0 <= limit < 1", model=9)
    scenarios: Dict[str, ScenarioConfig] = param(unit="", help="the scenarios every trial simulates (the objective "
                                                 "is the mean over them)", range="at least one", model=9,
                                                 factory=dict)
    held_out: HeldOutConfig = param(unit="", help="held-out seeds of the evaluation at tuned gains", model=9,
                                    factory=HeldOutConfig)


#: documentation of the launcher presets' ``cluster`` keys (conf/launcher/*.yaml), not model numbers
CLUSTER_KEYS = MappingProxyType({
    "cpus": ("1", "cpus: processes for the joblib launcher (-1 = all cores), cpus per job for submitit and ray"),
    "partition": ("", "SLURM partition (-p); null = the cluster's default"),
    "time_min": ("min", "wall-time limit per job"),
    "mem_gb": ("GB", "memory per job"),
    "jobs": ("1", "SLURM array tasks running at once"),
    "address": ("", "Ray cluster address (ray://host:10001); null = start Ray locally"),
})


@dataclass
class WheelPlantConfig:
    """The paper's plant (docs/model.md §1, §5), inlined in the step loop (``wheel``) or stepped from Python
    (``wheel_python``, the external-plant contract's reference): nothing to set but its name."""

    name: str = param("wheel", unit="", help="the plant: wheel (the paper's 2x2 wheel model, compiled) | "
                      "wheel_python (the same, stepped from Python)", model=13)


PLANT_MODEL = 13  # docs/model.md §13, the physics plant


@dataclass
class HeightfieldSchema:
    resolution: float = param(unit="m", help="grid spacing of the heightfield", model=PLANT_MODEL,
                              range="> 0; <= robot.wheel_radius / 2 and <= correlation_length / 2")
    x_min: float = param(unit="m", help="the field's start along x (behind the start pose)", model=PLANT_MODEL)
    x_max: float = param(unit="m", help="the field's end along x (past the path)", range="> x_min",
                         model=PLANT_MODEL)
    half_width: float = param(unit="m", help="the field spans y in [-half_width, half_width]", range="> 0",
                              model=PLANT_MODEL)
    origin: float = param(unit="m", help="x where the reference line starts: zone starts are distances from it",
                          range="inside (x_min, x_max)", model=PLANT_MODEL)
    correlation_length: float = param(unit="m", help="l of the heights' Gaussian correlation exp(-r^2/l^2) [13d]",
                                      range="> 0", model=PLANT_MODEL)
    truncation: float = param(unit="1", help="heights clipped at +-truncation x the zone's height SD [13e]",
                              range="> 0", model=PLANT_MODEL)
    ramp: float = param(unit="m", help="a zone's height SD ramps from the previous zone's over its first metres",
                        range=">= 0", model=PLANT_MODEL)


@dataclass
class PlantWheelSchema:
    shape: str = param(unit="", help="collision shape of the driven wheels", range="sphere | cylinder",
                       model=PLANT_MODEL)
    mass: float = param(unit="kg", help="each driven wheel's mass, part of robot.mass", range="> 0",
                        model=PLANT_MODEL)
    width: float = param(unit="m", help="tyre width (cylinder shape)", range="> 0", model=PLANT_MODEL)
    friction: float = param(unit="1", help="sliding friction coefficient tyre-ground", range="> 0",
                            model=PLANT_MODEL)
    torsional_friction: float = param(unit="m", help="MuJoCo's torsional friction (spin about the contact normal)",
                                      range=">= 0", model=PLANT_MODEL)


@dataclass
class CasterSchema:
    radius: float = param(unit="m", help="ball casters' radius (frictionless)", range="> 0", model=PLANT_MODEL)
    offset: float = param(unit="m", help="one caster ahead of and one behind the axle", range="> 0",
                          model=PLANT_MODEL)
    mass: float = param(unit="kg", help="each caster's mass, part of robot.mass", range="> 0", model=PLANT_MODEL)
    stiffness: float = param(unit="N/m", help="each caster's vertical spring", range="> 0; timestep < "
                             "2 sqrt(mass / stiffness)", model=PLANT_MODEL)
    damping: float = param(unit="N s/m", help="each caster spring's damper", range=">= 0", model=PLANT_MODEL)


@dataclass
class ChassisSchema:
    length: float = param(unit="m", help="collision box length (mass and inertia come from conf/robot)",
                          range="> 0", model=PLANT_MODEL)
    width: float = param(unit="m", help="collision box width", range="> 0", model=PLANT_MODEL)
    height: float = param(unit="m", help="collision box height", range="> 0", model=PLANT_MODEL)
    clearance: float = param(unit="m", help="box bottom above the ground at rest", range="> 0", model=PLANT_MODEL)


@dataclass
class ContactSchema:
    timeconst: float = param(unit="s", help="MuJoCo solref time constant of every contact",
                             range=">= 2 x timestep", model=PLANT_MODEL)
    dampratio: float = param(unit="1", help="MuJoCo solref damping ratio (1 = critically damped)", range="> 0",
                             model=PLANT_MODEL)


@dataclass
class PlantDivergenceSchema:
    tip_angle: float = param(unit="rad", help="chassis tilt from upright beyond which the robot has tipped over",
                             range="(0, pi)", model=PLANT_MODEL)
    airborne_time: float = param(unit="s", help="neither wheel touching the ground this long: a diverged run",
                                 range="> 0", model=PLANT_MODEL)


@dataclass
class MujocoPlantConfig:
    """The rigid-body plant (docs/model.md §13). Fields as :class:`ddmr_cli.plant.mujoco_model.PhysicsConfig`."""

    name: str = param("mujoco", unit="", help="the plant: mujoco (the robot as a rigid body on a heightfield; the "
                      "physics extra)", model=PLANT_MODEL)
    timestep: float = param(unit="s", help="MuJoCo's step", range="> 0; simulation.dt a whole multiple of it",
                            model=PLANT_MODEL)
    threads: int = param(unit="1", help="threads stepping a batch's runs, the caller's included; 0 = "
                         "run.threads' choice (1 per job of a sweep in parallel processes, else one per 12 runs, at "
                         "most every core)",
                         range=">= 0", model=PLANT_MODEL)
    settle_time: float = param(unit="s", help="the robot settles onto its ground (held still) before the run",
                               range=">= 0", model=PLANT_MODEL)
    heightfield: HeightfieldSchema = param(unit="", help="the ground's extent and roughness mapping",
                                           model=PLANT_MODEL, factory=HeightfieldSchema)
    wheel: PlantWheelSchema = param(unit="", help="the driven wheels' collision geometry", model=PLANT_MODEL,
                                    factory=PlantWheelSchema)
    caster: CasterSchema = param(unit="", help="the two ball casters", model=PLANT_MODEL, factory=CasterSchema)
    chassis: ChassisSchema = param(unit="", help="the chassis's collision box", model=PLANT_MODEL,
                                   factory=ChassisSchema)
    contact: ContactSchema = param(unit="", help="MuJoCo's soft-contact parameters", model=PLANT_MODEL,
                                   factory=ContactSchema)
    divergence: PlantDivergenceSchema = param(unit="", help="when a run has diverged on this plant",
                                              model=PLANT_MODEL, factory=PlantDivergenceSchema)


@dataclass
class DDMRConfig:
    robot: RobotConfig = param(unit="", help="the robot and its motors (conf/robot)", model=1)
    terrain: TerrainConfig = param(unit="", help="terrain zones along the distance travelled (conf/terrain)",
                                   model=5)
    controller: Any = param(unit="", help="wheel-speed controller (conf/controller)", model=6)
    scenario: ScenarioConfig = param(unit="", help="scenario phases and damping uncertainty (conf/scenario)",
                                     model=5)
    trajectory: Any = param(unit="", help="reference trajectory (conf/trajectory)", model=3)
    outer_loop: OuterLoopConfig = param(unit="", help="Kanayama outer loop: pose error -> wheel-speed references",
                                        model=3, factory=OuterLoopConfig)
    simulation: SimulationConfig = param(unit="", help="time stepping, initial state, divergence", model=4,
                                         factory=SimulationConfig)
    sensor: SensorConfig = param(unit="", help="what the controller measures (conf/sensor)", model=10)
    actuator: ActuatorConfig = param(unit="", help="PWM, delay and driver lag before the motor (conf/actuator)",
                                     model=10)
    control: ControlConfig = param(unit="", help="the controller's rate", model=10, factory=ControlConfig)
    plant: Any = param(unit="", help="the plant the controllers drive (conf/plant): wheel, the paper's 2x2 wheel "
                       "model (default); mujoco, the robot as a rigid body on a heightfield (the physics extra; "
                       "its keys and units in conf/plant/mujoco.yaml)", model=13, factory=lambda: {"name": "wheel"})
    metrics: MetricsConfig = param(unit="", help="how the run metrics are counted", model=7,
                                   factory=MetricsConfig)
    run: RunConfig = param(unit="", help="seeds, kept series and display settings of a job", factory=RunConfig)
    experiment_name: str = param(unit="", help="first level of the output dir outputs/<experiment_name>/")
    cluster: Dict[str, Any] = param(unit="", help="launcher settings set by conf/launcher presets",
                                    entries=CLUSTER_KEYS, factory=dict)
    tags: Dict[str, Any] = param(unit="", help="free-form labels recorded with the results (+tags.note=...); not "
                                 "used by the model", factory=dict)
    report: ReportConfig = param(unit="", help="the report written at the end of a run or sweep",
                                 factory=ReportConfig)
    tuning: Optional[TuningConfig] = param(unit="", help="gain-tuning study set by +tune=<controller> (null: none)",
                                           model=9)
    study: Any = param(None, unit="", help="sensitivity study of the paper's claims (conf/study, set by the "
                       "+experiment=sensitivity_* presets; null: a plain run)", model=11)


def register_configs() -> None:
    """Register the schemas; idempotent."""
    cs = ConfigStore.instance()
    cs.store(name="ddmr_schema", node=DDMRConfig)
    for name, node in [
        ("robot", RobotConfig), ("terrain", TerrainConfig), ("scenario", ScenarioConfig),
        ("sensor", SensorConfig), ("actuator", ActuatorConfig),
        ("plant_wheel", WheelPlantConfig), ("plant_mujoco", MujocoPlantConfig),
        ("controller_pid", PIDConfig), ("controller_smc", SMCConfig), ("controller_open_loop", OpenLoopConfig),
        ("controller_adaptive_smc", AdaptiveSMCConfig), ("controller_sta", STAConfig), ("controller_adrc", ADRCConfig),
        ("trajectory_line", LineConfig), ("trajectory_circle", CircleConfig),
        ("trajectory_figure_eight", FigureEightConfig), ("trajectory_sinusoid", SinusoidConfig),
    ]:
        # root-level names (not groups), so `ddmr run --help` lists only the real options
        cs.store(name=f"schema_{name}", node=node)


register_configs()
