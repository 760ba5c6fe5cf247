"""Property-based tests (hypothesis) of the kinematics, the terrain zones, the engine's saturation and the config
validators."""

from __future__ import annotations

import math

import numpy as np
import pytest
from hypothesis import HealthCheck, assume, example, given, settings
from hypothesis import strategies as st

from paper import make_smc, make_pid, make_robot, make_simulation, make_terrain
from ddmr_cli import PID, SMC, NonlinearDisturbanceObserver, Robot, Simulation, Terrain, TerrainZone, simulate
from ddmr_cli.control import rbf
from ddmr_cli.model import elementary, kinematics
from ddmr_cli import checks as validate
from ddmr_cli.control.pid import _pd_spectral_radius
from ddmr_cli.compiled import plain
from ddmr_cli.errors import ConfigError

FAST = settings(max_examples=60, deadline=None, database=None)
SLOW = settings(max_examples=8, deadline=None, database=None, suppress_health_check=[HealthCheck.too_slow])

speeds = st.floats(-100.0, 100.0, allow_nan=False, allow_infinity=False)
radii = st.floats(0.01, 0.5)
tracks = st.floats(0.05, 1.0)
angles = st.floats(-1e4, 1e4, allow_nan=False, allow_infinity=False)


# --------------------------------------------------------------------------------------------------------------
# kinematics
# --------------------------------------------------------------------------------------------------------------


@FAST
@given(v=st.floats(-5.0, 5.0), omega=st.floats(-10.0, 10.0), R=radii, L=tracks)
def test_inverse_then_forward_is_identity(v, omega, R, L):
    v2, omega2 = kinematics.forward(*kinematics.inverse(v, omega, R, L), R, L)
    assert v2 == pytest.approx(v, rel=1e-12, abs=1e-12)
    assert omega2 == pytest.approx(omega, rel=1e-12, abs=1e-11)


@FAST
@given(wr=speeds, wl=speeds, R=radii, L=tracks)
def test_forward_then_inverse_is_identity(wr, wl, R, L):
    wr2, wl2 = kinematics.inverse(*kinematics.forward(wr, wl, R, L), R, L)
    assert wr2 == pytest.approx(wr, rel=1e-12, abs=1e-11)
    assert wl2 == pytest.approx(wl, rel=1e-12, abs=1e-11)


@FAST
@given(a=angles)
@example(a=math.pi)
@example(a=-math.pi)
@example(a=3 * math.pi)
@example(a=float(np.nextafter(math.pi, 4.0)))  # the next float above pi must wrap to just above -pi, not to -pi
@example(a=float(np.nextafter(-math.pi, 0.0)))
def test_wrap_angle_range_and_offset(a):
    w = kinematics.wrap_angle(a)
    assert -math.pi < w <= math.pi
    turns = (a - w) / (2.0 * math.pi)
    assert abs(turns - round(turns)) <= 1e-12 * max(1.0, abs(a))


@FAST
@given(a=angles)
@example(a=math.pi)
@example(a=-math.pi)
@example(a=float(np.nextafter(-math.pi, -4.0)))  # pi - a just at 2 pi: the modulo's branch
@example(a=float(np.nextafter(math.pi, 4.0)))
def test_wrap_angle_is_the_modulo_formula_bit_for_bit(a):
    """The fast path (no modulo inside one turn) gives the bits of ``pi - ((pi - a) % 2 pi)`` everywhere
    (subtraction is correctly rounded and fmod exact under IEEE 754, so the bits are the same on every CPU)."""
    plain = math.pi - ((math.pi - a) % (2.0 * math.pi))
    plain = plain + 2.0 * math.pi if plain <= -math.pi else plain
    assert kinematics.wrap_angle(a).hex() == plain.hex()


@FAST
@given(w_R=st.floats(-300, 300), w_L=st.floats(-300, 300), width=st.floats(0.3, 100.0),
       n=st.integers(1, 25), low=st.floats(-80, 0), span=st.floats(0.1, 160))
