"""Each private-API wrapper of ddmr_cli/compat.py does what the code relies on (an upgrade that breaks one fails
here, by name), and the version check refuses an unsupported release."""

from __future__ import annotations

import subprocess
import sys
import textwrap

import pytest
from hydra.core.override_parser.overrides_parser import OverridesParser
from omegaconf import OmegaConf

from ddmr_cli import compat
from ddmr_cli.errors import DDMRError


def parse(*lines):
    return OverridesParser.create().parse_overrides(list(lines))


def test_the_installed_hydra_is_supported_and_others_are_refused():
    compat.check_hydra()
    compat.check_hydra("1.3.2")
    for version in ("1.4.0", "2.0.0.dev1", "1.2.0"):
        with pytest.raises(DDMRError, match=f"hydra-core {version} is installed"):
            compat.check_hydra(version)


def test_apply_overrides_sets_values_in_struct_mode_as_hydra_does():
    cfg = OmegaConf.create({"a": {"b": 1, "c": [1, 2]}})
    OmegaConf.set_struct(cfg, True)
    compat.apply_overrides(parse("a.b=5", "a.c=[3]", "+a.d=x", "~a.b"), cfg)
    assert OmegaConf.to_container(cfg) == {"a": {"c": [3], "d": "x"}}
    with pytest.raises(Exception):  # struct mode: a new key needs +
        compat.apply_overrides(parse("a.e=1"), cfg)


def test_overrides_dirname_is_hydras_job_dirname():
    name = compat.overrides_dirname(parse("b=2", "a=1", "seed=3"), exclude_keys=["seed"], item_sep=",", kv_sep="=")
    assert name == "a=1,b=2"


def test_split_sweep_is_the_cartesian_product_in_hydras_order():
    assert compat.split_sweep(parse("a=1,2", "b=x,y")) == [["a=1", "b=x"], ["a=1", "b=y"], ["a=2", "b=x"],
                                                           ["a=2", "b=y"]]


def test_basic_sweeper_is_hydras():
    sweeper = compat.basic_sweeper(max_batch_size=3, params={"a": "1,2"})
    assert type(sweeper).__name__ == "BasicSweeper" and sweeper.max_batch_size == 3


def test_locate_finds_a_class_and_raises_on_a_missing_one():
    from ddmr_cli.control.smc import SMC

    assert compat.locate("ddmr_cli.control.smc.SMC") is SMC
    with pytest.raises(Exception):
        compat.locate("ddmr_cli.control.smc.NoSuchClass")


def test_config_repository_answers_group_questions():
    from hydra.core.global_hydra import GlobalHydra

    from ddmr_cli.config import _initialized

    with _initialized():
        repo = compat.config_repository(GlobalHydra.instance().config_loader())
        assert repo.group_exists("controller") and not repo.group_exists("no_such_group")
        assert "smc" in repo.get_group_options("controller")


def test_a_worker_scans_hydras_plugins_once():
    """A launcher's worker restores Hydra's state for every job (Singleton.set_state), which scanned every
    hydra_plugins module again (new plugin classes each time); once the sweep's loader is unpickled in the worker
    (cache_plugin_scan) the scan is made once and every job gets the same classes. The worker also emits its jobs'
    .hydra files by libyaml from then on (libyaml_for_omegaconf).

    Run in a fresh interpreter, as a worker is: each scan re-executes Hydra's plugin modules in place, so doing it
    in the test process would leave later tests with config sources whose classes are no longer the modules'.
    And its jobs' configs are copied by the faster copies (fast_config_copies)."""
    script = textwrap.dedent("""
        import pickle
        from hydra.core.plugins import Plugins
        from hydra.core.singleton import Singleton
        from ddmr_cli.config.compose_once import SweepConfigLoader

        pickle.loads(pickle.dumps(SweepConfigLoader(None)))  # what a worker does with each batch of jobs
        import yaml, omegaconf.omegaconf
        libyaml = getattr(omegaconf.omegaconf.get_omega_conf_dumper, "ddmr_libyaml", False)
        assert libyaml == yaml.__with_libyaml__, "the worker's .hydra files are not emitted by libyaml"
        from ddmr_cli import compat
        from omegaconf import base, nodes
        assert base.Metadata.__deepcopy__ is compat._metadata_deepcopy, "the worker copies metadata generically"
        assert nodes.StringNode.__deepcopy__ is compat._value_node_deepcopy, "the worker constructs node copies"
        Singleton.set_state(Singleton.get_state())
        first = dict(Plugins.instance().class_name_to_class)
        Singleton.set_state(Singleton.get_state())
        again = Plugins.instance().class_name_to_class
        assert first, "no plugin found"
        moved = [name for name, cls in first.items() if again[name] is not cls]
        assert not moved, f"scanned again: {moved}"
        print("scanned once:", len(first), "plugins")
    """)
    done = subprocess.run([sys.executable, "-c", script], capture_output=True, text=True, timeout=120)
    assert done.returncode == 0, done.stderr[-2000:]
    assert "scanned once:" in done.stdout


