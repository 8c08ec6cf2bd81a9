#!/usr/bin/env bash
# Builds the runtime without std for a bare-metal target (default: Cortex-M4F), or for an OS
# target whose app links the static library (aarch64-linux-android: a phone or headset app).
# Only `core` is built for the target (-Zbuild-std=core), so the build fails if the runtime
# links `alloc`.
set -euo pipefail
cd "$(dirname "$0")/../runtime"
target="${1:-thumbv7em-none-eabihf}"
# wasm is built with 128-bit SIMD (the runtime's int8 kernel uses it; every current engine has it).
flags=""
case "$target" in wasm32-*) flags="-C target-feature=+simd128" ;; esac
RUSTFLAGS="$flags" RUSTC=/usr/bin/rustc RUSTC_BOOTSTRAP=1 cargo build --release --no-default-features --features capi \
  -Zbuild-std=core,panic_abort --target "$target" --target-dir ../target/cross
echo "mochi-runtime (with its C ABI) builds for $target with core only (no std, no alloc)"
