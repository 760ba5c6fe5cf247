"""The report's placement of a job on a realism axis (ddmr_cli/report/realism.py) from its config."""

from __future__ import annotations

import math
from pathlib import Path

import pytest

from ddmr_cli.report.data import Job
from ddmr_cli.report.realism import classify


def job(**settings) -> Job:
    config = {"simulation": {"dt": 0.001},
              "sensor": {"kind": "ideal", "counts_per_rev": 1024, "speed_filter": 0.0, "pose": "odometry",
                         "speed_std": 0.0, "position_std": 0.0, "heading_std": 0.0},
              "actuator": {"delay": 0.0, "lag": 0.0, "pwm_bits": 0}, "control": {"rate": None}}
    for dotted, value in settings.items():
        group, key = dotted.split("__")
        config[group][key] = value
    return Job(Path("x"), {}, config)


@pytest.mark.parametrize("settings,effect,level", [
    ({}, "ideal", math.nan),
    ({"control__rate": 1000.0}, "ideal", math.nan),  # the plant rate: no effect
    ({"sensor__kind": "encoder", "sensor__counts_per_rev": 256}, "counts_per_rev", 256),
    ({"sensor__kind": "noisy", "sensor__speed_std": 0.2}, "speed_std", 0.2),
    ({"actuator__delay": 0.005}, "delay", 5.0),
    ({"control__rate": 250.0}, "rate", 250.0),
    ({"sensor__kind": "noisy", "sensor__speed_std": 0.2, "sensor__position_std": 0.01}, "combined", math.nan),
    ({"sensor__kind": "encoder", "actuator__delay": 0.002, "control__rate": 250.0}, "combined", math.nan),
    ({"actuator__pwm_bits": 10}, "combined", math.nan),
])
def test_classify(settings, effect, level):
    place = classify(job(**settings))
    assert place.effect == effect
    assert (math.isnan(level) and math.isnan(place.level)) or place.level == pytest.approx(level)
