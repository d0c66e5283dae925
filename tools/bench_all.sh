#!/usr/bin/env bash
# Runs the benchmarks behind BENCHMARKS.md (release build; ../shared/data beside the repo).
# Writes docs/benchmarks/scaling.{csv,json,svg}; prints everything else.
set -euo pipefail
cd "$(dirname "$0")/.."
cargo build --release -q
B=target/release/verisplat
D=../shared/data
PC=$D/playbot_orbit_cameras.synthetic.json
mkdir -p docs/benchmarks
echo "## device"; vulkaninfo --summary 2>/dev/null | grep -E "deviceName|driverInfo|apiVersion" | head -3 || true
J=$(mktemp -d)
for res in 1280x720 1920x1080; do
  w=${res%x*}; h=${res#*x}
  echo "## per-scene GPU, $res, camera 0"
  for s in playbot_lod6_1873_sh2 playbot_lod3_31k_sh2 playbot_lod2_125k_sh2 playbot_lod1_250k_sh1; do
    $B bench $D/$s.ply --cameras $PC --camera 0 --width $w --height $h --frames 10 --warmup 2 --json $J/$res-$s.json
  done
  $B bench $D/plant_113k_sh0.ply --cameras $D/plant_orbit_cameras.synthetic.json --width $w --height $h --frames 10 --warmup 2 --json $J/$res-plant.json
  $B bench $D/train3_sh3.ply --width $w --height $h --frames 10 --warmup 2 --json $J/$res-train3.json
  echo "### table, $res"
  python3 tools/bench_table.py $J/$res-playbot_lod6_1873_sh2.json $J/$res-playbot_lod3_31k_sh2.json \
    $J/$res-playbot_lod2_125k_sh2.json $J/$res-playbot_lod1_250k_sh1.json $J/$res-plant.json $J/$res-train3.json
done
rm -rf "$J"
echo "## blend kernels, playbot_lod2_125k_sh2 1280x720"
for k in shared texel texel:2 texel:4 texel:8; do
  echo "### VERISPLAT_BLEND=$k"; VERISPLAT_BLEND=$k $B bench $D/playbot_lod2_125k_sh2.ply --cameras $PC --frames 5 --warmup 1 | grep -E "blend kernel|^blend|wall"
done
echo "## where llvmpipe spends the LOD2 frame (perf samples per shader block)"
if command -v perf >/dev/null; then
  python3 tools/profile_stages.py --binary $B --frames 5 -- $D/playbot_lod2_125k_sh2.ply --cameras $PC
else
  echo "perf not installed: skipped"
fi
echo "## CPU reference, playbot_lod2_125k_sh2 1280x720"
$B bench $D/playbot_lod2_125k_sh2.ply --cameras $PC --frames 5 --warmup 1 --cpu
echo "## scaling sweep (synthetic scenes, SH 2, default camera)"
$B bench --sweep gaussians=1e3,1e4,1e5,1e6 --sweep resolution=720p,1080p,4k --frames 3 --warmup 1 \
  --csv docs/benchmarks/scaling.csv --json docs/benchmarks/scaling.json --plot docs/benchmarks/scaling.svg --overwrite \
  | grep -E "^scene|^frame|^blend |^sort |^wall|evaluations"
echo "## scaling sweep to 10 M Gaussians at 1080p (chunked frames; lavapipe's 2 GiB heap is raised)"
VERISPLAT_MEMORY_LIMIT=16G $B bench --sweep gaussians=3e6,1e7 --sweep resolution=1080p --frames 1 --warmup 0 \
  --csv docs/benchmarks/scaling_10m.csv --json docs/benchmarks/scaling_10m.json --plot docs/benchmarks/scaling_10m.svg --overwrite \
  | grep -E "^scene|^frame|^blend |^sort |^wall|chunks|device memory"
echo "## --compact against the exact render, every scene at 1280x720"
tools/bench_compact.sh $B
echo "## 10 M Gaussians at SH 3, 1920x1080: gen, exact and --compact (bench; render to EXR and compare)"
T=$(mktemp -d)
export VERISPLAT_MEMORY_LIMIT=16G
/usr/bin/time -f "gen: wall %e s, peak RSS %M KB" $B gen 10000000 -o $T/big.ply --sh-degree 3
for c in "" "--compact"; do
  echo "### bench $c"
  /usr/bin/time -f "bench $c: wall %e s, peak RSS %M KB" $B bench $T/big.ply --width 1920 --height 1080 --frames 1 --warmup 0 $c 2>&1 \
    | grep -E "^frame|chunks|device memory|wall"
  $B render $T/big.ply --width 1920 --height 1080 -o $T/big$c.exr -q $c >/dev/null 2>&1
done
$B compare $T/big--compact.exr $T/big.exr
unset VERISPLAT_MEMORY_LIMIT
rm -rf "$T"
echo "## start-up (render --demo, 1280x720, -v): empty caches (Mesa's and verisplat's), then warm"
C=$(mktemp -d)
for run in first second third; do
  /usr/bin/time -f "$run run: %e s wall" env XDG_CACHE_HOME="$C" MESA_SHADER_CACHE_DIR="$C/mesa" \
    $B render --demo -o "$C/demo.png" --overwrite -v 2>&1 | grep -E "start-up|wall"
done
/usr/bin/time -f "Mesa cache off: %e s wall" env XDG_CACHE_HOME="$C" MESA_SHADER_CACHE_DISABLE=true \
  $B render --demo -o "$C/demo.png" --overwrite -v 2>&1 | grep -E "start-up|wall"
rm -rf "$C"
echo "## cargo bench --bench building_blocks"
cargo bench -q --bench building_blocks 2>&1 | grep -vE "^\s*(Compiling|Finished|Running)"
echo "## cargo bench --bench tuning"
cargo bench -q --bench tuning 2>&1 | grep -vE "^\s*(Compiling|Finished|Running)"
