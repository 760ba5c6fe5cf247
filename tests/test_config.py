"""Configs composed with Hydra's compose API: every controller x scenario, presets, schemas, hashing."""

from __future__ import annotations

import dataclasses
import itertools

import numpy as np
import pytest
from conftest import catalogue
from hydra import compose, initialize_config_module
from omegaconf import MISSING, OmegaConf

from paper import make_smc, make_robot, make_simulation
from ddmr_cli import PID, SMC, ConfigError, Robot, paper_scenario, paper_terrain
from ddmr_cli.config import build_simulation, config_hash, group_options, validate_config
from ddmr_cli.config import schema
from ddmr_cli.config.build import build_scenario, build_terrain

CONTROLLERS = ["pid", "smc", "smc_ndo", "smc_ndo_nno", "smc_ndo_nno_text"]
SCENARIOS = ["paper_1", "paper_2"]


def _compose(overrides=(), return_hydra_config=False):
    with initialize_config_module(config_module="ddmr_cli.conf", version_base="1.3"):
        return compose(config_name="config", overrides=list(overrides), return_hydra_config=return_hydra_config)


@pytest.mark.parametrize("scenario,controller", catalogue(
    # the paper's controller in scenario 2 and PID fast; every pair in the full suite
    sorted(itertools.product(SCENARIOS, CONTROLLERS), key=lambda p: p not in {("paper_2", "smc_ndo_nno"),
                                                                            ("paper_1", "pid")}), fast=2))
def test_every_controller_and_scenario_composes_validates_and_builds(controller, scenario):
    cfg = _compose([f"controller={controller}", f"scenario={scenario}"])
    validate_config(cfg)
    sim = build_simulation(cfg)
    assert sim.controller.name == controller
    assert sim.scenario.name == scenario
    assert isinstance(sim.controller, PID if controller == "pid" else SMC)
    if controller.startswith("smc"):
        assert (sim.controller.ndo is not None) == ("ndo" in controller)
        assert (sim.controller.nn is not None) == ("nno" in controller)


def test_default_config_is_the_paper_scenario_1_with_smc_ndo_nno():
    cfg = _compose()
    assert cfg.controller.name == "smc_ndo_nno" and cfg.scenario.name == "paper_1"
    assert cfg.run.n_runs == 50 and cfg.simulation.dt == 0.001 and cfg.simulation.duration == 15.0
    assert list(cfg.simulation.initial_pose) == [0.0, 0.05, 0.05]


def test_yaml_values_match_model_md():
    cfg = _compose(["scenario=paper_2"])
    assert Robot(**OmegaConf.to_container(cfg.robot)) == Robot(15.0, 0.03, 0.5, 0.27, 0.0075, 0.3, 0.3, 0.7, 0.01, 24.0)
    zones = [(z.name, z.start, z.roughness, z.mu) for z in build_terrain(cfg.terrain).zones]
    assert zones == [("flat", 0.0, 0.1, 0.02), ("very_rough", 5.0, 100.0, 0.10), ("slightly_rough", 10.0, 5.0, 0.05)]
    assert [(p.start, p.roughness, p.uncertainty) for p in build_scenario(cfg.scenario).phases] == [
        (0.0, True, False), (5.0, False, True), (10.0, True, True)]
    assert tuple(build_scenario(cfg.scenario).uncertainty) == (0.5, 0.4, -0.5, 1.0, False)  # the OU form (constant=False)
    assert build_scenario(_compose().scenario) == paper_scenario(1)


def _leaf_fields(node_type, path=""):
    for f in dataclasses.fields(node_type):
        if dataclasses.is_dataclass(f.default_factory if f.default_factory is not dataclasses.MISSING else None):
            yield from _leaf_fields(f.default_factory, f"{path}{f.name}.")
        else:
            yield f"{path}{f.name}", f


