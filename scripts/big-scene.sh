#!/usr/bin/env bash
# The big scene end to end (docs/results/big-scene.md), every figure of its page:
#
#   scripts/big-scene.sh [SCENE] [FRAME_MEMORY]     # defaults: beam-22k 64M
#
# 1. its dataset in one process (`mochi dataset`), then through Ray with two worker processes
#    (scripts/ray-dataset.sh, a local instance), and the two compared byte for byte;
# 2. `mochi train` on it with at most FRAME_MEMORY of training frames in memory (the split is
#    larger: its frames are read back from out/SCENE/frames.f64 in batches), printing stage
#    times and peak memory; then the same training with every frame in memory (the default
#    budget, out/SCENE-memory) for the peak memory beside it;
# 3. `mochi eval --full-space-reference`: the model, its supervised twin and the adaptive
#    solver against the test split simulated in full space (out/SCENE/dataset-full-space);
# 4. `mochi bench runtime`: the runtime's time per frame in each weight storage;
# 5. the Cortex-M4 firmware built for the model (scripts/run-cortex-m4.sh, int8): its link
#    fails when the model does not fit the 1 MiB flash / 64 KiB RAM budget, naming the region.
#
# Wall times and peak memory come from GNU time (/usr/bin/time -v) around each command.
set -euo pipefail

cd "$(dirname "$0")/.."
scene=${1:-beam-22k}
budget=${2:-64M}
out=out/$scene
cargo build --release -q -p mochi-trainer --bin mochi
mochi=target/release/mochi
timed() { /usr/bin/time -f "%e s wall, %M KiB peak: $*" "$@"; }

timed "$mochi" dataset "$scene" --out "$out/dataset-one"
RAY_AUTH_MODE=disabled timed scripts/ray-dataset.sh run "$scene" --out "$out/dataset" --mochi "$mochi"
for f in "$out"/dataset-one/*.npz; do cmp "$f" "$out/dataset/$(basename "$f")"; done
echo "the one-process and Ray datasets are the same bytes"

timed "$mochi" train "$scene" --out "$out" --frame-memory "$budget"
mkdir -p "$out-memory" && cp -r "$out/dataset" "$out-memory/"
timed "$mochi" train "$scene" --out "$out-memory"
timed "$mochi" eval "$out/$scene.mochi" --full-space-reference --out "$out/eval"
"$mochi" bench runtime "$out/$scene.mochi" --weights f32,f16,int8 --out "$out/bench.md"
scripts/run-cortex-m4.sh "$out/$scene.mochi" int8 || echo "$scene does not fit the Cortex-M4 budget (the link error above names the region)"
