#!/usr/bin/env bash
# Installs what cross-compiling and running the targets need on these machines (docs/design.md,
# "Cross-compiling"): Debian's rustc-web (a rustc that can build `core` for any target with
# -Zbuild-std), the standard library sources for it, rust-web-llvm (which provides the
# `rust-lld` that links the firmware and the wasm module; apt does not pull it in when
# recommends are off), lld, QEMU for the Cortex-M4 firmware, the aarch64 cross C compiler and C
# library with QEMU user-mode emulation (whose instruction-counting plugin is built from
# targets/aarch64/insn-count.c with the host's cc), Chromium for the web page's headless test,
# and node for the wasm module (when the machine has none). Idempotent:
# installs only what is missing, and checks afterwards that every tool is really there.
set -euo pipefail
need=()
for package in rustc-web rust-web-src rust-web-llvm lld-22 qemu-system-arm gcc-aarch64-linux-gnu \
  libc6-dev-arm64-cross qemu-user chromium "$@"; do
  dpkg -s "$package" >/dev/null 2>&1 || need+=("$package")
done
command -v node >/dev/null 2>&1 || need+=(nodejs)
# npm installs the glTF validator (scripts/gltf.sh).
command -v npm >/dev/null 2>&1 || need+=(npm)
if [ ${#need[@]} -gt 0 ]; then
  sudo=""
  if [ "$(id -u)" -ne 0 ]; then sudo=sudo; fi
  echo "installing: ${need[*]}"
  $sudo apt-get update -qq
  DEBIAN_FRONTEND=noninteractive $sudo apt-get install -y -qq --no-install-recommends "${need[@]}" >/dev/null
fi
for tool in /usr/bin/rustc rust-lld qemu-system-arm aarch64-linux-gnu-gcc qemu-aarch64 cc chromium node npm; do
  command -v "$tool" >/dev/null 2>&1 || { echo "install-cross.sh: $tool is still missing after installing" >&2; exit 1; }
done
