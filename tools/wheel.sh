#!/usr/bin/env bash
# Builds the Python package as a wheel that installs without Rust or glslc
# (docs/python.md, "A wheel, for machines without Rust"): `maturin build` of python/, with
# every shader's SPIR-V compiled in by build.rs and the Vulkan loader (libvulkan.so.1)
# opened at run time as the `verisplat` binary opens it, never linked. zig links it
# against glibc 2.28's symbols, so it carries the tag manylinux_2_28_x86_64 (pip takes it
# on x86-64 Linux with glibc 2.28 or newer) and cp39-abi3 (any CPython >= 3.9); maturin
# refuses the tag if the library needs a newer symbol.
# maturin and zig (PyPI's ziglang) are pinned and installed into target/wheel-env. The
# build itself needs what any build needs (Rust, glslc: tools/setup.sh).
# Usage: tools/wheel.sh (no arguments): the wheel goes to target/wheels/, replacing the one
# there; its path is printed last (tools/test.sh builds it so and runs tools/wheel_test.sh).
set -euo pipefail
cd "$(dirname "$0")/.."

if [ $# -gt 0 ]; then
  echo "usage: tools/wheel.sh (no arguments)" >&2
  exit 2
fi
out=target/wheels

maturin_version=1.16.0
zig_version=0.17.0
env_dir=target/wheel-env
want="maturin==$maturin_version ziglang==$zig_version"
if [ "$(cat "$env_dir/.installed" 2>/dev/null)" != "$want" ]; then
  rm -rf "$env_dir"
  python3 -m venv "$env_dir"
  # shellcheck disable=SC2086 # $want is two requirement words
  "$env_dir/bin/pip" install -q $want >&2
  echo "$want" >"$env_dir/.installed"
fi

mkdir -p "$out"
rm -f "$out"/verisplat-*.whl
# With the virtualenv first on the PATH, maturin finds its python and runs zig from its ziglang.
PATH="$PWD/$env_dir/bin:$PATH" maturin build --release --zig \
  --compatibility manylinux_2_28 -m python/Cargo.toml -o "$out" >&2
ls "$out"/verisplat-*.whl
