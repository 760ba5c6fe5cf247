"""Every private or version-dependent API of a library the package uses, in one place: one section per library.

An upgrade of a library touches this file only. Each section states the versions it supports, checks the installed
one (:func:`check_hydra`, :func:`require_optuna`), and wraps each private symbol in one function with a test of its
own (``tests/test_compat.py``), so a release that moves a symbol fails that test by name.

Hydra
    ddmr reaches into Hydra where its public API has no equivalent: composing a sweep's jobs from one composition
    (its loader's override application and its repository), naming job dirs exactly as Hydra will, expanding a
    sweep as its basic sweeper does, locating a ``_target_`` class without Hydra's error log line, and running
    Hydra's per-job work outside a launcher (``ddmr bench`` times it: :func:`run_hydra_job`).
    :data:`HYDRA_SUPPORTED`: the ``major.minor`` releases these wrappers are written for (``hydra-core>=1.3.2,<1.4``
    in ``pyproject.toml``). :func:`check_hydra` raises :class:`~ddmr_cli.errors.DDMRError` on another release.

OmegaConf
    ``OmegaConf.to_yaml`` emits through PyYAML's pure-Python emitter (``omegaconf._utils.get_omega_conf_dumper``):
    Hydra writes every job's three ``.hydra`` files with it. :func:`libyaml_for_omegaconf` points it at PyYAML's C
    emitter with OmegaConf's own representer. Hydra deep-copies a job's whole config four times a job, and most of
    each copy is the generic ``copy.deepcopy`` of every node's metadata (``omegaconf.base.Metadata``, a dataclass)
    and the construction of every value node that its copy then overwrites: :func:`fast_config_copies` gives both a
    ``__deepcopy__`` that makes the same copy directly. :func:`omegaconf_speedups` installs both hooks. Tested with
    omegaconf 2.3.

Optuna (the ``tune`` extra: gain tuning and the calibration search, ``hydra/sweeper=ddmr_optuna``)
    Supported: :data:`OPTUNA_MIN` and later (the plugin uses the public ask-and-tell and ``suggest_*`` API; tested
    with 4.x and 5.0). Private symbols: a trial's storage id and the storage behind a study
    (:func:`mark_killed`: a user attribute on a trial a killed session left RUNNING; Optuna has no public way to
    annotate a trial it did not hand out in this process), and the system attribute ``fixed_params`` that
    ``Study.enqueue_trial`` writes (:func:`was_enqueued`).
"""

from __future__ import annotations

import contextlib
import functools
from typing import Any, Callable, Iterable, Iterator, Sequence

from ddmr_cli.errors import ConfigError, DDMRError

def _release(version: str) -> tuple[int, ...]:
    """``'4.5.0'`` -> ``(4, 5, 0)`` (pre-releases and local tags dropped: ``'5.0.0rc1'`` -> ``(5, 0, 0)``)."""
    from packaging.version import Version

    return Version(version).release


# --- Hydra ------------------------------------------------------------------------------------------------------

#: Hydra releases (major, minor) the wrappers below are written for
HYDRA_SUPPORTED = ((1, 3),)


def check_hydra(version: str | None = None) -> None:
    """Raise DDMRError (one line) unless the installed Hydra (or ``version``) is a release the wrappers support."""
    if version is None:
        import hydra

        version = hydra.__version__
    if _release(version)[:2] not in HYDRA_SUPPORTED:
        supported = ", ".join(f"{a}.{b}" for a, b in HYDRA_SUPPORTED)
        raise DDMRError(f"hydra-core {version} is installed; ddmr uses private Hydra APIs written for {supported}.x "
                        f"(ddmr_cli/compat.py): pip install 'hydra-core>=1.3.2,<1.4'")


def apply_overrides(overrides: Sequence, cfg) -> None:
    """Apply parsed value overrides to a composed config in place, as Hydra's loader does after composing the
    defaults tree (struct mode on): ``ConfigLoaderImpl._apply_overrides_to_config``."""
    from hydra._internal.config_loader_impl import ConfigLoaderImpl

    ConfigLoaderImpl._apply_overrides_to_config(list(overrides), cfg)


