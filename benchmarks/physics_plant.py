"""The physics plant's validation figure and speed (issue 30; docs/model.md, "Physics plant (MuJoCo)").

    python benchmarks/physics_plant.py step             # flat-ground step response vs the nominal model: numbers
                                                       # and docs/figures/physics_step_response.png
    python benchmarks/physics_plant.py speed [--runs 8] [--seconds 2] [--threads 0]
                                                       # plant steps per second over the paper terrain's zones

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

from physics_cases import (STEP_VOLTAGE, nominal_step_response, physics_step_response, plant_config, robot,  # noqa: E402
                           terrain)
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
    plant = MujocoPlant(robot(), terrain("paper"), plant_config(threads=threads), 0.001)
    t0 = time.perf_counter()
    # start each run in another zone, so the batch steps over flat, very rough and slightly rough ground
    x0 = np.array([1.0, 6.0, 11.0])[np.arange(runs) % 3]
    plant.reset(np.arange(runs), np.column_stack([x0, np.zeros(runs), np.zeros(runs)]), np.full((runs, 2), 33.3))
    reset = time.perf_counter() - t0
    rob = plant.robot
    w_d = np.full((runs, 2), 1.0 / rob.wheel_radius)
    steps = int(round(seconds / plant.dt))
    in_step = 0.0
    t0 = time.perf_counter()
    for _ in range(steps):
        u = np.clip(rob.damping / rob.voltage_gain * w_d + 2.0 * (w_d - plant.state()["w"]), -24, 24)
        t1 = time.perf_counter()
        plant.step(u, np.ones(runs))
        in_step += time.perf_counter() - t1
    total = time.perf_counter() - t0
    rate = runs * steps / total
    print(f"{runs} runs x {steps} steps (dt 1 ms), {plant._threads} thread(s): reset {reset:.2f} s, "
          f"{rate:,.0f} run-steps/s ({in_step / total:.0%} of the time in plant.step), "
          f"diverged {int(plant.diverged().sum())}")
    print(f"  table4_physics (400 runs x 15 s) at this rate: {400 * 15000 / rate / 60:.1f} min")


def main(argv=None) -> int:
    parser = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    sub = parser.add_subparsers(dest="what", required=True)
    s = sub.add_parser("step")
    s.add_argument("--out", type=Path, default=ROOT / "docs" / "figures" / "physics_step_response.png")
    p = sub.add_parser("speed")
    p.add_argument("--runs", type=int, default=8)
    p.add_argument("--seconds", type=float, default=2.0)
    p.add_argument("--threads", type=int, default=0)
    args = parser.parse_args(argv)
    if args.what == "step":
        step(args.out)
    else:
        speed(args.runs, args.seconds, args.threads)
    return 0


if __name__ == "__main__":
    sys.exit(main())
