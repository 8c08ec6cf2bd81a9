#!/usr/bin/env bash
# Checks of `mochi export`'s glTF files by their own tools, run as their own packages, never
# copied: the Khronos glTF validator (npm `gltf-validator`, pinned, into target/gltf-tools)
# and trimesh (PyPI, pinned, into target/gltf-venv).
#
#   scripts/gltf.sh check FILE.glb [...]   # validator (no error, no warning) and trimesh (opens,
#       one mesh; its vertices and triangles those the file's JSON gives; the animation's
#       keyframes one per morph target and the base)
#   scripts/gltf.sh self-check              # exports two committed models with `mochi export`
#       (a render mesh with UVs; a surface pushed out of a collider) and checks both
#   scripts/gltf.sh setup                   # only install the tools
set -euo pipefail

cd "$(dirname "$0")/.."
tools=target/gltf-tools
venv=target/gltf-venv
VALIDATOR=2.0.0-dev.3.10
TRIMESH=4.12.2
NUMPY=2.4.6

if [ "$(node -p "require('./$tools/node_modules/gltf-validator/package.json').version" 2>/dev/null)" != "$VALIDATOR" ]; then
  command -v npm >/dev/null || scripts/install-cross.sh
  echo "== gltf-validator $VALIDATOR from npm into $tools" >&2
  mkdir -p "$tools"
  [ -f "$tools/package.json" ] || echo '{"private": true}' >"$tools/package.json"
  npm install --prefix "$tools" --silent --no-audit --no-fund "gltf-validator@$VALIDATOR" >&2
fi
if ! "$venv/bin/python" -c "import trimesh, numpy; assert trimesh.__version__ == '$TRIMESH' and numpy.__version__ == '$NUMPY'" 2>/dev/null; then
  echo "== trimesh $TRIMESH and numpy $NUMPY from PyPI into $venv" >&2
  python3 -m venv "$venv" ||
    { echo "python3 -m venv failed (on Debian and Ubuntu: apt-get install python3-venv)" >&2; exit 1; }
  "$venv/bin/python" -m pip install --quiet --disable-pip-version-check "trimesh==$TRIMESH" "numpy==$NUMPY"
fi

check() {
  local status=0
  GLTF_TOOLS=$tools node scripts/gltf_validate.mjs "$@" || status=1
  "$venv/bin/python" scripts/gltf_check.py "$@" || status=1
  return $status
}

usage() { sed -n '2,/^set -e/p' "$0" | sed '$d' | sed 's/^# \{0,1\}//' >&2; exit 2; }
[ $# -ge 1 ] || usage
cmd=$1
shift
case "$cmd" in
  setup) ;;
  check)
    [ $# -ge 1 ] || usage
    check "$@"
    ;;
  self-check)
    dir=$(mktemp -d)
    trap 'rm -rf "$dir"' EXIT
    mochi=$(scripts/mochi-bin.sh)
    "$mochi" export tests/artifacts/tiny-render.mochi --out "$dir/tiny-render.glb" --frames 40
    "$mochi" export tests/artifacts/tiny-poke.mochi --out "$dir/tiny-poke.glb" --frames 40 --weights int8
    if check "$dir/tiny-render.glb" "$dir/tiny-poke.glb"; then
      echo "gltf self-check: 2 passed, 0 failed"
    else
      echo "gltf self-check: 0 passed, 2 failed"
      exit 1
    fi
    ;;
  *) usage ;;
esac
