"""Hydra at the edge: config schemas, composition, validation and building the model from a config."""

from __future__ import annotations

import dataclasses
from typing import Any, Callable, Iterator, Sequence

from omegaconf import DictConfig, ListConfig, OmegaConf

from ddmr_cli.compat import check_hydra, config_repository
from ddmr_cli.config import schema  # noqa: F401  (registers the schemas in Hydra's ConfigStore)
from hydra_plugins.ddmr_sweeper import ddmr_sweeper  # noqa: F401  (registers hydra/sweeper=ddmr, conf/launcher/*.yaml)
from hydra_plugins.ddmr_optuna_sweeper import config as _optuna_sweeper  # noqa: F401  (hydra/sweeper=ddmr_optuna, its samplers)
from ddmr_cli.config.build import build_simulation, config_hash, seeds_of
from ddmr_cli.config.validate import kept_seeds, validate_config

CONFIG_MODULE = "ddmr_cli.conf"
MODEL_DOC = "docs/model.md"


def _register_resolvers() -> None:
    """``${ddmr.eq:a,b}``: true when the two (interpolated) strings are equal; e.g. per-job plots for one job of
    a sweep (conf/experiment/smoke.yaml); ``${ddmr.digest:text}`` (:func:`_digest`); ``${ddmr.jobdir:name}``
    (:func:`ddmr_cli.storage.jobdir.safe_name`). Registered on import, in every process that composes a config."""
    from ddmr_cli.storage.jobdir import safe_name

    OmegaConf.register_new_resolver("ddmr.eq", lambda a, b: str(a) == str(b), replace=True)
    OmegaConf.register_new_resolver("ddmr.digest", _digest, replace=True)
    # ``${ddmr.jobdir:${hydra.job.override_dirname}}``: a job's dir name, safe and bounded (conf/config.yaml)
    OmegaConf.register_new_resolver("ddmr.jobdir", lambda name="": safe_name(str(name)), replace=True)


def _digest(text) -> str:
    """``${ddmr.digest:text}``: 12 hex digits of SHA-256, e.g. a tuning trial's dir from its overrides (a resumed
    study's trials get new dirs, and the same gains the same dir)."""
    import hashlib

    return hashlib.sha256(str(text).encode()).hexdigest()[:12]


check_hydra()  # the private Hydra APIs of ddmr_cli/compat.py are written for this release
_register_resolvers()


def compose_config(overrides: Sequence[str] = (), config_name: str = "config", return_hydra_config: bool = False,
                   config_dir: str | None = None):
    """Compose the packaged config (or the primary config of ``config_dir``, as ``ddmr run --config-path``)
    with Hydra's compose API (no output directory is made), through the composition memo
    (:func:`~ddmr_cli.config.compose_once.compositions_once`): the defaults tree of a set of group choices of the
    packaged config is composed by Hydra once and kept in ddmr's cache between processes
    (:mod:`~ddmr_cli.config.skeleton_cache`; about 0.02 s to load against 0.3 s to compose), the values applied to
    a copy as Hydra's loader applies them; with ``DDMR_SKELETON_CACHE=0``, Hydra's compose API alone. Like Hydra's
    compose API, not for concurrent threads."""
    import contextlib

    from hydra import compose

    from ddmr_cli.config import skeleton_cache
    from ddmr_cli.config.compose_once import compositions_once

    with _initialized(config_dir), (compositions_once() if skeleton_cache.enabled() else contextlib.nullcontext()):
        return compose(config_name=config_name, overrides=list(overrides), return_hydra_config=return_hydra_config)


def _initialized(config_dir: str | None = None):
    """Hydra initialised on the packaged config (or on ``config_dir``), as a context."""
    from hydra import initialize_config_dir, initialize_config_module
    from hydra.core.global_hydra import GlobalHydra

    if GlobalHydra.instance().is_initialized():
        GlobalHydra.instance().clear()
    return (initialize_config_dir(config_dir=str(config_dir), version_base="1.3") if config_dir else
            initialize_config_module(config_module=CONFIG_MODULE, version_base="1.3"))


