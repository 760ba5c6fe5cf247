"""Compose the jobs of a sweep from one composition per set of group choices (issue: one composition per sweep).

Hydra composes a config in two stages (``ConfigLoaderImpl._load_configuration_impl``): the defaults tree, from
the overrides that choose a config group option (``controller=pid``, ``+experiment=table4``, ``hydra/launcher=
joblib``) and those of the ``hydra`` node; then the remaining value overrides, applied in order to the result
with struct mode on (``ConfigLoaderImpl._apply_overrides_to_config``). The jobs of a sweep of values (seeds,
gains, a study's parameters) share the first stage, which is nearly all of a composition's 0.1-0.15 s, so it is
done once per distinct set of group choices (the *skeleton*) and each job costs a copy and its value overrides.

:func:`split_overrides` is the rule (Hydra's own: an override is a value override when its key is not a config
group or its value is a dict); any override this module does not derive exactly (a package ``@``, a delete of a
group, ``hydra.searchpath``) makes the job compose in full. :class:`SweepConfigLoader` is Hydra's config loader
with this shortcut in :meth:`~SweepConfigLoader.load_sweep_config`, the call by which Hydra's sweeper validates
every job and its launchers (joblib, submitit, Ray) compose each job; :class:`ddmr_cli.config.JobComposer`
uses the same rule for the CLI's own validation of every job. tests/test_config.py compares both with a full
composition, ``hydra`` node included, for every kind of override.

:class:`CompositionMemo` is the same idea for the few whole compositions of one ``ddmr run`` process: the CLI's
validation, Hydra's ``get_mode`` and Hydra's run (or multirun) compose the same config name and overrides, the
last two with values of the ``hydra`` node added at the end (``hydra.run.dir=...``, ``hydra.mode=RUN``); with
the memo (:func:`compositions_once`) the first call composes and the others copy its result and
apply their added values as Hydra would (issue 28: a single run composed three times). It keys a composition by
its defaults tree, as the skeletons are, so its cache on disk (:mod:`ddmr_cli.config.skeleton_cache`) serves the
next run with other values too.
"""

from __future__ import annotations

import contextlib
import pickle
from typing import Callable, Iterable, Iterator, Sequence

from omegaconf import DictConfig, OmegaConf

from ddmr_cli.compat import config_repository


def split_overrides(parsed: Sequence, is_group: Callable[[str], bool]) -> tuple[list, list] | None:
    """``(structure, values)`` of parsed overrides, in their order, or None when the job must compose in full.

    ``structure``: overrides of the ``hydra`` node and choices of a config group (the defaults tree);
    ``values``: value overrides of the job's own keys, applied after composition (Hydra's rule)."""
    structure, values = [], []
    for o in parsed:
        if o.package is not None or o.get_key_element() == "hydra.searchpath" or \
                (o.is_delete() and is_group(o.key_or_group)):
            return None
        if o.is_hydra_override() or (not isinstance(o.value(), dict) and is_group(o.key_or_group)):
            structure.append(o)
        else:
            values.append(o)
    return structure, values


class OverrideParser:
    """Hydra's override parser that parses each distinct line once (it takes about 1 ms an override, and the jobs
    of a sweep share most of their lines), and which keys name a config group, each asked of Hydra once."""

    def __init__(self) -> None:
        self._parsed: dict[str, object] = {}
        self._groups: dict[str, bool] = {}

    def parse(self, lines: Sequence[str]) -> list:
        """``OverridesParser.create().parse_overrides(lines)``."""
        from hydra.core.override_parser.overrides_parser import OverridesParser

        new = [line for line in dict.fromkeys(lines) if line not in self._parsed]
        if new:
            self._parsed.update(zip(new, OverridesParser.create().parse_overrides(new)))
        return [self._parsed[line] for line in lines]

    def is_group(self, key: str, repository: Callable[[], object]) -> bool:
        """Whether ``key`` names a config group of Hydra's config repository ``repository()`` (called the first
        time a key is asked)."""
        if key not in self._groups:
            self._groups[key] = repository().group_exists(key)
        return self._groups[key]

    def __getstate__(self) -> dict:  # pickled to every batch of jobs: the parsed lines stay (they grow with jobs)
        return {**self.__dict__, "_parsed": {}}


