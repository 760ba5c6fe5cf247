"""The refusals of issue 12, as data: ``ddmr run`` arguments, the exit status, a part of the one-line message.

Every case is refused before Hydra starts (exit 2: bad input; exit 1: a file-system fault or a held lock) and
leaves nothing behind but what the case set up. ``tests/test_integrity_refusals.py`` runs them in-process;
``benchmarks/integrity_table.py`` runs them through the console script and prints the table of the notes.

``{tmp}`` in an argument is the case's scratch dir; ``setup`` names what the case puts there first:
``file`` (a file ``afile``), ``conf`` (a copy of the packaged configs in ``myconf/``), ``extra`` (a config dir
``extra/`` adding ``controller=mine``), ``lock`` (``locked/`` held by the test process).
"""

from __future__ import annotations

import shutil
from pathlib import Path
from typing import NamedTuple

LONG = "x" * 300


class Case(NamedTuple):
    name: str
    args: tuple[str, ...]
    exit: int
    message: str
    setup: str = ""


CASES = (
    # bounded work: the memory estimate against run.max_memory_gb
    Case("runs over budget", ("run.n_runs=10000000",), 2, "run.max_memory_gb=null: the job needs about"),
    Case("duration over budget", ("simulation.duration=1e9",), 2, "raise simulation.dt or lower simulation.duration"),
    Case("tiny step over budget", ("simulation.dt=1e-12",), 2, "15000000000000 steps"),
    Case("huge network", ("controller.nn.n_neurons=100000000",), 2, "controller's state takes"),
    Case("explicit budget", ("run.max_memory_gb=0.05",), 2, "over the budget of 0.05 GB (run.max_memory_gb)"),
    Case("budget zero", ("run.max_memory_gb=0",), 2, "run.max_memory_gb=0.0: must be > 0"),
    Case("sweep at once", ("-m", "run.n_runs=400000", "run.base_seed=0,1", "run.max_memory_gb=12", "cluster.cpus=2"),
         2, "2 jobs at once x 400000 runs"),
    Case("all series over budget", ("run.keep_series=all", "run.n_runs=2000", "run.max_memory_gb=2"), 2,
         "keep fewer series"),
    # kept series: seeds of the job, compact forms
    Case("keep seed outside", ("run.keep_series=[0]", "run.base_seed=1000"), 2,
         "run.keep_series[0]=0: is not a seed of this job (seeds 1000..1049)"),
    Case("keep bad form", ("run.keep_series=first:x",), 2, "run.keep_series='first:x': must be a list of seeds"),
    Case("keep a number", ("run.keep_series=5",), 2, "run.keep_series=5: must be a list of seeds"),
    Case("keep negative", ("run.keep_series=[-1]",), 2, "run.keep_series[0]=-1: must be >= 0"),
    # new keys only under a free-form dict
    Case("typo added", ("+run.nruns=5",), 2, "+run.nruns=5: unknown key run.nruns (did you mean run.n_runs?)"),
    Case("typo force-added", ("++run.nruns=5",), 2, "++run.nruns=5: unknown key run.nruns"),
    # a key a schema does not have, set without +: the same did-you-mean (issue 29)
    Case("typo set", ("run.nruns=5",), 2, "run.nruns=5: unknown key run.nruns (did you mean run.n_runs?)"),
    Case("group typo set", ("controler=pid",), 2, "controler=pid: unknown key controler (did you mean controller?)"),
    Case("sensor typo", ("sensor=encodr",), 2, "sensor=encodr: unknown sensor; available: encoder, ideal, noisy"),
    Case("actuator typo", ("actuator=delay_2ms",), 2, "actuator=delay_2ms: unknown actuator; available: ideal, pwm8, "
                                                       "realistic"),
    Case("unknown controller key", ("+controller.foo=1",), 2, "+controller.foo=1: unknown key controller.foo"),
    Case("nested typo", ("+simulation.dtt=0.001",), 2, "did you mean simulation.dt?"),
    Case("typo set", ("run.nruns=5",), 2, "run.nruns=5: unknown key run.nruns (did you mean run.n_runs?)"),
    Case("controller typo set", ("controller.switchng_gain=3",), 2,
         "controller.switchng_gain=3: unknown key controller.switchng_gain (did you mean controller.switching_gain?)"),
    Case("unknown cluster key", ("+cluster.foo=1",), 2, "cluster.foo=1: unknown cluster key"),
    # _target_ swaps
    Case("robot as controller", ("controller._target_=ddmr_cli.model.robot.Robot",), 2, "must be a WheelController"),
    Case("callback as trajectory", ("trajectory._target_=ddmr_cli.cli.callbacks.SweepAggregator",), 2,
         "must be a trajectory class of ddmr_cli.model.trajectory"),
    Case("PID as observer", ("controller.ndo._target_=ddmr_cli.control.PID",), 2,
         "must be a NonlinearDisturbanceObserver"),
    Case("missing class", ("controller._target_=ddmr_cli.control.Nope",), 2, "cannot be imported"),
    # derived numbers
    Case("mass overflows J", ("robot.mass=1e308",), 2, "robot.mass=1e308: gives no usable inertia matrix J"),
    Case("speed overflows reference", ("trajectory.speed=1e308",), 2, "trajectory.speed=1e308: the reference at t"),
    Case("pose overflows deviation", ("simulation.initial_pose=[1e308,0,0]",), 2,
         "simulation.initial_pose=[1e+308, 0.0, 0.0]: starts inf m from the reference"),
    Case("start beyond divergence", ("simulation.initial_pose=[0,5,0]",), 2,
         "starts 5 m from the reference, not within simulation.divergence_bound=1 m"),
    # cluster.*
    Case("cpus text", ("cluster.cpus=abc",), 2, "cluster.cpus='abc': must be -1 (every core) or an integer >= 1"),
    Case("cpus zero", ("cluster.cpus=0",), 2, "cluster.cpus=0: must be -1"),
    Case("slurm time", ("launcher=slurm", "cluster.time_min=-5"), 2, "cluster.time_min=-5: must be >= 1"),
    Case("slurm memory", ("launcher=slurm", "cluster.mem_gb=-1"), 2, "cluster.mem_gb=-1: must be > 0"),
    Case("slurm partition", ("launcher=slurm", "cluster.partition='a b'"), 2,
         "cluster.partition='a b': must be null or a name without spaces"),
    # sweeps: empty, two jobs in one dir
    Case("empty range", ("-m", "run.base_seed=range(1,1)"), 2, "run.base_seed=range(1,1): the sweep has no jobs"),
    Case("constant subdir", ("-m", "controller=pid,smc", "hydra.sweep.subdir=same"), 2,
         "hydra.sweep.subdir=same: jobs 'controller=pid' and 'controller=smc' would write into one job dir"),
    Case("excluded key swept", ("-m", "run.plots=true,false", "run.n_runs=1"), 2,
         "run.plots: jobs 'run.plots=True run.n_runs=1' and 'run.plots=False run.n_runs=1' would write into one"),
    # other config dirs are validated too
    Case("config path", ("-cp", "{tmp}/myconf", "robot.mass=-1"), 2, "robot.mass=-1.0: must be > 0", "conf"),
    Case("config path typo", ("-cp", "{tmp}/myconf", "+run.nruns=5"), 2, "unknown key run.nruns", "conf"),
    Case("config dir", ("--config-dir", "{tmp}/extra", "controller=mine", "controller.kp=-1"), 2,
         "controller.kp=-1: must be >= 0", "extra"),
    # faults before anything runs: one line naming the path, exit 1
    Case("output is a file", ("hydra.run.dir={tmp}/afile",), 1,
         "afile: a file is in the way of an output dir", "file"),
    Case("output under a file", ("hydra.run.dir={tmp}/afile/run",), 1,
         "afile/run: a file is in the way of an output dir", "file"),
    Case("sweep dir is a file", ("-m", "controller=pid,smc", "hydra.sweep.dir={tmp}/afile"), 1,
         "afile: a file is in the way of an output dir", "file"),
    Case("name too long", (f"hydra.run.dir={{tmp}}/{LONG}",), 1, "File name too long"),
    Case("dir locked", ("hydra.run.dir={tmp}/locked",), 1, "locked: in use by pid", "lock"),
)

