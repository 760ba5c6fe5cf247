"""What the report's figures share, on constructed data: styles, decimation, draw order, saving, and the numbers
computed from time series (the NN's share, the voltage spectrum)."""

from __future__ import annotations

import dataclasses
import math

import numpy as np
import pytest

from paper import make_robot
from ddmr_cli.plots import common as P
from ddmr_cli.report import signals as S


# --- styles ------------------------------------------------------------------------------------------------------
BASELINES = ("sta", "sta_ndo", "adrc", "adaptive_smc", "adaptive_smc_ndo")
#: the packaged controllers' styles (their conf/controller/*.yaml display nodes)
KNOWN = P.known_styles()


def test_known_controllers_differ_in_colour_and_dash():
    """The paper's controllers (and the other pre-existing ones) differ in colour and in dash; with the baselines
    (12 built-in controllers, 8 colours) every two still differ in their (colour, dash) pair, not by a marker only."""
    paper = [s for c, s in KNOWN.items() if c not in BASELINES]
    assert len({s.color for s in paper}) == len(paper) and len({s.dash for s in paper}) == len(paper)
    styles = list(KNOWN.values())
    assert set(BASELINES) <= set(KNOWN)
    assert len({(s.color, s.dash) for s in styles}) == len(styles) >= 12
    assert set(s.color for s in styles) <= set(P.OKABE_ITO.values())
    assert KNOWN["smc_ndo_nno"].color == "#000000" and KNOWN["smc_ndo_nno"].dash == "solid"


def test_style_book_gives_every_controller_its_own_style():
    unknown = ["twisting", "mpc", "computed_torque"] + [f"ctrl{i}" for i in range(60)]
    book = P.StyleBook(list(KNOWN) + unknown)
    styles = [book[c] for c in list(KNOWN) + unknown]
    assert len(set(styles)) == len(styles)                          # no two controllers alike
    assert all(book[c] == KNOWN[c] for c in KNOWN)  # the paper's keep theirs
    # the same controller gets the same style in another report without a clash, whatever the order
    assert P.StyleBook(["mpc", "twisting"])["twisting"] == P.StyleBook(["twisting"])["twisting"]
    assert P.StyleBook(reversed(unknown))["ctrl7"] == book["ctrl7"]


def test_style_kwargs_mark_variants():
    s = KNOWN["smc"]
    assert "marker" not in s.kwargs(0) and s.kwargs(0)["color"] == s.color
    assert s.kwargs(1)["marker"] != s.kwargs(2)["marker"]


# --- decimation, draw order, saving ----------------------------------------------------------------------------
def test_thin_keeps_the_envelope():
    t = np.linspace(0, 10, 100_001)
    y = np.sin(2 * np.pi * 50 * t) + 0.1 * t      # fast chattering on a slow ramp
    y[12_345] = 7.0                                # a lone spike must survive
    idx = P.thin(y, 2000)
    assert len(idx) <= 2100 and idx[0] == 0 and idx[-1] == len(y) - 1
    assert np.all(np.diff(idx) > 0)
    assert y[idx].max() == pytest.approx(7.0) and y[idx].min() == pytest.approx(y.min())
    assert np.array_equal(P.thin(y[:100], 2000), np.arange(100))
    y_nan = y.copy()
    y_nan[:10] = np.nan
    assert len(P.thin(y_nan, 2000)) <= 2100
    even = y[:100_000]  # a whole number of bins (100 samples each): the last sample is kept for itself
    idx = P.thin(even, 2000)
    assert idx[0] == 0 and idx[-1] == len(even) - 1 and np.all(np.diff(idx) > 0)


def test_draw_order_puts_quiet_lines_on_top():
    rng = np.random.default_rng(0)
    loud, quiet = 5 * rng.standard_normal(1000), 0.1 * rng.standard_normal(1000)
    assert P.draw_order([quiet, loud]) == [1, 0]
    # overlapping lines: the thick one at the back, so the thin dashed one shows on it
    same = rng.standard_normal(1000)
    assert P.draw_order([same, same * 1.01], widths=[1.0, 1.5]) == [1, 0]


def test_save_writes_a_png_and_closes(tmp_path):
    plt = P.pyplot()
    fig, ax = plt.subplots()
    ax.plot([0, 1], [0, 1])
    path = P.save(fig, tmp_path / "a" / "f.png")
    assert path.read_bytes()[:8] == b"\x89PNG\r\n\x1a\n"
    assert not plt.fignum_exists(fig.number)