@pytest.mark.parametrize("node_type", [schema.RobotConfig, schema.TerrainConfig, schema.ZoneConfig,
                                       schema.PhaseConfig, schema.ScenarioConfig, schema.NDOConfig, schema.NNConfig,
                                       schema.PIDConfig, schema.SMCConfig, schema.OpenLoopConfig, schema.LineConfig,
                                       schema.CircleConfig, schema.FigureEightConfig, schema.OuterLoopConfig,
                                       schema.STAConfig, schema.ADRCConfig, schema.AdaptiveSMCConfig,
                                       schema.SinusoidConfig,
                                       schema.SimulationConfig, schema.RunConfig, schema.ReportConfig])
def test_defaults_live_only_in_the_yaml(node_type):
    """The schema marks every value required (MISSING); only a class's _target_ and an absent observer (None)
    are structure. The YAML under conf/ is the one place a default lives."""
    for key, f in _leaf_fields(node_type):
        if key == "_target_" or key in ("ndo", "nn", "display"):
            continue
        if f.default_factory is dataclasses.MISSING:
            assert f.default == MISSING, f"{node_type.__name__}.{key} has a default in the schema"
        else:  # an empty container of entries (zones, phases) or a nested node, never values
            assert f.default_factory is dict or dataclasses.is_dataclass(f.default_factory), key


@pytest.mark.parametrize("group", catalogue(["robot", "scenario", "terrain", "trajectory", "controller"], fast=2))
def test_every_option_of_every_group_gives_every_value(group):
    for option in group_options(group):
        cfg = _compose([f"{group}={option}"])
        assert OmegaConf.missing_keys(cfg) == set(), (group, option)


@pytest.mark.parametrize("cls", ["Robot", "SMC", "PID", "NonlinearDisturbanceObserver", "RBFNetworkObserver",
                                 "OpenLoop", "Simulation", "Terrain", "Scenario", "StraightLine", "Circle",
                                 "FigureEight", "Kanayama", "DampingUncertainty", "SuperTwisting", "ADRC",
                                 "AdaptiveSMC", "Sinusoid"])
def test_model_classes_have_no_numeric_defaults(cls):
    import inspect

    import ddmr_cli

    params = inspect.signature(getattr(ddmr_cli, cls)).parameters.values()
    defaults = {p.name: p.default for p in params if p.default is not inspect.Parameter.empty}
    assert set(defaults) <= {"ndo", "nn", "name"}, defaults  # absent observers and a label only


def test_both_readings_of_the_nn_parameters_ship_as_presets():
    eq25 = _compose(["controller=smc_ndo_nno"]).controller.nn
    text = _compose(["controller=smc_ndo_nno_text"]).controller.nn
    assert (eq25.learning_rate, eq25.width) == (50.0, 2.0)
    assert (text.learning_rate, text.width) == (2.0, 50.0)


def test_group_options_hide_schemas():
    assert set(CONTROLLERS) <= set(group_options("controller"))
    assert not any(o.startswith("schema") for o in group_options("controller"))
    assert group_options("scenario") == ["paper_1", "paper_2"]


@pytest.mark.slow
def test_experiment_presets_define_their_sweeps():
    cfg = _compose(["+experiment=table4"], return_hydra_config=True)
    assert dict(cfg.hydra.sweeper.params) == {"controller": "pid,smc,smc_ndo,smc_ndo_nno", "scenario": "paper_1,paper_2"}
    smoke = _compose(["+experiment=smoke"], return_hydra_config=True)
    assert smoke.run.n_runs == 2
    assert set(smoke.hydra.sweeper.params.controller.split(",")) == set(group_options("controller"))  # every preset
    # per-job plots for one job of the smoke sweep only
    plotting = [(c, s) for c in group_options("controller") for s in SCENARIOS
                if _compose(["+experiment=smoke", f"controller={c}", f"scenario={s}"]).run.plots]
    assert plotting == [("smc_ndo_nno", "paper_2")]
    assert _compose(["+experiment=smoke", "controller=pid", "run.plots=true"]).run.plots is True