def test_run_hydra_job_is_hydras_per_job_work(tmp_path):
    """run_hydra_job runs a task as Hydra's launchers do: the task gets the config without its hydra node, and the
    job's dir gets Hydra's three .hydra files."""
    from hydra.core.hydra_config import HydraConfig

    from ddmr_cli.config import compose_config

    before = HydraConfig.instance().cfg
    cfg = compose_config(["run.n_runs=1", "run.plots=false"], return_hydra_config=True)
    cfg.hydra.sweep.dir, cfg.hydra.sweep.subdir = str(tmp_path), "job0"
    seen = compat.run_hydra_job(lambda task_cfg: ("hydra" in task_cfg, int(task_cfg.run.n_runs)), cfg)
    assert seen == (False, 1)
    assert sorted(p.name for p in (tmp_path / "job0" / ".hydra").iterdir()) == ["config.yaml", "hydra.yaml",
                                                                               "overrides.yaml"]
    assert OmegaConf.load(tmp_path / "job0" / ".hydra" / "config.yaml").run.n_runs == 1
    assert HydraConfig.instance().cfg is before  # restored as it was

    def failing(task_cfg):
        raise ValueError("boom")

    with pytest.raises(Exception, match="boom"):
        compat.run_hydra_job(failing, cfg)


def test_libyaml_for_omegaconf_emits_the_same_data_and_is_put_back():
    """OmegaConf.to_yaml through libyaml (what Hydra writes each job's .hydra files with, in ddmr's sweep workers and
    runs) reads back as the same data as through OmegaConf's own emitter: the strings OmegaConf's representer quotes
    (those that would read back as a bool, int or float), None, unicode, long strings with newlines and escapes (the
    two emitters fold those at other places), interpolations, and a job's whole hydra node. A second install does
    nothing; the restore puts OmegaConf's emitter back. Without libyaml in PyYAML, nothing is installed. ("1e3" is a
    string to PyYAML but a float to OmegaConf's loader: OmegaConf's representer quotes it, PyYAML's would not.)"""
    import omegaconf.omegaconf as module
    import yaml
    from omegaconf._utils import OmegaConfDumper

    from ddmr_cli.config import compose_config

    tricky = OmegaConf.create({"bool": "true", "yes": "yes", "int": "12", "float": "1.5e3", "sci": "1e3", "none": None,
                               "empty": "",
                               "unicode": "Zürich ± 5 %", "interp": "${bool}", "nested": {"list": [1, "2", None]},
                               "long": "Examples:\n  ddmr run   " * 20 + "\ttab \"quote\""})
    job = compose_config(["run.n_runs=1"], return_hydra_config=True).hydra
    configs = [tricky, OmegaConf.create({"hydra": job})]
    plain = [OmegaConf.to_yaml(cfg) for cfg in configs]
    restore = compat.libyaml_for_omegaconf()
    try:
        installed = module.get_omega_conf_dumper()
        fast = [OmegaConf.to_yaml(cfg) for cfg in configs]
        compat.libyaml_for_omegaconf()()  # installed already: its restore does nothing
        assert module.get_omega_conf_dumper() is installed
    finally:
        restore()
    assert module.get_omega_conf_dumper() is OmegaConfDumper
    assert issubclass(installed, yaml.CDumper) == bool(yaml.__with_libyaml__)
    for cfg, a, b in zip(configs, plain, fast):  # read back by PyYAML and by OmegaConf's own loader (YAML 1.2 floats)
        assert yaml.safe_load(b) == yaml.safe_load(a) == OmegaConf.to_container(cfg)
        assert OmegaConf.to_container(OmegaConf.create(b)) == OmegaConf.to_container(cfg)
    assert OmegaConf.create(fast[0]).sci == "1e3"  # a string OmegaConf would read as a float is quoted


def _node_pairs(a, b):
    """Every node of two configs of the same shape, in step (depth first), and each one's parent in its config."""
    todo = [(a, b)]
    while todo:
        x, y = todo.pop()
        yield x, y
        cx, cy = x.__dict__.get("_content"), y.__dict__.get("_content")
        if isinstance(cx, dict):
            assert isinstance(cy, dict) and list(cx) == list(cy)
            todo.extend((cx[k], cy[k]) for k in cx)
        elif isinstance(cx, list):
            assert isinstance(cy, list) and len(cx) == len(cy)
            todo.extend(zip(cx, cy))
        else:
            assert cx == cy or cx is cy


