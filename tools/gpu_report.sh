#!/usr/bin/env bash
# Real-GPU figures in one command: builds vksplat (release), then on the chosen Vulkan
# device times the forward pass (`vksplat bench`) and forward + backward
# (`vksplat bench --backward`) of the shared scenes at 720p, 1080p and 4K, and prints one
# markdown table with the device's name, ready for BENCHMARKS.md. Training will join it
# once `vksplat train` exists.
#
#   tools/gpu_report.sh                 # the default device (discrete GPU first)
#   tools/gpu_report.sh --device 1      # any vksplat --device choice
#   RESOLUTIONS=720p FRAMES=3 tools/gpu_report.sh   # a quicker run
#
# Environment: SCENES (paths; default: the shared scenes), RESOLUTIONS (comma-separated,
# default 720p,1080p,4k), FRAMES (measured frames, default 10), OUT (folder for the JSON
# reports, default target/gpu_report). Runs tools/setup.sh first (glslc, Vulkan loader).
set -euo pipefail
cd "$(dirname "$0")/.."
tools/setup.sh
cargo build --release -q --bin vksplat
bin=target/release/vksplat
data=../shared/data
scenes=${SCENES:-"$data/playbot_lod3_31k_sh2.ply $data/playbot_lod2_125k_sh2.ply $data/playbot_lod1_250k_sh1.ply $data/plant_113k_sh0.ply"}
resolutions=${RESOLUTIONS:-720p,1080p,4k}
frames=${FRAMES:-10}
out=${OUT:-target/gpu_report}
mkdir -p "$out"
i=0
for scene in $scenes; do
  if [ ! -e "$scene" ]; then
    echo "gpu_report: $scene is missing; skipped" >&2
    continue
  fi
  cams=()
  case "$(basename "$scene")" in
    playbot*) cams=(--cameras "$data/playbot_orbit_cameras.synthetic.json" --camera 0) ;;
    plant*) cams=(--cameras "$data/plant_orbit_cameras.synthetic.json" --camera 0) ;;
  esac
  i=$((i + 1))
  "$bin" bench "$scene" "${cams[@]}" --sweep "resolution=$resolutions" --frames "$frames" \
    --warmup 2 --json "$out/forward_$i.json" --overwrite -q "$@"
  "$bin" bench "$scene" "${cams[@]}" --sweep "resolution=$resolutions" --frames "$frames" \
    --warmup 2 --backward --json "$out/backward_$i.json" --overwrite -q "$@"
done
python3 - "$out" <<'PY'
import glob, json, os, sys
out = sys.argv[1]
fwd = {}
for path in sorted(glob.glob(os.path.join(out, "forward_*.json"))):
    for r in json.load(open(path))["runs"]:
        fwd[(r["scene"], r["width"], r["height"])] = r
rows = []
device = driver = None
for path in sorted(glob.glob(os.path.join(out, "backward_*.json"))):
    for r in json.load(open(path))["backward_runs"]:
        device, driver = r["device"], r["driver"]
        f = fwd.get((r["scene"], r["width"], r["height"]))
        rows.append((
            os.path.basename(r["scene"]), r["gaussians"], f"{r['width']}x{r['height']}",
            f["frame_ms"]["median"] if f else float("nan"), f["fps"] if f else float("nan"),
            r["forward_ms"]["median"], r["backward_ms"]["median"], r["backward_over_forward"],
            next((s["median"] for s in r["backward_stages"] if s["name"] == "blend_bwd"), 0.0),
            r["device_bytes_per_gaussian"],
        ))
print(f"### {device} ({driver})\n")
print("| scene | Gaussians | resolution | forward ms (bench) | frames/s | forward ms (saving state) "
      "| backward ms | backward / forward | blend_bwd ms | device bytes / Gaussian (training) |")
print("|---|--:|---|--:|--:|--:|--:|--:|--:|--:|")
for r in rows:
    print("| {} | {:,} | {} | {:.2f} | {:.1f} | {:.2f} | {:.2f} | {:.2f}x | {:.2f} | {:.0f} |".format(*r))
print("\nMedians of device timestamps; reports in", out)
PY
