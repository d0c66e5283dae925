#!/usr/bin/env bash
# Makes a self-contained folder that measures a real GPU: copy it to any x86-64 Linux
# machine with a Vulkan driver (no Rust, no compiler, no Python, no network needed there)
# and run DIR/run.sh; it writes one markdown report (doctor, GPU-vs-CPU comparisons,
# forward/backward benches, training). See BENCHMARKS.md, "Real GPU: how to measure one".
#
#   tools/gpu_bundle.sh DIR                  # builds verisplat (release) and fills DIR
#   tools/gpu_bundle.sh DIR --bin PATH       # uses an already-built verisplat binary
#   scp -r DIR gpu-host: && ssh gpu-host DIR/run.sh     # then read DIR/report.md
#
# DIR gets: bin/verisplat, lib/libvulkan.so.1 (Debian's libvulkan1, used only when the target
# has no loader), lib/glvnd/ (glvnd's libGLdispatch.so.0 and libEGL.so.1, Debian's
# libglvnd0 and libegl1, which NVIDIA's driver needs; used only when the target lacks them), scenes/*.spz (the shared scenes, converted to SPZ to stay small; their
# licences in scenes/LICENSES.md), cameras/*.json, run.sh and README.txt. At most 60 MiB.
set -euo pipefail
repo=$(cd "$(dirname "$0")/.." && pwd)
usage="usage: tools/gpu_bundle.sh DIR [--bin PATH]"
dir=""
bin=""
while [ $# -gt 0 ]; do
  case $1 in
    --bin) bin=${2:?$usage}; shift 2 ;;
    -h | --help) echo "$usage"; exit 0 ;;
    -*) echo "$usage" >&2; exit 2 ;;
    *) [ -z "$dir" ] || { echo "$usage" >&2; exit 2; }; dir=$1; shift ;;
  esac
done
[ -n "$dir" ] || { echo "$usage" >&2; exit 2; }
data=${DATA:-$repo/../shared/data}
max_bytes=$((60 << 20))

if [ -z "$bin" ]; then
  "$repo/tools/setup.sh"
  (cd "$repo" && cargo build --release -q --bin verisplat)
  bin=$repo/target/release/verisplat
fi
[ -x "$bin" ] || { echo "gpu_bundle: $bin is not an executable" >&2; exit 1; }

rm -rf "$dir"
mkdir -p "$dir"/{bin,lib,scenes,cameras}
cp "$bin" "$dir/bin/verisplat"
# Debug information is most of a binary's size and none of its use on the target.
if command -v strip >/dev/null; then strip "$dir/bin/verisplat"; fi

# The Vulkan loader, the real file (libvulkan.so.1 is a symbolic link), and its copyright.
loader=""
for cand in $(/sbin/ldconfig -p 2>/dev/null | awk '$1 == "libvulkan.so.1" { print $NF }') \
  /usr/lib/x86_64-linux-gnu/libvulkan.so.1; do
  if [ -e "$cand" ]; then loader=$(readlink -f "$cand"); break; fi
done
[ -n "$loader" ] || { echo "gpu_bundle: no libvulkan.so.1 (apt-get install libvulkan1)" >&2; exit 1; }
cp "$loader" "$dir/lib/libvulkan.so.1"
if [ -e /usr/share/doc/libvulkan1/copyright ]; then
  cp /usr/share/doc/libvulkan1/copyright "$dir/lib/libvulkan1.copyright"
fi
# glvnd's dispatch library and EGL (Debian's libglvnd0 and libegl1): NVIDIA's Vulkan driver
# (libGLX_nvidia.so.0) links the first and loads the second when an instance is made, and a
# CUDA-only image may lack both. On the first H200 runs (2026-11-28) the loader found no
# driver without them ("Could not get 'vkCreateInstance' via 'vk_icdGetInstanceProcAddr'",
# ERROR_INCOMPATIBLE_DRIVER); glvnd's libGLdispatch.so.0 with libEGL.so.1 was the least
# that made it work. run.sh uses them only when the system has none.
mkdir -p "$dir/lib/glvnd"
for pair in libGLdispatch.so.0:libglvnd0 libEGL.so.1:libegl1; do
  name=${pair%%:*}
  package=${pair##*:}
  found=""
  for cand in $(/sbin/ldconfig -p 2>/dev/null | awk -v n="$name" '$1 == n { print $NF }') \
    "/usr/lib/x86_64-linux-gnu/$name"; do
    if [ -e "$cand" ]; then found=$(readlink -f "$cand"); break; fi
  done
  [ -n "$found" ] || { echo "gpu_bundle: no $name (apt-get install $package)" >&2; exit 1; }
  cp "$found" "$dir/lib/glvnd/$name"
  if [ -e "/usr/share/doc/$package/copyright" ]; then
    cp "/usr/share/doc/$package/copyright" "$dir/lib/glvnd/$package.copyright"
  fi
done

# The shared scenes as SPZ (about a tenth of the PLY's bytes; lossy: positions to 1/4096
# of a unit, colours and SH quantised, which matters to neither the timings nor the GPU-vs-
# CPU comparison, as both sides read the same file).
for s in playbot_lod3_31k_sh2 playbot_lod2_125k_sh2 playbot_lod1_250k_sh1 plant_113k_sh0; do
  "$dir/bin/verisplat" convert "$data/$s.ply" "$dir/scenes/$s.spz" >/dev/null
done
cp "$data/playbot_orbit_cameras.synthetic.json" "$data/plant_orbit_cameras.synthetic.json" \
  "$dir/cameras/"
{
  echo "# Scenes of this bundle and their licences"
  echo
  echo "The scenes are the verisplat repository's shared test data, converted from INRIA PLY to"
  echo "SPZ by \`verisplat convert\` (a format change, lossy as SPZ is). The cameras are"
  echo "synthetic orbits (CC0). From the data's README:"
  echo
  sed -n '/^## Licences and attribution/,$p' "$data/README.md"
  echo
  echo "CC BY 4.0: https://creativecommons.org/licenses/by/4.0/legalcode"
} >"$dir/scenes/LICENSES.md"

cp "$repo/tools/bundle/run.sh" "$dir/run.sh"
chmod +x "$dir/run.sh" "$dir/bin/verisplat"
cat >"$dir/README.txt" <<EOF
verisplat GPU bundle ($("$dir/bin/verisplat" --version), made $(date -u '+%Y-%m-%d') by tools/gpu_bundle.sh)

Run ./run.sh on a Linux x86-64 machine with a Vulkan driver; it writes report.md.
QUICK=1 ./run.sh is a few-minute version, SMOKE=1 ./run.sh a smoke test; DEVICE=N picks
another Vulkan device. bin/verisplat is the whole renderer (verisplat --help); the scenes'
licences are in scenes/LICENSES.md, the Vulkan loader's in lib/libvulkan1.copyright.
EOF

bytes=$(du -sb "$dir" | cut -f1)
if [ "$bytes" -gt "$max_bytes" ]; then
  echo "gpu_bundle: $dir is $bytes bytes, more than the 60 MiB allowed" >&2
  exit 1
fi
echo "gpu_bundle: $dir ($((bytes >> 20)) MiB): copy it to the GPU machine and run $dir/run.sh" >&2
