"""The physics plant's validation figure and speed (issue 30; docs/model.md, "Physics plant (MuJoCo)").

    python benchmarks/physics_plant.py step             # flat-ground step response vs the nominal model: numbers
                                                       # and docs/figures/physics_step_response.png
    python benchmarks/physics_plant.py speed [--runs 8] [--seconds 2] [--threads 0]
                                                       # plant steps per second over the paper terrain's zones
    python benchmarks/physics_plant.py path [--seed 0] # one run's path over the terrain zones: the true d per zone
                                                       # and docs/figures/physics_path.png
    python benchmarks/physics_plant.py batch [--runs 50] [--scenario 1] [--threads 0]
                                                       # the same loop over many seeds: wall, divergences

Needs the physics extra (pip install -e ".[physics]").
"""

from __future__ import annotations

import argparse
import sys
import time
from pathlib import Path

import numpy as np

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT / "tests"))

from physics_cases import (STEP_VOLTAGE, load, nominal_step_response, physics_step_response,  # noqa: E402
                           plant_config, robot, terrain)
from ddmr_cli.plant.mujoco import MujocoPlant  # noqa: E402


def step(out: Path) -> None:
    import matplotlib
    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    plant = MujocoPlant(robot(), terrain("none"), plant_config(threads=1), 0.001)
    t, w, d = physics_step_response(plant, STEP_VOLTAGE, 1.0)
    nominal = nominal_step_response(plant.robot, STEP_VOLTAGE, t)
    error = np.abs(w - nominal).max(axis=0) / np.abs(nominal).max(axis=0)
    print(f"voltage step {STEP_VOLTAGE} V from rest, flat ground, no roughness or rolling resistance, dt = 1 ms")
    for k in (10, 50, 100, 200, 500, 1000):
        print(f"  t = {t[k]:.2f} s  MuJoCo {w[k].round(3)}  nominal {nominal[k].round(3)} rad/s")
    print(f"  largest deviation / peak: right {error[0]:.2%}, left {error[1]:.2%} (limit 5 %)")
    fig, (ax, ax2) = plt.subplots(2, 1, figsize=(7, 5.5), sharex=True, height_ratios=(3, 1.3))
    for i, (side, colour) in enumerate((("right", "C0"), ("left", "C1"))):
        ax.plot(t, nominal[:, i], color=colour, lw=3, alpha=0.35, label=f"{side}: nominal 2x2 model")
        ax.plot(t, w[:, i], color=colour, lw=1, label=f"{side}: MuJoCo plant")
        ax2.plot(t, w[:, i] - nominal[:, i], color=colour, lw=1)
    ax.set_ylabel("wheel speed [rad/s]")
    ax.set_title(f"Step {STEP_VOLTAGE[0]:g} V / {STEP_VOLTAGE[1]:g} V from rest on flat ground: "
                 f"max deviation {error.max():.2%} of peak")
    ax.legend(loc="lower right", fontsize=8)
    ax2.set_ylabel("MuJoCo - nominal\n[rad/s]")
    ax2.set_xlabel("t [s]")
    fig.tight_layout()
    out.parent.mkdir(parents=True, exist_ok=True)
    fig.savefig(out, dpi=110)
    print(f"figure: {out}")


def speed(runs: int, seconds: float, threads: int) -> None:
    from ddmr_cli.bench.physics import plant_throughput

    r = plant_throughput(runs, seconds, threads)
    print(f"{r.runs} runs x {r.steps} steps (dt 1 ms), {r.threads} thread(s): reset {r.reset:.2f} s, "
          f"{r.rate:,.0f} run-steps/s ({r.mujoco / r.wall:.0%} of the time in the MuJoCo steps, "
          f"{r.plant / r.wall:.0%} in the rest of plant.step), diverged {r.diverged}")
    print(f"  table4_physics (400 runs x 15 s) at this rate: {400 * 15000 / r.rate / 60:.1f} min")


