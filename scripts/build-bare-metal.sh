#!/usr/bin/env bash
# Compiles the runtime (with its C ABI) without std for a bare-metal target (default:
# Cortex-M4F), or for an OS target whose app links the library (aarch64-linux-android: a phone
# or headset app). Only `core` is available for the target (-Zbuild-std=core), so this fails
# if the runtime uses `std` or `alloc`. `cargo check` (no code generation) is enough for that:
# the library is linked by nothing here, and the Cortex-M4, wasm and AArch64 tests generate
# and run the same code for those instruction sets (`scripts/run-*.sh`).
set -euo pipefail
cd "$(dirname "$0")/../runtime"
target="${1:-thumbv7em-none-eabihf}"
# wasm is built with 128-bit SIMD (the runtime's int8 kernel uses it; every current engine has it).
flags=""
case "$target" in wasm32-*) flags="-C target-feature=+simd128" ;; esac
RUSTFLAGS="$flags" RUSTC=/usr/bin/rustc RUSTC_BOOTSTRAP=1 cargo check --release --no-default-features --features capi \
  -Zbuild-std=core,panic_abort --target "$target" --target-dir ../target/cross
echo "mochi-runtime (with its C ABI) compiles for $target with core only (no std, no alloc)"