@example(w_R=33.3, w_L=33.3, width=2.0, n=10, low=-40.0, span=80.0)  # the paper: 3 far neurons at exactly 0
@example(w_R=0.0, w_L=1e-05, width=1.0, n=2, low=0.0, span=5.0)  # a fused multiply-add moves the exponent 1 ulp
@example(w_R=1.0, w_L=-37.6, width=1.0, n=3, low=-1.0, span=2.0)  # an exponent in exp's subnormal range
def test_rbf_basis_is_exp_of_every_exponent_to_an_ulp(w_R, w_L, width, n, low, span):
    """(27): every phi_j is exp of its exponent to 1 ulp (elementary.exp_neg, fdlibm's exp, against libm's), and
    exactly 0 where the exponent is below elementary.EXP_ZERO (where libm's exp is 0 too).

    The exponent is the law's own (``rbf.exponent``): compiled, numba may fuse ``a*a + b*b`` into one FMA on CPUs
    that have it, one rounding fewer than Python's, and exp turns that last-bit difference of an exponent of -25
    into 25 ulp of phi (seen here on an AVX-512 CPU, w = (0, 1e-5), c = 5). The exponent itself must agree with
    the formula to 2 ulp: the fused and the unfused sum differ by at most the rounding of one square (1 ulp of the
    sum), and the product with -1/(2 sigma^2) by at most one more."""
    nn = rbf.RBFNetworkObserver(n_neurons=n, width=width, learning_rate=50.0, center_min=low, center_max=low + span)
    p, centers = nn.law_parameters(), nn.centers
    assert [rbf.center(p, j) for j in range(n)] == list(centers)  # the laws' c_j are numpy.linspace's, exactly
    exponents = np.array([rbf.exponent(p, j, w_R, w_L) for j in range(n)])
    formula = np.array([((w_R - c) ** 2 + (w_L - c) ** 2) * (-0.5 / (width * width)) for c in centers])
    np.testing.assert_array_max_ulp(exponents, formula, maxulp=2)
    phi = np.full(n, np.nan)
    rbf.basis(p, phi, w_R, w_L)
    below = exponents < elementary.EXP_ZERO
    assert (phi[below] == 0.0).all()
    np.testing.assert_array_max_ulp(phi[~below], np.exp(exponents[~below]), maxulp=1)


@FAST
@given(speed=st.floats(-5, 5), heading=st.floats(-7, 7), x0=st.floats(-100, 100), y0=st.floats(-100, 100),
       dt=st.floats(1e-5, 0.05), n=st.integers(1, 400))
def test_the_straight_lines_table_is_its_reference_step_by_step(speed, heading, x0, y0, dt, n):
    """The engine reads the reference from the line's vectorised table: the same bits as ``reference(k dt)``
    (elementwise IEEE products and sums of the same operands), and a trajectory without a table falls back to it."""
    from ddmr_cli.model.trajectory import StraightLine, reference_table

    line = StraightLine(speed=speed, heading=heading, x0=x0, y0=y0)
    by_step = np.array([line.reference(k * dt) for k in range(n)])
    assert reference_table(line, n, dt).tobytes() == by_step.tobytes()

    class Plain:  # only the protocol's reference(t)
        reference = line.reference

    assert reference_table(Plain(), n, dt).tobytes() == by_step.tobytes()


@FAST
@given(n=st.integers(1, 300), rows=st.integers(1, 30), scale=st.floats(1e-9, 1e6), seed=st.integers(0, 2**32 - 1))
def test_band_percentiles_of_sorted_rows_are_numpys(n, rows, scale, seed):
    """The seed bands' percentiles (rows sorted, two order statistics interpolated as numpy's 'linear' method
    does) are np.percentile's, to the last ulp."""
    from ddmr_cli.engine.bands import HIGH, LOW, percentiles_of_sorted

    x = np.random.default_rng(seed).standard_normal((rows, n)) * scale
    ours = percentiles_of_sorted(np.sort(x, axis=1), [LOW, HIGH])
    for mine, numpys in zip(ours, np.percentile(x, [LOW, HIGH], axis=1)):
        np.testing.assert_array_max_ulp(mine, numpys, maxulp=1)