def check_sweep_overrides(parsed: Sequence, run_mode, from_shell: bool = True) -> None:
    """Hydra's check that sweep overrides appear only in a multirun (and, from the shell, not as bare lists):
    ``ConfigLoaderImpl.validate_sweep_overrides_legal``."""
    from hydra._internal.config_loader_impl import ConfigLoaderImpl

    ConfigLoaderImpl.validate_sweep_overrides_legal(list(parsed), run_mode=run_mode, from_shell=from_shell)


@contextlib.contextmanager
def loading_through(load: Callable[..., Any]) -> Iterator[None]:
    """Within the context, every whole composition of this process (Hydra's compose API, Hydra's ``get_mode``,
    run and multirun) calls ``load(loader, compose, config_name, overrides, run_mode, from_shell,
    validate_sweep_overrides)``, ``compose`` being the loader's own method: ``ConfigLoaderImpl.load_configuration``
    is wrapped, and restored on leaving (:func:`ddmr_cli.config.compose_once.compositions_once`)."""
    from hydra._internal.config_loader_impl import ConfigLoaderImpl

    original = ConfigLoaderImpl.load_configuration

    def load_configuration(self, config_name, overrides, run_mode, from_shell=True, validate_sweep_overrides=True):
        return load(self, functools.partial(original, self), config_name, overrides, run_mode, from_shell,
                    validate_sweep_overrides)

    load_configuration.ddmr_load = load  # what current_load reads
    ConfigLoaderImpl.load_configuration = load_configuration
    try:
        yield
    finally:
        ConfigLoaderImpl.load_configuration = original


def current_load() -> Callable[..., Any] | None:
    """The ``load`` of the innermost :func:`loading_through` context this process is in, or None outside one."""
    from hydra._internal.config_loader_impl import ConfigLoaderImpl

    return getattr(ConfigLoaderImpl.load_configuration, "ddmr_load", None)


def cache_plugin_scan() -> None:
    """Make Hydra's plugin scan of this process run once: ``Plugins._scan_all_plugins`` re-executes every module of
    ``hydra_plugins`` whenever the plugin registry is made anew, which a launcher's worker does for every job
    (``Singleton.set_state`` drops the registry and scans again: about a quarter of a short job's CPU, more with
    the Optuna and submitit plugins installed). Later scans of the same packages return the first scan's plugin
    classes, as a worker that ran one job has them. Idempotent."""
    from hydra.core.plugins import Plugins

    scan = Plugins.__dict__["_scan_all_plugins"].__func__
    if getattr(scan, "ddmr_cached", False):
        return
    found: dict[tuple[str, ...], Any] = {}

    def scan_once(modules):
        key = tuple(m.__name__ for m in modules)
        if key not in found:
            found[key] = scan(modules)
        return found[key]

    scan_once.ddmr_cached = True
    Plugins._scan_all_plugins = staticmethod(scan_once)


def overrides_dirname(parsed: Sequence, exclude_keys: Iterable[str], item_sep: str, kv_sep: str) -> str:
    """``hydra.job.override_dirname`` of parsed overrides, as Hydra computes it for a job."""
    from hydra._internal.config_loader_impl import get_overrides_dirname

    return get_overrides_dirname(list(parsed), exclude_keys=list(exclude_keys), item_sep=item_sep, kv_sep=kv_sep)


def basic_sweeper(max_batch_size: int | None = None, params: dict | None = None):
    """A new instance of Hydra's basic sweeper (the class Hydra's own plugin registry holds)."""
    from hydra._internal.core_plugins.basic_sweeper import BasicSweeper

    return BasicSweeper(max_batch_size=max_batch_size, params=params)