def _two_panels(plt):
    fig, axes = plt.subplots(2, 1, figsize=(5, 4))
    for k, ax in enumerate(axes):
        ax.plot(np.linspace(0, 10, 200), np.sin(np.linspace(0, 10, 200)) * 10 ** (3 * k), label=f"line {k}")
        ax.set_ylabel(f"a long label, panel {k} [unit]")
        ax.set_title(f"panel {k}")
        ax.legend(loc="upper right")
    return fig


def _draws(fig) -> list:
    """The renderers of every draw of ``fig`` from now on (one entry per draw)."""
    drawn = []
    original_draw = fig.draw
    fig.draw = lambda renderer: (drawn.append(renderer), original_draw(renderer))[1]
    return drawn


def test_save_lays_out_once_and_draws_once_with_the_pixels_of_a_plain_tight_layout(tmp_path):
    """``save`` removes the placeholder engine ``tight_layout`` leaves, so ``savefig`` does not draw the whole figure
    once more without rendering: one draw per save, and the same pixels as ``tight_layout`` + ``savefig``."""
    import matplotlib.image as mpimg

    plt = P.pyplot()
    fig = _two_panels(plt)
    drawn = _draws(fig)
    P.save(fig, tmp_path / "ours.png")
    assert len(drawn) == 1
    fig = _two_panels(plt)
    fig.tight_layout()
    fig.savefig(tmp_path / "plain.png", format="png", dpi=P.DPI, pil_kwargs={"compress_level": P.PNG_COMPRESSION})
    plt.close(fig)
    ours, plain = mpimg.imread(tmp_path / "ours.png"), mpimg.imread(tmp_path / "plain.png")
    assert ours.shape == plain.shape and np.array_equal(ours, plain)


def test_titles_at_the_top_of_their_axes_give_the_pixels_of_matplotlibs_own_placement(tmp_path):
    """``RC_PARAMS`` turns matplotlib's automatic title placement off (it lays out the y tick labels once more per
    titled axes and draw); where it would not move a title, the figure is the same."""
    import matplotlib
    import matplotlib.image as mpimg

    plt = P.pyplot()
    assert matplotlib.rcParams["axes.titley"] == 1.0
    P.save(_two_panels(plt), tmp_path / "ours.png")
    with matplotlib.rc_context({"axes.titley": None}):  # None: matplotlib places the titles itself
        P.save(_two_panels(plt), tmp_path / "auto.png")
    ours, auto = mpimg.imread(tmp_path / "ours.png"), mpimg.imread(tmp_path / "auto.png")
    assert ours.shape == auto.shape and np.array_equal(ours, auto)


def _offset_panel(plt, title: str):
    """An axes whose y tick labels need an offset text ("1e-5+1.1e1", drawn above the top left corner)."""
    fig, ax = plt.subplots(figsize=(4, 3))
    t = np.linspace(0.0, 6.0, 50)
    ax.plot(t, 11.0 + 1e-5 * np.sin(t))
    ax.set_title(title)
    return fig, ax


def test_a_title_running_into_its_axis_offset_text_is_lifted_over_it(tmp_path):
    plt = P.pyplot()
    fig, ax = _offset_panel(plt, "a long title that reaches the left edge of the axes")
    drawn = _draws(fig)
    P.save(fig, tmp_path / "lifted.png")
    offset = ax.yaxis.offsetText
    assert offset.get_visible() and offset.get_text()
    assert ax.title.get_window_extent().y0 >= offset.get_window_extent().y1 - 0.5  # pixels
    assert ax.title.get_position()[1] > 1.0 and len(drawn) >= 2  # lifted, then laid out and drawn again
    fig, ax = _offset_panel(plt, "short")  # clear of the offset text: not moved, drawn once
    drawn = _draws(fig)
    P.save(fig, tmp_path / "short.png")
    assert len(drawn) == 1
    assert ax.title.get_position()[1] == 1.0  # the value set, not a computed one
    assert not ax.title.get_window_extent().overlaps(ax.yaxis.offsetText.get_window_extent())