@FAST
@given(n=st.integers(1, 5000), rows=st.integers(1, 4), ties=st.booleans(), seed=st.integers(0, 2**32 - 1))
def test_band_rows_partitioned_give_the_sorted_rows_order_statistics(n, rows, ties, seed):
    """From PARTITION_MIN_RUNS runs on, the bands partition each row instead of sorting it: the percentiles read
    from the partitioned rows are those of the sorted rows, bit for bit (ties too), and numpy's to 1 ulp."""
    from ddmr_cli.engine.bands import HIGH, LOW, order_rows, percentiles_of_sorted

    x = np.random.default_rng(seed).standard_normal((rows, n))
    if ties:
        x = np.round(x, 1)  # many equal values around each order statistic
    ordered = x.copy()
    order_rows(ordered, [LOW, HIGH])
    ours = percentiles_of_sorted(ordered, [LOW, HIGH])
    for mine, sorted_, numpys in zip(ours, percentiles_of_sorted(np.sort(x, axis=1), [LOW, HIGH]),
                                     np.percentile(x, [LOW, HIGH], axis=1)):
        assert mine.tobytes() == sorted_.tobytes()
        np.testing.assert_array_max_ulp(mine, numpys, maxulp=1)


@FAST
@given(runs=st.integers(1, 40), points=st.integers(1, 6), seed=st.integers(0, 2**32 - 1))
def test_band_reduction_of_diverged_runs_is_numpys_and_warns_about_nothing(runs, points, seed):
    """With diverged runs (NaN, inf) and grid steps where every run has diverged, the bands are numpy's nanmean and
    nanpercentile over the finite values (NaN where none is), to the bit, and the reduction raises no warning.
    It may not silence one instead: ``warnings.catch_warnings`` is process-wide, and a thread leaving it restores
    the filters while another thread is still reducing (the engine's threads reduce disjoint grid points at once);
    the test takes the filters' changes away, as such a thread does."""
    import contextlib
    import warnings

    from ddmr_cli.engine.bands import BAND_CHANNELS, HIGH, LOW, BandAccumulator

    rng = np.random.default_rng(seed)
    buffer = rng.standard_normal((runs, points, len(BAND_CHANNELS)))
    buffer[rng.random(buffer.shape) < 0.3] = np.nan
    buffer[rng.random(buffer.shape) < 0.1] = np.inf
    buffer[:, 0, 6:] = np.nan  # a controller without a sliding surface: s is NaN for every run
    finite = np.where(np.isfinite(buffer), buffer, np.nan)
    with warnings.catch_warnings():
        warnings.simplefilter("ignore", RuntimeWarning)
        mean = np.nanmean(finite, axis=0)
        low, high = np.nanpercentile(finite.reshape(runs, -1).T, [LOW, HIGH], axis=1)
    acc = BandAccumulator(points, 1e-3)
    with warnings.catch_warnings(record=True) as caught:
        warnings.simplefilter("always")
        with pytest.MonkeyPatch.context() as patch:
            patch.setattr(warnings, "catch_warnings", contextlib.nullcontext)
            patch.setattr(warnings, "simplefilter", lambda *args, **kwargs: None)
            acc.add_chunk(buffer.copy(), 0)
    assert [str(w.message) for w in caught] == []
    assert acc.mean.tobytes() == mean.T.tobytes()
    assert acc.low.tobytes() == low.reshape(points, -1).T.tobytes()
    assert acc.high.tobytes() == high.reshape(points, -1).T.tobytes()



@FAST
@given(runs=st.integers(1, 40), points=st.integers(1, 9), block=st.integers(1, 4), seed=st.integers(0, 2**32 - 1))
def test_band_reduction_in_blocks_of_grid_points_is_the_whole_reduction_to_the_bit(runs, points, block, seed):
    """A chunk is reduced in blocks of grid points (bands.REDUCE_BLOCK_BYTES bounds the reduction's copy at any
    number of seeds): the bands are the same bits as one reduction of the whole buffer, with blocks of finite runs
    beside blocks with diverged ones (each block takes its own path)."""
    from ddmr_cli.engine import bands
    from ddmr_cli.engine.bands import BAND_CHANNELS, BandAccumulator

    rng = np.random.default_rng(seed)
    buffer = rng.standard_normal((runs, points, len(BAND_CHANNELS)))
    buffer[:, rng.random(points) < 0.4] *= np.where(rng.random((runs, 1, 1)) < 0.2, np.inf, 1.0)  # some points
    whole, blocked = BandAccumulator(points, 1e-3), BandAccumulator(points, 1e-3)
    whole.add_chunk(buffer.copy(), 0)
    with pytest.MonkeyPatch.context() as patch:
        patch.setattr(bands, "REDUCE_BLOCK_BYTES", block * runs * len(BAND_CHANNELS) * 8)  # `block` points a copy
        blocked.add_chunk(buffer.copy(), 0)
    for name in ("mean", "low", "high"):
        assert getattr(blocked, name).tobytes() == getattr(whole, name).tobytes()


