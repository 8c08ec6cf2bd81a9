#!/usr/bin/env bash
# Builds the runtime for aarch64-unknown-linux-gnu (the artifact runner `targets/aarch64` and
# the C static library with the C program `targets/c/main.c`) and runs them under QEMU user-mode
# emulation, counting instructions with a QEMU plugin (targets/aarch64/insn-count.c).
#   scripts/run-aarch64.sh [ARTIFACT:WEIGHTS[:KERNELS] ...]
# KERNELS: neon (default: the NEON kernels, SDOT for int8), canonical (the hand-written
# kernels off: what the compiler makes of the portable loops), nodot (a CPU without the
# dot-product extension, QEMU's Cortex-A72: int8 through SMLAL). Without arguments: every
# shipped model (beam-m8, cloth-line-m24, rods-m8, beam), the collider model tiny-poke and the
# render-mesh model tiny-render (its render pass too) in f32, f16 and int8 with the NEON
# kernels, beam-m8 in all three with the canonical code, and beam-m8 int8 without SDOT.
# Each run's output (the protocol every target prints, plus `instructions_per_frame`: step +
# full decode, mean over 100 frames) goes to target/targets/aarch64-<name>-<weights>-<kernels>.txt,
# the C program's to target/targets/aarch64-c.txt; one summary line per run is printed.
set -euo pipefail
repo="$(cd "$(dirname "$0")/.." && pwd)"
triple=aarch64-unknown-linux-gnu
for tool in /usr/bin/rustc aarch64-linux-gnu-gcc qemu-aarch64 cc; do
  command -v "$tool" >/dev/null || { echo "$tool not found: run scripts/install-cross.sh" >&2; exit 1; }
done
if [ ! -d "$(/usr/bin/rustc --print sysroot)/lib/rustlib/src/rust/library/std" ]; then
  echo "the standard library sources for /usr/bin/rustc are missing: run scripts/install-cross.sh" >&2
  exit 1
fi
runs=("$@")
if [ ${#runs[@]} -eq 0 ]; then
  for model in beam-m8 cloth-line-m24 rods-m8 beam tiny-poke tiny-render; do
    for weights in f32 f16 int8; do runs+=("$repo/tests/artifacts/$model.mochi:$weights:neon"); done
  done
  for weights in f32 f16 int8; do runs+=("$repo/tests/artifacts/beam-m8.mochi:$weights:canonical"); done
  runs+=("$repo/tests/artifacts/beam-m8.mochi:int8:nodot")
fi
out="$repo/target/targets"
build="$repo/target/cross-aarch64"
release="$build/$triple/release"
mkdir -p "$out"
# One build at a time; std is built from Debian's rust-web-src (-Zbuild-std).
(
  flock 9
  cd "$repo"
  RUSTC=/usr/bin/rustc RUSTC_BOOTSTRAP=1 CARGO_TARGET_AARCH64_UNKNOWN_LINUX_GNU_LINKER=aarch64-linux-gnu-gcc \
    RUSTFLAGS="-D warnings" cargo build --release --quiet -Zbuild-std=std,panic_abort --target "$triple" \
    -p mochi-aarch64 -p mochi-c --target-dir "$build"
  cc -shared -fPIC -O2 -Wall -Wextra -Werror -o "$build/insn-count.so" "$repo/targets/aarch64/insn-count.c"
  # The committed header (its test checks it equals the generated one).
  aarch64-linux-gnu-gcc -std=c11 -Wall -Wextra -Werror -O2 -I "$repo/targets/c/include" "$repo/targets/c/main.c" \
    "$release/libmochi_c.a" -lm -lpthread -ldl -o "$build/mochi-c-program"
) 9>"$out/.aarch64.lock"
qemu() { qemu-aarch64 -L /usr/aarch64-linux-gnu "$@"; }
# The C program (the tiny model in f32, as the host's C test).
qemu "$build/mochi-c-program" > "$out/aarch64-c.txt"
echo "C program: $(grep -c '^checksum' "$out/aarch64-c.txt") checksums, $(tail -n 1 "$out/aarch64-c.txt")"
# One run: its report, the instruction count appended, one summary line; its exit status.
run_one() {
  local artifact weights kernels name report log status args cpu
  IFS=: read -r artifact weights kernels <<<"$1"
  kernels="${kernels:-neon}"
  name="$(basename "$artifact" .mochi)"
  report="$out/aarch64-$name-$weights-$kernels.txt"
  args=()
  cpu=()
  case "$kernels" in
    neon) ;;
    canonical) args+=(canonical) ;;
    nodot) cpu=(-cpu cortex-a72) ;;
    *) echo "unknown kernels \`$kernels\` (neon, canonical, nodot)" >&2; exit 1 ;;
  esac
  log="$(mktemp)"
  status=0
  qemu "${cpu[@]}" -plugin "$build/insn-count.so" -d plugin -D "$log" "$release/mochi-aarch64" \
    "$artifact" "$weights" "${args[@]}" > "$report" || status=$?
  # instructions per frame: the plugin's counts at the two marks around the timed frames.
  awk -v frames="$(awk '$1 == "timed_frames" { print $2 }' "$report")" \
    '$1 == "count_mark" { c[n++] = $2 } END { if (n == 2 && frames > 0) printf "instructions_per_frame %d\n", (c[1] - c[0]) / frames }' \
    "$log" >> "$report"
  rm -f "$log"
  echo "$name $weights $kernels: $(awk '$1 == "instructions_per_frame" { print $2 " instructions per frame" }' "$report"), $(grep '^status' "$report")"
  if [ "$status" -ne 0 ]; then
    echo "$name ($weights, $kernels) exited with status $status (output in $report)" >&2
    return "$status"
  fi
}
# The runs are independent (one QEMU process each): as many at once as there are cores.
failed=0
for run in "${runs[@]}"; do
  while [ "$(jobs -rp | wc -l)" -ge "$(nproc)" ]; do wait -n || failed=1; done
  run_one "$run" &
done
for pid in $(jobs -p); do wait "$pid" || failed=1; done
exit "$failed"
