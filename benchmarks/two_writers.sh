#!/usr/bin/env bash
# One writer per tree (issues 12 and 26). Three races, each started at once:
#  1. two different sweeps into one dir: one holds the dir's lock and runs, the other is refused at once with one
#     line naming the holder (pid, host, command), exit 1, having written nothing;
#  2. a single run into a job dir of the running sweep: refused (inside the sweep's dir, in use by its pid), exit 1;
#  3. two reports of the finished sweep into one --out: one writes, the other is refused naming the holder, exit 1;
#     the --out then holds exactly the files of one report (its manifest's, with their digests).
# Usage: benchmarks/two_writers.sh [WORK_DIR]
set -u
work=${1:-$(mktemp -d)}
mkdir -p "$work" && cd "$work" || exit 1
dir=sweep
ddmr run -m +experiment=smoke controller=pid,smc scenario=paper_1 launcher=basic run.n_runs=100 hydra.sweep.dir=$dir >a.out 2>a.err &
a=$!
ddmr run -m +experiment=smoke controller=smc_ndo scenario=paper_1,paper_2 launcher=basic run.n_runs=100 hydra.sweep.dir=$dir >b.out 2>b.err &
b=$!
# 2. wait for the winner's first job dir, then a single run into it
for _ in $(seq 1 200); do
  job=$(find "$dir" -mindepth 1 -maxdepth 1 -type d ! -name '.*' 2>/dev/null | sort | head -n 1)
  [ -n "$job" ] && break
  sleep 0.05
done
ddmr run controller=pid run.n_runs=1 simulation.duration=0.2 "hydra.run.dir='$job'" >c.out 2>c.err
cc=$?
wait $a; ca=$?
wait $b; cb=$?
echo "A (pid $a, controller=pid,smc x paper_1, 100 seeds): exit $ca"
grep -h "ddmr: error\|ddmr sweep:" a.err a.out
echo "B (pid $b, controller=smc_ndo x paper_1,paper_2, 100 seeds): exit $cb"
grep -h "ddmr: error\|ddmr sweep:" b.err b.out
echo "job dirs in $dir:"
find "$dir" -mindepth 1 -maxdepth 1 -type d -printf '  %f\n' | sort
echo "plan: $(python3 -c "import json; print([j['dir'] for j in json.load(open('$dir/sweep_plan.json'))['jobs']])")"
echo "C (a single run into the running sweep's job dir ${job#$dir/}): exit $cc"
cat c.err
# 3. two reports at once into one --out
ddmr report $dir --out rep >d.out 2>d.err &
d=$!
ddmr report $dir --out rep >e.out 2>e.err &
e=$!
wait $d; cd_=$?
wait $e; ce=$?
echo "D (report, pid $d): exit $cd_"; grep -h "ddmr: error\|report written" d.err d.out
echo "E (report, pid $e): exit $ce"; grep -h "ddmr: error\|report written" e.err e.out
python3 - <<'PY'
import hashlib, json, pathlib
out = pathlib.Path("rep")
listed = json.loads((out / ".ddmr-report.json").read_text())["digests"]
files = sorted(p.relative_to(out).as_posix() for p in out.rglob("*") if p.is_file() and not p.name.startswith(".ddmr-report"))
same = all(hashlib.sha256((out / f).read_bytes()).hexdigest() == d["sha256"] for f, d in listed.items())
print(f"rep: {len(files)} files, {len(listed)} in the manifest, all listed: {sorted(listed) == files}, digests match: {same}")
PY