@FAST
@given(n_steps=st.integers(1, 20_000), k0=st.integers(0, 20_000), n=st.integers(1, 5000))
def test_band_most_points_bounds_every_chunks_grid_points_and_is_reached(n_steps, k0, n):
    """The engine sizes its one band buffer by BandAccumulator.most_points(chunk): no chunk, wherever it starts,
    holds more grid points, and a chunk starting on a grid point holds that many."""
    from ddmr_cli.engine.bands import BandAccumulator

    acc = BandAccumulator(n_steps, 1e-3)
    first, end = acc.grid_range(k0, n)
    assert end - first <= acc.most_points(n)
    first, end = acc.grid_range(k0 * acc.stride, n)
    assert end - first == acc.most_points(n)


def test_band_reduction_of_10000_runs_copies_a_block_not_the_buffer():
    """The reduction's working memory is about a block (bands.REDUCE_BLOCK_BYTES), not the chunk's buffer: 10,000
    runs x 19 grid points x 8 channels (the engine's chunk at 10,000 seeds) is 12 MiB."""
    import tracemalloc

    from ddmr_cli.engine.bands import BAND_CHANNELS, REDUCE_BLOCK_BYTES, BandAccumulator

    buffer = np.random.default_rng(1).standard_normal((10_000, 19, len(BAND_CHANNELS)))
    acc = BandAccumulator(19, 1e-3)
    tracemalloc.start()
    try:
        acc.add_chunk(buffer, 0)
        peak = tracemalloc.get_traced_memory()[1]
    finally:
        tracemalloc.stop()
    assert peak < 3 * REDUCE_BLOCK_BYTES < buffer.nbytes / 3, peak


@FAST
@given(a=st.lists(angles, min_size=1, max_size=20))
def test_wrap_angle_vectorised_agrees_with_scalar(a):
    arr = np.vectorize(kinematics.wrap_angle)(np.array(a))
    assert arr.shape == (len(a),)
    np.testing.assert_array_equal(arr, [kinematics.wrap_angle(x) for x in a])


@FAST
@given(x=st.floats(-1e140, 1e140), y=st.floats(-1e140, 1e140), x_ref=st.floats(-1e140, 1e140),
       y_ref=st.floats(-1e140, 1e140))
@example(x=0.0, y=0.0, x_ref=3.0, y_ref=4.0)
@example(x=1.0, y=-2.0, x_ref=1.0, y_ref=-2.0)
def test_deviation_is_the_euclidean_distance_to_an_ulp(x, y, x_ref, y_ref):
    """The deviation (the square root of the sum of squares, compiled and as Python) is ``math.hypot``'s distance
    to within 2 ulp wherever the squares neither overflow nor underflow (examples: a 3-4-5 triangle, and 0 at the
    reference)."""
    dx, dy = x_ref - x, y_ref - y
    exact = math.hypot(dx, dy)
    assume(not 0.0 < exact <= 1e-150)  # the squares underflow (they cannot overflow below 1e140)
    for law in (kinematics.deviation, plain(kinematics.deviation)):
        assert law(x, y, x_ref, y_ref) == pytest.approx(exact, rel=4.5e-16, abs=0.0)


poses = st.tuples(st.floats(-50, 50), st.floats(-50, 50), st.floats(-10, 10))


@FAST
@given(robot=poses, ref=poses)
def test_pose_error_invariant_to_full_turns(robot, ref):
    x, y, th = robot
    xr, yr, thr = ref
    base = kinematics.pose_error(x, y, th, xr, yr, thr)
    for shifted in (kinematics.pose_error(x, y, th + 2 * math.pi, xr, yr, thr),
                    kinematics.pose_error(x, y, th, xr, yr, thr - 2 * math.pi)):
        assert shifted[0] == pytest.approx(base[0], abs=1e-11)
        assert shifted[1] == pytest.approx(base[1], abs=1e-11)
        # the heading errors agree as angles (near +-pi they may land on opposite ends of the interval)
        d = shifted[2] - base[2]
        assert abs(math.remainder(d, 2 * math.pi)) < 1e-12


@FAST
@given(robot=poses, ref=poses)
def test_pose_error_preserves_distance(robot, ref):
    x, y, th = robot
    xr, yr, thr = ref
    e_x, e_y, _ = kinematics.pose_error(x, y, th, xr, yr, thr)
    assert math.hypot(e_x, e_y) == pytest.approx(math.hypot(xr - x, yr - y), rel=1e-12, abs=1e-12)


