"""The rigid-body plant (issue 30; docs/model.md, "Physics plant (MuJoCo)"): the generated MuJoCo model is the
paper's robot (flat-ground step response against the nominal 2x2 model, a closed loop that tracks the line), its
energy and momentum are sane, a robot off the ground is a diverged run and never an exception, bad input is one
line naming the key, the same seed gives the same ground and bit-identical runs whatever the thread count.

mujoco is in the test extra, so these run in CI; they are skipped only where it is not installed.
"""

from __future__ import annotations

import sys
from pathlib import Path

import numpy as np
import pytest

from physics_cases import STEP_VOLTAGE, nominal_step_response, physics_step_response, plant_config, robot, terrain
from ddmr_cli.errors import ConfigError

mujoco = pytest.importorskip("mujoco")

from ddmr_cli.plant.mujoco import MujocoPlant  # noqa: E402  (after the skip: it needs mujoco at construction)
from ddmr_cli.plant.mujoco_model import slope_gain  # noqa: E402

DT = 0.001


def make(terrain_name="paper", dt=DT, **overrides):
    return MujocoPlant(robot(), terrain(terrain_name), plant_config(**overrides), dt)


# -- the model is the paper's robot ------------------------------------------------------------------------------

def test_flat_ground_step_response_matches_the_nominal_model_within_5_percent():
    """No roughness, no rolling resistance (terrain=none): a voltage step from rest excites both modes; the wheel
    speeds stay within 5 % (of the response's peak) of the nominal w' = -J^-1 B w + J^-1 K_u u at every step."""
    plant = make("none", threads=1)
    t, w, d = physics_step_response(plant, STEP_VOLTAGE, 1.0)
    nominal = nominal_step_response(plant.robot, STEP_VOLTAGE, t)
    error = np.abs(w - nominal).max(axis=0) / np.abs(nominal).max(axis=0)
    for k in (10, 100, 1000):
        print(f"t = {t[k]:.2f} s: w = {w[k].round(3)} (MuJoCo), {nominal[k].round(3)} (nominal) rad/s")
    print(f"largest deviation / peak: right {error[0]:.2%}, left {error[1]:.2%}; "
          f"RMS of the true d: {np.sqrt((d ** 2).mean(axis=0)).round(2)} rad/s^2")
    assert np.all(error < 0.05), error
    # and the true d the nominal model leaves unexplained is small against the voltage's own acceleration
    assert np.sqrt((d[50:] ** 2).mean()) < 0.05 * np.abs(plant.robot.input_matrix @ STEP_VOLTAGE).max()


def test_a_proportional_wheel_speed_loop_drives_the_robot_along_the_line():
    """A DDMR: equal wheel speeds v / R drive it straight along its heading at v (flat paper terrain, rolling
    resistance on), x ~ v t, y and theta ~ 0."""
    plant = make("flat", threads=1)
    rob = plant.robot
    v = 0.5
    w_d = np.full((1, 2), v / rob.wheel_radius)
    plant.reset(np.array([3]), np.zeros((1, 3)), w_d)
    kp, steps = 2.0, 4000  # V s/rad; 4 s
    for _ in range(steps):
        w = plant.state()["w"]
        u = rob.damping / rob.voltage_gain * w_d + kp * (w_d - w)
        plant.step(u, np.ones(1))
    s = plant.state()
    print(f"after {steps * DT:g} s: x = {s['x'][0]:.4f} m, y = {s['y'][0]:.5f} m, theta = {s['theta'][0]:.5f} rad, "
          f"w = {s['w'][0].round(3)} rad/s")
    assert not plant.diverged()[0]
    assert abs(s["y"][0]) < 0.01 and abs(s["theta"][0]) < 0.01
    assert s["x"][0] == pytest.approx(v * steps * DT, rel=0.03)
    assert s["distance"][0] == pytest.approx(s["x"][0], rel=1e-3)
    assert np.allclose(s["w"][0], w_d[0], rtol=0.03)