def test_report_node_defaults_and_leaves_the_numbers_alone():
    cfg = _compose()
    assert cfg.report.auto is False and cfg.report.margin is None
    assert config_hash(_compose(["report.auto=true", "report.margin=0.1"])) == config_hash(cfg)


@pytest.mark.parametrize("launcher,target_part", [("local", "joblib"), ("submitit_local", "submitit"),
                                                  ("slurm", "submitit")])
def test_launcher_presets_compose(launcher, target_part):
    cfg = _compose([f"launcher={launcher}"], return_hydra_config=True)
    assert target_part in cfg.hydra.launcher._target_.lower()
    if launcher == "slurm":
        cfg = _compose(["launcher=slurm", "cluster.partition=compute", "cluster.time_min=30"], True)
        assert cfg.hydra.launcher.partition == "compute" and cfg.hydra.launcher.timeout_min == 30


def test_bad_values_are_refused_naming_the_key():
    with pytest.raises(ConfigError, match=r"robot\.mass=-1\.0: must be > 0"):
        validate_config(_compose(["robot.mass=-1"]))
    with pytest.raises(ConfigError, match=r"terrain\.zones\.slightly_rough\.start=10\.0: zone starts must be increasing"):
        validate_config(_compose(["terrain.zones.very_rough.start=12"]))
    with pytest.raises(ConfigError, match=r"simulation\.dt"):
        validate_config(_compose(["simulation.dt=0.05"]))


def test_foreign_targets_are_refused():
    with pytest.raises(ConfigError, match="only ddmr_cli"):
        validate_config(_compose(["controller._target_=os.system"]))
    with pytest.raises(ConfigError, match="only ddmr_cli"):
        build_simulation(_compose(["controller.ndo._target_=subprocess.Popen"]))


def test_config_hash_tracks_numbers_not_display_settings():
    base = config_hash(_compose())
    assert config_hash(_compose()) == base
    assert config_hash(_compose(["run.plots=false", "run.progress=false"])) == base
    assert config_hash(_compose(["controller.lam=24"])) != base
    assert config_hash(_compose(["run.n_runs=49"])) != base


def test_config_and_python_api_give_the_same_numbers():
    from ddmr_cli import NonlinearDisturbanceObserver, Simulation, run_config, simulate

    cfg = _compose(["controller=smc_ndo", "run.n_runs=2", "simulation.duration=0.3"])
    from_config = run_config(cfg)
    sim = make_simulation(controller=make_smc(ndo=NonlinearDisturbanceObserver(50.0), name="smc_ndo"), terrain=paper_terrain(),
                     scenario=paper_scenario(1), duration=0.3)
    direct = simulate(sim, seeds=[0, 1], keep_series=[0])
    for name, arr in direct.metrics.items():
        assert np.array_equal(arr, from_config.metrics[name], equal_nan=True), name


JOB_OVERRIDES = [
    [],
    ["run.base_seed=7", "run.n_runs=3"],
    ["controller=pid", "controller.kp=8", "scenario=paper_2"],
    ["controller=smc_ndo", "controller/ndo=paper", "controller.switching_gain=4.5"],
    ["+experiment=table4", "controller=smc", "scenario=paper_1"],
    ["+tags.note=baseline", "++run.n_runs=5", "simulation.initial_pose=[0.0,0.1,0.0]"],
    ["controller=smc_nno", "simulation.dt=0.0005", "run.keep_series=[0,2]"],
    ["terrain.zones.very_rough.roughness=50", "trajectory=circle", "trajectory.radius=3"],
    ["sensor=encoder", "actuator=realistic", "control.rate=200", "hydra.sweep.dir=/tmp/x"],
    ["~tags"],
]


