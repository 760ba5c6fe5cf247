"""Every use of a library's private or version-dependent API, in one place: one section per library.

An upgrade of a library touches this file only. Each section states the versions it supports, checks the
installed one (:func:`require_optuna`), and wraps each private symbol in one function with a test of its own
(tests/test_compat.py), so a release that moves a symbol fails that test by name.

Optuna (the ``tune`` extra: gain tuning and the calibration search, ``hydra/sweeper=ddmr_optuna``)
    Supported: :data:`OPTUNA_MIN` and later (the plugin uses the public ask-and-tell and ``suggest_*`` API; tested
    with 4.x and 5.0). Private symbols: a trial's storage id and the storage behind a study
    (:func:`mark_killed`: a user attribute on a trial a killed session left RUNNING; Optuna has no public way to
    annotate a trial it did not hand out in this process), and the system attribute ``fixed_params`` that
    ``Study.enqueue_trial`` writes (:func:`was_enqueued`).
"""

from __future__ import annotations

from typing import Any

from ddmr_cli.errors import ConfigError

# --- Optuna -----------------------------------------------------------------------------------------------------

#: The oldest Optuna the tuning and the calibration search support.
OPTUNA_MIN = (4, 0)
#: The user attribute a killed session's trial carries (``tuning_trials.csv`` column ``killed``).
KILLED_ATTR = "killed"
#: The system attribute ``Study.enqueue_trial`` writes on a trial with fixed parameters (Optuna >= 2.x, private).
ENQUEUED_ATTR = "fixed_params"


def _release(version: str) -> tuple[int, ...]:
    """``'4.5.0'`` -> ``(4, 5, 0)`` (pre-releases and local tags dropped: ``'5.0.0rc1'`` -> ``(5, 0, 0)``)."""
    from packaging.version import Version

    return Version(version).release


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


__all__ = ["OPTUNA_MIN", "KILLED_ATTR", "ENQUEUED_ATTR", "require_optuna", "mark_killed", "was_enqueued"]
