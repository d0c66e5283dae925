#!/usr/bin/env bash
# The Slurm test (docs/cluster.md): starts a single-node Slurm cluster
# (munged, slurmctld, slurmd; as root, no systemd, everything under a temporary folder),
# then
#   0. runs the sbatch lines of docs/cluster.md's example as written there (read from
#      the page, so the two cannot drift apart; in a folder holding examples/ and the
#      inputs they name, verisplat on PATH, nothing added to their options), waits for the
#      jobs, runs the example's verisplat line, and checks what they wrote: the frames
#      byte-identical to one process's, the merged evaluation equal to one process's, a
#      folder of models evaluated one per task, a bench sweep in two shards;
# and through the sbatch scripts of examples/slurm/, submitted without resource options:
#   1. renders a camera path of a shared scene as a 4-task array and checks that the
#      frames are byte-identical to one process's, and that --verify passes;
#   2. evaluates a model as a 4-task array, merges the shard reports and checks that the
#      merged report equals one process's, byte for byte;
#   3. kills one task of a render array mid-run (SIGKILL), checks that every file left is
#      complete and --verify lists the missing frames and fails, re-submits the same array
#      (--skip-existing) and checks that it completes, identical to one process;
#   4. checks that --shard slurm in a job that is not an array fails with one sentence.
# The node has no GPU generic resources (as a plain cluster): a script that asked for
# --gres=gpu would be refused. It claims 8 CPUs (config_overrides) so the scripts'
# --cpus-per-task fits as on a real node.
# Every daemon it started is stopped by its pid on exit, also on failure.
#
# Needs root and Debian's slurm-wlm and munge (tools/setup.sh installs them). Without
# them it skips with a message, except in CI (CI=true), where that is a failure.
# VERISPLAT_BIN names the binary [default: target/debug/verisplat, built by cargo test].
set -euo pipefail
cd "$(dirname "$0")/.."
repo=$PWD
t0=$SECONDS

skip() {
  if [ "${CI:-}" = true ]; then
    echo "slurm_test: FAILED: $1 (CI=true: the Slurm test must run)" >&2
    exit 1
  fi
  echo "slurm_test: ******** SKIPPED: $1 ********" >&2
  exit 0
}
[ "$(id -u)" -eq 0 ] || skip "not root (the test starts slurmctld and slurmd as root)"
for tool in munged mungekey slurmctld slurmd sbatch squeue scancel scontrol; do
  command -v "$tool" >/dev/null || skip "$tool missing (tools/setup.sh installs slurm-wlm and munge)"
done

bin=${VERISPLAT_BIN:-$repo/target/debug/verisplat}
[ -x "$bin" ] || { echo "slurm_test: $bin missing; build it first (cargo build)" >&2; exit 1; }
data=$repo/../shared/data
scene=$data/playbot_lod6_1873_sh2.ply
cameras=$data/playbot_orbit_cameras.synthetic.json

work=$(mktemp -d /tmp/verisplat-slurm.XXXXXX)
chmod 755 "$work"
pids=()  # daemons, in start order
jobs=()  # submitted job ids