def split_sweep(parsed: Sequence) -> list[list[str]]:
    """The job override lists Hydra's basic sweeper makes of parsed overrides (the cartesian product, in its
    order): ``BasicSweeper.split_arguments`` in one batch."""
    from hydra._internal.core_plugins.basic_sweeper import BasicSweeper

    return BasicSweeper.split_arguments(list(parsed), None)[0]


def locate(path: str) -> Any:
    """The object a dotted path names (``_target_``), raising on failure without the error line Hydra's public
    ``hydra.utils.get_class`` logs: ``hydra._internal.utils._locate``."""
    from hydra._internal.utils import _locate

    return _locate(path)


def run_hydra_job(task: Callable[[Any], Any], cfg) -> Any:
    """Hydra's own per-job work around ``task``, as every launcher runs a job (``hydra.core.utils.run_job``:
    the config copies, ``HydraConfig`` set for the job and restored after it, the job's
    ``.hydra/{config,hydra,overrides}.yaml``),
    outside a launcher: ``cfg`` is a composed job config with its ``hydra`` node (``hydra.sweep.dir`` and
    ``hydra.sweep.subdir`` name the job's dir), no callbacks (``hydra._internal.callbacks.Callbacks``), Hydra's
    logging left as it is. Returns what ``task`` returned (raises what it raised). What ``ddmr bench`` times as the
    floor of a job."""
    from hydra._internal.callbacks import Callbacks
    from hydra.core.utils import run_job
    from hydra.types import HydraContext

    context = HydraContext(config_loader=None, callbacks=Callbacks())
    ret = run_job(task, cfg, "hydra.sweep.dir", "hydra.sweep.subdir", context, configure_logging=False)
    return ret.return_value


# --- OmegaConf --------------------------------------------------------------------------------------------------

@functools.lru_cache(maxsize=1)
def _libyaml_dumper():
    """OmegaConf's YAML dumper on PyYAML's C emitter (libyaml), with OmegaConf's one representer (a string that would
    read back as a bool, int or float is quoted); None where PyYAML is built without libyaml or omegaconf's dumper
    has moved."""
    import yaml

    try:
        from omegaconf._utils import OmegaConfDumper
    except ImportError:
        return None
    if not getattr(yaml, "__with_libyaml__", False) or not hasattr(OmegaConfDumper, "str_representer"):
        return None

    class LibyamlOmegaConfDumper(yaml.CDumper):
        pass

    LibyamlOmegaConfDumper.add_representer(str, OmegaConfDumper.str_representer)
    return LibyamlOmegaConfDumper


def libyaml_for_omegaconf() -> Callable[[], None]:
    """Make ``OmegaConf.to_yaml`` emit through libyaml (what Hydra writes every job's ``.hydra/config.yaml``,
    ``hydra.yaml`` and ``overrides.yaml`` with: about 9 ms of a job's CPU by PyYAML's Python emitter, 3.4 ms by
    libyaml). The same data: the texts differ only where the two emitters fold a long quoted string at other
    places. Replaces ``get_omega_conf_dumper`` in ``omegaconf.omegaconf``, the module ``to_yaml`` reads it from.
    Returns a function that puts back what was there (nothing to do where it was installed already, or where
    libyaml or the hook is missing). Idempotent."""
    import omegaconf.omegaconf as module

    original = getattr(module, "get_omega_conf_dumper", None)
    dumper = _libyaml_dumper()
    if original is None or dumper is None or getattr(original, "ddmr_libyaml", False):
        return lambda: None

    def get_omega_conf_dumper():
        return dumper

    get_omega_conf_dumper.ddmr_libyaml = True
    module.get_omega_conf_dumper = get_omega_conf_dumper

    def restore() -> None:
        module.get_omega_conf_dumper = original

    return restore


#: the fields of ``omegaconf.base.Metadata`` :func:`fast_config_copies` was written for (omegaconf 2.3)
_METADATA_FIELDS = ("ref_type", "object_type", "optional", "key", "flags", "flags_root", "resolver_cache")
#: the types ``copy.deepcopy`` returns as they are (``copy._deepcopy_atomic``), of those a node's metadata holds
_ATOMIC = frozenset({type(None), bool, int, float, str, type})


