#!/usr/bin/env bash
# Datasets fanned out over Ray (PyPI `ray`, pinned, run as its own package in its own virtual
# environment target/ray-venv, never copied): one task per sequence, each running the `mochi`
# binary, against a local instance or a cluster's address.
#
#   scripts/ray-dataset.sh run SCENE --out DIR [--address HOST:PORT] [--mochi PATH] [--retries N]
#       [--no-shared-path]            # see scripts/ray_dataset.py; the mochi binary defaults to
#                                     # target/release/mochi and must be at that path on every node
#   scripts/ray-dataset.sh self-check # a local head and one worker node, a worker killed once,
#                                     # the dataset byte for byte the single-process one
#   scripts/ray-dataset.sh setup      # only make the virtual environment
set -euo pipefail
cd "$(dirname "$0")/.."
venv=target/ray-venv
RAY=2.60.0

if [ "$("$venv/bin/python" -c 'import ray; print(ray.__version__)' 2>/dev/null)" != "$RAY" ]; then
  echo "== ray $RAY from PyPI into $venv" >&2
  python3 -m venv "$venv" ||
    { echo "python3 -m venv failed (on Debian and Ubuntu: apt-get install python3-venv)" >&2; exit 1; }
  "$venv/bin/python" -m pip install --quiet --disable-pip-version-check "ray==$RAY"
fi

usage() { sed -n '2,/^set -e/p' "$0" | sed '$d' | sed 's/^# \{0,1\}//' >&2; exit 2; }
[ $# -ge 1 ] || usage
cmd=$1
shift
case "$cmd" in
  setup) ;;
  run) "$venv/bin/python" scripts/ray_dataset.py "$@" ;;
  self-check)
    mochi=$(scripts/mochi-bin.sh)
    "$venv/bin/python" scripts/ray_dataset.py --self-check --mochi "$mochi" "$@"
    ;;
  *) usage ;;
esac
