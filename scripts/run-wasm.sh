#!/usr/bin/env bash
# Builds the wasm module for a generated model, runs the reference script in node, and checks
# the web page in headless Chromium.
#   scripts/run-wasm.sh [ARTIFACT] [f32|f16|int8]
# The page offers the model compiled into the module and the artifacts it fetches from its
# models/ folder: MOCHI_PAGE_MODELS (space-separated .mochi files; default the committed
# right-sized models tests/artifacts/beam-m8.mochi and cloth-line-m24.mochi). Models without
# triangles to draw (rods) are drawn as points.
# Outputs: target/targets/wasm-<name>-<weights>.txt (the node run, the protocol every target
# prints), target/targets/web/ (the page, ready to serve), target/targets/wasm-page.png and
# wasm-page-<model>.png (screenshots). Fails when node fails, or when for some model the page's
# frames do not advance, the surface does not move or is not drawn, or no time per frame shows
# (scripts/check-page.py).
set -euo pipefail
repo="$(cd "$(dirname "$0")/.." && pwd)"
artifact="$(realpath "${1:-$repo/tests/artifacts/tiny.mochi}")"
weights="${2:-f32}"
name="$(basename "$artifact" .mochi)"
page_models=()
for page_model in ${MOCHI_PAGE_MODELS:-$repo/tests/artifacts/beam-m8.mochi $repo/tests/artifacts/cloth-line-m24.mochi}; do
  page_models+=("$(realpath "$page_model")")
done
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
cp web/index.html web/main.js web/render.js "$web/"
# The artifacts the page fetches (not the compiled one again), and the list it reads.
rm -rf "$web/models"
mkdir -p "$web/models"
entries=""
first=""
page_names=()
for page_model in "${page_models[@]}"; do
  page_name="$(basename "$page_model" .mochi)"
  [ "$page_name" = "$name" ] && continue
  cp "$page_model" "$web/models/$page_name.mochi"
  entries+="${entries:+, }{\"name\": \"$page_name\", \"file\": \"models/$page_name.mochi\", \"bytes\": $(stat -c %s "$page_model")}"
  first="${first:-$page_name}"
  page_names+=("$page_name")
done
printf '{"compiled": {"name": "%s", "weights": "%s"}, "default": "%s", "models": [%s]}\n' \
  "$name" "$weights" "${first:-$name}" "$entries" > "$web/models.json"
t1=$(seconds)
echo "module: $(stat -c %s "$module") bytes"

node test.mjs "$module" "$name" "$weights" "$artifact" > "$out/wasm-$name-$weights.txt"
grep -v '^positions\|^frame\|^render_positions\|^render_normals' "$out/wasm-$name-$weights.txt"
t2=$(seconds)

# The page, from a local server, in headless Chromium (no GPU, no sandbox: CI runs as root).
port=$(python3 -c 'import socket; s = socket.socket(); s.bind(("127.0.0.1", 0)); print(s.getsockname()[1])')
server=""
trap 'if [ -n "$server" ]; then kill "$server" 2>/dev/null || true; fi' EXIT
python3 -m http.server "$port" --bind 127.0.0.1 --directory "$web" >/dev/null 2>&1 &
server=$!
for _ in $(seq 50); do
  python3 -c "import urllib.request; urllib.request.urlopen('http://127.0.0.1:$port/index.html')" 2>/dev/null && break
  sleep 0.1
done
python3 "$repo/scripts/check-page.py" "http://127.0.0.1:$port/index.html?test=1" "$out" --frames 120 \
  --expect "$name" "${page_names[@]}"
t3=$(seconds)
awk -v a="$t0" -v b="$t1" -v c="$t2" -v d="$t3" 'BEGIN { printf "build %.1f s, node %.1f s, browser %.1f s\n", b - a, c - b, d - c }'
