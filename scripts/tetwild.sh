#!/usr/bin/env bash
# Tet meshes of surface assets: fTetWild through PyPI's `pytetwild` (MPL-2.0, pinned), run as
# its own package in its own virtual environment, never copied. `mochi mesh` calls `run`;
# TetGen (Debian's `tetgen`, AGPL, a separately invoked program) is here only to compare
# robustness on real assets.
#
#   scripts/tetwild.sh run SURFACE.npz OUT.mesh [--edge-length L] [--epsilon E] [--threads N]
#       SURFACE.npz: `vertices` (n, 3) f64, `faces` (m, 3) int (closed, outward, as `mochi
#       mesh` writes it); OUT.mesh: MEDIT tets, written whole or not at all; prints one JSON
#       line: vertices, tets, seconds, min_volume, flipped.
#   scripts/tetwild.sh tetgen SURFACE.npz OUT.mesh [--edge-length L]
#       the same with TetGen (`tetgen -pq1.414a...`; apt-get install tetgen)
#   scripts/tetwild.sh self-check     # seconds: a sphere meshed at two resolutions, checked
#   scripts/tetwild.sh check-render NAME.mesh NAME.render.npz   # a `mochi mesh` output's
#       render embedding: weights within tolerance, rest positions rebuilt within their distance
#   scripts/tetwild.sh setup          # only make the virtual environment
#
# 1. a virtual environment target/tetwild-venv with pytetwild, pyvista and numpy from PyPI
#    (made once);
# 2. scripts/tetwild_run.py, whose docstring says what it checks and writes.
set -euo pipefail

cd "$(dirname "$0")/.."
venv=target/tetwild-venv
PYTETWILD=0.4.2
NUMPY=2.4.6
# pytetwild imports pyvista (and so VTK) on import without declaring it: installed beside it.
PYVISTA=0.49.1

if ! "$venv/bin/python" -c "import pytetwild, pyvista, numpy; assert numpy.__version__ == '$NUMPY'" 2>/dev/null ||
  [ "$("$venv/bin/python" -m pip show pytetwild 2>/dev/null | sed -n 's/^Version: //p')" != "$PYTETWILD" ]; then
  echo "== pytetwild $PYTETWILD and numpy $NUMPY from PyPI into $venv" >&2
  python3 -m venv "$venv" ||
    { echo "python3 -m venv failed (on Debian and Ubuntu: apt-get install python3-venv)" >&2; exit 1; }
  "$venv/bin/python" -m pip install --quiet --disable-pip-version-check "pytetwild==$PYTETWILD" "pyvista==$PYVISTA" "numpy==$NUMPY"
fi

usage() { sed -n '2,/^set -e/p' "$0" | sed '$d' | sed 's/^# \{0,1\}//' >&2; exit 2; }
[ $# -ge 1 ] || usage
cmd=$1
shift
case "$cmd" in
  setup) ;;
  self-check) "$venv/bin/python" scripts/tetwild_run.py --self-check "$@" ;;
  check-render)
    [ $# -ge 2 ] || usage
    "$venv/bin/python" scripts/tetwild_run.py "$1" "$2" --check-render
    ;;
  run)
    [ $# -ge 2 ] || usage
    "$venv/bin/python" scripts/tetwild_run.py "$1" "$2" "${@:3}"
    ;;
  tetgen)
    [ $# -ge 2 ] || usage
    command -v tetgen >/dev/null || { echo "tetgen is not installed (apt-get install tetgen)" >&2; exit 1; }
    "$venv/bin/python" scripts/tetwild_run.py "$1" "$2" --mesher tetgen "${@:3}"
    ;;
  *) usage ;;
esac