def test_free_rolling_conserves_wheel_momentum_and_energy_and_damping_only_removes_energy():
    """No voltage and no motor damping (b = 0), no rolling resistance: with its centre of mass on the axle the
    robot's wheel-space dynamics are J w' = 0, so the wheel speeds (the generalised momentum J w) would stay
    constant, turning or not. MuJoCo's soft contacts dissipate a little (tyre deformation and slip): the stated
    sense is that the mechanical energy never increases, the height does not change, and the wheel speeds decay no
    faster than a rolling resistance of coefficient 0.005 would make them (a quarter of the paper's flat ground,
    mu = 0.02). With the motor's damping (b = 1) the kinetic energy only decreases, as e^(-2 t B / J) does."""
    plant = make("none", threads=1)
    rob = plant.robot
    w0 = np.array([[10.0, 10.0], [10.0, 4.0]])
    plant.reset(np.array([0, 1]), np.zeros((2, 3)), w0)
    e0 = plant.energy()
    total = [e0.sum(axis=1)]
    for k in range(2000):
        plant.step(np.zeros((2, 2)), np.zeros(2))
        if k % 100 == 99:
            total.append(plant.energy().sum(axis=1))
    e1, w1, seconds = plant.energy(), plant.state()["w"], 2000 * DT
    j_common = rob.inertia.p + rob.inertia.q
    mu_equivalent = j_common * np.abs(w1 - w0).max(axis=1) / seconds / (rob.mass * 9.81 / 2 * rob.wheel_radius)
    print(f"free rolling 2 s: kinetic energy {e0[:, 1].round(5)} -> {e1[:, 1].round(5)} J, potential "
          f"{e0[:, 0].round(5)} -> {e1[:, 0].round(5)} J, wheel speeds {w0.tolist()} -> {w1.round(4).tolist()} "
          f"rad/s: as a rolling resistance mu = {mu_equivalent.round(4)}")
    # kinetic + gravity + caster springs never grows (every 0.1 s), but for the contacts' own elastic energy, which
    # MuJoCo does not count: the weight m g over 0.05 mm of contact deformation
    assert np.all(np.diff(total, axis=0) <= rob.mass * 9.81 * 5e-5), np.diff(total, axis=0).max()
    assert np.all(mu_equivalent < 0.005)
    assert np.allclose(e1[:, 0], e0[:, 0], atol=0.01 * e0[:, 1].min())  # flat: no height gained or lost
    plant.reset(np.array([0, 1]), np.zeros((2, 3)), w0)
    energy = [plant.energy()]
    for k in range(1000):
        plant.step(np.zeros((2, 2)), np.ones(2))
        if k % 10 == 9:
            energy.append(plant.energy())
    energy = np.array(energy)
    assert np.all(np.diff(energy.sum(axis=2), axis=0) <= rob.mass * 9.81 * 5e-5)
    assert np.all(energy[-1, :, 1] < 1e-3 * energy[0, :, 1])


def test_the_true_disturbance_is_what_the_nominal_model_does_not_explain():
    """On flat ground with rolling resistance mu, the true d at cruise is about -J^-1 mu m g R / 2 (both wheels),
    the wheel plant's rolling-resistance term; with damping scale b it gains -J^-1 B (b - 1) w."""
    plant = make("flat", threads=1)
    rob = plant.robot
    w_c = np.full((1, 2), 20.0)
    jinv = rob.inverse_inertia
    for b in (1.0, 1.5):
        plant.reset(np.array([0]), np.zeros((1, 3)), w_c)
        d = []
        for _ in range(500):
            w = plant.state()["w"]
            u = b * rob.damping / rob.voltage_gain * w_c + 2.0 * (w_c - w) + 0.3  # the extra volts beat mu
            plant.step(u, np.full(1, b))
            d.append(plant.true_disturbance()[0])
        w = plant.state()["w"][0]
        expected = -(jinv.p + jinv.q) * (rob.rolling_resistance_torque(0.02) + rob.damping * (b - 1) * w)
        measured = np.mean(d[250:], axis=0)
        print(f"b = {b}: mean true d {measured.round(3)}, the wheel plant's {expected.round(3)} rad/s^2")
        assert np.allclose(measured, expected, rtol=0.15)


# -- divergence is recorded, never raised -------------------------------------------------------------------------

