#!/usr/bin/env bash
# --compact against the exact render on every bundled scene at 1280x720: colour and alpha
# PSNR (`verisplat compare` of the two EXRs) and the peak device bytes of `verisplat bench`
# with and without --compact. Usage: tools/bench_compact.sh [BINARY] (default: release).
set -euo pipefail
cd "$(dirname "$0")/.."
B=${1:-target/release/verisplat}
D=../shared/data
T=$(mktemp -d)
trap 'rm -rf "$T"' EXIT
echo "| scene | Gaussians | colour PSNR vs exact | colour max error | alpha PSNR | peak device B exact | compact | saved per Gaussian |"
echo "|---|--:|--:|--:|--:|--:|--:|--:|"
for s in playbot_lod6_1873_sh2 playbot_lod3_31k_sh2 playbot_lod2_125k_sh2 playbot_lod1_250k_sh1 plant_113k_sh0 train3_sh3; do
  case $s in
    plant*) cams=(--cameras $D/plant_orbit_cameras.synthetic.json --camera 0) ;;
    train3*) cams=() ;;
    *) cams=(--cameras $D/playbot_orbit_cameras.synthetic.json --camera 0) ;;
  esac
  args=($D/$s.ply "${cams[@]}" --width 1280 --height 720)
  $B render "${args[@]}" -o "$T/e.exr" --overwrite -q >/dev/null 2>&1
  $B render "${args[@]}" --compact -o "$T/c.exr" --overwrite -q >/dev/null 2>&1
  cmp=$($B compare "$T/c.exr" "$T/e.exr" --min-psnr 0 --min-within 0 || true)
  colour=$(echo "$cmp" | awk '$1 == "color" {print $3, $4}')
  alpha=$(echo "$cmp" | awk '$1 == "alpha" {print $3}')
  $B bench "${args[@]}" --frames 1 --warmup 0 -q --json "$T/e.json" --overwrite
  $B bench "${args[@]}" --frames 1 --warmup 0 -q --compact --json "$T/c.json" --overwrite
  python3 - "$s" "$colour" "$alpha" "$T/e.json" "$T/c.json" <<'PY'
import json, sys
s, colour, alpha, e, c = sys.argv[1:]
psnr, err = colour.split()
re, rc = (json.load(open(p))["runs"][0] for p in (e, c))
ge, gc = re["device_bytes_peak"], rc["device_bytes_peak"]
print(f"| {s} | {re['gaussians']:,} | {psnr} dB | {err} | {alpha} dB | {ge:,} | {gc:,} | {(ge - gc) / re['gaussians']:.0f} B |")
PY
done