def test_run_plots_use_the_shared_helpers(tmp_path):
    from ddmr_cli.plots.run import run_plots

    n = 3000
    t = np.linspace(0, 3, n)
    series = {c: np.zeros(n) for c in ("x_ref", "y_ref", "x", "y", "deviation", "e_x", "e_y", "e_theta",
                                        "u_right", "u_left", "s_right", "s_left", "d_true_right",
                                        "d_hat_ndo_right", "d_hat_nn_right")}
    series.update(t=t, x_ref=t, x=t, y=0.01 * np.sin(t))
    paths = run_plots(series, "sta", "paper_1", 0, tmp_path)   # a controller the report does not know
    assert [p.name for p in paths] == ["trajectory.png", "errors.png", "control.png"]
    assert all(p.read_bytes()[:8] == b"\x89PNG\r\n\x1a\n" for p in paths)


def _run_series(n: int = 3000) -> dict:
    t = np.linspace(0, 3, n)
    series = {c: np.zeros(n) for c in ("x_ref", "y_ref", "x", "y", "deviation", "e_x", "e_y", "e_theta",
                                        "u_right", "u_left", "s_right", "s_left", "d_true_right",
                                        "d_hat_ndo_right", "d_hat_nn_right")}
    series.update(t=t, x_ref=t, x=t, y=0.01 * np.sin(t), deviation=0.01 + 0.001 * t)
    return series


def _pixels(path) -> np.ndarray:
    from PIL import Image

    with Image.open(path) as image:
        return np.asarray(image)


def test_plot_processes_draw_every_figure_and_end(tmp_path):
    """``ddmr run``'s figures drawn by the forked processes into frames drawn before the run was known: the same
    files as drawn in the job's process (same names, same pixels), each by another process, and no process left
    behind."""
    import multiprocessing
    import os

    from ddmr_cli.plots import run as R
    from ddmr_cli.plots.processes import PlotProcesses

    drawers = tmp_path / "drawers"
    drawers.mkdir()
    real = dict(R.FIGURES)

    def recording(name, figure):
        class Recording(figure):
            def finish(self, run, series):
                (drawers / f"{name}.{os.getpid()}").touch()
                return super().finish(run, series)
        return Recording

    R.FIGURES.update({name: recording(name, figure) for name, figure in real.items()})
    try:
        with PlotProcesses() as processes:
            paths = processes.draw(_run_series(), "smc_ndo", "paper_1", 0, tmp_path / "forked")
    finally:
        R.FIGURES.update(real)
    here = R.run_plots(_run_series(), "smc_ndo", "paper_1", 0, tmp_path / "here")
    assert [p.name for p in paths] == [p.name for p in here] == ["trajectory.png", "errors.png", "control.png"]
    for forked, local in zip(paths, here):
        assert forked.read_bytes()[:8] == b"\x89PNG\r\n\x1a\n"
        assert np.array_equal(_pixels(forked), _pixels(local))
    pids = {p.name.split(".")[1] for p in drawers.iterdir()}
    assert len(pids) == 3 and str(os.getpid()) not in pids  # one process a figure, none of them this one
    assert not multiprocessing.active_children()


def test_a_warm_frame_draws_the_same_figure(tmp_path):
    """A frame drawn before its run (the drawing processes' ``warm``) gives the same pixels as one drawn once."""
    from ddmr_cli.plots.run import Run, RunInfo, frames

    series = _run_series()
    run = Run.of(RunInfo("smc_ndo", "paper_1", 0, tmp_path / "warm"), series)
    cold = Run.of(RunInfo("smc_ndo", "paper_1", 0, tmp_path / "cold"), series)
    for warm, once in zip(frames(warm=True), frames()):
        assert np.array_equal(_pixels(warm.finish(run, warm.channels(series))),
                              _pixels(once.finish(cold, once.channels(series))))


def test_each_figure_is_sent_every_channel_it_reads(tmp_path):
    """A drawing process is sent only its figures' channels (:meth:`channels`): every channel a figure reads (or
    looks for: ``distance``, ``zone``) is among them."""
    from ddmr_cli.plots.run import FIGURES, Run, RunInfo

    class Reads(dict):
        def __init__(self, *args):
            super().__init__(*args)
            self.read = set()

        def __getitem__(self, key):
            self.read.add(key)
            return super().__getitem__(key)

        def get(self, key, default=None):
            self.read.add(key)
            return super().get(key, default)

        def __contains__(self, key):
            self.read.add(key)
            return super().__contains__(key)

    series = _run_series()
    series.update(distance=series["t"], zone=(series["t"] > 1.5).astype(float), d_hat_ndo_left=series["t"])
    run = Run.of(RunInfo("smc_ndo", "paper_1", 0, tmp_path), series)
    for name, figure in FIGURES.items():
        sent = figure.channels(series)
        reads = Reads(sent)
        figure().finish(run, reads)
        assert reads.read <= set(sent), name
        assert len(sent) < len(series), name


