#!/usr/bin/env bash
# Checks that a wheel built by tools/wheel.sh works where there is no Rust and no glslc:
# makes a fresh virtualenv (target/wheel-test), installs the wheel into it with a PATH
# that holds only that virtualenv's bin/ (no cargo, rustc, rustup or glslc: checked), numpy
# from PyPI, then renders the built-in demo scene from Python on the Vulkan device the
# loader finds (lavapipe here) and compares it with the CPU reference: the image must not be
# empty and must be within the GPU-vs-CPU tolerance of the Python tests (PSNR >= 55 dB, 99.9 %
# of values within 1/255). Any failure exits non-zero.
# Usage: tools/wheel_test.sh [WHEEL]   (default: the wheel in target/wheels/)
set -euo pipefail
cd "$(dirname "$0")/.."

if [ $# -gt 0 ]; then
  wheel=$1
else
  wheels=(target/wheels/verisplat-*.whl)
  wheel=${wheels[0]}
fi
if [ ! -f "$wheel" ]; then
  echo "wheel_test: no wheel at $wheel (build one with tools/wheel.sh)" >&2
  exit 1
fi
wheel=$(realpath "$wheel")
venv=$PWD/target/wheel-test

# The extension links only the C library's parts; the Vulkan loader is opened at run time.
scratch=$(mktemp -d)
trap 'rm -rf "$scratch"' EXIT
lib=$(python3 - "$wheel" "$scratch" <<'EOF'
import sys, zipfile
wheel = zipfile.ZipFile(sys.argv[1])
lib = next(n for n in wheel.namelist() if n.startswith("verisplat/_native") and n.endswith(".so"))
print(wheel.extract(lib, sys.argv[2]))
EOF
)
needed=$(ldd "$lib")
if grep -q -e vulkan -e "not found" <<<"$needed"; then
  echo "wheel_test: $(basename "$lib") links the Vulkan loader or misses a library:" >&2
  echo "$needed" >&2
  exit 1
fi

t0=$SECONDS
rm -rf "$venv"
python3 -m venv "$venv"
# Without Rust or glslc: only the virtualenv's own programs, and none of the variables
# that would point a build at a toolchain or the package at shader sources (any *_GLSL_DIR,
# the former names included).
unset_glsl=()
for name in $(compgen -e); do
  case $name in *_GLSL_DIR) unset_glsl+=(-u "$name") ;; esac
done
bare() {
  env -u CARGO_HOME -u RUSTUP_HOME -u CARGO_TARGET_DIR -u RUSTC -u RUSTC_WRAPPER \
    -u RUSTC_WORKSPACE_WRAPPER -u GLSLC "${unset_glsl[@]}" PATH="$venv/bin" "$@"
}
# --only-binary: pip must not build anything (numpy is a wheel from PyPI too).
bare "$venv/bin/pip" install -q --only-binary :all: "$wheel"
echo "wheel_test: a fresh virtualenv and pip install $(basename "$wheel") took $((SECONDS - t0)) s" >&2

t0=$SECONDS
# Run outside the repository, so that python/verisplat cannot stand in for the installed package.
(cd "$scratch" && bare "$venv/bin/python" - <<'EOF'
import pathlib, shutil, sys
import verisplat

found = [t for t in ("cargo", "rustc", "rustup", "glslc", "glslangValidator") if shutil.which(t)]
if found:
    sys.exit(f"wheel_test: {', '.join(found)} found on the PATH; the check needs none")
installed = pathlib.Path(verisplat.__file__).resolve()
if pathlib.Path(sys.prefix).resolve() not in installed.parents:
    sys.exit(f"wheel_test: verisplat was imported from {installed}, not the virtualenv")

scene = verisplat.demo()
camera = verisplat.default_camera(scene, 160, 120)
renderer = verisplat.Renderer()
gpu = renderer.render(scene, camera)
cpu = verisplat.render_cpu(scene, camera)
covered = float((gpu["alpha"] > 0).mean())
m = verisplat.compare(cpu["rgb"], gpu["rgb"])
print(f"wheel_test: rendered the demo scene on {renderer.device}: {covered:.0%} of pixels "
      f"covered, PSNR {m['psnr']:.1f} dB against the CPU reference, "
      f"{m['within']:.4%} within 1/255", file=sys.stderr)
if covered < 0.05:
    sys.exit("wheel_test: the image is (nearly) empty")
if not (m["psnr"] >= 55 and m["within"] >= 0.999):
    sys.exit("wheel_test: the GPU image is not the CPU reference's")
EOF
)
echo "wheel_test: import and render took $((SECONDS - t0)) s" >&2
