"""Sensors, actuator and control rate (docs/model.md §10): the laws against their closed forms, the engine's
zero-order hold and delay, bit-identity with every effect off, determinism with every effect on, validation."""

from __future__ import annotations

import math

import numpy as np
import pytest
from conftest import catalogue

import ddmr_cli.engine.simulation as simulation_module
from ddmr_cli import ConfigError, paper_simulation, simulate
from ddmr_cli.engine.batch import RUN_FIELDS
from ddmr_cli.model.noise import NoiseStreams, SensorNoise
from ddmr_cli.model import actuator, sensor
from ddmr_cli.model.actuator import Actuator
from ddmr_cli.model.sensor import NOISE_CHANNELS, SENSOR_FIELDS, Sensor

SHORT = ("terrain=paper", "simulation.duration=0.3")
#: every effect on at once: encoder wheels with speed noise and a noisy pose fix, the realistic driver, 250 Hz
EVERYTHING = ("sensor=encoder", "sensor.pose=noisy", "sensor.speed_std=0.05", "sensor.speed_filter=0.004",
              "actuator=realistic", "control.rate=250")
#: every effect off, spelt out (the non-ideal code paths with zero noise, zero delay, control at the plant rate)
ALL_OFF = ("sensor=noisy", "sensor.speed_std=0", "sensor.position_std=0", "sensor.heading_std=0",
           "actuator.delay=0", "actuator.lag=0", "actuator.pwm_bits=0", "control.rate=1000")


def make_sensor(**values) -> Sensor:
    base = dict(kind="encoder", counts_per_rev=1024, speed_filter=0.0, pose="odometry", speed_std=0.0,
                position_std=0.0, heading_std=0.0)
    return Sensor(**{**base, **values})


def sensor_run(x=0.0, y=0.0, theta=0.0):
    run = np.zeros(1, dtype=np.dtype(RUN_FIELDS + SENSOR_FIELDS))
    run["x"], run["y"], run["theta"] = x, y, theta
    return run


def run_sim(*overrides, seeds=(0, 1, 2), keep=(1,), threads=1, controller="smc_ndo_nno"):
    sim = paper_simulation(f"controller={controller}", *SHORT, *overrides)
    return simulate(sim, seeds=list(seeds), keep_series=list(keep), threads=threads)


def assert_same(a, ia, b, ib, series_seed=None):
    for name in a.metrics:
        assert np.array_equal(a.metrics[name][ia], b.metrics[name][ib], equal_nan=True), name
    if series_seed is not None:
        for ch in a.series[series_seed]:
            assert np.array_equal(a.series[series_seed][ch], b.series[series_seed][ch], equal_nan=True), ch


# --- the laws ----------------------------------------------------------------------------------------------------

@pytest.mark.parametrize("counts", [1, 7, 256, 1024, 4096])
def test_quantisation_error_stays_within_half_a_count(counts):
    q = 2 * math.pi / counts
    angles = np.concatenate([np.random.default_rng(counts).uniform(-500.0, 500.0, 2000),
                             q * (np.arange(-50, 50) + 0.5), q * np.arange(-50, 50)])
    read = np.array([sensor.quantise(a, q) for a in angles])
    assert np.all(np.abs(read - angles) <= 0.5 * q * (1 + 1e-9))
    n = read / q
    assert np.allclose(n, np.round(n), rtol=0, atol=1e-6)  # whole counts
    assert np.abs(read - angles).max() > 0.45 * q  # and really quantised


