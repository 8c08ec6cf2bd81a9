#!/usr/bin/env bash
# Every method on one chart for one scene, peers included (docs/results/methods/SCENE.md):
#
#   scripts/compare.sh SCENE "S,I" [mochi compare options...]
#
# 1. `mochi compare SCENE --cases-only`: the implicit-Euler references of the chart's test
#    sequences and of every stability condition, written as peer cases
#    (target/compare/SCENE/cases/CASE.npz);
# 2. XPBD (scripts/xpbd.sh, one core): the full sweep of substeps and iterations on each chart
#    case, and the setting "S,I" (substeps, iterations per substep) on each condition's case
#    (target/compare/SCENE/peers/CASE/);
# 3. `mochi compare SCENE --peers ...`: every method, the recordings replayed among them, the
#    page and charts -> docs/results/methods/SCENE.md (OUT with --out).
#
# The options after "S,I" go to both `mochi compare` calls (--model, --reduced, --frames,
# --sequences, --matrix-frames, --long-frames, --max-substeps); the shipped pages' options are
# on each page. A contact scene's cases carry its obstacle boxes and run-time box colliders
# (each collider's centre on the sequence's path), which the XPBD peer collides
# through the library's own collision detection (scripts/xpbd_run.py); pass "-" for "S,I" to
# skip step 2 (twist-bar: quasi-static, XPBD steps dynamics).
#
# XPBD_SWEEP="--substeps-list 1,2,4 --iterations-list 1" narrows step 2's sweep (default: every
# setting of scripts/xpbd_run.py's sweep). The cases and recordings go to target/compare/SCENE
# (WORK=DIR for another); the cases are written afresh by every call. `--sequences 0
# --conditions 10000-frames` measures the long condition alone (docs/results/methods/long/).
set -euo pipefail

cd "$(dirname "$0")/.."
[ $# -ge 2 ] || { sed -n '2,/^set -e/p' "$0" | sed '$d' | sed 's/^# \{0,1\}//' >&2; exit 2; }
scene=$1 setting=$2
shift 2
work=${WORK:-target/compare/$scene}
rm -rf "$work/cases"
cargo build --release -q -p mochi-trainer --bin mochi
mochi=target/release/mochi

"$mochi" compare "$scene" --cases "$work/cases" --cases-only "$@"
peers=()
if [ "$setting" != "-" ]; then
  substeps=${setting%,*} iterations=${setting#*,}
  for case_file in "$work"/cases/*.npz; do
    name=$(basename "$case_file" .npz)
    mkdir -p "$work/peers/$name"
    case $name in
      # shellcheck disable=SC2086 # the options are words
      test-*) scripts/xpbd.sh sweep "$case_file" "$work/peers/$name" ${XPBD_SWEEP:-} ;;
      *) scripts/xpbd.sh run "$case_file" "$work/peers/$name/s$substeps-i$iterations.npz" \
        --substeps "$substeps" --iterations "$iterations" ;;
    esac
  done
  peers=(--peers "$work/peers")
fi
"$mochi" compare "$scene" "${peers[@]}" "$@"
