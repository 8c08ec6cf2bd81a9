#!/usr/bin/env bash
# Compiles the runtime (with its C ABI) without std for bare-metal targets (default:
# Cortex-M4F), or for an OS target whose app links the library (aarch64-linux-android: a phone
# or headset app).
#   scripts/build-bare-metal.sh [TARGET ...]
# Only `core` is available for a target (-Zbuild-std=core), so this fails if the runtime uses
# `std` or `alloc`. `cargo check` (no code generation) is enough for that: the library is
# linked by nothing here, and the Cortex-M4, wasm and AArch64 tests generate and run the same
# code for those instruction sets (`scripts/run-*.sh`). Several targets go to one `cargo`,
# which checks their `core`s side by side.
set -euo pipefail
cd "$(dirname "$0")/../runtime"
[ $# -gt 0 ] || set -- thumbv7em-none-eabihf
targets=()
for target in "$@"; do targets+=(--target "$target"); done
# wasm is built with 128-bit SIMD (the runtime's int8 kernel uses it; every current engine has
# it). Flags per target: RUSTFLAGS, when set, would override them for every target.
env -u RUSTFLAGS CARGO_TARGET_WASM32_UNKNOWN_UNKNOWN_RUSTFLAGS="-C target-feature=+simd128" \
  RUSTC=/usr/bin/rustc RUSTC_BOOTSTRAP=1 cargo check --release --no-default-features --features capi \
  -Zbuild-std=core,panic_abort "${targets[@]}" --target-dir ../target/cross
echo "mochi-runtime (with its C ABI) compiles with core only (no std, no alloc) for: $*"