class JobComposer:
    """Compose the jobs of one sweep as Hydra does, the defaults once per distinct set of group choices.

    Hydra composes a config in two stages: the defaults tree from the overrides that name a config group
    (``controller=pid``, ``+experiment=table4``), then the remaining value overrides applied in order to the
    result (``ConfigLoaderImpl._apply_overrides_to_config``, struct mode on). A sweep of values (seeds, gains,
    parameters of a study) has one set of group choices, so the first stage, about 0.12 s a job, is done once
    and each job costs a copy and its value overrides, by the rule of :mod:`ddmr_cli.config.compose_once`
    (which Hydra's own composition of the jobs, in the sweeper and the launchers, also follows). Any job of a
    user's config dir (``--config-path``, ``--config-dir``) composes in full. tests/test_config.py checks the
    result against a full composition for every kind of override.
    """

    def __init__(self, config_name: str = "config", config_dir: str | None = None, extra: Sequence[str] = ()):
        from ddmr_cli.config.compose_once import Skeletons

        self.config_name, self.config_dir, self.extra = config_name, config_dir, list(extra)
        self._skeletons = Skeletons()

    def compose(self, overrides: Sequence[str]) -> DictConfig:
        """The job's config, without the hydra node: equal to ``compose_config(overrides + extra)``."""
        from ddmr_cli.config.compose_once import split_overrides

        full = [*overrides, *self.extra]
        if self.config_dir or self.extra:  # the groups of a user's config dirs: Hydra's repository of the job
            return compose_config(full, self.config_name, config_dir=self.config_dir)
        split = split_overrides(self._skeletons.parse(full), self._is_group)
        if split is None:
            return compose_config(full, self.config_name)
        groups, values = split
        return self._skeletons.job(tuple(o.input_line for o in groups), lambda: self._skeleton(groups), values)

    def _skeleton(self, groups: Sequence) -> DictConfig:
        """The composition of the group choices ``groups`` (parsed overrides), without the hydra node."""
        from omegaconf import open_dict

        cfg = compose_config([o.input_line for o in groups], self.config_name, return_hydra_config=True)
        with open_dict(cfg):
            del cfg["hydra"]
        return cfg

    def prefetch(self, jobs: Sequence[Sequence[str]], workers: int,
                 while_composing: Callable[[int, int], Any] | None = None) -> int:
        """Compose ahead the skeletons of ``jobs`` (each its override lines) that ddmr's cache lacks, in this process
        and ``workers - 1`` helper processes at once (:mod:`ddmr_cli.config.compose_parallel`): the first sweep after
        an edit of ``conf/``. ``while_composing(n_sets, n_processes)``: a context shown meanwhile. Returns the
        helpers started (0: the cache held the first set, or too few sets, or a user's config dir)."""
        from ddmr_cli.config import compose_parallel, skeleton_cache
        from ddmr_cli.config.compose_once import compositions_once, split_overrides

        if self.config_dir or self.extra or not skeleton_cache.enabled():
            return 0
        sets: dict[tuple[str, ...], Sequence] = {}
        for job in jobs:
            split = split_overrides(self._skeletons.parse(list(job)), self._is_group)
            if split is not None:
                sets.setdefault(tuple(o.input_line for o in split[0]), split[0])

        def compose(key: tuple[str, ...]) -> bool:  # a set that does not compose is validation's to report
            with compositions_once() as memo:
                before = memo.composed
                try:
                    self._skeletons.keep(key, lambda: self._skeleton(sets[key]))
                except Exception:  # noqa: BLE001 - Hydra's and OmegaConf's errors, reported by validation
                    return False
                return memo.composed > before

        return compose_parallel.share([k for k in sets if not self._skeletons.holds(k)], compose, self.config_name,
                                      workers, while_composing)

    def _is_group(self, key: str) -> bool:
        return self._skeletons.is_group(key, _packaged_repository)


