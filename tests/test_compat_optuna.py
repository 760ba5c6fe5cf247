"""ddmr_cli/compat.py: one test per private or version-dependent symbol, so a library release that moves one
fails here by name (issue 27). Optuna section: the version check, the killed-trial mark (private storage and
trial id), the enqueued-trial flag (private system attribute)."""

from __future__ import annotations

import sys

import pytest

optuna = pytest.importorskip("optuna", reason="the tune extra is not installed (pip install -e '.[tune]')")

from ddmr_cli import compat  # noqa: E402
from ddmr_cli.errors import ConfigError  # noqa: E402


def test_the_installed_optuna_is_supported_and_an_old_or_missing_one_is_one_line(monkeypatch):
    assert compat.require_optuna() is optuna
    assert compat._release(optuna.__version__) >= compat.OPTUNA_MIN
    assert compat._release("5.0.0rc1") == (5, 0, 0) and compat._release("4.10.2") > compat._release("4.9")
    monkeypatch.setattr(optuna, "__version__", "2.10.1")
    with pytest.raises(ConfigError, match=r"needs optuna >= 4\.0 \(installed: 2\.10\.1\)"):
        compat.require_optuna()
    monkeypatch.setitem(sys.modules, "optuna", None)  # not installed
    with pytest.raises(ConfigError) as info:
        compat.require_optuna()
    assert str(info.value).startswith("hydra/sweeper='ddmr_optuna': needs optuna, which is not installed; pip "
                                      "install 'ddmr-cli[tune]'")


def test_mark_killed_fails_a_trial_another_process_left_running(tmp_path):
    storage = f"sqlite:///{tmp_path / 'study.db'}"
    optuna.logging.set_verbosity(optuna.logging.WARNING)
    session = optuna.create_study(study_name="s", storage=storage)
    session.tell(session.ask({"x": optuna.distributions.FloatDistribution(0, 1)}), 0.5)
    session.ask()  # the killed session's trial: asked, never told
    later = optuna.load_study(study_name="s", storage=storage)  # the resumed session: another Study object
    stale = later.get_trials(deepcopy=False, states=(optuna.trial.TrialState.RUNNING,))
    assert [t.number for t in stale] == [1]
    compat.mark_killed(later, stale[0])
    trials = optuna.load_study(study_name="s", storage=storage).trials
    assert [t.state.name for t in trials] == ["COMPLETE", "FAIL"]
    assert trials[1].user_attrs == {compat.KILLED_ATTR: True} and trials[0].user_attrs == {}
    assert trials[0].value == 0.5  # the complete trial untouched


def test_was_enqueued_tells_a_warm_start_trial_from_a_sampled_one():
    optuna.logging.set_verbosity(optuna.logging.WARNING)
    study = optuna.create_study()
    study.enqueue_trial({"x": 0.25})
    for _ in range(2):
        trial = study.ask()
        trial.suggest_float("x", 0.0, 1.0)
        study.tell(trial, 1.0)
    first, second = study.trials
    assert first.params == {"x": 0.25}
    assert compat.was_enqueued(first) and not compat.was_enqueued(second)
