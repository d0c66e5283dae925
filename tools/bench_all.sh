#!/usr/bin/env bash
# Runs the benchmarks behind BENCHMARKS.md (release build; ../shared/data beside the repo).
set -euo pipefail
cd "$(dirname "$0")/.."
cargo build --release -q
B=target/release/vksplat
D=../shared/data
PC=$D/playbot_orbit_cameras.synthetic.json
echo "## device"; vulkaninfo --summary 2>/dev/null | grep -E "deviceName|driverInfo|apiVersion" | head -3 || true
echo "## per-scene GPU, 1280x720, camera 0"
for s in playbot_lod6_1873_sh2 playbot_lod3_31k_sh2 playbot_lod2_125k_sh2 playbot_lod1_250k_sh1; do
  echo "### $s"; $B bench $D/$s.ply --cameras $PC --camera 0 --frames 10 --warmup 2
done
echo "### plant_113k_sh0"; $B bench $D/plant_113k_sh0.ply --cameras $D/plant_orbit_cameras.synthetic.json --frames 10 --warmup 2
echo "### train3_sh3 (default camera)"; $B bench $D/train3_sh3.ply --frames 10 --warmup 2
echo "## 1920x1080"
echo "### playbot_lod2_125k_sh2"; $B bench $D/playbot_lod2_125k_sh2.ply --cameras $PC --width 1920 --height 1080 --frames 10 --warmup 2
echo "## blend kernels, playbot_lod2_125k_sh2 1280x720"
for k in shared texel texel:2 texel:4 texel:8; do
  echo "### VKSPLAT_BLEND=$k"; VKSPLAT_BLEND=$k $B bench $D/playbot_lod2_125k_sh2.ply --cameras $PC --frames 5 --warmup 1 | grep -E "blend|wall"
done
echo "## CPU reference, playbot_lod2_125k_sh2 1280x720"
$B bench $D/playbot_lod2_125k_sh2.ply --cameras $PC --frames 5 --warmup 1 --cpu
echo "## start-up (render --demo --width 64 -v)"
VKSPLAT_NO_SHADER_CACHE=1 $B render --demo --width 64 -o /tmp/vksplat-startup.png --overwrite -v 2>&1 | grep -E "start-up"
$B render --demo --width 64 -o /tmp/vksplat-startup.png --overwrite -v 2>&1 | grep -E "start-up"
$B render --demo --width 64 -o /tmp/vksplat-startup.png --overwrite -v 2>&1 | grep -E "start-up"