@pytest.mark.parametrize("overrides", JOB_OVERRIDES, ids=lambda o: " ".join(o) or "none")
def test_the_sweep_composer_gives_hydras_composition(overrides):
    """Pre-validation composes a sweep's defaults tree once per set of group choices and applies each job's value
    overrides to a copy (JobComposer): every kind of override gives the config a full composition gives."""
    from ddmr_cli.config import JobComposer, compose_config

    composer = JobComposer()
    composer.compose(["run.base_seed=1"])  # a cached skeleton from an earlier job must not leak into the next
    ours, full = composer.compose(overrides), compose_config(overrides)
    assert OmegaConf.to_yaml(ours) == OmegaConf.to_yaml(full)
    assert OmegaConf.is_struct(ours)
    assert OmegaConf.to_yaml(composer.compose(overrides)) == OmegaConf.to_yaml(full)  # the copy, not the skeleton


@pytest.mark.parametrize("bad", [["run.n_runs=many"], ["run.nruns=5"], ["controller=nope"], ["+run.n_runs=5"]])
def test_the_sweep_composer_refuses_what_hydra_refuses(bad):
    from hydra.errors import HydraException
    from omegaconf.errors import OmegaConfBaseException

    from ddmr_cli.config import JobComposer, compose_config

    with pytest.raises((HydraException, OmegaConfBaseException)) as full:
        compose_config(bad)
    with pytest.raises((HydraException, OmegaConfBaseException)) as ours:
        JobComposer().compose(bad)
    assert type(ours.value) is type(full.value)


def _hydra_loader_and_master(hydra_overrides=("hydra.sweep.dir=/tmp/ddmr-test-sweep",)):
    """Hydra's own config loader on the packaged config and a multirun master config, as ``ddmr run -m`` has."""
    from hydra.core.global_hydra import GlobalHydra
    from hydra.types import RunMode

    from ddmr_cli.config import _initialized

    with _initialized():
        loader = GlobalHydra.instance().config_loader()
    master = loader.load_configuration("config", overrides=list(hydra_overrides), run_mode=RunMode.MULTIRUN)
    return loader, master


@pytest.mark.parametrize("overrides", JOB_OVERRIDES, ids=lambda o: " ".join(o) or "none")
def test_the_sweepers_loader_gives_hydras_job_config(overrides):
    """hydra/sweeper=ddmr hands Hydra's sweeper and launchers a loader that derives each job from one composition
    per set of group choices: every kind of override gives Hydra's own job config, hydra node included (the
    task overrides, override_dirname, choices)."""
    from ddmr_cli.config.compose_once import SweepConfigLoader

    loader, master = _hydra_loader_and_master(["hydra.sweep.dir=/tmp/ddmr-test-sweep", "hydra.job.chdir=false"])
    ours = SweepConfigLoader(loader)
    ours.load_sweep_config(master, ["run.base_seed=1"])  # a skeleton from an earlier job must not leak
    full = loader.load_sweep_config(master, list(overrides))
    for _ in range(2):  # the second time from the cached skeleton
        fast = ours.load_sweep_config(master, list(overrides))
        assert OmegaConf.to_container(fast) == OmegaConf.to_container(full)
        assert OmegaConf.is_struct(fast)
    assert fast.hydra.job.override_dirname == full.hydra.job.override_dirname
    assert list(fast.hydra.overrides.task) == [o for o in overrides if not o.startswith("hydra.")]


def test_the_sweepers_loader_travels_with_its_skeletons():
    """A launcher pickles the loader to its workers: they derive their jobs from the skeletons the main process
    composed while validating the sweep, without composing again."""
    import pickle

    from ddmr_cli.config.compose_once import SweepConfigLoader

    loader, master = _hydra_loader_and_master()
    ours = SweepConfigLoader(loader)
    expected = ours.load_sweep_config(master, ["controller=pid", "run.base_seed=3"])
    shipped = pickle.loads(pickle.dumps(ours))

    def no_composition(*args, **kwargs):
        raise AssertionError("composed again")

    shipped.inner.load_configuration = no_composition
    job = shipped.load_sweep_config(master, ["controller=pid", "run.base_seed=3"])
    assert OmegaConf.to_container(job) == OmegaConf.to_container(expected)
    assert shipped.load_sweep_config(master, ["controller=pid", "run.base_seed=4"]).run.base_seed == 4
    with pytest.raises(AssertionError, match="composed again"):  # another set of group choices composes
        shipped.load_sweep_config(master, ["controller=smc"])