cleanup() {
  local rc=$?
  set +e
  if [ ${#jobs[@]} -gt 0 ]; then
    scancel "${jobs[@]}" 2>/dev/null
    for _ in $(seq 50); do
      [ -z "$(squeue -h -j "$(IFS=,; echo "${jobs[*]}")" 2>/dev/null)" ] && break
      sleep 0.1
    done
  fi
  # Stop the daemons by pid, the last started first (slurmd, slurmctld, munged).
  local i pid
  for ((i = ${#pids[@]} - 1; i >= 0; i--)); do
    pid=${pids[$i]}
    kill "$pid" 2>/dev/null
    for _ in $(seq 100); do
      kill -0 "$pid" 2>/dev/null || break
      sleep 0.05
    done
    kill -9 "$pid" 2>/dev/null
    wait "$pid" 2>/dev/null
  done
  if [ $rc -ne 0 ]; then
    echo "slurm_test: FAILED (exit $rc); daemon logs:" >&2
    tail -n 30 "$work"/*.log "$work"/logs/* >&2 2>/dev/null
  fi
  [ -n "${VERISPLAT_SLURM_KEEP:-}" ] || rm -rf "$work"
  echo "slurm_test: took $((SECONDS - t0)) s" >&2
  exit $rc
}
trap cleanup EXIT

fail() {
  echo "slurm_test: FAILED: $*" >&2
  exit 1
}

# How many of the paths given exist (globs that match nothing stay as they are).
count() {
  local n=0 f
  for f in "$@"; do
    [ -e "$f" ] && n=$((n + 1))
  done
  echo "$n"
}

# --- the cluster -----------------------------------------------------------------------
mkdir -p "$work/munge-key" "$work/munge-run" "$work/state" "$work/spool" "$work/logs"
chmod 700 "$work/munge-key"
chmod 755 "$work/munge-run" # munged refuses a socket folder of mode 700
mungekey --create --keyfile="$work/munge-key/munge.key" --force
chmod 600 "$work/munge-key/munge.key"
socket=$work/munge-run/munge.socket
munged --foreground --force --key-file="$work/munge-key/munge.key" --socket="$socket" \
  --pid-file="$work/munge-run/munged.pid" --log-file="$work/munged.log" \
  --seed-file="$work/munge-key/munged.seed" 2>>"$work/munged.log" &
pids+=($!)

port=$((20000 + RANDOM % 20000))
host=$(hostname -s)
cat >"$work/slurm.conf" <<EOF
ClusterName=verisplat-test
SlurmctldHost=$host(127.0.0.1)
SlurmUser=root
SlurmdUser=root
SlurmctldPort=$port
SlurmdPort=$((port + 1))
AuthType=auth/munge
AuthInfo=socket=$socket
CredType=cred/munge
StateSaveLocation=$work/state
SlurmdSpoolDir=$work/spool
SlurmctldPidFile=$work/slurmctld.pid
SlurmdPidFile=$work/slurmd.pid
SlurmctldLogFile=$work/slurmctld.log
SlurmdLogFile=$work/slurmd.log
ProctrackType=proctrack/linuxproc
TaskPlugin=task/none
JobAcctGatherType=jobacct_gather/none
AccountingStorageType=accounting_storage/none
MailProg=/bin/true
SelectType=select/cons_tres
SelectTypeParameters=CR_CPU
SlurmdParameters=config_overrides
ReturnToService=2
KillWait=2
MinJobAge=300
NodeName=localhost NodeHostname=$host NodeAddr=127.0.0.1 CPUs=8 RealMemory=500 State=UNKNOWN
PartitionName=test Nodes=localhost Default=YES MaxTime=INFINITE State=UP
EOF
export SLURM_CONF=$work/slurm.conf
for _ in $(seq 100); do [ -S "$socket" ] && break; sleep 0.05; done
[ -S "$socket" ] || fail "munged did not start"
slurmctld -D -i -f "$SLURM_CONF" >"$work/logs/slurmctld.out" 2>&1 &
pids+=($!)
slurmd -D -N localhost -f "$SLURM_CONF" >"$work/logs/slurmd.out" 2>&1 &
pids+=($!)
state=""
for _ in $(seq 300); do
  state=$(sinfo -h -N -o %T 2>/dev/null || true)
  [ "$state" = idle ] && break
  sleep 0.1
done
[ "$state" = idle ] || fail "the node did not become idle (state: ${state:-none})"
echo "slurm_test: cluster up in $((SECONDS - t0)) s" >&2

# Waits until job $1 has left the queue.
wait_job() {
  for _ in $(seq 1200); do
    [ -z "$(squeue -h -j "$1" 2>/dev/null)" ] && return 0
    sleep 0.1
  done
  fail "job $1 did not finish in 120 s"
}

# Submits an sbatch script with the environment given, with no resource options beyond
# the script's own (only where it runs and logs); prints the job id.
submit() {
  local id
  id=$(sbatch --parsable --chdir="$work" --output="$work/logs/%x-%A_%a.out" "$@")
  echo "${id%%;*}"
}

# Waits until the queue is empty (this cluster runs only this test's jobs); fails on a
# dependency that can never be met.
wait_all() {
  for _ in $(seq 3000); do
    [ -z "$(squeue -h 2>/dev/null)" ] && return 0
    if squeue -h -o %r 2>/dev/null | grep -q DependencyNeverSatisfied; then
      fail "a job's dependency failed: $(squeue 2>&1)"
    fi
    sleep 0.1
  done
  fail "the jobs did not finish in 300 s: $(squeue 2>&1)"
}

export VERISPLAT_VALIDATE=1
source "$repo/tools/slurm_docs_test.sh"
export VERISPLAT=$bin
# The examples' scripts are submitted as users submit them; the lines a user edits come
# from the environment.
render_script=$repo/examples/slurm/render_path.sbatch
eval_script=$repo/examples/slurm/eval_sharded.sbatch

# --- 1. a camera path in 4 shards ------------------------------------------------------
"$bin" render "$scene" --cameras "$cameras" --width 160 -o "$work/one/f_%03d.png" -q
id=$(SCENE=$scene CAMERAS=$cameras OUT=$work/arr/f_%03d.png RENDER_ARGS="--width 160" \
  submit --array=0-3 "$render_script")
jobs+=("$id")
wait_job "$id"
n_one=$(count "$work"/one/*.png)
n_arr=$(count "$work"/arr/*.png)
[ "$n_one" = 24 ] && [ "$n_arr" = 24 ] || fail "frames: one process $n_one, the array $n_arr (want 24)"
for f in "$work"/one/*; do
  cmp -s "$f" "$work/arr/$(basename "$f")" || fail "$(basename "$f") differs from one process's"
done
for k in 0 1 2 3; do
  grep -q "shard $k/4: 6 frames of the 24 selected" "$work/logs/verisplat-render-${id}_$k.out" \
    || fail "task $k did not render shard $k/4: $(cat "$work/logs/verisplat-render-${id}_$k.out")"
done
"$bin" render "$scene" --cameras "$cameras" --width 160 -o "$work/arr/f_%03d.png" --verify -q
echo "slurm_test: 1. 4-shard render array: 24 frames byte-identical to one process" >&2

# --- 2. an eval array, merged ----------------------------------------------------------
# Photos: the finer LOD3 scene's renders, so the metrics are real numbers.
"$bin" render "$data/playbot_lod3_31k_sh2.ply" --cameras "$cameras" --width 160 \
  -o "$work/photos/{name}.png" -q
eval_args="--cameras $cameras --split all"
"$bin" eval "$scene" --images "$work/photos" -o "$work/eval_one" $eval_args -q >/dev/null
id=$(MODEL=$scene IMAGES=$work/photos OUT=$work/eval_arr EVAL_ARGS=$eval_args \
  submit --array=0-3 "$eval_script")
jobs+=("$id")
wait_job "$id"
"$bin" eval --merge "$work/eval_arr" >/dev/null
for f in report.json report.csv; do
  cmp "$work/eval_one/$f" "$work/eval_arr/$f" || fail "merged $f differs from one process's"
done
echo "slurm_test: 2. 4-shard eval array: merged report identical to one process's" >&2

# --- 3. tasks killed mid-run, the array re-submitted ------------------------------------
# A heavier path (64 frames of 640x360 of the 31k scene, 16 per task) so a task is caught
# mid-run. Task 1 is killed outright (SIGKILL, as a node failure or the OOM killer); task 2
# is cancelled as preemption does (SIGTERM, SIGKILL KillWait seconds later).
kill_args="--width 640"
kill_scene=$data/playbot_lod3_31k_sh2.ply
out=$work/kill/f_%03d.png
orbit=$work/orbit.json
"$bin" render "$kill_scene" --orbit 64 --width 640 --export-cameras "$orbit" -o "$work/probe.png" \
  --frames 0 -q
id=$(SCENE=$kill_scene CAMERAS=$orbit OUT=$out RENDER_ARGS="$kill_args" \
  submit --array=0-3 "$render_script")
jobs+=("$id")
# Task 1 renders frames 16..=31, task 2 frames 32..=47: each is stopped once it has
# written its first frame.
stop_after_first_frame() { # task, its first frame's glob, scancel options
  local task=$1 glob=$2
  shift 2
  for _ in $(seq 600); do
    if [ "$(count $glob)" -gt 0 ]; then
      scancel "$@" "${id}_$task"
      return 0
    fi
    sleep 0.05
  done
  fail "task $task wrote no frame to stop it after"
}
stop_after_first_frame 1 "$work/kill/f_01[6-9].png" --full --signal=KILL
stop_after_first_frame 2 "$work/kill/f_0[34][0-9].png"
wait_job "$id"
have1=$(count "$work"/kill/f_0{1[6-9],2[0-9],3[01]}.png)
have2=$(count "$work"/kill/f_0{3[2-9],4[0-7]}.png)
[ "$have1" -lt 16 ] || fail "task 1 finished all 16 frames before it was killed; nothing tested"
[ "$have2" -lt 16 ] || fail "task 2 finished all 16 frames before it was cancelled; nothing tested"
grep -q "interrupted after $have2 of 16 frames; every file written is complete" \
  "$work/logs/verisplat-render-${id}_2.out" \
  || fail "task 2 did not stop cleanly on SIGTERM: $(cat "$work/logs/verisplat-render-${id}_2.out")"
tmp_left=$(count "$work"/kill/.*.tmp)
# Every file is complete or absent: --verify lists only missing frames, and fails.
if "$bin" render "$kill_scene" --cameras "$orbit" $kill_args -o "$out" --verify \
  >"$work/verify.txt" 2>"$work/verify.err"; then
  fail "--verify passed with tasks 1 and 2 stopped"
fi
grep -v ': missing$' "$work/verify.txt" && fail "a stopped task left an unreadable file"
missing=$(wc -l <"$work/verify.txt")
[ "$missing" -eq $((64 - $(count "$work"/kill/*.png))) ] || fail "--verify listed $missing frames"
id=$(SCENE=$kill_scene CAMERAS=$orbit OUT=$out RENDER_ARGS="$kill_args" \
  submit --array=0-3 "$render_script")
jobs+=("$id")
wait_job "$id"
"$bin" render "$kill_scene" --cameras "$orbit" $kill_args -o "$out" --verify -q
[ "$(count "$work"/kill/.*.tmp)" -eq 0 ] || fail "temporary files left: $(ls -A "$work/kill")"
"$bin" render "$kill_scene" --cameras "$orbit" $kill_args --frames 16..48 \
  -o "$work/kill_one/f_%03d.png" -q
for f in "$work"/kill_one/*; do
  cmp -s "$f" "$work/kill/$(basename "$f")" || fail "$(basename "$f") differs after the re-run"
done
echo "slurm_test: 3. task 1 killed after $have1 of 16 frames, task 2 cancelled after $have2" \
  "($missing frames missing, $tmp_left temporary file(s) left); the re-submitted array completed" >&2

# --- 4. --shard slurm outside an array --------------------------------------------------
id=$(submit --output="$work/logs/not-array.out" \
  --wrap="'$bin' render '$scene' -o '$work/x.png' --shard slurm")
jobs+=("$id")
wait_job "$id"
grep -q '^error: --shard slurm: SLURM_ARRAY_TASK_ID .* not set' "$work/logs/not-array.out" \
  || fail "--shard slurm outside an array: $(cat "$work/logs/not-array.out")"
[ ! -e "$work/x.png" ] || fail "--shard slurm outside an array wrote a file"
echo "slurm_test: 4. --shard slurm outside an array refused" >&2

echo "slurm_test: passed" >&2
