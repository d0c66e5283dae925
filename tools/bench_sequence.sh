#!/usr/bin/env bash
# Camera-path throughput with and without overlapped encoding (BENCHMARKS.md, "Rendering
# camera paths"). Renders an orbit of PLAYBOT LOD2 at 1280x720 to PNG, 16-bit PNG and EXR,
# encoding on the rendering thread (--encode-threads 0) and on worker threads, three runs
# each, and prints the summary lines. Release build; ../shared/data beside the repo.
set -euo pipefail
cd "$(dirname "$0")/.."
cargo build --release -q
B=target/release/vksplat
S=../shared/data/playbot_lod2_125k_sh2.ply
OUT=$(mktemp -d)
trap 'rm -rf "$OUT"' EXIT
FRAMES=${FRAMES:-24}
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
