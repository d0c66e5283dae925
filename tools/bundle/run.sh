#!/bin/sh
# verisplat GPU bundle: measures this machine's Vulkan device and writes ONE markdown report.
# Needs only a Vulkan driver: no Rust, no compiler, no Python, no network. Made by
# tools/gpu_bundle.sh in the verisplat repository.
#
#   ./run.sh                    # everything (tens of minutes on a GPU) -> ./report.md
#   ./run.sh /tmp/gpu.md        # the report elsewhere
#   QUICK=1 ./run.sh            # 720p only, the small scenes, 2 frames, a short training run
#   SMOKE=1 ./run.sh            # doctor, one comparison, one bench frame (a CI smoke test)
#   DEVICE=1 ./run.sh           # another Vulkan device (index or part of its name)
#   GENERATED=1e6 COMPARE_SCENES= ./run.sh   # a part's list overridden (see "Steps")
#
# Steps: `verisplat doctor` (self-check against the CPU reference), `verisplat compare` (GPU vs
# CPU renders of the scenes), `verisplat bench` forward and backward at 720p, 1080p and 4K
# (PLAYBOT LOD2 and LOD1, plant, generated 1M and 10M Gaussian scenes), and a training run
# (`verisplat train --timings` on a data set rendered from PLAYBOT LOD3). A step that fails
# is recorded in the report and the run goes on. Exit status: non-zero when doctor failed.
# Raw results (JSON reports, logs) stay in results/ (RESULTS=DIR to choose).
set -u
here=$(cd "$(dirname "$0")" && pwd)
report=${1:-$here/report.md}
results=${RESULTS:-$here/results}
bin=$here/bin/verisplat
scenes=$here/scenes
cams=$here/cameras

mode=full
[ "${QUICK:-0}" = 1 ] && mode=quick
[ "${SMOKE:-0}" = 1 ] && mode=smoke

rm -rf "$results"
mkdir -p "$results" || exit 1
: >"$results/steps.tsv"
start=$(date +%s)

# ---- Vulkan loader: the system's when it has one, else the bundled libvulkan.so.1 -------
find_ldconfig() {
  for c in ldconfig /sbin/ldconfig /usr/sbin/ldconfig; do
    if command -v "$c" >/dev/null 2>&1; then
      echo "$c"
      return
    fi
  done
}
ldconfig_bin=$(find_ldconfig)
has_lib() { # name: found by the dynamic linker's cache or in a common directory
  if [ -n "$ldconfig_bin" ] && "$ldconfig_bin" -p 2>/dev/null | grep -q " $1 "; then
    "$ldconfig_bin" -p | awk -v n="$1" '$1 == n { print $NF; exit }'
    return 0
  fi
  for d in /usr/lib/x86_64-linux-gnu /usr/lib64 /usr/lib /lib/x86_64-linux-gnu /lib64 \
    /usr/local/nvidia/lib64 /usr/local/nvidia/lib /usr/local/lib; do
    if [ -e "$d/$1" ]; then
      echo "$d/$1"
      return 0
    fi
  done
  return 1
}
if [ "${BUNDLED_LOADER:-0}" != 1 ] && loader=$(has_lib libvulkan.so.1); then
  loader_note="system ($loader)"
else
  LD_LIBRARY_PATH=$here/lib${LD_LIBRARY_PATH:+:$LD_LIBRARY_PATH}
  export LD_LIBRARY_PATH
  loader_note="bundled ($here/lib/libvulkan.so.1, Debian libvulkan1)"
fi

# glvnd's dispatch library and EGL, which NVIDIA's Vulkan driver (libGLX_nvidia.so.0) needs:
# the system's, else the bundled ones (CUDA-only images often lack them).
if has_lib libGLdispatch.so.0 >/dev/null && has_lib libEGL.so.1 >/dev/null; then
  glvnd_note="system"
else
  LD_LIBRARY_PATH=$here/lib/glvnd${LD_LIBRARY_PATH:+:$LD_LIBRARY_PATH}
  export LD_LIBRARY_PATH
  glvnd_note="bundled ($here/lib/glvnd: libGLdispatch.so.0, libEGL.so.1 of Debian's libglvnd0, libegl1)"
fi

# ---- The driver's ICD JSON: the loader's standard folders, else a written NVIDIA one ----
icds=""
if [ -n "${VK_DRIVER_FILES:-}${VK_ICD_FILENAMES:-}" ]; then
  icd_note="from the environment: ${VK_DRIVER_FILES:-${VK_ICD_FILENAMES:-}}"