def set_derived(cfg: DictConfig, parsed: Sequence) -> None:
    """What Hydra's loader derives from a job's whole list of overrides (``_load_configuration_impl``), set on a
    composition made from part of it: ``hydra.overrides.hydra`` and ``.task``, and ``hydra.job.override_dirname``
    under the config's own ``exclude_keys`` and separators."""
    from ddmr_cli.compat import overrides_dirname

    app = [o for o in parsed if not o.is_hydra_override()]
    cfg.hydra.overrides.hydra = [o.input_line for o in parsed if o.is_hydra_override()]
    cfg.hydra.overrides.task = [o.input_line for o in app]
    dirname = cfg.hydra.job.config.override_dirname
    cfg.hydra.job.override_dirname = overrides_dirname(app, dirname.exclude_keys, dirname.item_sep, dirname.kv_sep)


class Skeletons(OverrideParser):
    """Composed skeletons by key, each kept pickled (a fresh copy is ``pickle.loads``: 3 ms against ``deepcopy``'s
    5 ms for the whole config), and the parsed form of every override line seen."""

    def __init__(self) -> None:
        super().__init__()
        self._pickled: dict[tuple[str, ...], bytes] = {}

    def holds(self, key: tuple[str, ...]) -> bool:
        """Whether the skeleton ``key`` is composed (in this process)."""
        return key in self._pickled

    def keep(self, key: tuple[str, ...], compose: Callable[[], DictConfig]) -> bytes:
        """The skeleton ``key``, pickled; ``compose()`` makes it the first time."""
        if key not in self._pickled:
            self._pickled[key] = pickle.dumps(compose(), protocol=pickle.HIGHEST_PROTOCOL)
        return self._pickled[key]

    def job(self, key: tuple[str, ...], compose: Callable[[], DictConfig], values: Sequence) -> DictConfig:
        """A copy of the skeleton ``key`` (``compose()`` makes it the first time) with the value overrides
        applied as Hydra applies them."""
        from ddmr_cli.compat import apply_overrides

        cfg = pickle.loads(self.keep(key, compose))
        apply_overrides(values, cfg)
        return cfg


class SweepConfigLoader:
    """Hydra's config loader (``inner``) that composes a sweep's jobs from skeletons (see the module docstring).

    Every method but :meth:`load_sweep_config` is the inner loader's. Its skeletons travel with it: Hydra's
    sweeper validates the jobs first (composing the skeletons in the main process), then a launcher pickles the
    loader with each batch of jobs to its workers or cluster nodes, which derive their jobs from them.
    """

    def __init__(self, inner) -> None:
        self.inner = inner
        self._skeletons = Skeletons()

    def __setstate__(self, state: dict) -> None:
        """Unpickled in a launcher's worker, before the job restores Hydra's state (``Singleton.set_state``, which
        scans every ``hydra_plugins`` module again): the scan is made once per worker process
        (:func:`ddmr_cli.compat.cache_plugin_scan`), and the job's ``.hydra`` files are emitted by libyaml and its
        config copied by the direct copies of node metadata and value nodes (:func:`ddmr_cli.compat.omegaconf_speedups`:
        the worker belongs to the launcher, so for good)."""
        from ddmr_cli.compat import cache_plugin_scan, omegaconf_speedups

        self.__dict__.update(state)
        cache_plugin_scan()
        omegaconf_speedups()

    def __getattr__(self, name: str):  # load_configuration, get_search_path, get_sources, list_groups, ...
        if name == "inner":  # not set yet (unpickling)
            raise AttributeError(name)
        return getattr(self.inner, name)

    def _is_group(self, key: str) -> bool:
        return self._skeletons.is_group(key, lambda: config_repository(self.inner))

    def _split(self, master_config: DictConfig, sweep_overrides: list[str]):
        """A job's parsed overrides (the sweep's ``hydra`` overrides first) and their split into group choices and
        values (:func:`split_overrides`; None: the job is composed in full)."""
        overrides = [*OmegaConf.to_container(master_config.hydra.overrides.hydra), *sweep_overrides]
        parsed = self._skeletons.parse(overrides)
        return parsed, split_overrides(parsed, self._is_group)

    def skeleton_of(self, master_config: DictConfig, sweep_overrides: list[str]) -> tuple[str, ...] | None:
        """The group choices whose composition (skeleton) a job is derived from; None for a job composed in full."""
        split = self._split(master_config, sweep_overrides)[1]
        return None if split is None else tuple(o.input_line for o in split[0])

    def load_sweep_config(self, master_config: DictConfig, sweep_overrides: list[str]) -> DictConfig:
        """The config of one job: Hydra's ``ConfigLoaderImpl.load_sweep_config``, the same config."""
        from hydra.types import RunMode

        parsed, split = self._split(master_config, sweep_overrides)
        if split is None:
            return self.inner.load_sweep_config(master_config, sweep_overrides)
        structure, values = split
        name = master_config.hydra.job.config_name
        cfg = self._skeletons.job((name, *(o.input_line for o in structure)), lambda: self.inner.load_configuration(
            config_name=name, overrides=[o.input_line for o in structure], run_mode=RunMode.RUN), values)
        set_derived(cfg, parsed)
        OmegaConf.copy_cache(from_config=master_config, to_config=cfg)
        return cfg


