"""Compositions kept on disk between processes (ddmr_cli/config/skeleton_cache.py): a loaded composition is the
composition, a change of the config makes a new key, a damaged file is composed again, a user's config dir is
never cached."""

from __future__ import annotations

import pickle

import pytest
from omegaconf import OmegaConf

from ddmr_cli.config import compose_config, skeleton_cache
from ddmr_cli.config.compose_once import compositions_once

KEY = ("config", (("hydra", "pkg://hydra.conf"), ("main", "pkg://ddmr_cli.conf"), ("schema", "structured://")),
       ("controller=pid",))


@pytest.fixture
def cache(skeletons):
    return skeletons


def _recording_loads(monkeypatch) -> list[bool]:
    """Whether each kept composition asked of the cache was loaded (True) or composed (False), in order."""
    real, loaded = skeleton_cache.cached_composition, []

    def recording(*args):
        kept, was_loaded = real(*args)
        loaded.append(was_loaded)
        return kept, was_loaded

    monkeypatch.setattr(skeleton_cache, "cached_composition", recording)
    return loaded


def _made(value="a"):
    calls = []

    def compose():
        calls.append(1)
        return (False, pickle.dumps({"value": value}), True)

    return compose, calls


def test_a_composition_is_made_once_then_loaded_as_it_was(cache):
    compose, calls = _made()
    first, loaded = skeleton_cache.cached_composition(KEY, False, compose)
    again, loaded_again = skeleton_cache.cached_composition(KEY, False, compose)
    assert (loaded, loaded_again, len(calls)) == (False, True, 1)
    assert again == first and len(list(cache.glob("*.pkl"))) == 1
    # another mode or other overrides: another entry
    skeleton_cache.cached_composition(KEY, True, compose)
    skeleton_cache.cached_composition((*KEY[:2], ("controller=smc",)), False, compose)
    assert len(calls) == 3 and len(list(cache.glob("*.pkl"))) == 3


def test_a_damaged_file_is_composed_again_and_replaced(cache):
    compose, calls = _made()
    skeleton_cache.cached_composition(KEY, False, compose)
    [path] = cache.glob("*.pkl")
    path.write_bytes(path.read_bytes()[:10])  # a crash mid-write of an older version
    kept, loaded = skeleton_cache.cached_composition(KEY, False, compose)
    assert not loaded and len(calls) == 2 and pickle.loads(kept[1]) == {"value": "a"}
    assert skeleton_cache.cached_composition(KEY, False, compose)[1]  # replaced by a whole file


def test_a_config_whose_classes_this_process_cannot_import_is_composed_again_and_replaced(cache):
    """Kept by a process that had a plugin this one has not (launcher=slurm with hydra-submitit hidden): the
    file loads but the config in it does not, so the process composes (Hydra names what is missing)."""
    compose, calls = _made()
    skeleton_cache.cached_composition(KEY, False, compose)
    [path] = cache.glob("*.pkl")
    plugin_config = b"cddmr_no_such_plugin\nLauncherConf\n."  # a pickled reference to a class of a missing module
    with pytest.raises(ImportError):
        pickle.loads(plugin_config)
    path.write_bytes(pickle.dumps((False, plugin_config, True)))
    kept, loaded = skeleton_cache.cached_composition(KEY, False, compose)
    assert not loaded and len(calls) == 2 and pickle.loads(kept[1]) == {"value": "a"}
    assert skeleton_cache.cached_composition(KEY, False, compose)[1] and len(calls) == 2  # replaced


def test_a_user_config_dir_or_the_switch_is_never_cached(cache, monkeypatch):
    compose, calls = _made()
    user = ("config", (("main", "file:///home/me/conf"),), ())
    skeleton_cache.cached_composition(user, False, compose)
    skeleton_cache.cached_composition(user, False, compose)
    monkeypatch.setenv(skeleton_cache.SWITCH, "0")
    skeleton_cache.cached_composition(KEY, False, compose)
    assert len(calls) == 3 and not cache.exists()


def test_an_edit_of_any_config_file_changes_the_key(monkeypatch):
    before = skeleton_cache.config_digest()
    real = skeleton_cache._files

    def edited(node, prefix=""):
        for name, data in real(node, prefix):
            yield name, (data + b"\n# edited" if name == "controller/pid.yaml" else data)

    assert _digest_with(monkeypatch, "_files", edited) != before
    assert skeleton_cache.config_digest() == before


def _digest_with(monkeypatch, reader: str, edited) -> str:
    """The config digest with ``skeleton_cache.<reader>`` replaced by ``edited``; the reader is restored after."""
    monkeypatch.setattr(skeleton_cache, reader, edited)
    skeleton_cache.config_digest.cache_clear()
    try:
        return skeleton_cache.config_digest()
    finally:
        monkeypatch.undo()
        skeleton_cache.config_digest.cache_clear()


def test_an_edit_of_a_hydra_plugin_changes_the_key(monkeypatch):
    """A plugin's structured config (the Optuna sweeper's, a launcher's) is composed into the hydra node: an edit
    or an upgrade of its source, with the same file names, makes a new key."""
    before = skeleton_cache.config_digest()
    real = skeleton_cache._plugin_files
    names = [name for name, _ in real(__import__("hydra_plugins").__path__)]
    assert any(name.endswith("config.py") for name in names), names

    def edited(paths):
        return [(name, data + b"\n# edited" if name.endswith("config.py") else data) for name, data in real(paths)]

    assert _digest_with(monkeypatch, "_plugin_files", edited) != before
    assert skeleton_cache.config_digest() == before


