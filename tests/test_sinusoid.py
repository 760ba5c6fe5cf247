"""The lane-change reference y = A sin(2 pi x / lambda) at constant path speed (ddmr_cli/model/trajectory.py;
docs/model.md §3), against its closed forms."""

from __future__ import annotations

import math

import numpy as np
import pytest

from ddmr_cli import ConfigError, Sinusoid, paper_trajectory

A, WAVELENGTH, V = 0.5, 5.0, 1.0
K = 2 * math.pi / WAVELENGTH


@pytest.fixture(scope="module")
def path():
    return Sinusoid(amplitude=A, wavelength=WAVELENGTH, speed=V)


def test_packaged_preset(path):
    assert paper_trajectory("sinusoid") == path


def test_the_pose_lies_on_the_curve_at_the_arc_length_v_t(path):
    """y_r = A sin(k x_r); the path length to x_r, integrated independently (composite Simpson, 20000 panels),
    equals v t."""
    for t in (0.0, 0.7, 2.5, 5.0, 9.3, 15.0):
        x, y, *_ = path.reference(t)
        assert y == pytest.approx(A * math.sin(K * x), abs=1e-12)
        xs = np.linspace(0.0, x, 20001)
        f = np.sqrt(1.0 + (A * K * np.cos(K * xs)) ** 2)
        simpson = (xs[1] - xs[0]) / 3 * (f[0] + f[-1] + 4 * f[1:-1:2].sum() + 2 * f[2:-1:2].sum())
        assert simpson == pytest.approx(V * t, abs=1e-9)


def test_whole_periods_land_on_the_axis(path):
    """One wavelength of path length is sqrt(1 + a^2) 4 E(m) / k: after that time the reference is back at
    y = 0 with x = lambda, heading atan(a)."""
    period = path.arc_length(WAVELENGTH) / V
    x, y, th, v, om = path.reference(period)
    assert x == pytest.approx(WAVELENGTH, abs=1e-10) and y == pytest.approx(0.0, abs=1e-10)
    assert th == pytest.approx(math.atan(A * K), abs=1e-10) and om == pytest.approx(0.0, abs=1e-9)


def test_v_r_and_omega_r_are_the_derivatives_of_the_pose(path):
    """v_r = |(x', y')| and omega_r = theta' by central differences (h = 1e-5 s: error O(h^2) ~ 1e-9), and the
    closed forms: omega_r at the crest x = lambda/4 is -v A k^2 (the curvature of the crest)."""
    h = 1e-5
    for t in (0.3, 1.9, 4.4, 7.0, 12.2):
        x0, y0, th0, *_ = path.reference(t - h)
        x1, y1, th1, *_ = path.reference(t + h)
        _, _, th, v, om = path.reference(t)
        assert v == V
        assert math.hypot(x1 - x0, y1 - y0) / (2 * h) == pytest.approx(V, abs=1e-8)
        assert math.atan2(y1 - y0, x1 - x0) == pytest.approx(th, abs=1e-8)
        assert (th1 - th0) / (2 * h) == pytest.approx(om, abs=1e-6)
    t_crest = path.arc_length(WAVELENGTH / 4) / V
    assert path.reference(t_crest)[4] == pytest.approx(-V * A * K * K, rel=1e-9)


@pytest.mark.parametrize("values, key", [({"wavelength": 0.0}, "wavelength"), ({"speed": -1.0}, "speed"),
                                         ({"amplitude": math.inf}, "amplitude")])
def test_bad_values_are_refused_naming_the_key(values, key):
    with pytest.raises(ConfigError, match=rf"trajectory\.{key}="):
        Sinusoid(**{"amplitude": A, "wavelength": WAVELENGTH, "speed": V, **values})