def _hydra_value(o) -> bool:
    """An override that sets a value of the ``hydra`` node (``hydra.run.dir=x``, ``hydra.mode=RUN``): applied
    after the defaults tree, like a job's values; not a group choice (``hydra/launcher=joblib``), not the search
    path, not a sweep, delete or dict merge."""
    key = o.key_or_group
    return (o.package is None and key.startswith("hydra.") and key != "hydra.searchpath" and not o.is_delete()
            and not o.is_sweep_override() and not isinstance(o.value(), dict))


class CompositionMemo(OverrideParser):
    """Whole compositions of one process, each kept pickled, by (config name, search path) and the overrides that
    make the defaults tree (see the module docstring); what a composition records of the process (its working dir,
    copied environment variables) is set on each copy (:func:`_record_process`).

    A composition is made from the call's group choices and overrides of the ``hydra`` node that are not values
    (:func:`split_overrides`, Hydra's rule): a single run with other values (``controller.lam=7``,
    ``run.n_runs=3``) or other values of the ``hydra`` node (``hydra.run.dir=...``, ``hydra.mode=RUN``) gets a copy
    of the same composition with its values applied as Hydra's loader applies them after the defaults tree, and
    what Hydra derives from the whole list (``hydra.overrides``, ``hydra.job.override_dirname``); its sweep
    overrides are checked as Hydra checks them. A call with a sweep of values keeps all its overrides but the
    ``hydra`` node's values in the key. A composition made for a multirun (Hydra skips missing defaults there)
    serves only multirun calls; one made for a run serves both."""

    def __init__(self) -> None:
        super().__init__()
        self._kept: dict[tuple, tuple[bool, bytes, bool]] = {}
        #: compositions Hydra made in this memo (not loaded from ddmr's cache)
        self.composed = 0
        #: the override lists of the jobs ddmr's plan composed and validated in this context (:func:`validated_jobs`)
        self.validated_jobs: set[tuple[str, ...]] = set()

    def _tree_and_values(self, loader, parsed: list) -> tuple[tuple[str, ...], list]:
        """The override lines the composition is made from, and the value overrides applied to each copy."""
        core = [o for o in parsed if not _hydra_value(o)]
        split = None if any(o.is_sweep_override() for o in core) else \
            split_overrides(core, lambda key: self.is_group(key, lambda: config_repository(loader)))
        if split is None:
            return tuple(o.input_line for o in core), []
        return tuple(o.input_line for o in split[0]), split[1]

    def load(self, loader, compose: Callable[..., DictConfig], config_name, overrides: Sequence[str], run_mode,
             from_shell: bool = True, validate_sweep_overrides: bool = True) -> DictConfig:
        """``loader.load_configuration(...)``, composed by ``compose`` (the loader's own method) only when no
        kept composition serves the call."""
        from hydra.core.utils import JobRuntime
        from hydra.types import RunMode

        from ddmr_cli.compat import apply_overrides, check_sweep_overrides

        parsed = self.parse(list(overrides))
        tree, values = self._tree_and_values(loader, parsed)
        key = (config_name, tuple((e.provider, e.path) for e in loader.get_search_path().get_path()), tree)
        multirun = run_mode == RunMode.MULTIRUN
        kept = self._kept.get(key)
        if kept is None or (kept[0] and not multirun):
            from ddmr_cli.config.skeleton_cache import cached_composition

            def composed() -> tuple[bool, bytes, bool]:
                cfg = compose(config_name=config_name, overrides=list(tree), run_mode=run_mode,
                              from_shell=from_shell, validate_sweep_overrides=validate_sweep_overrides)
                derived = str(cfg.hydra.job.get("name")) == str(JobRuntime().get("name"))
                return multirun, pickle.dumps(cfg, protocol=pickle.HIGHEST_PROTOCOL), derived

            # kept on disk between processes when the search path is the packaged config's (skeleton_cache); a
            # search path an override adds (hydra.searchpath, as --config-dir adds it) is read while composing, after
            # the key is made, so the key would not hash its files: such a composition is made each time
            named_path = any(o.get_key_element() == "hydra.searchpath" for o in parsed)
            kept, loaded = (composed(), False) if named_path else cached_composition(key, multirun, composed)
            self._kept[key] = kept
            self.composed += not loaded
            if loaded and validate_sweep_overrides:
                check_sweep_overrides(parsed, run_mode, from_shell)
        elif validate_sweep_overrides:
            check_sweep_overrides(parsed, run_mode, from_shell)
        _, blob, derived_name = kept
        cfg = pickle.loads(blob)
        apply_overrides([o for o in parsed if _hydra_value(o)], cfg)
        apply_overrides(values, cfg)
        set_derived(cfg, parsed)
        if derived_name:  # Hydra names the job after the program composing it, unless the config names it
            cfg.hydra.job.name = JobRuntime().get("name")
        _record_process(cfg)
        return cfg