def test_a_robot_that_drives_off_the_field_is_flagged_diverged_and_never_raises():
    plant = make("flat", threads=1, heightfield__half_width=0.4)
    pose0 = np.array([[2.0, 0.0, np.pi / 2], [2.0, 0.0, 0.0]])  # run 0 heads for the field's side, run 1 along it
    plant.reset(np.array([0, 1]), pose0, np.full((2, 2), 10.0))
    flagged_at = None
    for k in range(1500):
        plant.step(np.full((2, 2), 12.0), np.ones(2))
        if flagged_at is None and plant.diverged()[0]:
            flagged_at = k
    s = plant.state()
    print(f"run 0 off the field: diverged after {flagged_at} steps at y = {s['y'][0]:.3f} m")
    assert plant.diverged().tolist() == [True, False]
    assert np.isnan(plant.true_disturbance()[0]).all() and np.isfinite(plant.true_disturbance()[1]).all()
    assert all(np.isfinite(v).all() for v in s.values())


def test_a_robot_knocked_onto_its_side_is_flagged_tipped_and_never_raises():
    """A roll rate of 80 rad/s (a kick from the side) tumbles run 0 past plant.divergence.tip_angle (it would reach
    2.5 rad, on its back); run 1 drives on.
    The tipped run is no longer stepped: its state stays finite where it diverged, its disturbance NaN."""
    plant = make("flat", threads=1)
    plant.reset(np.array([0, 1]), np.zeros((2, 3)), np.full((2, 2), 10.0))
    plant._datas[0].qvel[3] = 80.0  # the chassis's roll rate [rad/s] (free joint: dofs 3-5 are body rates)
    flagged_at = tipped_at = None
    for k in range(1000):
        plant.step(np.full((2, 2), 5.0), np.ones(2))
        q = plant._qpos[0]
        tilt = np.arccos(np.clip(1.0 - 2.0 * (q[4] ** 2 + q[5] ** 2), -1, 1))
        if tipped_at is None and tilt > plant.config.divergence.tip_angle:
            tipped_at = k
        if flagged_at is None and plant.diverged()[0]:
            flagged_at, tilt_at = k, tilt
    s = plant.state()
    print(f"run 0 kicked over: diverged after {flagged_at} steps at a tilt of {tilt_at:.3f} rad "
          f"(tip_angle {plant.config.divergence.tip_angle} rad); run 1 at x = {s['x'][1]:.3f} m")
    assert plant.diverged().tolist() == [True, False]
    assert flagged_at == tipped_at and tilt_at > plant.config.divergence.tip_angle  # flagged the step it tipped
    assert np.isnan(plant.true_disturbance()[0]).all() and np.isfinite(plant.true_disturbance()[1]).all()
    assert all(np.isfinite(v).all() for v in s.values())


def test_a_start_on_very_rough_ground_settles_upright_whatever_the_seed():
    """At reset the robot drops from above the highest ground under its footprint: none starts with a wheel inside a
    crest (seed 37 at x = 6 m did when placed by the ground under the axle midpoint: flung, tipped at step 0)."""
    plant = make(threads=1)
    seeds = np.arange(30, 50)
    plant.reset(seeds, np.column_stack([np.full(20, 6.0), np.zeros(20), np.zeros(20)]), np.full((20, 2), 33.3))
    for _ in range(20):
        plant.step(np.full((20, 2), 10.8), np.ones(20))
    q = plant._qpos
    tilt = np.arccos(np.clip(1.0 - 2.0 * (q[:, 4] ** 2 + q[:, 5] ** 2), -1, 1))
    print(f"after reset and 20 ms on very rough ground: largest tilt {tilt.max():.3f} rad, z {q[:, 2].min():.4f} .. "
          f"{q[:, 2].max():.4f} m")
    assert not plant.diverged().any() and tilt.max() < 0.2 and q[:, 2].max() < 0.06


def test_non_finite_voltages_are_a_diverged_run_not_an_exception():
    plant = make("flat", threads=1)
    plant.reset(np.array([0, 1]), np.zeros((2, 3)), np.zeros((2, 2)))
    for _ in range(3):
        plant.step(np.array([[np.nan, 1.0], [1.0, 1.0]]), np.ones(2))
    assert plant.diverged().tolist() == [True, False]


# -- bad input ------------------------------------------------------------------------------------------------------

