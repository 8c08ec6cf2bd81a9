#!/usr/bin/env bash
# Compares mochi's contact primitives with IPC's toolkit (PyPI `ipctk`) on random cases:
# builds a venv under target/ipctk-venv, builds the `contact_cases` example of mochi-sim,
# and runs scripts/check_ipctk.py (which prints a table of the primitives, one of CCD times
# of impact and one of hard-case families against exact references, `mpmath` for the roots).
# Extra arguments go to the script (e.g. --cases 20000 --seed 7, --only ccd, --only families,
# --families degenerate,distance-0).
set -euo pipefail
cd "$(dirname "$0")/.."
target="${CARGO_TARGET_DIR:-target}"
venv=target/ipctk-venv
if [ ! -x "$venv/bin/python" ]; then
    python3 -m venv "$venv"
fi
"$venv/bin/python" -c 'import ipctk, numpy, mpmath' 2>/dev/null || "$venv/bin/pip" install --quiet ipctk numpy mpmath
"$venv/bin/python" -c 'import ipctk; print("ipctk", getattr(ipctk, "__version__", "(version unknown)"))' || true
cargo build --quiet --release -p mochi-sim --example contact_cases
"$venv/bin/python" scripts/check_ipctk.py "$target/release/examples/contact_cases" target/ipctk-check "$@"
