#!/usr/bin/env bash
# Bad inputs on the command line: each prints one line and exits 2, leaving no output directory.
# Usage: benchmarks/bad_inputs.sh  (prints a markdown table)
set -u
work=$(mktemp -d)
errfile=$(mktemp)
cd "$work" || exit 1
echo "| command | exit | stderr | dirs left |"
echo "|---|---|---|---|"
while IFS= read -r args; do
  [ -z "$args" ] && continue
  # shellcheck disable=SC2086
  ddmr run $args >/dev/null 2>"$errfile"
  code=$?
  err=$(tail -n 5 "$errfile")
  left=$(find . -mindepth 1 | wc -l)
  echo "| \`ddmr run $args\` | $code | \`$(echo "$err" | tr '\n' ' ' | sed 's/|/\\|/g')\` | $left |"
done <<'ARGS'
robot.mass=-1
robot.wheel_radius=0
robot.max_voltage=0
robot.mass=abc
robot.masss=3
controller=foo
scenario=paper_9
terrain=mud
+experiment=nope
simulation.dt=0
simulation.dt=0.05
controller=pid simulation.dt=0.005
simulation.duration=-3
simulation.integrator=rk5
simulation.integrator=midpoint
simulation.initial_pose=[0,0]
controller.lam=nan
controller.switching=bang
controller.nn.n_neurons=0
controller.nn.width=0
controller.ndo.gain=[1,2,3]
controller._target_=os.system
terrain.zones.very_rough.start=12
terrain.zones.flat.roughness=-5
scenario.uncertainty.low=-2
run.n_runs=0
run.n_runs=2.5
run.base_seed=-1
run.keep_series=[-1]
controller=pid,smc
-m controller.switching_gain=4,-1
trajectory=circle trajectory.radius=0
ARGS
rm -rf "$work" "$errfile"