@pytest.mark.parametrize("overrides, terrain_name, key, rule", [
    ({"heightfield__resolution": 0.02, "heightfield__correlation_length": 0.1}, "paper",
     "plant.heightfield.resolution=0.02", "too coarse for the wheel radius"),
    ({"heightfield__x_max": 8.0}, "paper", "terrain.zones.slightly_rough.start=10.0", "zone outside the heightfield"),
    ({"timestep": 0.005}, "paper", "plant.timestep=0.005", "MuJoCo cannot hold the contacts stable"),
    ({"timestep": 0.0003}, "paper", "plant.timestep=0.0003", "whole number of steps"),
    ({"caster__stiffness": 1e6}, "paper", "plant.timestep=0.001", "MuJoCo cannot hold the caster springs stable"),
    ({"wheel__shape": "square"}, "paper", "plant.wheel.shape='square'", "must be one of"),
    ({"wheel__colour": "red"}, "paper", "plant.wheel.colour='red'", "unknown key"),
])
def test_bad_input_is_one_line_naming_the_key_and_value(overrides, terrain_name, key, rule):
    _assert_one_line(lambda: make(terrain_name, **overrides), key, rule)


def _assert_one_line(build, key, rule):
    """``build()`` raises a ConfigError of one line that starts ``key`` and states ``rule``."""
    with pytest.raises(ConfigError) as info:
        build()
    message = str(info.value)
    assert message.startswith(key) and rule in message and "\n" not in message, message


def test_without_mujoco_constructing_the_plant_names_the_extra(monkeypatch):
    monkeypatch.setitem(sys.modules, "mujoco", None)  # `import mujoco` now raises ImportError
    with pytest.raises(ConfigError) as info:
        make("flat")
    assert str(info.value) == 'plant=\'mujoco\': needs MuJoCo, the optional extra: pip install -e ".[physics]"'


def _validated(overrides=(), **plant_overrides):
    """validate_config of the composed config with the plant node of conf/plant/mujoco.yaml (and overrides) added:
    the CLI's validation, before a run."""
    from hydra import compose, initialize_config_module
    from omegaconf import OmegaConf

    from ddmr_cli.config import validate_config

    with initialize_config_module(config_module="ddmr_cli.conf", version_base="1.3"):
        cfg = compose(config_name="config", overrides=list(overrides))
    OmegaConf.set_struct(cfg, False)
    cfg.plant = plant_config(**plant_overrides)
    return validate_config(cfg)


@pytest.mark.parametrize("overrides, plant_overrides, key, rule", [
    ((), {"heightfield__resolution": 0.02, "heightfield__correlation_length": 0.1},
     "plant.heightfield.resolution=0.02", "too coarse for the wheel radius"),
    (("terrain.zones.slightly_rough.start=17.5",), {}, "terrain.zones.slightly_rough.start=17.5",
     "zone outside the heightfield"),
    ((), {"timestep": 0.004}, "plant.timestep=0.004", "MuJoCo cannot hold the contacts stable"),
    ((), {"caster__stiffness": 2e6}, "plant.timestep=0.001", "MuJoCo cannot hold the caster springs stable"),
    (("simulation.duration=17",), {}, "plant.heightfield.x_max=17.0", "the reference leaves the field"),
    (("trajectory=circle",), {}, "plant.heightfield.x_min=-1.0", "the reference leaves the field"),
    (("trajectory.y0=0.9",), {}, "plant.heightfield.half_width=1.0", "the reference leaves the field"),
    (("scenario=paper_2", "scenario.phase_clock=time"), {}, "scenario.phase_clock='time'", "ground is a place"),
])
def test_config_validation_refuses_what_the_plant_cannot_run(overrides, plant_overrides, key, rule):
    """The checks run in the CLI's validation (ddmr_cli.config.validate.check_plant), before any run: one line."""
    _assert_one_line(lambda: _validated(overrides, **plant_overrides), key, rule)


def test_config_validation_passes_the_shipped_plant_and_names_the_missing_extra(monkeypatch):
    _validated()  # conf/plant/mujoco.yaml with the default config: valid
    import importlib.util
    real = importlib.util.find_spec
    monkeypatch.setattr(importlib.util, "find_spec", lambda name, *a: None if name == "mujoco" else real(name, *a))
    with pytest.raises(ConfigError) as info:
        _validated()
    assert str(info.value) == 'plant=\'mujoco\': needs MuJoCo, the optional extra: pip install -e ".[physics]"'


# -- seeds ---------------------------------------------------------------------------------------------------------

