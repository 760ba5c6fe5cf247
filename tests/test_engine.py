"""The one step loop: compiled per controller and cached on disk, the same numbers as plain Python, any threads.

Each law is defined once (docs/model.md); the step loop that runs them is compiled with numba when it is
installed and runs as plain Python when it is not (or with NUMBA_DISABLE_JIT=1). These tests hold the two to
the same numbers, and check that the compiled loop is loaded from the disk cache by a later process.
"""

from __future__ import annotations

import json
import os
import subprocess
import sys
import textwrap

import numpy as np
import pytest

from paper import make_smc, make_pid, make_rbf, make_simulation
from ddmr_cli import (PID, SMC, NonlinearDisturbanceObserver, OpenLoop, RBFNetworkObserver, Simulation,
                      paper_scenario, paper_terrain, simulate)
from ddmr_cli.compiled import AVAILABLE
from ddmr_cli.engine.catalog import METRICS, STEADY

#: the controllers of the presets plus every switching function and surface
CONTROLLERS = {
    "open_loop": "OpenLoop([11.0, 10.5])",
    "pid": "make_pid()",
    "pid_per_wheel": "make_pid(kp=[5.0, 4.0], ki=[0.1, 0.3], kd=[0.01, 0.0], anti_windup=False)",
    "smc_sign": "make_smc(switching='sign', switching_gain=4.0)",
    "smc_tanh_integral": "make_smc(switching='tanh', surface='integral', lam=[20.0, 30.0])",
    "smc_ndo_nno": "make_smc(ndo=NonlinearDisturbanceObserver([50.0, 40.0]), nn=make_rbf())",
}

_SCRIPT = textwrap.dedent("""
    import json, sys
    {block}
    from ddmr_cli import *
    from ddmr_cli.compiled import jit_enabled
    sys.path.insert(0, {tests_dir!r})
    from paper import make_pid, make_rbf, make_simulation, make_smc
    out = {{}}
    for name, make in {controllers}.items():
        for scenario, integrator in ((1, "euler"), (2, "rk4")):
            sim = make_simulation(controller=eval(make), terrain=paper_terrain(), scenario=paper_scenario(scenario),
                             duration={duration}, integrator=integrator)
            r = simulate(sim, [3, 4], keep_series=[4])
            out[f"{{name}}/{{scenario}}/{{integrator}}"] = {{
                "metrics": {{m: v.tolist() for m, v in r.metrics.items()}},
                "u": r.series[4]["u_right"][::50].tolist(), "engine": r.engine}}
    print(json.dumps({{"jit": jit_enabled(), "runs": out}}))
""")


def _run(env_extra: dict, block: str = "", duration: float = 0.3) -> dict:
    script = _SCRIPT.format(block=block, controllers=json.dumps(CONTROLLERS), duration=duration,
                            tests_dir=os.path.dirname(__file__))
    proc = subprocess.run([sys.executable, "-c", script], capture_output=True, text=True, timeout=900,
                          env={**os.environ, **env_extra})
    assert proc.returncode == 0, proc.stderr[-3000:]
    return json.loads(proc.stdout.strip().splitlines()[-1])


@pytest.fixture(scope="module")
def compiled_runs():
    return _run({})


def _assert_same(a: dict, b: dict, rtol: float) -> None:
    assert a.keys() == b.keys()
    for key in a:
        for metric, values in a[key]["metrics"].items():
            np.testing.assert_allclose(b[key]["metrics"][metric], values, rtol=rtol, atol=1e-300,
                                       err_msg=f"{key} {metric}")
        np.testing.assert_allclose(b[key]["u"], a[key]["u"], rtol=rtol, atol=1e-12, err_msg=f"{key} u")


@pytest.mark.slow  # two interpreter processes
@pytest.mark.skipif(not AVAILABLE, reason="numba is a dependency; without it every run is the Python fallback")
def test_plain_python_gives_the_compiled_numbers(compiled_runs):
    python = _run({"NUMBA_DISABLE_JIT": "1"}, duration=0.3)
    assert compiled_runs["jit"] and not python["jit"]
    assert {r["engine"] for r in python["runs"].values()} == {"python"}
    _assert_same(compiled_runs["runs"], python["runs"], rtol=1e-12)


@pytest.mark.slow  # two interpreter processes
@pytest.mark.skipif(not AVAILABLE, reason="numba is a dependency; without it every run is the Python fallback")
def test_without_numba_installed_the_same_laws_run_as_python(compiled_runs):
    block = "import builtins; _imp = builtins.__import__\n" \
            "def _no_numba(name, *a, **k):\n" \
            "    if name == 'numba' or name.startswith('numba.'): raise ImportError('no numba here')\n" \
            "    return _imp(name, *a, **k)\n" \
            "builtins.__import__ = _no_numba"
    python = _run({}, block=block)
    assert not python["jit"]
    _assert_same(compiled_runs["runs"], python["runs"], rtol=1e-12)