def test_a_failing_plot_process_leaves_its_figure_to_the_job(tmp_path):
    """A drawing process that fails (here: its figure raises in it) reports it, and the job draws that figure
    itself: every figure is there, the others drawn by the processes."""
    import os

    from ddmr_cli.plots import run as R
    from ddmr_cli.plots.processes import PlotProcesses

    job = os.getpid()
    real = R.FIGURES["control"]

    class OnlyHere(real):
        def finish(self, run, series):
            if os.getpid() != job:
                raise RuntimeError("no drawing in this process")
            return super().finish(run, series)

    R.FIGURES["control"] = OnlyHere
    try:
        with PlotProcesses() as processes:
            paths = processes.draw(_run_series(), "smc_ndo", "paper_1", 0, tmp_path)
    finally:
        R.FIGURES["control"] = real
    assert [p.name for p in paths] == ["trajectory.png", "errors.png", "control.png"]
    assert all(p.read_bytes()[:8] == b"\x89PNG\r\n\x1a\n" for p in paths)


def test_plot_processes_end_when_nothing_is_drawn():
    """A job that fails before its figures (or keeps no series) ends its drawing processes on the way out."""
    import multiprocessing

    from ddmr_cli.plots.processes import PlotProcesses

    with PlotProcesses():
        pass
    assert not multiprocessing.active_children()


def test_plot_processes_started_early_are_the_jobs():
    """Drawing processes started before the job (``ddmr run``'s console) are the ones its job takes, once; they
    end with the context, and a context without them gives a job its own."""
    import multiprocessing

    from ddmr_cli.plots.processes import PlotProcesses

    with PlotProcesses.started() as early:
        taken = PlotProcesses.take()
        assert taken is early
        with PlotProcesses.take() as own:  # a second job of the context: its own processes
            assert own is not early
    assert not multiprocessing.active_children()


def test_the_console_starts_drawing_processes_for_a_single_run_only():
    """Started first thing for ``ddmr run [KEY=VALUE ...]``; not for a sweep, a flag, ``run.plots=false`` or
    another command."""
    import contextlib
    import multiprocessing

    from ddmr_cli.cli import main as M
    from ddmr_cli.plots.processes import PlotProcesses

    for argv in (None, [], ["report"], ["run", "-m"], ["run", "--cfg", "job"], ["run", "run.plots=false"],
                 ["run", "controller=pid", "run.plots = False"], ["run", "+run.plots=0"]):
        assert isinstance(M._plot_processes(argv), contextlib.nullcontext), argv
    with M._plot_processes(["run", "controller=pid", "run.plots=true"]) as processes:
        assert isinstance(processes, PlotProcesses)
    assert not multiprocessing.active_children()


def test_a_stop_where_python_cannot_raise_it_is_silent_and_the_process_goes_on():
    """A SIGTERM (close of processes never sent a run) that lands where Python cannot propagate an exception (an
    at-fork hook: logging's, seen once in CI; a weakref callback) prints nothing into the job's stderr, and the
    drawing process goes on to its next wait; elsewhere it still ends the process, and other unraisable errors are
    still reported."""
    import subprocess
    import sys

    code = ("import os, signal, weakref\n"
            "from ddmr_cli.plots.processes import _take_signals\n"
            "_take_signals()\n"
            "def stop(*_):\n    os.kill(os.getpid(), signal.SIGTERM)\n    for _ in range(1000): pass\n"
            "os.register_at_fork(after_in_parent=stop)\n"
            "pid = os.fork()\n"
            "if pid == 0: os._exit(0)\n"
            "os.waitpid(pid, 0)\n"
            "class A: pass\n"
            "a = A(); r = weakref.ref(a, stop); del a\n"
            "class B:\n    def __del__(self): raise ValueError('not a stop')\n"
            "B()\n"
            "print('went on', flush=True)\n"
            "stop()\n"
            "print('not reached')\n")
    proc = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, timeout=60)
    assert proc.stdout == "went on\n"
    assert proc.returncode == 0, proc.stderr
    assert "SystemExit" not in proc.stderr and "_Stop" not in proc.stderr, proc.stderr
    assert "ValueError: not a stop" in proc.stderr


