#!/usr/bin/env bash
# The test command from the README: installs system packages if missing, then runs the
# whole suite on lavapipe with the Khronos validation layer enabled (any validation
# message fails the GPU tests): the Rust tests, the Slurm job-array test
# (tools/slurm_test.sh), then the Python package built with pip
# in a fresh virtualenv (target/pyenv) and its pytest suite.
# Arguments go to `cargo test` (e.g. a test name); VKSPLAT_SKIP_PYTHON=1 skips the
# Python part.
set -euo pipefail
cd "$(dirname "$0")/.."
tools/setup.sh
export VKSPLAT_VALIDATE=1
t0=$SECONDS
cargo test --all-targets "$@"
echo "test.sh: cargo test took $((SECONDS - t0)) s" >&2

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