EXTRA_CONTROLLER = """defaults:
  - /schema_controller_pid@_here_
  - _self_
kp: 7.0
ki: 0.1
kd: 0.01
anti_windup: true
"""


def prepare(case: Case, tmp: Path) -> list[str]:
    """Set the case up in ``tmp``; returns its arguments with ``{tmp}`` filled in."""
    if case.setup == "file":
        (tmp / "afile").write_text("not a dir\n")
    elif case.setup == "conf":
        import ddmr_cli.conf

        shutil.copytree(Path(ddmr_cli.conf.__file__).parent, tmp / "myconf",
                        ignore=shutil.ignore_patterns("__init__.py", "__pycache__"))
    elif case.setup == "extra":
        (tmp / "extra" / "controller").mkdir(parents=True)
        (tmp / "extra" / "controller" / "mine.yaml").write_text(EXTRA_CONTROLLER)
    return [a.replace("{tmp}", str(tmp)) for a in case.args]


def left_behind(tmp: Path, case: Case) -> list[str]:
    """What is in ``tmp`` besides what the case set up."""
    setup = {"file": {"afile"}, "conf": {"myconf"}, "extra": {"extra"}, "lock": {"locked"}}.get(case.setup, set())
    return sorted(p.name for p in tmp.iterdir() if p.name not in setup)
