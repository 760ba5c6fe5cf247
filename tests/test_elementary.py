"""The elementary functions the laws share (ddmr_cli/model/elementary.py): fdlibm's exp and (sin, cos) written as
arithmetic. Each is held to numpy's (libm's) to 1 ulp over its range, to its exact values at the edges, and to
itself: compiled, as plain Python and inside a loop the compiler vectorises, the same bits."""

from __future__ import annotations

import math

import numpy as np
import pytest

from ddmr_cli.compiled import AVAILABLE, jit_enabled, law, plain
from ddmr_cli.model.elementary import EXP_ZERO, exp_neg, sincos


def _exponents():
    rng = np.random.default_rng(11)
    return np.concatenate([-rng.uniform(0, 708, 20000), -rng.uniform(0, 1, 2000), -rng.uniform(1e-12, 1e-6, 500),
                           -rng.uniform(708, 745.9, 2000),  # exp's subnormal results
                           [0.0, -0.0, -1e-300, -5e-324, -708.39, -745.13, -745.14]])


def _angles():
    rng = np.random.default_rng(12)
    return np.concatenate([rng.uniform(-np.pi, np.pi, 20000), rng.uniform(-0.2, 0.2, 2000),
                           rng.uniform(-1e4, 1e4, 2000), rng.uniform(-8e5, 8e5, 500),
                           [0.0, -0.0, np.pi / 4, np.pi / 2, np.pi, -np.pi, 3 * np.pi / 2, 1e-300, 5e-324]])


@law
def _exp_loop(x, out):
    """exp_neg over an array: a loop LLVM vectorises (as rbf.basis's)."""
    for i in range(x.shape[0]):
        out[i] = exp_neg(x[i])


@law
def _sincos_loop(x, s, c):
    for i in range(x.shape[0]):
        s[i], c[i] = sincos(x[i])


def test_exp_neg_is_within_an_ulp_of_libms_exp():
    x = _exponents()
    got = np.empty_like(x)
    _exp_loop(x, got)
    np.testing.assert_array_max_ulp(got, np.exp(x), maxulp=1)
    assert exp_neg(0.0) == 1.0 and exp_neg(-0.0) == 1.0


def test_exp_neg_is_zero_below_its_range_and_nan_outside_its_domain():
    for x in (EXP_ZERO - 1e-9, -746.5, -800.0, -1e308, -math.inf):
        assert exp_neg(x) == 0.0, x
        assert math.exp(x) == 0.0  # libm's too: below exp(-745.14), half the smallest subnormal
    for x in (math.nan, 1e-300, 1.0, math.inf):
        assert math.isnan(exp_neg(x)), x


def test_sincos_is_within_an_ulp_of_libms_and_exact_at_zero():
    x = _angles()
    s, c = np.empty_like(x), np.empty_like(x)
    _sincos_loop(x, s, c)
    assert (np.abs(s - np.sin(x)) <= np.spacing(np.abs(np.sin(x)))).all()
    assert (np.abs(c - np.cos(x)) <= np.spacing(np.abs(np.cos(x)))).all()
    assert sincos(0.0) == (0.0, 1.0)
    np.testing.assert_allclose(s * s + c * c, 1.0, rtol=4e-16)


@pytest.mark.skipif(not (AVAILABLE and jit_enabled()), reason="compares compiled with plain Python")
def test_compiled_vectorised_and_plain_python_give_the_same_bits():
    """No fused multiply-add, no reassociation: the scalar compiled call, the vectorised loop and Python agree to
    the bit (the laws' numbers do not depend on how the compiler schedules them, or on numba being there)."""
    x = _exponents()[::7]
    looped = np.empty_like(x)
    _exp_loop(x, looped)
    python = np.array([plain(exp_neg)(v) for v in x])
    scalar = np.array([exp_neg(v) for v in x])
    assert looped.tobytes() == python.tobytes() == scalar.tobytes()
    a = _angles()[::7]
    s, c = np.empty_like(a), np.empty_like(a)
    _sincos_loop(a, s, c)
    python = np.array([plain(sincos)(v) for v in a])
    assert s.tobytes() == python[:, 0].copy().tobytes() and c.tobytes() == python[:, 1].copy().tobytes()
