#!/usr/bin/env bash
# Builds the Cortex-M4F firmware for a generated model and runs it under QEMU (mps2-an386).
#   scripts/run-cortex-m4.sh [ARTIFACT] [f32|f16|int8]
# Prints flash and RAM use from the linked ELF, the firmware's output (checksums, final
# positions, instructions per frame, peak stack), and the frame rate a 168 MHz Cortex-M4 would
# reach at one instruction per cycle; keeps the output in
# target/targets/cortex-m4-<name>-<weights>.txt. The linker script gives the firmware 1 MiB
# of flash and 64 KiB of RAM: a model that does not fit fails to link.
set -euo pipefail
repo="$(cd "$(dirname "$0")/.." && pwd)"
artifact="$(realpath "${1:-$repo/tests/artifacts/tiny.mochi}")"
weights="${2:-f32}"
name="$(basename "$artifact" .mochi)"
for tool in /usr/bin/rustc rust-lld qemu-system-arm readelf; do
  command -v "$tool" >/dev/null || { echo "$tool not found: run scripts/install-cross.sh" >&2; exit 1; }
done
# -Zbuild-std compiles `core` from the sources of Debian's rust-web-src.
if [ ! -d "$(/usr/bin/rustc --print sysroot)/lib/rustlib/src/rust/library/core" ]; then
  echo "the standard library sources for /usr/bin/rustc are missing: run scripts/install-cross.sh" >&2
  exit 1
fi
cd "$repo/targets/cortex-m4"
out="$repo/target/targets/cortex-m4-$name-$weights.txt"
elf="$repo/target/targets/cortex-m4-$name-$weights.elf"
mkdir -p "$(dirname "$out")"
log="$(mktemp)"
trap 'rm -f "$log"' EXIT
# One build at a time (the ELF's path is shared by every model): build, then keep a copy.
(
  flock 9
  if ! MOCHI_ARTIFACT="$artifact" MOCHI_WEIGHTS="$weights" RUSTC=/usr/bin/rustc RUSTC_BOOTSTRAP=1 \
    RUSTFLAGS="-D warnings -C link-arg=-Tlink.x" \
    cargo build --release --quiet -Zbuild-std=core,panic_abort --target thumbv7em-none-eabihf \
    --target-dir "$repo/target/cross" 2>"$log"; then
    cat "$log" >&2
    if grep -q "will not fit in region" "$log"; then
      echo "$name with $weights weights does not fit the firmware's 1 MiB of flash / 64 KiB of RAM" \
        "(memory.x): the linker's overflow is above" >&2
    fi
    echo "building the Cortex-M4 firmware for $artifact ($weights) failed" >&2
    exit 1
  fi
  cat "$log" >&2
  cp "$repo/target/cross/thumbv7em-none-eabihf/release/mochi-cortex-m4" "$elf"
) 9>"$repo/target/targets/.cortex-m4.lock"
# Section sizes: flash holds the vector table, code, read-only data and the initial values of
# .data; RAM holds .data, .bss and the stack (its peak is measured by the firmware).
read -r flash statics < <(readelf -S -W "$elf" | python3 -c '
import re, sys
flash = ram = 0
for line in sys.stdin:
    m = re.search(r"\]\s+(\.\S+)\s+\S+\s+[0-9a-f]+\s+[0-9a-f]+\s+([0-9a-f]+)", line)
    if not m:
        continue
    name, size = m.group(1), int(m.group(2), 16)
    if name in (".vector_table", ".text", ".rodata"):
        flash += size
    elif name == ".data":
        flash += size
        ram += size
    elif name in (".bss", ".uninit"):
        ram += size
print(flash, ram)')
status=0
timeout 600 qemu-system-arm -machine mps2-an386 -cpu cortex-m4 -semihosting-config enable=on,target=native \
  -nographic -icount shift=0 -kernel "$elf" > "$out" || status=$?
grep -v '^positions' "$out" || true
stack=$(awk '$1 == "stack_bytes" { print $2 }' "$out")
per_frame=$(awk '$1 == "instructions_per_frame" { print $2 }' "$out")
echo "flash ${flash} bytes ($(awk -v b="$flash" 'BEGIN { printf "%.1f", b / 1024 }') KiB of 1024), RAM ${statics} bytes static + ${stack:-?} stack = $(( statics + ${stack:-0} )) bytes ($(awk -v b="$(( statics + ${stack:-0} ))" 'BEGIN { printf "%.1f", b / 1024 }') KiB of 64)"
if [ -n "$per_frame" ]; then
  awk -v n="$per_frame" 'BEGIN { printf "168 MHz Cortex-M4 at one instruction per cycle: %.0f frames/s (%.2f ms/frame)\n", 168e6 / n, 1e3 * n / 168e6 }'
fi
if [ "$status" -ne 0 ]; then
  echo "firmware exited with status $status (output in $out)" >&2
  exit "$status"
fi
