#!/usr/bin/env bash
# Installs what cross-compiling needs on these machines (DESIGN.md, "Cross-compiling"):
# Debian's rustc-web (a rustc that can build `core` for any target with -Zbuild-std), the
# standard library sources for it, and lld. Idempotent: installs only what is missing.
set -euo pipefail
need=()
for package in rustc-web rust-web-src lld-22 "$@"; do
  dpkg -s "$package" >/dev/null 2>&1 || need+=("$package")
done
if [ ${#need[@]} -gt 0 ]; then
  sudo=""
  if [ "$(id -u)" -ne 0 ]; then sudo=sudo; fi
  $sudo apt-get update -qq
  DEBIAN_FRONTEND=noninteractive $sudo apt-get install -y -qq "${need[@]}" >/dev/null
fi
