#!/usr/bin/env bash
# The test command from the README: installs system packages if missing, then runs the
# whole suite on lavapipe with the Khronos validation layer enabled (any validation
# message fails the GPU tests): the Rust tests, the Slurm job-array test
# (tools/slurm_test.sh), then the Python package built with pip
# in a fresh virtualenv (target/pyenv) and its pytest suite.
# Then the GPU tests again at lavapipe's other subgroup sizes (below). Arguments go to
# `cargo test` (e.g. a test name); VKSPLAT_SKIP_PYTHON=1 skips the Python part.
set -euo pipefail
cd "$(dirname "$0")/.."
tools/setup.sh
export VKSPLAT_VALIDATE=1
t0=$SECONDS
cargo test --all-targets "$@"
echo "test.sh: cargo test took $((SECONDS - t0)) s" >&2

# The GPU tests at the other subgroup sizes lavapipe runs (docs/portability.md):
# LP_NATIVE_VECTOR_WIDTH=128 gives 4 lanes, 512 16, 1024 and 2048 say 32 and 64 lanes but
# run 16 (vksplat measures and follows that). Every GPU-vs-CPU, sort, scan, gradient,
# loss, training-step and doctor test; the 4-lane run also under the Vulkan spec's minimum
# workgroup limits (VKSPLAT_EMULATE=spec-limits: 128 invocations, 16 KiB shared memory).
# VKSPLAT_WIDTHS="" skips them (a test name given to this script skips them too).
width_tests=(
  gpu_sort:: gpu_stages:: gradients::gpu_ loss::device_loss features::gpu_ mlp::gpu_shade
  field_renders::gpu_field time_fields::gpu_equals compact::compact_scenes
  gpu_frames::every_blend_kernel gpu_frames::antialiased gpu_frames::plant_and_train
  gpu_frames::per_frame_options gpu_frames::rgba8 gpu_frames::playbot_lods
  gpu_frames::power_kernel chunked_frames::tiny_chunks pipelined::pipelined_frames_match
  train::the_state_on_the_device train::feature_splats_and_clipping doctor::doctor_passes
  limits::pair
)
widths=${VKSPLAT_WIDTHS-128 512 1024 2048}
if [ $# -gt 0 ]; then
  widths=""
fi
for width in $widths; do
  t0=$SECONDS
  emulate=""
  if [ "$width" = 128 ]; then
    emulate=spec-limits
  fi
  LP_NATIVE_VECTOR_WIDTH=$width VKSPLAT_EMULATE=$emulate \
    cargo test -q --test all -- "${width_tests[@]}"
  echo "test.sh: GPU tests at LP_NATIVE_VECTOR_WIDTH=$width${emulate:+ with $emulate} took $((SECONDS - t0)) s" >&2
done

# The binary `cargo test` built for the integration tests (same profile: nothing to rebuild),
# used by the Slurm test and the Python tests below.
cargo build -q --profile test --bin vksplat
# Job arrays on a single-node Slurm cluster it starts and stops (skipped, loudly, only when
# not root or without Slurm, and never with CI=true).
t0=$SECONDS
VKSPLAT_BIN="$PWD/target/debug/vksplat" tools/slurm_test.sh
echo "test.sh: slurm_test.sh took $((SECONDS - t0)) s" >&2

if [ "${VKSPLAT_SKIP_PYTHON:-0}" = 1 ]; then
  exit 0
fi
# The Python package: built and installed as a user does (`pip install ./python`), into
# a virtualenv made anew, and tested against the command-line binary built above.
venv=target/pyenv
rm -rf "$venv"
python3 -m venv "$venv"
"$venv/bin/pip" install -q --upgrade pip
# torch (the `torch` extra, for vksplat.torch) first, timed on its own: PyPI's Linux wheel
# with its CUDA libraries, about 5 GB (torch runs on the CPU here).
t0=$SECONDS
"$venv/bin/pip" install -q "torch>=2"
echo "test.sh: pip install torch took $((SECONDS - t0)) s" >&2
t0=$SECONDS
CARGO_TARGET_DIR="$PWD/target/python" "$venv/bin/pip" install -q "./python[notebook,test,torch]"
echo "test.sh: pip install ./python took $((SECONDS - t0)) s" >&2
t0=$SECONDS
# The torch tests must run here, not skip.
VKSPLAT_REQUIRE_TORCH=1 VKSPLAT_BIN="$PWD/target/debug/vksplat" "$venv/bin/pytest" -q python/tests
echo "test.sh: pytest took $((SECONDS - t0)) s" >&2