# --------------------------------------------------------------------------------------------------------------
# terrain zones
# --------------------------------------------------------------------------------------------------------------


@st.composite
def terrains_and_distances(draw):
    gaps = draw(st.lists(st.floats(0.01, 20.0), min_size=0, max_size=6))
    starts = [0.0] + list(np.cumsum(gaps))
    zones = [TerrainZone(f"z{i}", float(s), 1.0, 0.0) for i, s in enumerate(starts)]
    distance = draw(st.one_of(st.floats(0.0, starts[-1] + 30.0), st.sampled_from(starts)))
    return make_terrain(*zones), starts, distance


@FAST
@given(case=terrains_and_distances())
def test_zone_index_contains_the_distance(case):
    terrain, starts, distance = case
    i = int(terrain.zone_index(np.array([distance]))[0])
    assert 0 <= i < len(starts)
    upper = starts[i + 1] if i + 1 < len(starts) else math.inf
    assert starts[i] <= distance < upper


@FAST
@given(case=terrains_and_distances())
def test_zone_index_vectorised(case):
    terrain, starts, _ = case
    d = np.linspace(0.0, starts[-1] + 5.0, 17)
    idx = terrain.zone_index(d)
    expected = [max(j for j, s in enumerate(starts) if s <= dk) for dk in d]
    np.testing.assert_array_equal(idx, expected)


# --------------------------------------------------------------------------------------------------------------
# saturation inside the engine
# --------------------------------------------------------------------------------------------------------------

ROUGH = make_terrain(TerrainZone("rough", 0.0, 100.0, 0.1))


@SLOW
@given(lam=st.floats(1.0, 400.0), k=st.floats(0.0, 200.0), ndo=st.booleans(),
       u_max=st.floats(3.0, 30.0), seed=st.integers(0, 2**31))
def test_smc_applied_voltage_within_u_max(lam, k, ndo, u_max, seed):
    assume(lam + k / 0.1 < 1990.0)  # a step the validator accepts (dt (lambda + K / Phi) < 2 for Euler)
    robot = make_robot(max_voltage=u_max)
    ctrl = make_smc(lam=lam, switching_gain=k, ndo=NonlinearDisturbanceObserver(50.0) if ndo else None)
    sim = make_simulation(controller=ctrl, robot=robot, terrain=ROUGH, dt=1e-3, duration=0.05,
                     initial_pose=(0.0, 0.0, 0.0), initial_wheel_speeds="rest", divergence_bound=1e9)
    res = simulate(sim, seeds=[seed], keep_series=[seed])
    s = res.series[seed]
    u = np.concatenate([s["u_right"], s["u_left"]])
    assert np.all(np.abs(u) <= u_max)
    # first step in closed form: w = 0, e = s = w_ref = 1/R on both wheels, w_d' = 0, f(0) = 0, d_hat = 0,
    # sat(s / Phi) = 1, so u_cmd = g^-1 (lambda s + K) [1, 1] = (J11 + J12) / K_u (lambda / R + K) on both wheels
    J = robot.inertia_matrix
    u_cmd0 = (J[0, 0] + J[0, 1]) / robot.voltage_gain * (lam / robot.wheel_radius + k)
    assert s["u_right"][0] == pytest.approx(min(u_cmd0, u_max), rel=1e-12)
    assert s["u_left"][0] == pytest.approx(min(u_cmd0, u_max), rel=1e-12)


@SLOW
@given(kp=st.floats(0.0, 50.0), ki=st.floats(0.0, 50.0), kd=st.floats(0.0, 0.05), seed=st.integers(0, 1000))
def test_pid_applied_voltage_within_u_max(kp, ki, kd, seed):
    g = max(make_robot().input_gain.eigenvalues)
    assume(_pd_spectral_radius(1e-3 * g * kp, g * kd) < 0.999)  # a sampled loop the validator accepts
    sim = make_simulation(controller=make_pid(kp=kp, ki=ki, kd=kd), terrain=ROUGH, dt=1e-3, duration=0.05,
                     initial_wheel_speeds="rest", divergence_bound=1e9)
    res = simulate(sim, seeds=[seed], keep_series=[seed])
    u = np.concatenate([res.series[seed]["u_right"], res.series[seed]["u_left"]])
    assert np.all(np.abs(u) <= make_robot().max_voltage)
    assert 0.0 <= res.metric("saturation_fraction")[0] <= 1.0