def _packaged_repository():
    """Hydra's config repository of ddmr's packaged config."""
    from hydra.core.global_hydra import GlobalHydra

    with _initialized():
        return config_repository(GlobalHydra.instance().config_loader())


def group_options(group: str) -> list[str]:
    """The options of a config group (``controller`` -> ``pid, smc, ...``), schemas left out."""
    from hydra.core.global_hydra import GlobalHydra

    with _initialized():
        options = GlobalHydra.instance().config_loader().get_group_options(group)
    return sorted(options)


#: groups chosen with ``+group=option`` (no default in config.yaml): the experiment presets and tuning studies
ADDED_GROUPS = ("experiment", "tune")


def config_groups() -> list[str]:
    """Every config group of the packaged config (``robot``, ``controller``, ..., ``sensor``, ``actuator``), in
    ``config.yaml``'s defaults order, then the groups added with ``+`` (:data:`ADDED_GROUPS`), then the rest;
    read from the packaged config, so a new group is listed without a code change."""
    from hydra.core.global_hydra import GlobalHydra
    from hydra.core.object_type import ObjectType

    with _initialized():
        repo = config_repository(GlobalHydra.instance().config_loader())
        groups = [name for name in repo.get_group_options("", results_filter=ObjectType.GROUP)
                  if name != "hydra" and not name.startswith("_")]
    defaults = [str(d).split(":")[0].split("@")[0].lstrip("/") for d in _defaults_order()]
    order = {g: i for i, g in enumerate([*defaults, *ADDED_GROUPS])}
    return sorted(groups, key=lambda g: (order.get(g, len(order)), g))


def _defaults_order() -> list[str]:
    """The group names of the packaged ``config.yaml``'s defaults list, in order."""
    from importlib import resources

    from omegaconf import OmegaConf

    text = resources.files(CONFIG_MODULE).joinpath("config.yaml").read_text(encoding="utf-8")
    out = []
    for entry in OmegaConf.create(text).get("defaults", []):
        if isinstance(entry, str):
            out.append(entry)
        else:
            out.extend(str(k) for k in entry)
    return out


def run_config(cfg, progress: Callable[[int, int], None] | None = None):
    """Validate a composed config, build its simulation and run its seeds. Returns a SimulationResult."""
    from ddmr_cli.engine.simulation import simulate

    sim = validate_config(cfg)
    return simulate(sim, seeds_of(cfg), keep_series=kept_seeds(cfg.run), progress=progress)


@dataclasses.dataclass(frozen=True)
class KeyDoc:
    """What the schema says about one key of a composed config (see :func:`ddmr_cli.config.schema.param`)."""

    key: str
    value: Any
    unit: str = ""
    help: str = ""
    range: str = ""
    model: int | None = None
    paper: str = ""
    schema_name: str = ""
    is_leaf: bool = True

    @property
    def section(self) -> str:
        """The title of the model section the key belongs to (``6. Controllers and observers``), or ''."""
        return model_section(self.model) if self.model else ""

    @property
    def reference(self) -> str:
        """``docs/model.md §N (its title)`` (and the paper's place), or a dash for run settings outside the model."""
        title = self.section.partition(". ")[2]
        parts = [f"{MODEL_DOC} §{self.model}" + (f" ({title})" if title else "")] if self.model else []
        if self.paper:
            parts.append(f"paper {self.paper}")
        return "; ".join(parts) or "-"


def model_doc():
    """docs/model.md as shipped with the package (``ddmr_cli.docs``, a wheel install too): an
    :mod:`importlib.resources` Traversable (``.read_text()``; ``importlib.resources.as_file`` for a path)."""
    from importlib.resources import files

    return files("ddmr_cli.docs").joinpath("model.md")


def model_section(number: int) -> str:
    """The heading of section ``number`` of docs/model.md (``6. Controllers and observers``), or ''."""
    prefix = f"## {int(number)}. "
    return next((line[3:].strip() for line in model_doc().read_text(encoding="utf-8").splitlines()
                 if line.startswith(prefix)), "")