def test_thread_count_does_not_change_the_numbers():
    sim = make_simulation(controller=make_smc(ndo=NonlinearDisturbanceObserver(50.0), nn=make_rbf()),
                     terrain=paper_terrain(), scenario=paper_scenario(2), duration=0.5)
    one = simulate(sim, range(7), keep_series=[5], threads=1)
    three = simulate(sim, range(7), keep_series=[5], threads=3)
    for metric, values in one.metrics.items():
        assert np.array_equal(values, three.metrics[metric], equal_nan=True), metric
    for channel, values in one.series[5].items():
        assert np.array_equal(values, three.series[5][channel], equal_nan=True), channel


@pytest.mark.parametrize("multiple", [1, 32])
@pytest.mark.parametrize("n_runs, n_threads", [(1, 1), (7, 1), (7, 2), (64, 2), (1000, 2), (1000, 3), (5, 8)])
def test_the_threads_blocks_cover_the_runs_once_in_order(n_runs, n_threads, multiple):
    from ddmr_cli.engine import simulation

    blocks = simulation.blocks_of(n_runs, n_threads, multiple)
    assert blocks[0][0] == 0 and blocks[-1][1] == n_runs
    assert all(end == first for (_, end), (first, _) in zip(blocks, blocks[1:]))
    assert all(end > first for first, end in blocks)
    assert all((end - first) % multiple == 0 for first, end in blocks[:-1])  # whole blocks of lanes but the last
    if n_threads == 1:
        assert blocks == [(0, n_runs)]
    else:
        assert len(blocks) <= n_threads * simulation.BLOCKS_PER_THREAD
        if multiple == 1:
            assert len(blocks) == n_runs or min(end - first for first, end in blocks) >= min(
                simulation.MIN_BLOCK_RUNS, n_runs // len(blocks))


def test_several_blocks_per_thread_do_not_change_the_numbers(monkeypatch):
    """The threads take blocks as they come free (more blocks than threads): the same numbers as one thread."""
    from ddmr_cli.engine import simulation

    sim = make_simulation(controller=make_smc(ndo=NonlinearDisturbanceObserver(50.0)), terrain=paper_terrain(),
                          scenario=paper_scenario(1), duration=0.3)
    one = simulate(sim, range(9), keep_series=[4], threads=1)
    monkeypatch.setattr(simulation, "MIN_BLOCK_RUNS", 1)
    assert len(simulation.blocks_of(9, 2)) == 8
    blocks = simulate(sim, range(9), keep_series=[4], threads=2)
    for metric, values in one.metrics.items():
        assert np.array_equal(values, blocks.metrics[metric], equal_nan=True), metric
    for channel, values in one.series[4].items():
        assert np.array_equal(values, blocks.series[4][channel], equal_nan=True), channel


def test_the_step_state_is_released_before_the_metrics_are_formed(monkeypatch):
    """A large batch's memory peaks while its metrics are formed: by then the runs' generators (800 bytes a run) and
    controller states are gone, only the sums and the run records the metrics read are left."""
    import gc
    import weakref

    from ddmr_cli.engine import metrics, simulation

    made, alive_at_finalize = [], []
    streams = simulation.NoiseStreams

    class Tracked(streams):
        def __init__(self, *args, **kwargs):
            super().__init__(*args, **kwargs)
            made.append(weakref.ref(self))

    finalize = metrics.MetricAccumulator.finalize

    def spying_finalize(self, state):
        gc.collect()
        alive_at_finalize.append(sum(ref() is not None for ref in made))
        return finalize(self, state)

    monkeypatch.setattr(simulation, "NoiseStreams", Tracked)
    monkeypatch.setattr(metrics.MetricAccumulator, "finalize", spying_finalize)
    sim = make_simulation(controller=make_smc(ndo=NonlinearDisturbanceObserver(50.0)), terrain=paper_terrain(),
                          scenario=paper_scenario(1), duration=0.05)
    result = simulate(sim, range(3))
    assert len(made) == 1 and alive_at_finalize == [0]
    assert np.isfinite(result.metrics["deviation_mae"][:, 0]).all()


def numpy_metrics(sums, dev_max, dev_final, dt):
    """The metrics of docs/model.md §7 from sums ``(runs, segments, SUMS)``, as numpy array expressions: the oracle
    of the compiled finalize (the engine's own form until it was compiled)."""
    from ddmr_cli.engine.metrics import SUMS

    S = {name: sums[:, :, i] for i, name in enumerate(SUMS)}
    with np.errstate(invalid="ignore", divide="ignore"):
        n = np.where(S["count"] > 0, S["count"], np.nan)

        def wheels(name, f=lambda x: x / n):
            return f(S[name + "_R"]), f(S[name + "_L"])

        def hf(side):
            mean_u = S["u" + side] / n
            var_u = S["u2" + side] / n - mean_u ** 2
            return np.where(var_u > 1e-12 * np.maximum(S["u2" + side] / n, 1e-300), S["u_hp2" + side] / n / var_u, 0.0)

        chat_R, chat_L = wheels("abs_du", lambda x: x / n / dt)
        out = {"deviation_mae": S["dev"] / n, "deviation_rmse": np.sqrt(S["dev2"] / n),
               "deviation_max": np.full(n.shape, np.nan), "deviation_final": np.full(n.shape, np.nan),
               "e_x_mae": S["abs_ex"] / n, "e_y_mae": S["abs_ey"] / n, "e_theta_mae": S["abs_eth"] / n,
               "iae": S["dev"] * dt, "ise": S["dev2"] * dt, "itae": S["tdev"] * dt,
               "chattering": (chat_R + chat_L) / 2.0, "chattering_right": chat_R, "chattering_left": chat_L,
               "hf_fraction": (hf("_R") + hf("_L")) / 2.0, "mean_voltage": sum(wheels("abs_u")) / 2.0,
               "energy_u2": sum(wheels("u2", lambda x: x)) * dt, "electrical_energy": sum(wheels("power", lambda x: x)) * dt,
               "saturation_fraction": S["saturated"] / n, "d_est_mae": sum(wheels("abs_dtilde")) / 2.0,
               "d_est_mae_ndo": sum(wheels("abs_dtilde_ndo")) / 2.0, "s_mae": sum(wheels("abs_s")) / 2.0}
    out["deviation_max"][:, 0] = np.where(np.isfinite(dev_max), dev_max, np.nan)
    out["deviation_final"][:, 0] = np.where(S["count"][:, 0] > 0, dev_final, np.nan)
    return out


def test_metrics_written_over_their_sums_are_the_formulas_computed_apart():
    """finalize (compiled) writes each run's metrics over the sums they came from (no second array of 2 x 21
    metrics beside the sums at the batch's peak): every metric is a view of the sums' memory and equals, to the
    bit, the formulas as numpy expressions on a copy of the sums, empty segments (NaN means, 0 integrals),
    a constant voltage (hf_fraction 0), an unbounded largest deviation (NaN) and a run that never counted a step
    included."""
    from ddmr_cli.engine import metrics

    rng = np.random.default_rng(7)
    n_runs, dt = 11, 0.001
    acc = metrics.MetricAccumulator(n_runs, dt, ["flat", "rough"], ["cruise"])
    acc.sums[...] = rng.uniform(0.1, 2.0, acc.sums.shape)
    acc.sums[..., metrics.SUMS.index("count")] = rng.integers(0, 50, acc.sums.shape[:2])  # some segments empty
    acc.sums[3] = 0.0  # a run that never counted a step
    count = acc.sums[..., metrics.SUMS.index("count")]
    for side in "RL":  # a constant voltage: u2 / n = (u / n)^2 exactly
        acc.sums[4, :, metrics.SUMS.index("u_" + side)] = 2.0 * count[4]
        acc.sums[4, :, metrics.SUMS.index("u2_" + side)] = 4.0 * count[4]
    state = np.zeros(n_runs, metrics.ACCUMULATOR_FIELDS)
    state["dev_max"], state["dev_max_ss"], state["dev_final"] = rng.uniform(0, 1, (3, n_runs))
    state["dev_max"][5] = -np.inf
    sums, n = acc.sums.copy(), len(acc.segments)
    apart = {**numpy_metrics(sums[:, :n], state["dev_max"], state["dev_final"], dt),
             **{name + STEADY: v for name, v in
                numpy_metrics(sums[:, n:], state["dev_max_ss"], state["dev_final"], dt).items()}}
    written = acc.finalize(state)
    assert list(written) == list(apart) == [*METRICS, *(name + STEADY for name in METRICS)]
    assert np.isnan(written["deviation_mae"][3]).all() and (written["iae"][3] == 0).all()
    assert (written["hf_fraction"][4] == 0).all() and np.isnan(written["deviation_max"][5, 0])
    for name, values in written.items():
        assert np.shares_memory(values, acc.sums), name
        assert values.shape == (n_runs, n)
        assert np.array_equal(values, apart[name], equal_nan=True), name


@pytest.mark.slow
@pytest.mark.skipif(not AVAILABLE, reason="the disk cache is numba's")
def test_a_later_process_loads_the_compiled_loop_from_the_disk_cache(tmp_path):
    script = textwrap.dedent("""
        import numpy as np
        from ddmr_cli import paper_simulation, simulate
        import sys
        sim = paper_simulation("controller=pid", "simulation.duration=0.01")
        simulate(sim, [0], lanes=False)
        [copy] = [m for name, m in sys.modules.items() if name.startswith("ddmr_stepper_ddmr_cli_control_pid_")]
        stats = copy.run_chunk.stats
        print(sum(stats.cache_hits.values()), sum(stats.cache_misses.values()))
    """)
    env = {**os.environ, "DDMR_CACHE_DIR": str(tmp_path)}
    runs = [subprocess.run([sys.executable, "-c", script], capture_output=True, text=True, env=env, timeout=600)
            for _ in range(2)]
    assert all(p.returncode == 0 for p in runs), runs[-1].stderr[-2000:]
    (hits1, misses1), (hits2, misses2) = (map(int, p.stdout.split()) for p in runs)
    assert (hits1, misses1) == (0, 1)  # compiled in the first process
    assert (hits2, misses2) == (1, 0)  # loaded in the second


@pytest.mark.slow
@pytest.mark.skipif(not AVAILABLE, reason="the disk cache is numba's")
def test_a_warm_cache_keeps_controllers_of_one_module_apart(tmp_path):
    """SMC-NDO and SMC-NDO-NNO share the law module smc.py but not their state layout (1 vs 10 neurons): with both
    compiled into a warm cache, one process running SMC-NDO then SMC-NDO-NNO gets each one's own numbers (it
    once got SMC-NDO's for both, numba's on-disk index conflating the two record types)."""
    script = textwrap.dedent("""
        import json, sys
        from ddmr_cli import paper_simulation, simulate
        out = {}
        for c in sys.argv[1:]:
            r = simulate(paper_simulation(f"controller={c}", "simulation.duration=0.3"), [0, 1])
            out[c] = r.metric("deviation_mae").tolist() + r.metric("d_est_mae").tolist()
        print(json.dumps(out))
    """)
    env = {**os.environ, "DDMR_CACHE_DIR": str(tmp_path)}

    def run(*controllers):
        p = subprocess.run([sys.executable, "-c", script, *controllers], capture_output=True, text=True, env=env,
                           timeout=900)
        assert p.returncode == 0, p.stderr[-2000:]
        return json.loads(p.stdout.strip().splitlines()[-1])

    fresh = {**run("smc_ndo"), **run("smc_ndo_nno")}  # each compiled in its own process: the cache is now warm
    both = run("smc_ndo", "smc_ndo_nno")
    assert both == fresh
    assert fresh["smc_ndo"] != fresh["smc_ndo_nno"]


def test_a_numba_without_the_parts_of_the_draw_is_named_not_run(monkeypatch):
    """The compiled loop draws its runs' noise with numba's parts (ddmr_cli/bit_generators.py: its ziggurat tables):
    where numba lacks them, simulate says so (EngineUnavailable, naming numba and NUMBA_DISABLE_JIT) before any step."""
    from ddmr_cli import bit_generators
    from ddmr_cli.errors import EngineUnavailable

    sim = make_simulation(controller=make_smc(), terrain=paper_terrain(), scenario=paper_scenario(1), duration=0.05)
    monkeypatch.setattr(bit_generators, "AVAILABLE", False)
    with pytest.raises(EngineUnavailable, match="numba .* NUMBA_DISABLE_JIT"):
        simulate(sim, range(2))


@pytest.mark.parametrize("bytes_per_run_step, n_runs", [(0, 10_000), (0, 1000), (0, 50), (64, 1000), (12, 10_000),
                                                         (0, 10**7)])
def test_a_chunk_holds_no_more_run_steps_than_a_progress_report_may_wait_for(bytes_per_run_step, n_runs):
    """Progress is reported after every chunk: with no per-step buffer (no bands, an ideal sensor) the memory budget
    alone would let 10,000 seeds run 4096 steps unreported; a chunk is held to CHUNK_RUN_STEPS run-steps too, and to
    the budget and the fewest and most steps."""
    from ddmr_cli.engine import simulation

    steps = simulation.chunk_steps(bytes_per_run_step, n_runs)
    assert simulation.MIN_CHUNK_STEPS <= steps <= simulation.MAX_CHUNK_STEPS
    assert steps == simulation.MIN_CHUNK_STEPS or steps * n_runs <= simulation.CHUNK_RUN_STEPS
    assert steps == simulation.MIN_CHUNK_STEPS or steps * n_runs * bytes_per_run_step <= simulation.CHUNK_BUDGET
    if n_runs == 50 and bytes_per_run_step == 0:
        assert steps == simulation.MAX_CHUNK_STEPS  # a small batch still runs long chunks