def _record_process(cfg: DictConfig) -> None:
    """What Hydra's loader records of the composing process (``ConfigLoaderImpl._load_configuration_impl``), set
    again on a kept composition: the working dir (``hydra.runtime.cwd``) and the variables of
    ``hydra.job.env_copy`` (into ``hydra.job.env_set``, after the call's own ``hydra.job.env_copy=[...]``).
    Nothing else of a composition depends on the process, so a composition kept by one directory or process
    serves every other (:mod:`ddmr_cli.config.skeleton_cache`)."""
    import os

    from omegaconf import open_dict

    cfg.hydra.runtime.cwd = os.getcwd()
    with open_dict(cfg.hydra):
        for name in cfg.hydra.job.env_copy:
            cfg.hydra.job.env_set[name] = os.environ[name]


def _active_memo() -> CompositionMemo | None:
    """The memo of the innermost :func:`compositions_once` context this process is in, or None outside one."""
    from ddmr_cli.compat import current_load

    active = getattr(current_load(), "__self__", None)
    return active if isinstance(active, CompositionMemo) else None


def record_validated_jobs(jobs: Iterable[Sequence[str]]) -> None:
    """Record the override lists of jobs ddmr's plan composed and validated (each as Hydra's sweeper will list it)
    in the active :func:`compositions_once` context; outside one, nothing (no sweep of this process will ask)."""
    memo = _active_memo()
    if memo is not None:
        memo.validated_jobs.update(tuple(job) for job in jobs)


def validated_jobs() -> frozenset[tuple[str, ...]]:
    """The override lists of the jobs ddmr's plan has composed and validated within the active
    :func:`compositions_once` context (``ddmr run``'s), each as Hydra's sweeper lists it; empty outside one. Hydra's
    sweeper need not compose these again to check that they compose (``hydra_plugins/ddmr_sweeper``)."""
    memo = _active_memo()
    return frozenset(memo.validated_jobs) if memo is not None else frozenset()


@contextlib.contextmanager
def compositions_once() -> Iterator[CompositionMemo]:
    """Within the context, every whole composition of this process goes through one :class:`CompositionMemo`
    (:func:`ddmr_cli.compat.loading_through`). Yields the memo; within another such context, that one's memo (a
    composition asked of the cache once, not once per context)."""
    from ddmr_cli.compat import loading_through

    active = _active_memo()
    if active is not None:
        yield active
        return
    memo = CompositionMemo()
    with loading_through(memo.load):
        yield memo


__all__ = ["compositions_once", "CompositionMemo", "OverrideParser", "Skeletons", "SweepConfigLoader", "set_derived",
           "split_overrides"]