def test_same_seed_same_ground_and_the_roughness_mapping():
    """Same seed, same ground; another seed, another. In each zone the height SD is the stated mapping's,
    roughness / slope_gain x l / sqrt(2), and the slope SD along x roughness / slope_gain."""
    a, b = make(), make()
    h0, h0_again, h1 = a.heights(0), b.heights(0), a.heights(1)
    assert np.array_equal(h0, h0_again) and not np.array_equal(h0, h1)
    x, _ = a.field_axes()
    cfg, rob = a.config.heightfield, a.robot
    for zone, lo, hi in (("very_rough", 5.5, 9.5), ("slightly_rough", 10.5, 16.5)):
        roughness = {z.name: z.roughness for z in a.terrain.zones}[zone]
        band = (x >= lo) & (x < hi)
        slope = np.diff(h0[:, band], axis=1) / (x[1] - x[0])
        target_slope = roughness / slope_gain(rob)
        target_sd = target_slope * cfg.correlation_length / np.sqrt(2)
        print(f"{zone}: height SD {h0[:, band].std() * 1e3:.3f} mm (mapping {target_sd * 1e3:.3f}), "
              f"slope SD {slope.std():.4f} (mapping {target_slope:.4f})")
        assert h0[:, band].std() == pytest.approx(target_sd, rel=0.05)
        assert slope.std() == pytest.approx(target_slope, rel=0.35)


def test_scenario_2s_roughness_off_phase_is_flat_ground_and_the_rest_the_same_ground():
    """Scenario 2 turns the roughness off over [5, 10) m travelled: on the physics plant that stretch is flat ground
    (rolling friction kept), and the rest is scenario 1's ground of the same seed. A time clock cannot place it."""
    from ddmr_cli.config.presets import paper_scenario

    one, two = make(), MujocoPlant(robot(), terrain("paper"), plant_config(), DT, paper_scenario(2))
    h1, h2 = one.heights(4), two.heights(4)
    x, _ = one.field_axes()
    off, before, after = (x >= 5.1) & (x < 10.0), x < 5.0, x >= 10.1  # past the 0.1 m ramps
    print(f"height SD on [5.1, 10) m: scenario 1 {h1[:, off].std() * 1e3:.3f} mm, scenario 2 {h2[:, off].std():.1e} m")
    assert np.abs(h2[:, off]).max() == 0.0 and h1[:, off].std() > 5e-3
    assert np.array_equal(h2[:, before], h1[:, before])
    assert np.allclose(h2[:, after], h1[:, after], rtol=1e-12, atol=0.0)
    assert np.array_equal(two.heights(4), h2)
    _assert_one_line(lambda: make_with(paper_scenario(2, "scenario.phase_clock=time")), "scenario.phase_clock='time'",
                     "ground is a place")
    make_with(paper_scenario(1, "scenario.phase_clock=time"))  # roughness never off: the clock does not matter


def make_with(scenario):
    return MujocoPlant(robot(), terrain("paper"), plant_config(), DT, scenario)


def _run(plant, seeds, steps=300):
    n = len(seeds)
    plant.reset(np.asarray(seeds), np.column_stack([np.full(n, 5.2), np.zeros(n), np.zeros(n)]),
                np.full((n, 2), 30.0))
    rng = np.random.default_rng(7)
    out = []
    for _ in range(steps):
        plant.step(rng.uniform(5.0, 15.0, (n, 2)), rng.uniform(0.8, 1.2, n))
        s = plant.state()
        out.append(np.column_stack([s["x"], s["y"], s["theta"], s["distance"], s["w"], plant.true_disturbance()]))
    seconds = plant.timing()  # ddmr bench's share: the MuJoCo steps within the whole plant step
    assert 0.0 < seconds["mujoco"] <= seconds["step"], seconds
    return np.array(out)


def test_runs_are_bit_identical_whatever_the_thread_count_on_very_rough_ground():
    seeds = [11, 12, 13, 14, 15]
    one = _run(make(threads=1), seeds)
    for threads in (2, 3):
        assert np.array_equal(_run(make(threads=threads), seeds), one, equal_nan=True), threads
    assert np.isfinite(one).all() and np.abs(one[..., 6:]).max() > 10.0  # none diverged; the rough zone disturbs


