#!/usr/bin/env bash
# Camera-path throughput (BENCHMARKS.md, "Rendering camera paths"). Release build;
# ../shared/data beside the repo. Usage: tools/bench_sequence.sh [encode|inflight|all]
#   encode:   an orbit of PLAYBOT LOD2 at 1280x720 to PNG, 16-bit PNG and EXR, encoding on
#             the rendering thread (--encode-threads 0) and on worker threads, three runs
#             each.
#   inflight: the same orbit to PNG and EXR with --frames-in-flight 1 and 2, runs
#             alternating between the two (RUNS each, default 5), so that load from
#             other processes falls on both alike; then `verisplat bench` on the orbit's
#             orbit for the GPU frame time.
# Each run prints its summary line.
set -euo pipefail
cd "$(dirname "$0")/.."
cargo build --release -q
B=target/release/verisplat
S=../shared/data/playbot_lod2_125k_sh2.ply
OUT=$(mktemp -d)
trap 'rm -rf "$OUT"' EXIT
FRAMES=${FRAMES:-24}
RUNS=${RUNS:-5}
WHAT=${1:-all}

if [ "$WHAT" = encode ] || [ "$WHAT" = all ]; then
  for fmt in png png16 exr; do
    ext=$fmt; extra=()
    if [ "$fmt" = png16 ]; then ext=png; extra=(--png16); fi
    for threads in 0 1 2; do
      for run in 1 2 3; do
        echo "## $fmt, --encode-threads $threads, run $run"
        $B render "$S" --orbit "$FRAMES" -o "$OUT/{:03}.$ext" "${extra[@]}" \
          --encode-threads "$threads" --overwrite -q 2>&1 | tail -1
      done
    done
  done
fi

if [ "$WHAT" = inflight ] || [ "$WHAT" = all ]; then
  for ext in png exr; do
    for run in $(seq "$RUNS"); do
      for depth in 1 2; do
        echo "## $ext, --frames-in-flight $depth, run $run"
        $B render "$S" --orbit "$FRAMES" -o "$OUT/{:03}.$ext" \
          --frames-in-flight "$depth" --overwrite -q 2>&1 | tail -1
      done
    done
  done
  # The GPU frame time of the same scene and orbit.
  echo "## verisplat bench"
  $B bench "$S" --orbit "$FRAMES" --frames 5 --warmup 1 2>&1 | tail -25
fi