@pytest.mark.parametrize("bad", [["run.n_runs=many"], ["run.nruns=5"], ["controller=nope"]])
def test_the_sweepers_loader_refuses_what_hydra_refuses(bad):
    from hydra.errors import HydraException
    from omegaconf.errors import OmegaConfBaseException

    from ddmr_cli.config.compose_once import SweepConfigLoader

    loader, master = _hydra_loader_and_master()
    with pytest.raises((HydraException, OmegaConfBaseException)) as full:
        loader.load_sweep_config(master, bad)
    with pytest.raises((HydraException, OmegaConfBaseException)) as ours:
        SweepConfigLoader(loader).load_sweep_config(master, bad)
    assert type(ours.value) is type(full.value)


@pytest.mark.parametrize("overrides", JOB_OVERRIDES[:6] + [["+tags.note=a: b", "+tags.when='2026-11-23'",
                                                          "simulation.dt=1e-05", "control.rate=null"]],
                         ids=lambda o: " ".join(o) or "none")
def test_a_jobs_config_file_is_omegaconfs_yaml(overrides):
    """Jobs write their resolved config with PyYAML's C emitter (io.yaml_text): the same text OmegaConf prints,
    which reads back to the same values."""
    from ddmr_cli.storage import io
    from ddmr_cli.config import compose_config
    from ddmr_cli.config.build import result_config

    container = result_config(compose_config(overrides))
    text = io.yaml_text(container)
    assert text == OmegaConf.to_yaml(OmegaConf.create(container), resolve=True)
    assert OmegaConf.to_container(OmegaConf.create(text)) == container


#: the calls one ``ddmr run`` process makes (issue 28): the CLI's validation, Hydra's get_mode (multirun, no sweep
#: check), Hydra's run or multirun, each with the values of the hydra node Hydra adds
MEMO_CALLS = [
    [(["run.n_runs=3"], "RUN"), (["run.n_runs=3", "hydra.run.dir=/tmp/ddmr-x"], "MULTIRUN"),
     (["run.n_runs=3", "hydra.run.dir=/tmp/ddmr-x", "hydra.mode=RUN"], "RUN")],
    [(["hydra.run.dir=/tmp/ddmr-y", "controller=pid", "hydra.job.chdir=false"], "RUN"),
     (["controller=pid", "hydra.job.chdir=false", "hydra.run.dir=/tmp/ddmr-z"], "RUN")],
    # one composition for other values: of the job, added, and of the hydra node that override_dirname reads
    [(["controller=smc", "controller.lam=7"], "RUN"),
     (["controller=smc", "run.n_runs=3", "+run.note=x", "hydra.job.config.override_dirname.exclude_keys=[run.n_runs]",
       "hydra.run.dir=/tmp/ddmr-${hydra.job.override_dirname}"], "RUN"),
     (["run.n_runs=4", "controller=smc"], "MULTIRUN")],
    [(["launcher=basic", "controller=smc,pid", "run.n_runs=2"], "MULTIRUN"),
     (["launcher=basic", "controller=smc,pid", "run.n_runs=2", "hydra.sweep.dir=/tmp/s", "hydra.mode=MULTIRUN"],
      "MULTIRUN")],
]