@pytest.mark.parametrize("w", [33.3, -12.7, 0.4])
@pytest.mark.parametrize("period_steps", [1, 5])
def test_finite_difference_of_a_constant_speed_wheel_is_within_one_count_per_period(w, period_steps):
    dt, counts = 1e-3, 1024
    period, q = period_steps * dt, 2 * math.pi / counts
    p = make_sensor(counts_per_rev=counts).law_parameters(period)
    run = sensor_run()
    sensor.start(p, run[0], w, w)
    xi = np.zeros(len(NOISE_CHANNELS))
    errors = []
    for k in range(400):
        if k % period_steps == 0:
            m_R, m_L, *_ = sensor.measure(p, run[0], 0.0, 0.0, 0.0, w, w, xi, 0.03, 0.25)
            errors.append(m_R - w)
        for i in range(2):
            run[0]["wheel_angle"][i] = sensor.wheel_angle(run[0]["wheel_angle"][i], w, w, dt)
    errors = np.abs(errors)
    assert errors.max() <= q / period * (1 + 1e-9)
    assert errors.max() > 0.2 * q / period  # the estimate really is quantised


def test_odometry_of_a_wheel_turn_gives_the_arc():
    R, L, w = 0.03, 0.25, 20.0  # right wheel only: a circle of radius L about the left wheel
    x, y, th = 0.0, 0.0, 0.0
    d = w * 1e-3
    for _ in range(1000):
        x, y, th = sensor.odometry(x, y, th, d, 0.0, R, L)
    phi = R * w * 1.0 / (2 * L)  # heading after 1 s
    assert th == pytest.approx(phi, rel=1e-12)
    assert x == pytest.approx(L * math.sin(phi), rel=1e-6) and y == pytest.approx(L * (1 - math.cos(phi)), rel=1e-6)


def test_low_pass_and_driver_lag_follow_the_exponential():
    tau, dt, u_in, u0 = 0.004, 1e-3, 5.0, -2.0
    a = math.exp(-dt / tau)
    u = u0
    for k in range(1, 30):
        u = actuator.driver_lag(u, u_in, a)
        assert u == pytest.approx(u_in + (u0 - u_in) * math.exp(-k * dt / tau), rel=1e-12)
        assert sensor.low_pass(u0, u_in, a) == pytest.approx(actuator.driver_lag(u0, u_in, a), rel=1e-15)


@pytest.mark.parametrize("bits", [1, 8, 10])
def test_pwm_levels(bits):
    p = Actuator(delay=0.0, lag=0.0, pwm_bits=bits).law_parameters(1e-3, 24.0)
    du = 24.0 / (2**bits - 1)
    assert p.pwm_step == pytest.approx(du)
    for u in np.linspace(-24.0, 24.0, 997):
        level = actuator.pwm(u, p.pwm_step)
        assert abs(level - u) <= 0.5 * du * (1 + 1e-9) and abs(level) <= 24.0 * (1 + 1e-12)
        assert level / du == pytest.approx(round(level / du), abs=1e-9)


def test_sensor_noise_stream_is_its_own():
    a = SensorNoise([3, 4], len(NOISE_CHANNELS)).next_chunk(10)
    b = SensorNoise([4], len(NOISE_CHANNELS)).next_chunk(10)
    assert np.array_equal(a[1], b[0])
    disturbance = NoiseStreams([3]).next_chunk(10)
    assert not np.allclose(a[0, :, :3], disturbance[0], atol=1e-3)


# --- the engine ---------------------------------------------------------------------------------------------------

def test_zero_order_hold_keeps_u_constant_between_control_instants():
    m = 5  # 200 Hz on the 1 kHz plant
    s = run_sim("control.rate=200", controller="smc_ndo_nno").series[1]
    for ch in ("u_command_right", "u_command_left", "u_right", "s_right", "d_hat_nn_left", "w_d_right"):
        held = s[ch].reshape(-1, m)
        assert np.array_equal(held, np.repeat(held[:, :1], m, axis=1)), ch  # bit-copies within a period
        assert np.all(np.abs(np.diff(held[:, 0])) > 0), ch  # and a new value at every control instant


