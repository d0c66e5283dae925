#!/usr/bin/env bash
# Runs every fuzz target one after the other for SECONDS each (default 240), logging to
# fuzz/logs/<target>.log; the final libFuzzer stats (executions, time) end each log.
# Usage: fuzz/run_all.sh [SECONDS] [TARGET...]
set -uo pipefail
cd "$(dirname "$0")/.."
SECS="${1:-240}"; shift || true
TARGETS=("$@")
[ ${#TARGETS[@]} -gt 0 ] || TARGETS=(ply detect compressed_ply spz splat sog_meta colmap_binary colmap_text cameras_json nerfstudio keyframes sog_zip npy)
mkdir -p fuzz/logs
for t in "${TARGETS[@]}"; do
  mkdir -p fuzz/corpus/$t
  echo "== $t ($SECS s) $(date +%T)"
  RUSTC_BOOTSTRAP=1 cargo fuzz run --fuzz-dir fuzz "$t" "fuzz/corpus/$t" -- \
    -max_total_time="$SECS" -rss_limit_mb=2048 -timeout=10 -print_final_stats=1 \
    > "fuzz/logs/$t.log" 2>&1
  echo "   exit $? $(grep -E 'stat::number_of_executed_units|stat::average_exec_per_sec|SUMMARY|ERROR' fuzz/logs/$t.log | tr '\n' ' ')"
done
