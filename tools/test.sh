#!/usr/bin/env bash
# The test command from the README: installs system packages if missing, then runs the
# whole suite on lavapipe with the Khronos validation layer enabled (any validation
# message fails the GPU tests).
set -euo pipefail
cd "$(dirname "$0")/.."
tools/setup.sh
export VKSPLAT_VALIDATE=1
cargo test --all-targets "$@"
