#!/usr/bin/env bash
# Installs what verisplat needs on Debian/Ubuntu: the Vulkan loader, Mesa's lavapipe CPU
# driver (so no GPU is needed), the Khronos validation layer, the GLSL compiler `glslc`
# that build.rs compiles the shaders with (and spirv-tools to inspect them), Chromium
# for the viewer's browser test, Slurm and munge for the cluster test, ffmpeg for video
# output (render -o out.mp4) and its tests, and Python with venv for the Python package.
# Idempotent: does nothing when everything is present. Needs root (or sudo).
set -euo pipefail

packages=(
  libvulkan1 libvulkan-dev mesa-vulkan-drivers vulkan-tools vulkan-validationlayers
  # glvnd's dispatch library and EGL, which tools/gpu_bundle.sh ships for NVIDIA's driver.
  libglvnd0 libegl1
  glslc spirv-tools
  pkg-config openexr
  chromium chromium-driver
  # `render -o out.mp4/.webm/.gif` streams frames to the system ffmpeg (libx264, libvpx-vp9);
  # tests/all/app/video.rs checks the videos with ffmpeg and ffprobe.
  ffmpeg
  # A single-node Slurm cluster for tools/slurm_test.sh (docs/cluster.md).
  slurm-wlm munge
)
# Python (for the `verisplat` package and its tests): any python3 >= 3.9 with venv and pip;
# Debian's when the machine has none of its own.
venv_probe=$(mktemp -d)
if ! python3 -c 'import sys; sys.exit(sys.version_info < (3, 9))' 2>/dev/null \
  || ! python3 -m venv "$venv_probe/v" >/dev/null 2>&1; then
  packages+=(python3 python3-venv python3-pip)
fi
rm -rf "$venv_probe"
# Node.js and npm, for tools/interop.sh (PlayCanvas splat-transform and gltf-validator from
# npm): Debian's when the machine has no node of its own. splat-transform 3.7 needs
# Node.js >= 20, which interop.sh checks (Debian 12's is 18: install a newer one, e.g.
# NodeSource's, where that is what apt offers).
if ! command -v node >/dev/null || ! command -v npm >/dev/null; then
  packages+=(nodejs npm)
fi

missing=()
for p in "${packages[@]}"; do
  dpkg-query -W -f='${Status}' "$p" 2>/dev/null | grep -q "install ok installed" || missing+=("$p")
done
if [ ${#missing[@]} -eq 0 ]; then
  exit 0
fi
echo "setup: installing ${missing[*]}" >&2
sudo=""
if [ "$(id -u)" -ne 0 ]; then
  command -v sudo >/dev/null || { echo "setup: run as root or install sudo" >&2; exit 1; }
  sudo="sudo"
fi
$sudo apt-get update -qq
DEBIAN_FRONTEND=noninteractive $sudo apt-get install -y -qq --no-install-recommends "${missing[@]}"