@pytest.mark.parametrize("calls", MEMO_CALLS, ids=lambda c: " ".join(c[-1][0]))
def test_one_composition_per_process_gives_hydras_configs(calls):
    """Within compositions_once, the calls of one ``ddmr run`` compose once and each gets the config a full
    composition gives, hydra node included (its overrides, override_dirname, choices, job name)."""
    from hydra.core.global_hydra import GlobalHydra
    from hydra.types import RunMode

    from ddmr_cli.config.compose_once import compositions_once
    from ddmr_cli.config import _initialized

    with _initialized():
        loader = GlobalHydra.instance().config_loader()
    full = [loader.load_configuration("config", overrides=list(o), run_mode=RunMode[m], validate_sweep_overrides=m == "RUN")
            for o, m in calls]
    composed = []
    original = type(loader).load_configuration
    with compositions_once() as memo:
        fast = []
        for o, m in calls:
            cfg = loader.load_configuration("config", overrides=list(o), run_mode=RunMode[m],
                                            validate_sweep_overrides=m == "RUN")
            cfg.run.n_runs = 99  # a caller's change must not reach the next call
            fast.append(cfg)
        assert len(memo._kept) == 1
    assert type(loader).load_configuration is original
    for a, b in zip(fast, full):
        a.run.n_runs = b.run.n_runs
        assert OmegaConf.to_container(a) == OmegaConf.to_container(b)
        assert OmegaConf.is_struct(a)


def test_one_composition_per_process_refuses_what_hydra_refuses():
    """A sweep in a run, or a bad value of the hydra node, is refused from the kept composition as Hydra refuses it."""
    from hydra.core.global_hydra import GlobalHydra
    from hydra.errors import HydraException
    from hydra.types import RunMode
    from omegaconf.errors import OmegaConfBaseException

    from ddmr_cli.config.compose_once import compositions_once
    from ddmr_cli.config import _initialized

    with _initialized():
        loader = GlobalHydra.instance().config_loader()
    with compositions_once():
        loader.load_configuration("config", overrides=["controller=pid,smc"], run_mode=RunMode.MULTIRUN)
        with pytest.raises(HydraException, match="sweep"):
            loader.load_configuration("config", overrides=["controller=pid,smc"], run_mode=RunMode.RUN)
        loader.load_configuration("config", overrides=[], run_mode=RunMode.RUN)
        with pytest.raises((HydraException, OmegaConfBaseException)):
            loader.load_configuration("config", overrides=["hydra.run.dri=x"], run_mode=RunMode.RUN)
    with pytest.raises(HydraException) as hydras:
        loader.load_configuration("config", overrides=["run.n_run=3"], run_mode=RunMode.RUN)
    with compositions_once():
        loader.load_configuration("config", overrides=["run.n_runs=3"], run_mode=RunMode.RUN)
        with pytest.raises(HydraException) as ours:  # a value that is no key, on the kept composition
            loader.load_configuration("config", overrides=["run.n_run=3"], run_mode=RunMode.RUN)
    assert type(ours.value) is type(hydras.value) and str(ours.value) == str(hydras.value)


@pytest.mark.parametrize("overrides, n_jobs, work, expected", [
    ([], 8, 6_000_000, True),                                      # table4: in this process (launcher=basic)
    ([], 17, 1_000, False),                                        # many jobs: joblib's workers
    ([], 8, 10 ** 9, False),                                       # much simulation: in parallel processes
    (["launcher=local"], 8, 6_000_000, False),                     # a launcher named on the command line is kept
    (["launcher=submitit_local"], 2, 1_000, False),
    (["cluster.cpus=2"], 2, 1_000, False),                         # the launcher's settings named: kept
    (["+experiment=sensitivity_oat"], 2, 1_000, False),            # a study stage's chunks: parallel processes
])
def test_small_local_sweeps_run_in_this_process(overrides, n_jobs, work, expected):
    from hydra.core.override_parser.overrides_parser import OverridesParser

    from ddmr_cli.cli.modes import small_local_sweep
    from ddmr_cli.config import compose_config

    base = compose_config(overrides, return_hydra_config=True)
    parsed = OverridesParser.create().parse_overrides(overrides)
    assert small_local_sweep(base, parsed, n_jobs, work) is expected