def _metadata_deepcopy(self, memo: dict) -> Any:
    """``copy.deepcopy`` of a node's metadata, as its generic path copies a dataclass (a new instance, every field
    deep-copied with ``memo``), without that path's ``__reduce_ex__`` and reconstruction: a field that deepcopy
    returns as it is (a type, a str, a bool, None) is kept, the resolver cache when empty (a ``defaultdict``) and a
    flags dict of plain values are copied directly, and anything else goes through ``copy.deepcopy``."""
    import copy
    from collections import defaultdict

    cls = type(self)
    new = cls.__new__(cls)
    memo[id(self)] = new
    fields = new.__dict__
    for name, value in self.__dict__.items():
        kind = type(value)
        if kind in _ATOMIC:
            fields[name] = value
        elif kind is defaultdict and not value:
            fields[name] = memo[id(value)] = defaultdict(value.default_factory)
        elif kind is dict and all(type(k) in _ATOMIC and type(v) in _ATOMIC for k, v in value.items()):
            fields[name] = memo[id(value)] = dict(value)
        else:
            fields[name] = copy.deepcopy(value, memo)
    return new


#: the value nodes :func:`fast_config_copies` copies without constructing a node first (those whose fresh instance
#: holds nothing but what their copy overwrites: not ``EnumNode``, which also holds its enum type)
_VALUE_NODES = ("AnyNode", "StringNode", "IntegerNode", "FloatNode", "BooleanNode", "PathNode", "BytesNode")
#: what a fresh value node holds (``Node.__init__`` and ``ValueNode._set_value``), in that order
_VALUE_NODE_FIELDS = ("_metadata", "_parent", "_flags_cache", "_val")


def _value_node_deepcopy(self, memo: dict) -> Any:
    """``copy.deepcopy`` of a value node as OmegaConf's own ``__deepcopy__`` makes it (a fresh node of the same class,
    then ``ValueNode._deepcopy_impl``: the metadata deep-copied, the value and the parent kept), without constructing
    the fresh node through ``__init__`` (which validates a None value under a read-write flag, all of it overwritten):
    the same four fields, set directly."""
    import copy

    cls = type(self)
    res = cls.__new__(cls)
    fields = res.__dict__
    fields["_metadata"] = copy.deepcopy(self.__dict__["_metadata"], memo)
    fields["_parent"] = self.__dict__["_parent"]
    fields["_flags_cache"] = None
    fields["_val"] = self.__dict__["_val"]
    return res


def fast_config_copies() -> Callable[[], None]:
    """Make OmegaConf's deep copies of a config twice as fast, the same copies: node metadata
    (``omegaconf.base.Metadata``, and so ``ContainerMetadata``) gets the ``__deepcopy__``
    :func:`_metadata_deepcopy`, and the plain value nodes (:data:`_VALUE_NODES`) :func:`_value_node_deepcopy`.
    Hydra's ``run_job`` copies a job's config four times a job (the job's, the task's, the hydra node's,
    ``HydraConfig.set_config``'s masked copy); the bench's job config with its hydra node: 6.8 -> 3.5 ms a copy by
    the metadata alone. Returns a function that takes them away again. Each part is installed only where OmegaConf
    is as it was written for: ``Metadata`` the dataclass of :data:`_METADATA_FIELDS` without a ``__deepcopy__`` of
    its own, a value node whose fresh instance holds :data:`_VALUE_NODE_FIELDS` and nothing else, with
    ``_flags_cache`` None. Idempotent."""
    import dataclasses

    from omegaconf import base, nodes

    undo: list[tuple[type, Any]] = []
    cls = base.Metadata
    if (dataclasses.is_dataclass(cls) and "__deepcopy__" not in cls.__dict__ and not hasattr(cls, "__slots__")
            and tuple(f.name for f in dataclasses.fields(cls)) == _METADATA_FIELDS):
        cls.__deepcopy__ = _metadata_deepcopy
        undo.append((cls, None))
    for name in _VALUE_NODES:
        node = getattr(nodes, name, None)
        own = getattr(node, "__dict__", {}).get("__deepcopy__")
        if own is None or own is _value_node_deepcopy or not hasattr(nodes.ValueNode, "_deepcopy_impl"):
            continue
        fresh = node()
        if tuple(fresh.__dict__) != _VALUE_NODE_FIELDS or fresh.__dict__["_flags_cache"] is not None:
            continue
        node.__deepcopy__ = _value_node_deepcopy
        undo.append((node, own))

    def restore() -> None:
        for owner, original in reversed(undo):
            if owner.__dict__.get("__deepcopy__") in (_metadata_deepcopy, _value_node_deepcopy):
                if original is None:
                    del owner.__deepcopy__
                else:
                    owner.__deepcopy__ = original

    return restore