@pytest.mark.parametrize("rate,n", [(None, 3), (250, 2)])
def test_an_n_period_delay_shifts_the_applied_u_by_n_periods(rate, n):
    m = 1 if rate is None else 1000 // rate
    shift = n * m
    extra = () if rate is None else (f"control.rate={rate}",)
    delayed = run_sim(f"actuator.delay={shift * 1e-3}", *extra, controller="smc_ndo").series[1]
    u, uc = delayed["u_right"], np.clip(delayed["u_command_right"], -24.0, 24.0)
    assert np.array_equal(u[shift:], uc[:-shift])  # copies: exactly the command n periods earlier
    assert np.all(u[:shift] == uc[0])  # before the first command arrives, the driver holds it
    assert not np.array_equal(u[shift:], uc[shift:])  # (the command really moves)


def test_every_effect_off_is_bit_identical_to_the_ideal_sensor_and_actuator():
    ideal = run_sim("sensor=ideal", "actuator=ideal")
    off = run_sim(*ALL_OFF)
    assert_same(ideal, slice(None), off, slice(None), series_seed=1)
    assert not np.array_equal(run_sim("sensor=encoder").metrics["deviation_mae"], ideal.metrics["deviation_mae"])


def test_sensor_noise_leaves_the_disturbance_streams_alone():
    # open loop: nothing measured acts on the plant, so the true run is the same with or without sensor noise
    ideal = run_sim(controller="open_loop").series[1]
    noisy = run_sim("sensor=noisy", "sensor.speed_std=1.0", controller="open_loop").series[1]
    for ch in ("d_true_right", "d_true_left", "w_right", "deviation", "damping_scale"):
        assert np.array_equal(noisy[ch], ideal[ch]), ch
    assert np.ptp(ideal["d_true_right"]) > 0.1  # the roughness noise is really there (flat zone: 0.1 rad/s^2)


@pytest.mark.parametrize("effects", [EVERYTHING, pytest.param(("sensor=noisy", "actuator.delay=0.003", "control.rate=500"),
                                                                marks=pytest.mark.slow)])
def test_determinism_with_every_effect_on(effects, monkeypatch):
    batch = run_sim(*effects, seeds=(0, 1, 2, 3), keep=(2,), threads=1)
    alone = run_sim(*effects, seeds=(2,), keep=(2,))
    assert_same(alone, 0, batch, 2, series_seed=2)
    threaded = run_sim(*effects, seeds=(3, 2, 1, 0), keep=(2,), threads=2)
    assert_same(threaded, 1, batch, 2, series_seed=2)
    monkeypatch.setattr(simulation_module, "CHUNK_BUDGET", 1)  # the smallest chunks the engine allows
    chunked = run_sim(*effects, seeds=(0, 1, 2, 3), keep=(2,))
    assert_same(chunked, slice(None), batch, slice(None), series_seed=2)
    assert len(np.unique(batch.metric("deviation_mae"))) == 4


# --- validation ---------------------------------------------------------------------------------------------------

@pytest.mark.parametrize("overrides,key", catalogue([
    (("sensor=noisy", "sensor.speed_std=-0.1"), "sensor.speed_std"),
    (("sensor=noisy", "sensor.position_std=-1"), "sensor.position_std"),
    (("sensor=encoder", "sensor.counts_per_rev=0"), "sensor.counts_per_rev"),
    (("sensor.speed_std=0.1",), "sensor.speed_std"),  # noise on the ideal sensor
    (("sensor=encoder", "sensor.speed_filter=-0.01"), "sensor.speed_filter"),
    (("actuator.delay=0.0015",), "actuator.delay"),  # 1.5 plant periods
    (("actuator.delay=-0.001",), "actuator.delay"),
    (("actuator.pwm_bits=-1",), "actuator.pwm_bits"),
    (("control.rate=2000",), "control.rate"),  # above the 1 kHz plant
    (("control.rate=300",), "control.rate"),  # does not divide it
    (("control.rate=0",), "control.rate"),
    (("controller=pid", "control.rate=200"), "control.rate"),  # the sampled PD loop is unstable at 5 ms
    (("controller=smc", "control.rate=50"), "control.rate"),  # lambda + K/Phi = 145 1/s at 20 ms
], fast=2))
def test_bad_realism_settings_are_refused_naming_the_key(overrides, key):
    with pytest.raises(ConfigError) as err:
        paper_simulation(*overrides).validate()
    assert err.value.key == key