def test_the_plant_schema_names_every_field_the_physics_plant_reads():
    """conf/plant/mujoco.yaml's schema (ddmr run --help, ddmr explain) and the plant's own config
    (plant/mujoco_model.PhysicsConfig, which validates) have the same keys, section by section."""
    from dataclasses import fields

    from ddmr_cli.config import schema
    from ddmr_cli.plant import mujoco_model as model

    def names(cls):
        return {f.name for f in fields(cls)}

    assert names(schema.MujocoPlantConfig) - {"name"} == names(model.PhysicsConfig)
    for ours, theirs in [(schema.HeightfieldSchema, model.HeightfieldConfig), (schema.PlantWheelSchema, model.WheelConfig),
                         (schema.CasterSchema, model.CasterConfig), (schema.ChassisSchema, model.ChassisConfig),
                         (schema.ContactSchema, model.ContactConfig),
                         (schema.PlantDivergenceSchema, model.DivergenceConfig)]:
        assert names(ours) == names(theirs), ours.__name__


def test_hydras_check_composes_only_what_ddmrs_plan_did_not_validate():
    """hydra/sweeper=ddmr: Hydra's check that a batch's jobs compose skips the jobs ddmr's plan validated in this
    process, but for the first job of each set of group choices (its skeleton, which the workers derive the set's
    jobs from); a job ddmr did not validate, or one composed in full, is checked as Hydra checks it."""
    from types import SimpleNamespace

    from hydra_plugins.ddmr_sweeper.ddmr_sweeper import DdmrSweeper

    from ddmr_cli.config.compose_once import compositions_once

    checked: list[list[str]] = []
    batches = [[["controller=pid", "run.base_seed=0"], ["controller=pid", "run.base_seed=1"],
                ["controller=smc", "run.base_seed=0"], ["controller=smc", "run.base_seed=1"]],
               [["controller=pid", "run.base_seed=2"], ["controller=smc", "run.base_seed=9"],
                ["+full=1", "run.base_seed=3"], ["+full=1", "run.base_seed=4"]]]

    def skeleton_of(master, job):  # the group choice; None: a job composed in full
        return None if job[0].startswith("+full") else (job[0],)

    def sweep(arguments):  # Hydra's basic sweep, as far as the check goes: each batch checked, then launched
        for batch in batches:
            sweeper.basic.validate_batch_is_legal(batch)

    sweeper = DdmrSweeper()
    sweeper.basic = SimpleNamespace(validate_batch_is_legal=lambda batch: checked.extend(batch), sweep=sweep,
                                    config=None, hydra_context=SimpleNamespace(
                                        config_loader=SimpleNamespace(skeleton_of=skeleton_of)))
    with compositions_once() as memo:
        memo.validated_jobs.update(tuple(job) for batch in batches for job in batch if job != batches[1][1])
        sweeper.sweep([])
    assert checked == [["controller=pid", "run.base_seed=0"], ["controller=smc", "run.base_seed=0"],
                       ["controller=smc", "run.base_seed=9"],  # not validated by ddmr
                       ["+full=1", "run.base_seed=3"], ["+full=1", "run.base_seed=4"]]


def test_a_sweeps_jobs_are_composed_once_by_hydras_check(tmp_path, monkeypatch):
    """Through `ddmr run -m` (ddmr's plan validates every job): Hydra's check composes one job of a sweep of one
    set of group choices, not each of them, and the sweep completes."""
    from hydra.plugins.sweeper import Sweeper

    from ddmr_cli.cli.main import main

    checked: list = []
    original = Sweeper.validate_batch_is_legal
    monkeypatch.setattr(Sweeper, "validate_batch_is_legal", lambda self, batch: (checked.extend(batch),
                                                                                 original(self, batch)))
    code = main(["run", "-m", "run.n_runs=1", "simulation.duration=0.05", "run.base_seed=range(0,5)",
                 "run.plots=false", "run.progress=false", "report.auto=false", f"hydra.sweep.dir={tmp_path / 's'}"])
    assert code == 0
    assert len(checked) == 1
    assert len(list((tmp_path / "s").glob("*/metrics.csv"))) == 5
