#!/usr/bin/env bash
# The README's test command: installs what the target tests need when it is missing (Debian's
# rustc-web, rust-web-src, rust-web-llvm and lld for cross-compiling; QEMU, Chromium, node), then runs every
# test of the workspace, the Cortex-M4 firmware under QEMU, the wasm module in node and in
# headless Chromium, and the C program among them, then the XPBD peer's, the tet mesher's,
# the glTF export's and the Ray dataset's self-checks. Prints one
# closing tally line.
set -euo pipefail
cd "$(dirname "$0")/.."
scripts/install-cross.sh
log=$(mktemp)
targets_log=$(mktemp)
trap 'rm -f "$log" "$targets_log"' EXIT
# Libraries, binaries and integration tests (examples are compiled by clippy, not here). The
# three target runs (`tests/tests/target_*.rs`, left out of a plain `cargo test`) spend most of
# their time on one core (each firmware's and module's LTO link, QEMU, node, Chromium), so they
# run beside the rest instead of after it. Both selections span the workspace, so that they
# resolve the same features and share every build; everything is built first. Arguments go
# to every `cargo test` below.
selection=(--workspace --lib --bins --tests)
targets=(--workspace --test 'target_*')
set +e
{ cargo test "${selection[@]}" --no-run "$@" && cargo test "${targets[@]}" --no-run "$@"; } 2>&1 | tee "$log"
status=${PIPESTATUS[0]}
if [ "$status" -eq 0 ]; then
  cargo test "${targets[@]}" "$@" >"$targets_log" 2>&1 &
  runs=$!
  cargo test "${selection[@]}" "$@" 2>&1 | tee -a "$log"
  [ "${PIPESTATUS[0]}" -eq 0 ] || status=1
  wait "$runs" || status=1
  echo "== the target runs (Cortex-M4, AArch64, wasm)"
  tee -a "$log" <"$targets_log"
fi
# The self-checks below that run `mochi` take the binary `cargo test` built for the trainer's
# integration tests (target/debug, the test profile; it did when those ran) instead of
# building the dev profile as well.
if grep -q "Running tests/cli.rs" "$log"; then
  export MOCHI_BIN="$PWD/target/debug/mochi"
fi
# The XPBD peer's self-check (pypbd from PyPI into target/pbd-venv once, then about a second).
scripts/xpbd.sh self-check 2>&1 | tee -a "$log"
[ "${PIPESTATUS[0]}" -eq 0 ] || status=1
# The tet mesher's self-check (pytetwild from PyPI into target/tetwild-venv once, then seconds).
scripts/tetwild.sh self-check 2>&1 | tee -a "$log"
[ "${PIPESTATUS[0]}" -eq 0 ] || status=1
# `mochi export`'s glTF files through the Khronos validator and trimesh (target/gltf-tools and
# target/gltf-venv once, then seconds).
scripts/gltf.sh self-check 2>&1 | tee -a "$log"
[ "${PIPESTATUS[0]}" -eq 0 ] || status=1
# Datasets through Ray: a local head and worker node, a worker killed once, the files byte for
# byte the single-process ones (ray from PyPI into target/ray-venv once, then about a minute).
scripts/ray-dataset.sh self-check 2>&1 | tee -a "$log"
[ "${PIPESTATUS[0]}" -eq 0 ] || status=1
set -e
# One closing line over every test binary (cargo prints one result line per binary) and the
# XPBD, tet mesher, glTF and Ray self-checks.
awk '/^(test result|xpbd self-check|tetwild self-check|gltf self-check|ray self-check):/ { for (i = 1; i <= NF; i++) { if ($i ~ /^passed[;,]?$/) p += $(i-1); if ($i ~ /^failed[;,]?$/) f += $(i-1) } }
     END { printf "tests: %d passed, %d failed\n", p, f }' "$log"
exit "$status"
