#!/usr/bin/env bash
# The runtime's step + full decode against JAX (and numpy) on the same networks, the same
# inputs and one core, in one invocation:
#
#   scripts/bench-jax.sh [ARTIFACT.mochi] [FRAMES]      # default tests/artifacts/beam.mochi 1000
#
# 1. a virtual environment target/jax-venv with jax[cpu] and numpy from PyPI (made once);
# 2. `mochi export-weights`: the artifact's f32 networks, the reference script's signals and
#    the runtime's own positions -> target/jax-bench/NAME.npz;
# 3. `mochi bench runtime` pinned to core $CORE (default 0) -> target/jax-bench/NAME-runtime.md;
# 4. scripts/bench_jax.py pinned to the same core with XLA's single-thread flags: JAX jit called
#    once per frame, JAX lax.scan over all frames, numpy eager; checks their positions against
#    the runtime's (max distance / diagonal < 1e-4) and prints one table of all four
#    -> target/jax-bench/NAME-jax.md.
#
# Timings are worth reporting only on a quiet machine (nothing else compiling or running).
set -euo pipefail

cd "$(dirname "$0")/.."
artifact=${1:-tests/artifacts/beam.mochi}
frames=${2:-1000}
core=${CORE:-0}
venv=target/jax-venv
work=target/jax-bench
name=$(basename "$artifact" .mochi)

[ -f "$artifact" ] || { echo "no artifact $artifact" >&2; exit 1; }
command -v taskset >/dev/null || { echo "taskset (util-linux) is needed to pin to one core" >&2; exit 1; }

if ! "$venv/bin/python" -c 'import jax, numpy' 2>/dev/null; then
  echo "== jax[cpu] and numpy from PyPI into $venv"
  python3 -m venv "$venv" ||
    { echo "python3 -m venv failed (on Debian and Ubuntu: apt-get install python3-venv)" >&2; exit 1; }
  "$venv/bin/python" -m pip install --quiet --upgrade pip
  "$venv/bin/python" -m pip install --quiet "jax[cpu]" numpy
fi

echo "== cargo build --release -p mochi-trainer"
cargo build --release -p mochi-trainer
target_dir=$(cargo metadata --format-version 1 --no-deps |
  "$venv/bin/python" -c 'import json, sys; print(json.load(sys.stdin)["target_directory"])')
mkdir -p "$work"
# A private copy: a shared target directory's binary may be rebuilt from another checkout.
cp "$target_dir/release/mochi" "$work/mochi"

echo "== mochi export-weights $artifact ($frames frames)"
"$work/mochi" export-weights "$artifact" --out "$work/$name.npz" --frames "$frames"

echo "== mochi bench runtime $artifact on core $core"
taskset -c "$core" "$work/mochi" bench runtime "$artifact" --frames "$frames" --out "$work/$name-runtime.md"

echo "== JAX and numpy on core $core"
export XLA_FLAGS="--xla_cpu_multi_thread_eigen=false intra_op_parallelism_threads=1"
export JAX_PLATFORMS=cpu OPENBLAS_NUM_THREADS=1 OMP_NUM_THREADS=1 MKL_NUM_THREADS=1
taskset -c "$core" "$venv/bin/python" scripts/bench_jax.py "$work/$name.npz" \
  --runtime-table "$work/$name-runtime.md" --out "$work/$name-jax.md"
echo "-> $work/$name-jax.md"