def line_runs(plant, seeds) -> dict[str, np.ndarray]:
    """Runs of the paper's line (initial pose and 1 m/s reference of conf/config.yaml, conf/trajectory/line.yaml),
    15 s, under the Kanayama outer loop (docs/model.md §3) and a proportional wheel-speed loop with the nominal
    feed-forward (not a controller of the paper: the physics, not a law, is on show). Returns ``x``, ``y``,
    ``distance`` and the right wheel's true ``d``, each ``(steps, n)``, and the ``wall`` seconds of the loop."""
    from ddmr_cli.compiled import plain
    from ddmr_cli.control.outer_loop import Kanayama, kanayama
    from ddmr_cli.model.kinematics import inverse, pose_error

    rob, n = plant.robot, len(seeds)
    gains, line = Kanayama(10.0, 25.0, 10.0), load("trajectory", "line")
    v_r, steps, kp = float(line["speed"]), 15000, 2.0  # m/s; 15 s; V s/rad
    start = plain(inverse)(v_r, 0.0, rob.wheel_radius, rob.half_track)
    plant.reset(np.asarray(seeds), np.tile([0.0, 0.05, 0.05], (n, 1)), np.tile(start, (n, 1)))
    out = {k: np.zeros((steps, n)) for k in ("x", "y", "distance", "d")}
    w_d = np.zeros((n, 2))
    t0 = time.perf_counter()
    for k in range(steps):
        s = plant.state()
        x_r = line["x0"] + v_r * k * plant.dt
        for i in range(n):
            e = plain(pose_error)(s["x"][i], s["y"][i], s["theta"][i], x_r, line["y0"], 0.0)
            w_d[i] = plain(inverse)(*plain(kanayama)(gains, *e, v_r, 0.0), rob.wheel_radius, rob.half_track)
        u = np.clip(rob.damping / rob.voltage_gain * w_d + kp * (w_d - s["w"]), -24.0, 24.0)
        plant.step(u, np.ones(n))
        s = plant.state()
        out["x"][k], out["y"][k], out["distance"][k] = s["x"], s["y"], s["distance"]
        out["d"][k] = plant.true_disturbance()[:, 0]
    out["wall"] = time.perf_counter() - t0
    return out


def batch(runs: int, scenario: int, threads: int) -> None:
    """``runs`` seeds of :func:`line_runs` on the paper terrain in paper scenario ``scenario``: wall time, the
    share in MuJoCo, divergences, the deviation (the plant's side of a table4_physics job)."""
    from ddmr_cli.config.presets import paper_scenario

    plant = MujocoPlant(robot(), terrain("paper"), plant_config(threads=threads), 0.001, paper_scenario(scenario))
    r = line_runs(plant, np.arange(runs))
    steps = r["x"].shape[0]
    dev = np.abs(r["y"])  # the line is y = 0: the lateral error is the deviation's cross-track part
    timing = plant.timing()
    print(f"scenario {scenario}: {runs} runs x {steps} steps in {r['wall']:.1f} s ({runs * steps / r['wall']:,.0f} "
          f"steps/s, {plant.threads} thread(s), {timing['mujoco'] / r['wall']:.0%} in MuJoCo); diverged "
          f"{int(plant.diverged().sum())}; |y| after 3 s: mean {1e3 * np.nanmean(dev[3000:]):.2f} mm, "
          f"max {1e3 * np.nanmax(dev[3000:]):.1f} mm")