else
  dirs="/etc/vulkan/icd.d /usr/local/share/vulkan/icd.d /usr/share/vulkan/icd.d"
  old_ifs=$IFS
  IFS=:
  for d in ${XDG_CONFIG_DIRS:-/etc/xdg}; do dirs="$dirs $d/vulkan/icd.d"; done
  for d in ${XDG_DATA_DIRS:-/usr/local/share:/usr/share}; do dirs="$dirs $d/vulkan/icd.d"; done
  IFS=$old_ifs
  for d in $dirs; do
    for f in "$d"/*.json; do
      case " $icds " in *" $f "*) continue ;; esac # a folder listed twice
      [ -e "$f" ] && icds="$icds $f"
    done
  done
  if [ -n "$icds" ]; then
    icd_note="found:$icds"
  elif nvidia=$(has_lib libGLX_nvidia.so.0); then
    # Cloud images often ship the NVIDIA driver (with CUDA) but not its Vulkan ICD JSON.
    icd=$results/nvidia_icd.json
    printf '{"file_format_version":"1.0.0","ICD":{"library_path":"%s","api_version":"1.3"}}\n' \
      "$nvidia" >"$icd"
    VK_DRIVER_FILES=$icd
    VK_ICD_FILENAMES=$icd
    export VK_DRIVER_FILES VK_ICD_FILENAMES
    icd_note="none installed; wrote $icd for the NVIDIA driver ($nvidia)"
  else
    icd_note="none found (no ICD JSON in $dirs, no NVIDIA driver): no Vulkan driver?"
  fi
fi

# ---- Steps -----------------------------------------------------------------------------
dev_args=""
[ -n "${DEVICE:-}" ] && dev_args="--device $DEVICE"

# step NAME LOG COMMAND...: runs the command (output to LOG), records its outcome.
step() {
  name=$1
  log=$2
  shift 2
  echo "run.sh: $name" >&2
  t0=$(date +%s)
  "$@" >"$log" 2>&1
  rc=$?
  t1=$(date +%s)
  if [ $rc -eq 0 ]; then status=ok; else status="FAILED (exit $rc)"; fi
  [ $rc -eq 0 ] || echo "run.sh: $name FAILED (exit $rc); see $log" >&2
  printf '%s\t%s\t%s\t%s\n' "$name" "$status" "$((t1 - t0))" "$*" | sed "s|$here/||g" \
    >>"$results/steps.tsv"
  return $rc
}

camera_file() { # the orbit cameras of a scene file
  case $(basename "$1") in
    playbot*) echo "$cams/playbot_orbit_cameras.synthetic.json" ;;
    plant*) echo "$cams/plant_orbit_cameras.synthetic.json" ;;
  esac
}

case $mode in
  full)
    res=720p,1080p,4k frames=10 warmup=2
    compare_scenes="playbot_lod3_31k_sh2 playbot_lod2_125k_sh2 playbot_lod1_250k_sh1 plant_113k_sh0"
    compare_args="--camera 0,6,12,18"
    bench_scenes="playbot_lod2_125k_sh2 playbot_lod1_250k_sh1 plant_113k_sh0"
    generated="1e6 1e7"
    train_args="--width 640 --iterations 2000"
    ;;
  quick)
    res=720p frames=2 warmup=1
    compare_scenes="playbot_lod3_31k_sh2 plant_113k_sh0"
    compare_args="--camera 0 --width 640"
    bench_scenes="playbot_lod3_31k_sh2 plant_113k_sh0"
    generated=""
    train_args="--width 160 --iterations 100"
    ;;
  smoke)
    res=720p frames=1 warmup=1
    compare_scenes="playbot_lod3_31k_sh2"
    compare_args="--camera 0 --width 320"
    bench_scenes="playbot_lod3_31k_sh2"
    generated=""
    train_args=""
    ;;
esac

# Each list can be overridden from the environment, for a run that must fit a time limit:
# COMPARE_SCENES, COMPARE_ARGS, BENCH_SCENES, RES, FRAMES, WARMUP, GENERATED, TRAIN_ARGS
# (an empty value skips that part, e.g. COMPARE_SCENES= GENERATED=1e6).
compare_scenes=${COMPARE_SCENES-$compare_scenes}
compare_args=${COMPARE_ARGS-$compare_args}
bench_scenes=${BENCH_SCENES-$bench_scenes}
res=${RES-$res}
frames=${FRAMES-$frames}
warmup=${WARMUP-$warmup}
generated=${GENERATED-$generated}
train_args=${TRAIN_ARGS-$train_args}

# shellcheck disable=SC2086 # dev_args and the mode's argument lists are word lists
step doctor "$results/doctor.txt" "$bin" doctor $dev_args --json "$results/doctor.json"
doctor_rc=$?

for s in $compare_scenes; do
  step "compare $s" "$results/compare_$s.log" "$bin" compare "$scenes/$s.spz" \
    --cameras "$(camera_file "$s")" $compare_args -o "$results/compare_$s" --overwrite $dev_args
done

for s in $bench_scenes; do
  c=$(camera_file "$s")
  step "bench $s" "$results/forward_$s.log" "$bin" bench "$scenes/$s.spz" --cameras "$c" \
    --camera 0 --sweep "resolution=$res" --frames $frames --warmup $warmup \
    --json "$results/forward_$s.json" --overwrite -q $dev_args
  [ $mode = smoke ] && continue
  step "bench --backward $s" "$results/backward_$s.log" "$bin" bench "$scenes/$s.spz" \
    --cameras "$c" --camera 0 --sweep "resolution=$res" --frames $frames --warmup $warmup \
    --backward --json "$results/backward_$s.json" --overwrite -q $dev_args
done

for n in $generated; do
  step "bench generated $n" "$results/forward_gen_$n.log" "$bin" bench \
    --sweep "gaussians=$n" --sweep "resolution=$res" --frames $frames --warmup $warmup \
    --json "$results/forward_gen_$n.json" --overwrite -q $dev_args
  step "bench --backward generated $n" "$results/backward_gen_$n.log" "$bin" bench \
    --sweep "gaussians=$n" --sweep "resolution=$res" --frames $frames --warmup $warmup \
    --backward --json "$results/backward_gen_$n.json" --overwrite -q $dev_args
done

if [ -n "$train_args" ]; then
  s=playbot_lod3_31k_sh2
  width=${train_args%% --iterations*}
  iterations=${train_args##*--iterations }
  if step "training data set" "$results/train_data.log" "$bin" render "$scenes/$s.spz" \
    --cameras "$(camera_file "$s")" $width --export-colmap "$results/train_data" $dev_args; then
    step "train $iterations iterations" "$results/train.txt" "$bin" train \
      "$results/train_data" -o "$results/train_model" --iterations "$iterations" \
      --densify-from-iter 50 --densification-interval 50 --timings -q $dev_args
  fi
fi

# ---- The report ------------------------------------------------------------------------
{
  echo "date: $(date -u '+%Y-%m-%d %H:%M UTC')"
  echo "verisplat: $("$bin" --version 2>&1)"
  echo "mode: $mode ($(($(date +%s) - start)) s)"
  echo "host: $(uname -srm), $(getconf _NPROCESSORS_ONLN 2>/dev/null || echo '?') CPU threads"
  if command -v nvidia-smi >/dev/null 2>&1; then
    echo "nvidia-smi: $(nvidia-smi --query-gpu=name,driver_version,memory.total \
      --format=csv,noheader 2>&1 | head -n 1)"
  fi
  echo "Vulkan loader: $loader_note"
  echo "Vulkan driver (ICD): $icd_note"
  echo "glvnd (libGLdispatch.so.0, libEGL.so.1): $glvnd_note"
  # What the drivers' libraries cannot find, the usual reason a driver is not loaded.
  for f in $icds ${VK_DRIVER_FILES:-} ${VK_ICD_FILENAMES:-}; do
    [ -r "$f" ] || continue
    lib=$(sed -n 's/.*"library_path"[^"]*"\([^"]*\)".*/\1/p' "$f" | head -n 1)
    [ -n "$lib" ] || continue
    case $lib in /*) path=$lib ;; *) path=$(has_lib "$lib") || path="" ;; esac
    if [ -z "$path" ]; then
      echo "driver library $lib (from $f): not found"
    elif command -v ldd >/dev/null 2>&1 && missing=$(ldd "$path" 2>/dev/null | grep 'not found'); then
      echo "driver library $path: missing $(echo "$missing" | awk '{ print $1 }' | tr '\n' ' ')"
    fi
  done
} >"$results/info.txt"
if ! "$bin" gpu-report "$results" -o "$report" 2>"$results/report.log"; then
  # The binary could not make it: a plain report with the steps and logs' tails.
  {
    echo "# verisplat GPU report (the report step failed: $(cat "$results/report.log"))"
    echo
    sed 's/^/- /' "$results/info.txt"
    echo
    echo '```'
    cat "$results/steps.tsv" "$results/doctor.txt" 2>/dev/null
    echo '```'
  } >"$report"
fi
echo "run.sh: report in $report (raw results in $results)" >&2
if [ $doctor_rc -ne 0 ]; then
  echo "run.sh: doctor FAILED on this device: its figures are not to be trusted" >&2
  exit 1
fi
exit 0