def test_a_drawing_process_imports_neither_the_configuration_nor_the_engine(tmp_path):
    """What a drawing process does (frames, then a run made in the job's process) imports matplotlib and the plots
    alone: started before the job's imports, it has none of Hydra, numba or the configuration to import."""
    import pickle
    import subprocess
    import sys

    from ddmr_cli.plots.run import FIGURES, Run, RunInfo

    series = _run_series()
    run = Run.of(RunInfo("smc_ndo", "paper_1", 0, tmp_path), series)
    job = tmp_path / "job.pickle"
    job.write_bytes(pickle.dumps((run, {name: figure.channels(series) for name, figure in FIGURES.items()})))
    code = ("import pickle, sys\nfrom ddmr_cli.plots.run import FIGURES\n"
            f"run, parts = pickle.loads(open({str(job)!r}, 'rb').read())\n"
            "for name, figure in FIGURES.items():\n    figure(warm=True).finish(run, parts[name])\n"
            "print(sorted(m for m in ('numba', 'hydra', 'omegaconf', 'ddmr_cli.config', 'ddmr_cli.engine') "
            "if m in sys.modules))\n")
    out = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, check=True).stdout
    assert out.strip() == "[]"
    assert sorted(p.name for p in tmp_path.glob("*.png")) == ["control.png", "errors.png", "trajectory.png"]


# --- numbers from time series -------------------------------------------------------------------------------------
def test_nn_share_on_constructed_signals():
    n = 1000
    s = {"d_hat_ndo_right": np.full(n, 3.0), "d_hat_ndo_left": np.full(n, -3.0),
         "d_hat_nn_right": np.full(n, 1.0), "d_hat_nn_left": np.full(n, -1.0),
         "u_right": np.full(n, 10.0), "u_left": np.full(n, 10.0)}
    out = S.nn_share([s], g_inv=lambda a: 0.5 * a)
    assert out["share_of_estimate"] == pytest.approx(1.0 / 4.0)
    assert out["mean_abs_u_nn"] == pytest.approx(0.5)
    assert out["share_of_u"] == pytest.approx(0.05)
    assert math.isnan(S.nn_share([s])["share_of_u"])    # no model: no voltage share, the rest stands
    assert S.has_nn(s) and not S.has_nn({**s, "d_hat_nn_right": np.zeros(n), "d_hat_nn_left": np.zeros(n)})


def test_nominal_input_inverse_is_the_models():
    from ddmr_cli.model.dynamics import voltage_for
    from ddmr_cli.model.robot import NominalModel, Robot

    robot = make_robot(mass=20.0, wheel_radius=0.04)
    g_inv = S.nominal_input_inverse(dataclasses.asdict(robot))
    a = np.array([[1.0, -2.0]])
    expected = voltage_for(NominalModel.from_robot(robot), 1.0, -2.0, 0.0, 0.0)
    assert np.allclose(g_inv(a), [expected], rtol=1e-14)
    assert S.nominal_input_inverse({"no_such_parameter": 1.0}) is None
    assert S.nominal_input_inverse({"mass": 15.0}) is None  # an incomplete robot: no share, no guess


def test_welch_finds_the_chattering_frequency():
    dt = 1e-3
    t = np.arange(0, 10, dt)
    s = {"u_right": 11 + np.sin(2 * np.pi * 37 * t), "u_left": 11 + 0.5 * np.sin(2 * np.pi * 37 * t)}
    f, p = S.welch_u(s, dt)
    assert f[np.argmax(p)] == pytest.approx(37.0, abs=0.5)
    assert p[0] < 1e-6 * p.max()   # the mean is removed


@pytest.mark.parametrize("n, nperseg", [(10000, 2000), (15001, 2000), (999, 999), (1000, 37), (64, 16), (20, 20)])
def test_welch_is_scipys(n, nperseg):
    """The report's Welch estimate (written out to spare importing scipy.signal) is scipy.signal.welch's with its
    defaults: odd and even segment lengths, a partial last segment, one segment."""
    from scipy.signal import welch

    rng = np.random.default_rng(n)
    x = 5.0 + 3.0 * rng.standard_normal(n) + np.sin(0.3 * np.arange(n))
    f, p = S.welch(x, 1000.0, nperseg)
    f_scipy, p_scipy = welch(x, fs=1000.0, nperseg=nperseg)
    assert f.shape == f_scipy.shape
    assert np.allclose(f, f_scipy, rtol=1e-14, atol=0.0)
    assert np.allclose(p, p_scipy, rtol=1e-12, atol=1e-12 * p_scipy.max())