def _fields(node_type) -> dict[str, dataclasses.Field]:
    if isinstance(node_type, type) and dataclasses.is_dataclass(node_type):
        return {f.name: f for f in dataclasses.fields(node_type)}
    return {}


def _value(node: Any, key: str) -> Any:
    """The (resolved when possible) plain value of a child node."""
    from omegaconf.errors import OmegaConfBaseException

    try:
        value = node[key]
        return OmegaConf.to_container(value, resolve=True) if isinstance(value, (DictConfig, ListConfig)) else value
    except OmegaConfBaseException:  # an interpolation that resolves only inside a Hydra job: show it as written
        raw = node._get_node(key)._value()
        return OmegaConf.to_container(raw) if isinstance(raw, (DictConfig, ListConfig)) else raw


def key_doc(cfg: DictConfig, key: str) -> KeyDoc:
    """The documentation of ``key`` (dotted) in a composed config; KeyError when the config has no such key.

    The schema of a node is the dataclass it was composed from (``OmegaConf.get_type``), so ``controller.*``
    is documented by the composed controller's schema; entries of free-form dicts (``terrain.zones.<name>``,
    ``cluster.<key>``) by the dict field's metadata."""
    node: Any = cfg
    meta: Any = {}
    schema_name = ""
    parts = key.split(".")
    for i, part in enumerate(parts):
        if isinstance(node, ListConfig):  # an element of a list: the list's documentation
            if not part.isdigit() or int(part) >= len(node) or i != len(parts) - 1:
                raise KeyError(key)
            return KeyDoc(key, node[int(part)], meta.get("unit", ""), meta.get("help", ""), meta.get("range", ""),
                          meta.get("model"), meta.get("paper", ""), schema_name)
        if not isinstance(node, DictConfig) or part not in node:
            raise KeyError(key)
        node_type = OmegaConf.get_type(node)
        fields = _fields(node_type)
        if part in fields:
            meta, schema_name = fields[part].metadata, node_type.__name__
        elif meta.get("entries") and part in meta["entries"]:  # a documented entry of a free-form dict
            unit, text = meta["entries"][part]
            meta = {"unit": unit, "help": text, "model": meta.get("model"), "paper": meta.get("paper", "")}
        elif meta:  # an entry of a dict of schemas (a zone, a phase): the dict's documentation
            meta = {**meta, "help": f"{part!r}: {meta.get('help', '')}", "range": ""}
        if i == len(parts) - 1:
            value = _value(node, part)
            child = node._get_node(part)
            leaf = not isinstance(child, DictConfig) or child._is_none() or len(child) == 0
            return KeyDoc(key, value, meta.get("unit", ""), meta.get("help", ""), meta.get("range", ""),
                          meta.get("model"), meta.get("paper", ""), schema_name, leaf)
        node = node[part]
    raise KeyError(key)


def iter_keys(node: DictConfig, prefix: str = "") -> Iterator[str]:
    """Every leaf key of a config (dotted, lists as one value), in the config's order; no ``hydra`` node."""
    for name in node:
        if not prefix and name == "hydra":
            continue
        child = node._get_node(name)
        key = f"{prefix}{name}"
        if isinstance(child, DictConfig) and not child._is_none() and len(child):
            yield from iter_keys(node[name], f"{key}.")
        else:
            yield key


def key_docs(cfg: DictConfig) -> list[KeyDoc]:
    """:func:`key_doc` of every leaf key (``ddmr run --help``)."""
    return [key_doc(cfg, key) for key in iter_keys(cfg)]


__all__ = ["KeyDoc", "model_doc", "model_section", "key_doc", "key_docs", "iter_keys", "compose_config", "JobComposer", "group_options", "run_config", "build_simulation", "validate_config", "config_hash", "seeds_of",
           "kept_seeds"]