def test_the_controllers_run_at_the_control_period():
    sim = paper_simulation("controller=pid", "control.rate=250")
    sim.validate()
    assert sim.control_steps == 4 and sim.control_dt == pytest.approx(0.004)
    assert paper_simulation("controller=smc_ndo_nno", "control.rate=100").control_steps == 10


# --- the cost of a control step ---------------------------------------------------------------------------------

@pytest.fixture(scope="module")
def counts():
    from ddmr_cli.bench.cost import operation_counts

    return operation_counts(["pid", "smc_ndo_nno"])


def test_operation_counts_match_the_laws_read_by_hand(counts):
    # PID per step (pid.py): e = w_d - w (2 add); e' = (e - e_prev) * (1/dt) (2 add, 2 div, 2 mul, not at step 0);
    # u = kp e + ki I + kd e' (6 mul, 4 add); update: dt * (w_d - w) added to I (2 mul, 4 add). 200 steps.
    pid = counts["pid"]
    assert pid["add"] == pytest.approx(12 - 2 / 200) and pid["mul"] == pytest.approx(10 - 2 / 200)
    assert pid["div"] == pytest.approx(2 - 2 / 200) and pid["transcendental"] == 0
    nno = counts["smc_ndo_nno"]
    # one exp per neuron (both wheels share it), the far ones too (rbf.basis: elementary.exp_neg is 0 below its
    # range at the cost of any other)
    assert nno["transcendental"] == pytest.approx(10)
    assert nno["add"] > 4 * 10 and nno["mul"] > 6 * 10  # basis, estimate and update: a few per neuron and wheel


def test_counting_leaves_every_module_its_math_and_a_module_imported_later_is_counted():
    """The counter swaps ``math`` in the laws' modules for a counting one and puts the real one back: a controller
    whose modules are imported after an earlier count (the control package imports each on first use) is counted
    in full, and no module keeps a counting ``math`` (it did: the counter swapped its own module's ``math`` too,
    and then put that back in the others) or a counting function of ``elementary``."""
    import os
    import subprocess
    import sys

    code = ("import json, math, sys; from ddmr_cli.bench.cost import packaged_counts; "
            "pid = packaged_counts(['pid']); later = sys.modules.get('ddmr_cli.control.rbf') is None; "
            "nno = packaged_counts(['smc_ndo_nno'])['smc_ndo_nno']; "
            "from ddmr_cli.model import elementary as e; "
            "kept = sorted(n for n, m in sys.modules.items() if n.startswith('ddmr_cli') "
            "and (hasattr(m, 'math') and m.math is not math or getattr(m, 'exp_neg', e.exp_neg) is not e.exp_neg "
            "or getattr(m, 'sincos', e.sincos) is not e.sincos)); "
            "print(json.dumps([later, nno['transcendental'], kept]))")
    out = subprocess.run([sys.executable, "-c", code], env={**os.environ, "NUMBA_DISABLE_JIT": "1"},
                         capture_output=True, text=True, check=True, timeout=300).stdout
    later, transcendental, kept = __import__("json").loads(out.strip().splitlines()[-1])
    assert later  # the NN's module was imported after the first count
    assert transcendental == pytest.approx(10)  # one elementary.exp_neg per neuron
    assert kept == []