def test_hf_cutoff_from_config_or_engine():
    assert S.hf_cutoff({"metrics.hf_cutoff": 25}) == pytest.approx(25.0)
    assert S.hf_cutoff({}) == pytest.approx(10.0)


def test_window_helpers():
    t = np.linspace(0, 10, 1001)
    y = np.where(t < 5, 1.0, 3.0)
    assert S.mean_in(t, y, 5.0) == pytest.approx(3.0)
    assert S.range_in(t, y, 0.0, 5.0, q=(0, 100)) == pytest.approx((1.0, 1.0))
    assert math.isnan(S.mean_in(t, y, 20.0))


def test_run_plot_axes_fit_the_steady_state_and_zoom_into_it():
    from ddmr_cli.plots.common import figure
    from ddmr_cli.plots.run import ZOOM_WIDTH, _fit, _zoom

    t = np.linspace(0, 15, 15001)
    y = np.where(t < 3.0, 50.0 * np.exp(-t), 0.0) + 0.01 * np.sin(7 * t)  # a start-up transient, then 10 um
    ax = figure().subplots()
    assert _fit(ax, t, [y], settle=3.0)  # the transient is off-scale
    lo, hi = ax.get_ylim()
    assert -0.02 < lo < -0.01 and 0.01 < hi < 0.02
    assert not _fit(ax, t, [y], settle=0.0)  # the whole run is the steady state: nothing off-scale
    t0, t1 = _zoom(t, 3.0)
    assert t1 - t0 == pytest.approx(ZOOM_WIDTH) and 3.0 < t0 < t1 < 15.0
    assert _zoom(t, 20.0)[0] >= 0.0  # no steady state: the zoom stays in the run


def test_figure_eight_covers_a_whole_eight_in_the_default_duration():
    import ddmr_cli
    from hydra.utils import instantiate

    cfg = ddmr_cli.compose_config(["trajectory=figure_eight"])
    traj = instantiate(cfg.trajectory)
    t = np.linspace(0.0, float(cfg.simulation.duration), 3001)
    xy = np.array([traj.reference(float(s))[:2] for s in t])
    a = float(cfg.trajectory.amplitude)
    assert xy[:, 0].min() < -0.99 * a and xy[:, 0].max() > 0.99 * a  # both lobes
    assert np.hypot(*xy[-1]) < 1e-6 * a  # back at the start: the eight is closed


def test_plot_processes_end_when_the_job_is_killed():
    """Killed (SIGKILL) while its drawing processes wait for a series, a job leaves none of them behind: each
    keeps only its own pipe's end, so the job's death closes every pipe they wait on."""
    import os
    import signal
    import subprocess
    import sys
    import time

    code = ("import time\nfrom ddmr_cli.plots.processes import PlotProcesses\nprocesses = PlotProcesses()\n"
            "print('started', flush=True)\ntime.sleep(60)\n")
    job = subprocess.Popen([sys.executable, "-c", code], stdout=subprocess.PIPE, text=True)
    assert job.stdout.readline().strip() == "started"

    def descendants(pid):
        kids = subprocess.run(["pgrep", "-P", str(pid)], capture_output=True, text=True).stdout.split()
        return [int(k) for k in kids] + [d for k in kids for d in descendants(int(k))]

    deadline = time.monotonic() + 20.0
    while len(drawing := descendants(job.pid)) < 3 and time.monotonic() < deadline:
        time.sleep(0.1)  # the drawing process imports matplotlib, then forks its copies
    assert len(drawing) == 3  # the drawing process and its two copies
    os.kill(job.pid, signal.SIGKILL)
    job.wait()

    def running(pid):
        try:
            with open(f"/proc/{pid}/stat") as fh:
                return fh.read().rsplit(")", 1)[1].split()[0] != "Z"
        except OSError:
            return False

    deadline = time.monotonic() + 10.0
    while any(map(running, drawing)) and time.monotonic() < deadline:
        time.sleep(0.1)
    left = [pid for pid in drawing if running(pid)]
    for pid in left:  # a failure leaves nothing behind either
        os.kill(pid, signal.SIGKILL)
    assert not left