# --------------------------------------------------------------------------------------------------------------
# config validators
# --------------------------------------------------------------------------------------------------------------

keys = st.from_regex(r"[a-z]{1,8}\.[a-z_]{1,10}", fullmatch=True)
finite_pos = st.floats(min_value=1e-300, max_value=1e300)
non_finite = st.sampled_from([math.inf, -math.inf, math.nan])


@FAST
@given(key=keys, v=st.one_of(finite_pos, st.integers(1, 10**9)))
def test_positive_accepts_positive_numbers(key, v):
    out = validate.positive(key, v)
    assert isinstance(out, float) and out == float(v)


@FAST
@given(key=keys, v=st.one_of(st.floats(max_value=0.0, allow_nan=False), st.integers(-10**9, 0), non_finite,
                             st.text(max_size=3), st.booleans(), st.none()))
def test_positive_rejects_with_key(key, v):
    with pytest.raises(ConfigError) as err:
        validate.positive(key, v)
    assert err.value.key == key and key in str(err.value)


@FAST
@given(key=keys, v=st.one_of(st.floats(0.0, 1e300), st.integers(0, 10**9)))
def test_non_negative_accepts(key, v):
    assert validate.non_negative(key, v) == float(v)


@FAST
@given(key=keys, v=st.one_of(st.floats(max_value=-1e-300, allow_nan=False), st.integers(-10**9, -1), non_finite,
                             st.booleans()))
def test_non_negative_rejects_with_key(key, v):
    with pytest.raises(ConfigError) as err:
        validate.non_negative(key, v)
    assert err.value.key == key and key in str(err.value)


@FAST
@given(key=keys, v=st.one_of(st.floats(0.0, 1e6), st.tuples(st.floats(0.0, 1e6), st.floats(0.0, 1e6)).map(list)))
def test_per_wheel_accepts_scalar_or_pair(key, v):
    out = validate.per_wheel(key, v)
    assert len(out) == 2
    np.testing.assert_array_equal(out, [v, v] if not isinstance(v, list) else v)


@FAST
@given(key=keys, items=st.lists(st.floats(0.0, 10.0), min_size=0, max_size=5).filter(lambda xs: len(xs) != 2))
def test_per_wheel_rejects_wrong_length(key, items):
    with pytest.raises(ConfigError) as err:
        validate.per_wheel(key, items)
    assert err.value.key == key and key in str(err.value)


@FAST
@given(key=keys, good=st.floats(0.0, 10.0), bad=st.one_of(non_finite, st.floats(max_value=-1e-9)),
       index=st.integers(0, 1))
def test_per_wheel_rejects_bad_element_naming_it(key, good, bad, index):
    pair = [good, good]
    pair[index] = bad
    with pytest.raises(ConfigError) as err:
        validate.per_wheel(key, pair)
    assert err.value.key == f"{key}[{index}]" and key in str(err.value)


@FAST
@given(key=keys, v=st.one_of(st.floats(max_value=0.0, allow_nan=False), non_finite))
def test_per_wheel_with_positive_rule_rejects(key, v):
    with pytest.raises(ConfigError) as err:
        validate.per_wheel(key, v, validate.positive)
    assert key in str(err.value)


@FAST
@given(key=keys, minimum=st.integers(-5, 5), extra=st.integers(0, 10**6))
def test_integer_accepts(key, minimum, extra):
    assert validate.integer(key, minimum + extra, minimum) == minimum + extra


@FAST
@given(key=keys, minimum=st.integers(-5, 5),
       v=st.one_of(st.floats(allow_nan=True), st.booleans(), st.text(max_size=3), st.none()))
def test_integer_rejects_non_integers(key, minimum, v):
    with pytest.raises(ConfigError) as err:
        validate.integer(key, v, minimum)
    assert err.value.key == key and key in str(err.value)


@FAST
@given(key=keys, minimum=st.integers(-5, 5), below=st.integers(1, 10**6))
def test_integer_rejects_below_minimum(key, minimum, below):
    with pytest.raises(ConfigError) as err:
        validate.integer(key, minimum - below, minimum)
    assert err.value.key == key and key in str(err.value) and str(minimum) in str(err.value)