def path(seed: int, out: Path) -> None:
    """One run of :func:`line_runs` over the paper terrain: the true d per zone and the figure (heightfield, path,
    lateral error, true d)."""
    import matplotlib
    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    rob, ter = robot(), terrain("paper")
    plant = MujocoPlant(rob, ter, plant_config(threads=1), 0.001)
    line = load("trajectory", "line")
    pose0 = np.array([[0.0, 0.05, 0.05]])
    r = line_runs(plant, [seed])
    x, y, d, dist, wall = r["x"][:, 0], r["y"][:, 0], r["d"][:, 0], r["distance"][:, 0], r["wall"]
    steps = len(x)
    print(f"seed {seed}: 15 s in {wall:.1f} s ({steps / wall:,.0f} steps/s), diverged {bool(plant.diverged()[0])}, "
          f"end x = {x[-1]:.3f} m, max |y - y_r| = {np.abs(y - line['y0'])[3000:].max() * 1e3:.2f} mm after 3 s")
    starts = [z.start for z in ter.zones] + [np.inf]
    rms = {}
    for zone, lo, hi in zip(ter.zones, starts, starts[1:]):
        inside = (dist >= lo + 0.5) & (dist < hi)  # half a metre past the zone's ramp and the previous zone
        rms[zone.name] = d[inside].std()
        print(f"  {zone.name:15s} roughness {zone.roughness:6g}: RMS of the true d about its mean "
              f"{d[inside].std():7.2f} rad/s^2, mean {d[inside].mean():7.2f} rad/s^2 (right wheel)")

    h = plant.heights(seed)
    fx, fy = plant.field_axes()
    band = np.abs(fy) <= 0.35
    fig, axes = plt.subplots(3, 1, figsize=(10, 7.5), sharex=True, height_ratios=(2.2, 1, 1.3))
    ax = axes[0]
    im = ax.imshow(h[band] * 1e3, origin="lower", aspect="auto", cmap="terrain",
                   extent=(fx[0], fx[-1], fy[band][0], fy[band][-1]))
    fig.colorbar(im, cax=ax.inset_axes([1.01, 0.0, 0.015, 1.0]), label="ground height [mm]")
    ax.plot(x, y, color="k", lw=1.2, label="robot (axle midpoint)")
    for i in (0, 1):  # the wheels' tracks
        sign = -1 if i == 0 else 1
        ax.plot(x, y + sign * rob.half_track, color="k", lw=0.5, ls=":")
    ax.set_ylabel("y [m]")
    fig.suptitle(f"One run (seed {seed}) on the MuJoCo plant over the paper's zones: heightfield, path, true d")
    ax.legend(loc="upper right", fontsize=8)
    axes[1].plot(x, (y - line["y0"]) * 1e3, color="k", lw=0.8)
    axes[1].set_ylabel("y - y_r [mm]")
    axes[2].plot(x, d, color="C3", lw=0.4)
    axes[2].set_ylabel("true d, right\n[rad/s^2]")
    axes[2].set_xlabel("x [m]")
    for a in axes:
        for zone, lo, hi in zip(ter.zones, starts, starts[1:]):
            lo, hi = lo + pose0[0, 0], min(hi, fx[-1])
            a.axvline(lo, color="0.3", lw=0.8, ls="--")
            if a is axes[0]:
                a.text((lo + hi) / 2, 1.02, f"{zone.name}: roughness {zone.roughness:g}, mu {zone.mu:g}\n"
                       f"RMS of the true d {rms[zone.name]:.0f} rad/s^2", transform=a.get_xaxis_transform(),
                       ha="center", va="bottom", fontsize=8)
    axes[0].set_xlim(-0.5, fx[-1])
    fig.tight_layout()
    out.parent.mkdir(parents=True, exist_ok=True)
    fig.savefig(out, dpi=110)
    print(f"figure: {out}")


def main(argv=None) -> int:
    parser = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    sub = parser.add_subparsers(dest="what", required=True)
    s = sub.add_parser("step")
    s.add_argument("--out", type=Path, default=ROOT / "docs" / "figures" / "physics_step_response.png")
    p = sub.add_parser("speed")
    p.add_argument("--runs", type=int, default=8)
    p.add_argument("--seconds", type=float, default=2.0)
    p.add_argument("--threads", type=int, default=0)
    b = sub.add_parser("batch")
    b.add_argument("--runs", type=int, default=50)
    b.add_argument("--scenario", type=int, default=1, choices=(1, 2))
    b.add_argument("--threads", type=int, default=0)
    q = sub.add_parser("path")
    q.add_argument("--seed", type=int, default=0)
    q.add_argument("--out", type=Path, default=ROOT / "docs" / "figures" / "physics_path.png")
    args = parser.parse_args(argv)
    if args.what == "step":
        step(args.out)
    elif args.what == "path":
        path(args.seed, args.out)
    elif args.what == "batch":
        batch(args.runs, args.scenario, args.threads)
    else:
        speed(args.runs, args.seconds, args.threads)
    return 0


if __name__ == "__main__":
    sys.exit(main())