def test_operation_counts_are_kept_by_what_they_are_a_function_of(tmp_path, monkeypatch):
    """Counts are counted once per key (the laws' sources, the parameters, dt), kept in the cache dir and read
    back; a controller whose key changed is counted again, alone."""
    import json
    import subprocess as real_subprocess

    from ddmr_cli.bench import cost

    counted = []

    def fake_run(argv, **kwargs):
        names = argv[3:]
        counted.append(names)
        out = json.dumps({name: {"add": float(len(name) + len(counted))} for name in names})
        return real_subprocess.CompletedProcess(argv, 0, stdout=out + "\n", stderr="")

    monkeypatch.setattr(cost.subprocess, "run", fake_run)
    keys = {"pid": "k1", "smc": "k2"}
    first = cost.operation_counts(["pid", "smc"], keys, tmp_path)
    assert counted == [["pid", "smc"]] and first == {"pid": {"add": 4.0}, "smc": {"add": 4.0}}
    assert cost.operation_counts(["pid", "smc"], keys, tmp_path) == first and len(counted) == 1
    again = cost.operation_counts(["pid", "smc"], {"pid": "k1", "smc": "k3"}, tmp_path)
    assert counted[1] == ["smc"] and again == {"pid": {"add": 4.0}, "smc": {"add": 5.0}}
    assert cost.operation_counts(["pid"], keys) == {"pid": {"add": 6.0}}  # no cache: always counted


def test_the_counts_key_follows_the_parameters_and_the_step():
    from ddmr_cli import paper_controller, paper_robot
    from ddmr_cli.bench.cost import counts_key
    from ddmr_cli.model.robot import NominalModel

    nominal = NominalModel.from_robot(paper_robot())
    base = counts_key(paper_controller("smc_ndo"), nominal, 0.001)
    assert base == counts_key(paper_controller("smc_ndo"), nominal, 0.001)
    assert base != counts_key(paper_controller("smc_ndo", "controller.switching_gain=21"), nominal, 0.001)
    assert base != counts_key(paper_controller("smc_ndo"), nominal, 0.002)
    assert base != counts_key(paper_controller("smc_ndo_nno"), nominal, 0.001)


def test_m4f_estimate_is_the_stated_cycle_model():
    from ddmr_cli.bench.cost import M4F_CYCLES, M4F_OVERHEAD, m4f_cycles

    ops = {"add": 10, "mul": 5, "div": 2, "cmp": 3, "transcendental": 1}
    expected = M4F_OVERHEAD * (10 * M4F_CYCLES["add"] + 5 * M4F_CYCLES["mul"] + 2 * M4F_CYCLES["div"]
                               + 3 * M4F_CYCLES["cmp"] + M4F_CYCLES["transcendental"])
    assert m4f_cycles(ops) == pytest.approx(expected)


def test_the_compiled_step_timing_runs_the_laws():
    from ddmr_cli import paper_controller, paper_robot
    from ddmr_cli.bench.cost import control_steps, inputs, time_per_step
    from ddmr_cli.model.robot import NominalModel

    pid = paper_controller("pid")
    nominal = NominalModel.from_robot(paper_robot())
    w, wd, wdd = inputs(50, 1e-3)
    state = pid.initial_state(1)
    total = control_steps(pid, pid.law_parameters(nominal, 1e-3), state, w, wd, wdd)
    e = wd - w  # the proportional part dominates: u ~ kp e per wheel
    assert abs(total) > 0 and np.sign(total) == np.sign(e.sum())
    fastest, median = time_per_step(pid, nominal, 1e-3, n=200, repeats=3)
    assert 0 < fastest <= median < 1e5


@pytest.mark.slow
@pytest.mark.parametrize("bad", ["control.rate=300", "actuator.delay=0.0025", "sensor=encoder sensor.counts_per_rev=0"])
def test_the_cli_refuses_bad_realism_settings_in_one_line(tmp_path, bad):
    from conftest import run_ddmr

    proc = run_ddmr(["run", *bad.split(), "run.n_runs=1", "hydra.run.dir=out"], cwd=tmp_path)
    assert proc.returncode == 2
    assert proc.stderr.strip().count("\n") == 0 and proc.stderr.startswith("ddmr: error: ")
    assert not (tmp_path / "out").exists()