def test_the_calling_thread_steps_a_share_and_the_workers_the_others():
    """With 3 threads, a step hands two shares to the pool's (at most) two workers and the calling thread steps the
    third itself."""
    import threading

    plant = make("none", threads=3)
    plant.reset(np.arange(6), [1.0, 0.0, 0.0], [0.0, 0.0])
    stepped, advance = [], plant._advance
    plant._advance = lambda runs, ctrl: (stepped.append((threading.get_ident(), tuple(runs))), advance(runs, ctrl))
    plant.step(np.full((6, 2), 5.0), np.ones(6))
    assert sorted(r for _, runs in stepped for r in runs) == list(range(6))  # every run stepped once
    mine = [runs for ident, runs in stepped if ident == threading.get_ident()]
    assert len(stepped) == 3 and mine == [(4, 5)], stepped  # three shares of two runs, the last one the caller's
    assert plant._pool()._max_workers == 2
    plant.close()


def test_the_thread_count_left_to_the_plant_is_one_per_12_runs_up_to_the_cores(monkeypatch):
    """plant.threads 0 (and the engine's run.threads 0): the threads follow the batch, as handing a few runs to
    threads at every step costs more than it saves; a count the config or the engine sets is kept."""
    from ddmr_cli.plant import mujoco as plant_module

    monkeypatch.setattr("os.sched_getaffinity", lambda pid: set(range(4)))  # a 4-core process (thread_count)
    few = plant_module.MIN_RUNS_PER_THREAD
    assert few == 12
    chosen, kept = make("none", threads=0), make("none", threads=3)
    counts = []
    for n in (6, 2 * few, 5 * few, 6):
        chosen.reset(np.arange(n), [1.0, 0.0, 0.0], [0.0, 0.0])
        counts.append(chosen.threads)
    kept.reset(np.arange(6), [1.0, 0.0, 0.0], [0.0, 0.0])
    assert counts == [1, 2, 4, 1] and kept.threads == 3


def test_ddmr_bench_times_the_plant_and_splits_the_wall_time():
    """ddmr bench's section 6 (ddmr_cli/bench/physics.py): steps per second and the share in MuJoCo."""
    from ddmr_cli.bench.physics import plant_throughput

    r = plant_throughput(3, 0.05, threads=1)
    print(f"{r.rate:,.0f} steps/s, MuJoCo {r.mujoco / r.wall:.0%}, plant {r.plant / r.wall:.0%}")
    assert (r.runs, r.steps, r.threads, r.diverged) == (3, 50, 1, 0)
    assert r.rate > 0 and 0 < r.mujoco and 0 <= r.plant and r.mujoco + r.plant <= r.wall


# -- through the engine and the command line -----------------------------------------------------------------------

def _engine_run(threads):
    from ddmr_cli import paper_simulation, simulate

    sim = paper_simulation("controller=smc_ndo_nno", "plant=mujoco", "simulation.duration=0.3",
                           "terrain.zones.flat.roughness=100", f"plant.threads={threads}")
    return simulate(sim, [3, 4, 5], keep_series=[4])


def test_the_engine_on_the_physics_plant_is_bit_identical_whatever_the_thread_count():
    """The controllers drive the plant through the engine (control half, plant step, accounting half); the plant's
    worker threads change nothing, on very rough ground from the start."""
    one, two = _engine_run(1), _engine_run(2)
    assert not one.diverged.any()
    for name, values in one.metrics.items():
        np.testing.assert_array_equal(two.metrics[name], values, err_msg=name)
    for channel, values in one.series[4].items():
        np.testing.assert_array_equal(two.series[4][channel], values, err_msg=channel)
    d = one.series[4]["d_true_right"]
    assert np.isfinite(d).all() and np.abs(d).max() > 10.0  # the ground disturbs the wheels


@pytest.mark.slow
def test_ddmr_run_sweeps_both_plants_and_the_report_puts_them_side_by_side(tmp_path):
    """`ddmr run -m ... plant=wheel,mujoco report=true`: every job ran on its plant (its saved config says which),
    and the report's claims section compares the plants."""
    import subprocess

    out = tmp_path / "sweep"
    done = subprocess.run([str(Path(sys.executable).with_name("ddmr")), "run", "-m", "controller=smc,smc_ndo,smc_ndo_nno",
                           "plant=wheel,mujoco", "run.n_runs=3", "simulation.duration=4", "run.progress=false",
                           "report=true", f"hydra.sweep.dir={out}"], capture_output=True, text=True, timeout=900)
    assert done.returncode == 0, done.stderr[-3000:]
    report = next(out.rglob("report.md")).read_text()
    assert "### The claims on both plants" in report
    assert "paper_1@mujoco" in report