@pytest.mark.parametrize("overrides", [["controller=pid", "scenario=paper_2"], ["+experiment=table4"],
                                       ["controller=smc", "controller.lam=7", "sensor=encoder"]])
def test_a_loaded_composition_equals_hydras(cache, overrides, monkeypatch):
    """Through the CLI's memo: the first process composes and keeps it, a second (a new memo) loads it; both equal
    Hydra's own composition with the cache off."""
    loaded = _recording_loads(monkeypatch)
    results = []
    for _ in range(2):
        with compositions_once():
            results.append(OmegaConf.to_container(compose_config(overrides, return_hydra_config=True)))
    assert loaded == [False, True]  # composed by the first memo, loaded by the second
    hydra_own = _hydras_own(overrides)
    assert results[0] == hydra_own and results[1] == hydra_own


def _hydras_own(overrides, return_hydra_config: bool = True) -> dict:
    import os

    os.environ[skeleton_cache.SWITCH] = "0"
    try:
        return OmegaConf.to_container(compose_config(overrides, return_hydra_config=return_hydra_config))
    finally:
        del os.environ[skeleton_cache.SWITCH]


def test_a_composition_made_in_one_directory_serves_another_as_hydra_composes_there(cache, tmp_path, monkeypatch):
    """The working dir is not part of the key: a process in another directory loads the kept composition, and gets
    what Hydra composes there (``hydra.runtime.cwd`` that directory), as do the variables of
    ``hydra.job.env_copy``, read from the loading process's environment."""
    overrides = ["controller=pid", "hydra.job.env_copy=[DDMR_TEST_COPIED]"]
    one, other = tmp_path / "one", tmp_path / "other"
    one.mkdir(), other.mkdir()
    loaded = _recording_loads(monkeypatch)
    results = []
    for directory, value in ((one, "first"), (other, "second")):
        monkeypatch.chdir(directory)
        monkeypatch.setenv("DDMR_TEST_COPIED", value)
        with compositions_once():
            results.append(OmegaConf.to_container(compose_config(overrides, return_hydra_config=True)))
        assert results[-1] == _hydras_own(overrides)
        assert results[-1]["hydra"]["runtime"]["cwd"] == str(directory)
        assert results[-1]["hydra"]["job"]["env_set"]["DDMR_TEST_COPIED"] == value
    assert loaded == [False, True]  # composed in the first directory, loaded in the second


def test_a_composition_kept_for_some_values_serves_others(cache, monkeypatch):
    """A single run with other values loads the composition another made (the key is the defaults tree), and gets
    Hydra's own composition of its own overrides."""
    loaded = _recording_loads(monkeypatch)
    for overrides in (["controller=smc", "run.n_runs=3"], ["controller.lam=9", "controller=smc", "run.plots=false"]):
        with compositions_once():
            ours = OmegaConf.to_container(compose_config(overrides, return_hydra_config=True))
        assert ours == _hydras_own(overrides)
    assert loaded == [False, True]


def test_the_python_api_composes_through_the_cache(cache, monkeypatch):
    """``paper_config`` (the Python API: scripts, the bench, the cost table) composes a set of group choices once and
    keeps it; a new process (the in-process memo cleared) loads it, with other values, and gets Hydra's own
    composition of its overrides (the hydra node left out, as Hydra's compose API leaves it)."""
    from ddmr_cli.config import presets

    loaded = _recording_loads(monkeypatch)
    presets._composed.cache_clear()
    try:
        for overrides in (("controller=smc_ndo", "scenario=paper_2"),
                          ("controller=smc_ndo", "controller.lam=9", "scenario=paper_2", "simulation.duration=2")):
            ours = OmegaConf.to_container(presets.paper_config(*overrides))
            assert OmegaConf.is_readonly(presets.paper_config(*overrides))
            presets._composed.cache_clear()
            assert ours == _hydras_own(list(overrides), return_hydra_config=False)
    finally:
        presets._composed.cache_clear()
    assert loaded == [False, True]  # composed by the first call, loaded by the second


def test_a_memo_within_another_is_that_one(cache, monkeypatch):
    """``compose_config`` inside the command line's memo (a run's validation, a sweep's skeletons) asks the cache
    once per composition, not once per memo: the inner context is the outer one's memo."""
    loaded = _recording_loads(monkeypatch)
    with compositions_once() as outer:
        with compositions_once() as inner:
            assert inner is outer
            compose_config(["controller=adrc", "scenario=paper_2"])
        compose_config(["controller=adrc", "scenario=paper_2", "run.n_runs=4"])
    assert loaded == [False]  # composed once; the second call a copy of the memo's


def test_a_search_path_named_by_an_override_is_read_each_time(cache, tmp_path):
    """``hydra.searchpath=[file://...]`` adds a search path while Hydra composes, after the key is made, so the key
    cannot hash its files: a composition that names one is never kept on disk, and an edit of a file there shows
    in the next process (the kept composition of the first served the second, stale, before)."""
    (tmp_path / "controller").mkdir()
    mine = tmp_path / "controller" / "mine.yaml"
    overrides = [f"hydra.searchpath=[file://{tmp_path}]", "controller=mine"]
    gains = []
    for gain in (11.0, 22.0):
        mine.write_text(f"defaults:\n  - smc\n  - _self_\nswitching_gain: {gain}\n")
        with compositions_once():  # a new memo: as a new process
            gains.append(compose_config(overrides).controller.switching_gain)
    assert gains == [11.0, 22.0]
    assert not list(cache.glob("*.pkl"))
