#!/usr/bin/env bash
# Prints the path of a `mochi` binary for the self-checks: the one the test command's
# `cargo test` built (MOCHI_BIN, set by scripts/test.sh), or a dev-profile build of it.
set -euo pipefail
cd "$(dirname "$0")/.."
if [ -n "${MOCHI_BIN:-}" ]; then
  echo "$MOCHI_BIN"
else
  cargo build -q -p mochi-trainer --bin mochi
  echo "$PWD/target/debug/mochi"
fi