def omegaconf_speedups() -> Callable[[], None]:
    """:func:`libyaml_for_omegaconf` and :func:`fast_config_copies`; returns a function that puts both back."""
    restores = [libyaml_for_omegaconf(), fast_config_copies()]

    def restore() -> None:
        for undo in reversed(restores):
            undo()

    return restore


def config_repository(loader) -> Any:
    """The config repository of a Hydra config loader (``group_exists``, ``get_group_options``):
    ``ConfigLoaderImpl.repository``."""
    return loader.repository


# --- Optuna -----------------------------------------------------------------------------------------------------

#: The oldest Optuna the tuning and the calibration search support.
OPTUNA_MIN = (4, 0)
#: The user attribute a killed session's trial carries (``tuning_trials.csv`` column ``killed``).
KILLED_ATTR = "killed"
#: The system attribute ``Study.enqueue_trial`` writes on a trial with fixed parameters (Optuna >= 2.x, private).
ENQUEUED_ATTR = "fixed_params"


def require_optuna(key: str = "hydra/sweeper", value: str = "ddmr_optuna") -> Any:
    """The ``optuna`` module, checked to be :data:`OPTUNA_MIN` or later.

    Raises
    ------
    ConfigError
        Naming ``key=value`` (what asked for Optuna) when Optuna is missing or too old, with the pip extra.
    """
    try:
        import optuna
    except ImportError:
        raise ConfigError(key, value, "needs optuna, which is not installed; pip install 'ddmr-cli[tune]' "
                                      "(pip install -e '.[tune]' in a checkout)") from None
    if _release(optuna.__version__) < OPTUNA_MIN:
        raise ConfigError(key, value, f"needs optuna >= {'.'.join(map(str, OPTUNA_MIN))} (installed: "
                                      f"{optuna.__version__}); pip install 'ddmr-cli[tune]'")
    return optuna


def mark_killed(study: Any, trial: Any) -> None:
    """Close a trial a killed session left RUNNING: user attribute :data:`KILLED_ATTR`, then state FAIL.

    Private: ``study._storage`` and ``trial._trial_id`` (the user attribute; Optuna >= 4 names no public way to
    annotate a trial by number). The state goes through the public ``Study.tell(number, state=FAIL)``."""
    from optuna.trial import TrialState

    study._storage.set_trial_user_attr(trial._trial_id, KILLED_ATTR, True)
    study.tell(trial.number, state=TrialState.FAIL)


def was_enqueued(trial: Any) -> bool:
    """True for a trial whose parameters were given by ``Study.enqueue_trial`` (a warm start).

    Private: the system attribute :data:`ENQUEUED_ATTR` Optuna writes on such a trial."""
    return ENQUEUED_ATTR in trial.system_attrs


__all__ = ["HYDRA_SUPPORTED", "check_hydra", "apply_overrides", "current_load", "overrides_dirname", "basic_sweeper",
           "run_hydra_job", "split_sweep", "locate", "config_repository",
           "OPTUNA_MIN", "KILLED_ATTR", "ENQUEUED_ATTR", "require_optuna", "mark_killed", "was_enqueued"]