def test_fast_config_copies_make_omegaconfs_copies_and_are_put_back():
    """copy.deepcopy of a config with the faster metadata and value-node copies (what Hydra's run_job does four times
    a job, in ddmr's workers and runs) gives what OmegaConf's own gives, node by node: the same classes, fields,
    values (the same objects), parents (each the copy's own), metadata (equal, not shared: a flag set on the copy
    leaves the original as it was), on a job's whole config with its hydra node and on a config with flags, lists,
    an enum, interpolations, a structured node and a filled resolver cache. A second install does nothing; the
    restore puts OmegaConf's own copies back."""
    import copy
    import enum
    from dataclasses import dataclass, field

    from omegaconf import base, nodes

    from ddmr_cli.config import compose_config

    class Colour(enum.Enum):
        RED = 1

    @dataclass
    class Gains:
        k: float = 1.5
        names: list = field(default_factory=lambda: ["a", "b"])

    mixed = OmegaConf.create({"a": 1, "b": "x", "c": 2.5, "d": True, "e": None, "f": b"raw", "list": [1, "two", {"z": 3}],
                              "interp": "${a}", "deep": {"readonly": {"v": 1}}})
    mixed.colour = Colour.RED  # an EnumNode (OmegaConf's own copy stays)
    mixed.gains = OmegaConf.structured(Gains)
    OmegaConf.set_readonly(mixed.deep.readonly, True)
    OmegaConf.set_struct(mixed.gains, True)
    mixed._get_node("a")._metadata.resolver_cache["r"]["k"] = "cached"
    configs = [compose_config(["run.n_runs=1"], return_hydra_config=True), mixed]
    own = [copy.deepcopy(c) for c in configs]
    originals = {name: getattr(nodes, name).__dict__["__deepcopy__"] for name in compat._VALUE_NODES}
    restore = compat.fast_config_copies()
    try:
        assert base.Metadata.__dict__["__deepcopy__"] is compat._metadata_deepcopy
        assert all(getattr(nodes, name).__dict__["__deepcopy__"] is compat._value_node_deepcopy
                   for name in compat._VALUE_NODES)
        fast = [copy.deepcopy(c) for c in configs]
        compat.fast_config_copies()()  # installed already: its restore leaves them in place
        assert base.Metadata.__dict__["__deepcopy__"] is compat._metadata_deepcopy
    finally:
        restore()
    assert "__deepcopy__" not in base.Metadata.__dict__
    assert all(getattr(nodes, name).__dict__["__deepcopy__"] is originals[name] for name in compat._VALUE_NODES)
    counted = 0
    for config, theirs, ours in zip(configs, own, fast):
        assert OmegaConf.to_container(ours, resolve=False) == OmegaConf.to_container(theirs, resolve=False)
        for (a, b), (o, _) in zip(_node_pairs(theirs, ours), _node_pairs(config, config)):
            counted += 1
            assert type(a) is type(b) and list(a.__dict__) == list(b.__dict__)
            ma, mb = a.__dict__["_metadata"], b.__dict__["_metadata"]
            assert type(ma) is type(mb) and ma.__dict__ == mb.__dict__ and mb is not o.__dict__["_metadata"]
            assert mb.flags is not o.__dict__["_metadata"].flags
            assert mb.resolver_cache is not o.__dict__["_metadata"].resolver_cache
            if "_val" in a.__dict__:
                assert b.__dict__["_val"] is a.__dict__["_val"] and b.__dict__["_flags_cache"] is None
            for child in (b.__dict__.get("_content") or {}).values() if isinstance(b.__dict__.get("_content"),
                                                                                   dict) else ():
                assert child.__dict__["_parent"] is b  # each node's parent is the copy's own
    assert counted > 250
    copied = fast[1]
    assert OmegaConf.is_readonly(copied.deep.readonly) and OmegaConf.is_struct(copied.gains)
    assert copied.interp == 1 and copied.colour is Colour.RED
    OmegaConf.set_readonly(copied.deep.readonly, False)
    copied._get_node("a")._metadata.resolver_cache["r"]["k"] = "changed"
    assert OmegaConf.is_readonly(mixed.deep.readonly)  # the original's metadata is its own
    assert mixed._get_node("a")._metadata.resolver_cache["r"]["k"] == "cached"
