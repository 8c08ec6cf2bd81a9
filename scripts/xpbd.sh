#!/usr/bin/env bash
# XPBD peer: Bender's PositionBasedDynamics from PyPI (`pypbd`, pinned) driven on a case that
# `mochi export-case` writes, pinned to one core. The library is used as installed, never copied.
#
#   scripts/xpbd.sh sweep CASE.npz OUTDIR [--frames N] [--substeps-list 1,4 --iterations-list 1,5]
#       every setting of substeps {1,2,4,8,16,32} x iterations {1,2,5,10,20}, plus 64, 128 and
#       256 substeps at 1 iteration -> OUTDIR/s{S}-i{I}.npz (one result per setting),
#       OUTDIR/sweep.md (table, Pareto front by thread CPU time), OUTDIR/sweep.json (the same rows)
#   scripts/xpbd.sh run CASE.npz RESULT.npz [--substeps 32] [--iterations 1] [--frames N]
#   scripts/xpbd.sh self-check        # seconds: the tiny hanging bar of scripts/xpbd_run.py
#   scripts/xpbd.sh threshold CASE.npz   # solid: share of tets the library's skip test turns off
#   scripts/xpbd.sh table OUTDIR      # rewrite OUTDIR/sweep.md from OUTDIR/sweep.json
#   scripts/xpbd.sh setup             # only make the virtual environment
#
# Further options (--mass-scale, --bending) pass through to scripts/xpbd_run.py, whose
# docstring describes the result files and how the library is driven.
#
# A result RESULT.npz holds positions (frames+1, n, 3), step_seconds (frames,), solver_seconds
# (frames,), cpu_seconds (frames,), substeps, iterations (0-d int64), mass_scale, bending,
# error_percent (frames+1,), frames_completed, constraint (description), pypbd_version. A run
# that diverges (a vertex 10 rest diagonals off the reference, or non-finite) stops there: its
# positions and times after frames_completed are NaN.
#
# 1. a virtual environment target/pbd-venv with pypbd and numpy from PyPI (made once);
# 2. scripts/xpbd_run.py pinned to core $CORE (default 0) with OpenMP on one thread.
# Timings are worth reporting only on a quiet machine (nothing else compiling or running).
set -euo pipefail

cd "$(dirname "$0")/.."
venv=target/pbd-venv
core=${CORE:-0}
PYPBD=2.2.2
NUMPY=2.4.6

if ! "$venv/bin/python" -c "import pypbd, numpy; assert numpy.__version__ == '$NUMPY'" 2>/dev/null ||
  [ "$("$venv/bin/python" -m pip show pypbd 2>/dev/null | sed -n 's/^Version: //p')" != "$PYPBD" ]; then
  echo "== pypbd $PYPBD and numpy $NUMPY from PyPI into $venv" >&2
  python3 -m venv "$venv" ||
    { echo "python3 -m venv failed (on Debian and Ubuntu: apt-get install python3-venv)" >&2; exit 1; }
  "$venv/bin/python" -m pip install --quiet --disable-pip-version-check "pypbd==$PYPBD" "numpy==$NUMPY"
fi

command -v taskset >/dev/null || { echo "taskset (util-linux) is needed to pin to one core" >&2; exit 1; }
export OMP_NUM_THREADS=1 OPENBLAS_NUM_THREADS=1 MKL_NUM_THREADS=1
run=(taskset -c "$core" "$venv/bin/python" scripts/xpbd_run.py)

usage() { sed -n '2,/^set -e/p' "$0" | sed '$d' | sed 's/^# \{0,1\}//' >&2; exit 2; }
[ $# -ge 1 ] || usage
cmd=$1
shift
case "$cmd" in
  setup) ;;
  self-check) "${run[@]}" --self-check "$@" ;;
  run)
    [ $# -ge 2 ] || usage
    case_file=$1 out=$2
    shift 2
    "${run[@]}" "$case_file" --out "$out" "$@"
    ;;
  sweep)
    [ $# -ge 2 ] || usage
    case_file=$1 outdir=$2
    shift 2
    "${run[@]}" "$case_file" --sweep "$outdir" "$@"
    ;;
  threshold)
    [ $# -ge 1 ] || usage
    "${run[@]}" "$1" --threshold-report
    ;;
  table)
    [ $# -ge 1 ] || usage
    "$venv/bin/python" scripts/xpbd_run.py --table "$1"
    ;;
  *) usage ;;
esac