# --- odometry over a whole run (issue 25: it once started one control period ahead of the true pose) -----------

def _odometry_along(series, counts: int, rate: float, dt: float = 1e-3):
    """Replay the encoder laws on a kept run's true wheel speeds and pose, as the engine does (trapezoidal wheel
    angles every plant step, a reading every control period); returns the true and the odometry poses at every
    control instant."""
    from ddmr_cli.compiled import plain

    robot = paper_simulation().robot
    R, L = robot.wheel_radius, robot.half_track
    p = make_sensor(counts_per_rev=counts).law_parameters(1.0 / rate)
    run = sensor_run(series["x"][0], series["y"][0], series["theta"][0])[0]
    w_R, w_L = series["w_right"], series["w_left"]
    plain(sensor.start)(p, run, w_R[0], w_L[0])
    m = int(round(1.0 / (rate * dt)))
    truth, odo = [], []
    for k in range(len(w_R)):
        if k % m == 0:
            _, _, mx, my, mth = plain(sensor.measure)(p, run, series["x"][k], series["y"][k], series["theta"][k],
                                                      w_R[k], w_L[k], np.zeros(5), R, L)
            truth.append((series["x"][k], series["y"][k], series["theta"][k]))
            odo.append((mx, my, mth))
        if k + 1 < len(w_R):
            for i, w in enumerate((w_R, w_L)):
                run["wheel_angle"][i] = plain(sensor.wheel_angle)(run["wheel_angle"][i], w[k], w[k + 1], dt)
    return np.array(truth), np.array(odo), R, L


@pytest.mark.parametrize("rate", [1000.0, 500.0, 250.0])
def test_a_fine_encoders_odometry_is_the_true_pose_to_within_its_quantisation(rate):
    """Over a whole run (1.5 s, the start-up transient included):

    - an unquantised encoder (2^40 counts): the wheel angles are trapezoid-integrated while the plant's pose is
      Euler-integrated, so the odometry's heading differs from the truth by exactly the telescoped
      ``R dt / (4 L) ((w_R,k - w_R,0) - (w_L,k - w_L,0))`` and its position by what that heading difference
      integrates to over the transient (0.15 mm measured, for good); the old odometry added one fictitious
      period's increment at the start and led by v T for the whole run (0.92 mm at 1 kHz, 4 mm at 250 Hz);
    - a fine encoder (65536 counts) against the unquantised one: quantisation telescopes in the sum of the
      increments, so each wheel's angle is off by at most q/2 at any time, the heading by at most R q / (2 L)
      and the position by R q / 2 plus that heading error over the distance travelled D."""
    dt = 1e-3
    s = paper_simulation("controller=smc_ndo", "terrain=paper", "simulation.duration=1.5")
    series = simulate(s, [0], keep_series=[0]).series[0]
    exact_truth, exact_odo, R, L = _odometry_along(series, 2 ** 40, rate)
    m = int(round(1.0 / (rate * dt)))
    w_R, w_L = series["w_right"][::m], series["w_left"][::m]
    scheme = R * dt / (4.0 * L) * ((w_R - w_R[0]) - (w_L - w_L[0]))
    np.testing.assert_allclose(exact_odo[:, 2] - exact_truth[:, 2], scheme, rtol=0, atol=1e-9)
    assert np.hypot(*(exact_odo[:, :2] - exact_truth[:, :2]).T).max() < 2e-4
    q = 2.0 * math.pi / 65536
    _, odo, _, _ = _odometry_along(series, 65536, rate)
    err = np.abs(odo - exact_odo)
    distance = np.hypot(np.diff(exact_truth[:, 0]), np.diff(exact_truth[:, 1])).sum()
    heading_bound = R * q / (2.0 * L)
    assert err[:, 2].max() <= heading_bound * (1 + 1e-9)
    assert np.hypot(err[:, 0], err[:, 1]).max() <= R * q / 2.0 + distance * heading_bound
