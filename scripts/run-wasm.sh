#!/usr/bin/env bash
# Builds the wasm module for a generated model, runs the reference script in node, and checks
# the web page in headless Chromium.
#   scripts/run-wasm.sh [ARTIFACT] [f32|f16|int8]
# Outputs: target/targets/wasm-<name>-<weights>.txt (the node run, the protocol every target
# prints), target/targets/web/ (the page, ready to serve), target/targets/wasm-page.png (a
# screenshot). Fails when node fails, when the page's frames do not advance, or when the mesh
# does not move.
set -euo pipefail
repo="$(cd "$(dirname "$0")/.." && pwd)"
artifact="$(realpath "${1:-$repo/tests/artifacts/tiny.mochi}")"
weights="${2:-f32}"
name="$(basename "$artifact" .mochi)"
for tool in /usr/bin/rustc node chromium python3; do
  command -v "$tool" >/dev/null || { echo "$tool not found: run scripts/install-cross.sh" >&2; exit 1; }
done
seconds() { date +%s.%N; }
t0=$(seconds)
cd "$repo/targets/wasm"
out="$repo/target/targets"
web="$out/web"
module="$out/mochi-$name-$weights.wasm"
mkdir -p "$web"
# One build at a time (the module's path is shared by every model): build, then keep a copy.
(
  flock 9
  MOCHI_ARTIFACT="$artifact" MOCHI_WEIGHTS="$weights" RUSTC=/usr/bin/rustc RUSTC_BOOTSTRAP=1 RUSTFLAGS="-D warnings -C target-feature=+simd128" \
    cargo build --release --quiet -Zbuild-std=core,panic_abort --target wasm32-unknown-unknown \
    --target-dir "$repo/target/cross"
  cp "$repo/target/cross/wasm32-unknown-unknown/release/mochi_wasm.wasm" "$module"
) 9>"$out/.wasm.lock"
cp "$module" "$web/mochi.wasm"
cp web/index.html web/main.js "$web/"
t1=$(seconds)
echo "module: $(stat -c %s "$module") bytes"

node test.mjs "$module" "$name" "$weights" > "$out/wasm-$name-$weights.txt"
grep -v '^positions\|^frame' "$out/wasm-$name-$weights.txt"
t2=$(seconds)

# The page, from a local server, in headless Chromium (no GPU, no sandbox: CI runs as root).
port=$(python3 -c 'import socket; s = socket.socket(); s.bind(("127.0.0.1", 0)); print(s.getsockname()[1])')
profile=$(mktemp -d)
server=""
trap 'if [ -n "$server" ]; then kill "$server" 2>/dev/null || true; fi; rm -rf "$profile"' EXIT
python3 -m http.server "$port" --bind 127.0.0.1 --directory "$web" >/dev/null 2>&1 &
server=$!
for _ in $(seq 50); do
  python3 -c "import urllib.request; urllib.request.urlopen('http://127.0.0.1:$port/index.html')" 2>/dev/null && break
  sleep 0.1
done
url="http://127.0.0.1:$port/index.html?test=1&frames=120"
browser=(chromium --headless --no-sandbox --disable-gpu --disable-dev-shm-usage --no-first-run
  --user-data-dir="$profile" --window-size=840,720 --virtual-time-budget=20000)
dom=$(timeout 120 "${browser[@]}" --dump-dom "$url" 2>/dev/null)
status=$(printf '%s' "$dom" | python3 -c 'import re, sys; m = re.search(r"<pre id=\"status\">([^<]*)</pre>", sys.stdin.read()); print(m.group(1) if m else "no status")')
timeout 120 "${browser[@]}" --screenshot="$out/wasm-page.png" "$url" >/dev/null 2>&1
t3=$(seconds)
echo "page: $status"
python3 - "$status" <<'PY'
import re, sys
line = sys.argv[1]
m = re.match(r"frames=(\d+) moved=([0-9.]+) status=(-?\d+)", line)
if not m:
    sys.exit(f"the page did not report its frames: {line!r}")
frames, moved, status = int(m.group(1)), float(m.group(2)), int(m.group(3))
if frames < 100 or " done" not in line:
    sys.exit(f"frames did not advance to the end of the test: {line!r}")
if not moved > 1e-3:
    sys.exit(f"the mesh did not move: {line!r}")
if status < 0:
    sys.exit(f"the last step was refused: {line!r}")
PY
[ -s "$out/wasm-page.png" ] || { echo "no screenshot" >&2; exit 1; }
awk -v a="$t0" -v b="$t1" -v c="$t2" -v d="$t3" 'BEGIN { printf "build %.1f s, node %.1f s, browser %.1f s\n", b - a, c - b, d - c }'
