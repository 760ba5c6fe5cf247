#!/usr/bin/env bash
# Two different sweeps started at once into one dir (issue 12): one holds the dir's lock and runs, the other is
# refused at once with one line naming the holder (pid, host, command), exit 1, having written nothing.
# Usage: benchmarks/two_writers.sh [WORK_DIR]
set -u
work=${1:-$(mktemp -d)}
mkdir -p "$work" && cd "$work" || exit 1
dir=sweep
ddmr run -m +experiment=smoke controller=pid,smc scenario=paper_1 launcher=basic hydra.sweep.dir=$dir >a.out 2>a.err &
a=$!
ddmr run -m +experiment=smoke controller=smc_ndo scenario=paper_1,paper_2 launcher=basic hydra.sweep.dir=$dir >b.out 2>b.err &
b=$!
wait $a; ca=$?
wait $b; cb=$?
echo "A (pid $a, controller=pid,smc x paper_1): exit $ca"
grep -h "ddmr: error\|ddmr sweep:" a.err a.out
echo "B (pid $b, controller=smc_ndo x paper_1,paper_2): exit $cb"
grep -h "ddmr: error\|ddmr sweep:" b.err b.out
echo "job dirs in $dir:"
find "$dir" -mindepth 1 -maxdepth 1 -type d -printf '  %f\n' | sort
echo "plan: $(python3 -c "import json; print([j['dir'] for j in json.load(open('$dir/sweep_plan.json'))['jobs']])")"
