#!/usr/bin/env bash
# Terrain benchmark: greedy TIN vs the delatin crate on Mt Fuji (10 m), Puget Sound (10 m, 50 m) and a 2049² fractal (1, 5, 20 m).
# Run from anywhere; uses ../shared/data relative to the repo root (override with VERDANT_DATA).
# Arguments go to the bench: an input filter (e.g. `puget`) and/or `--no-delatin`.
set -euo pipefail
cd "$(dirname "$0")/.."
if [ ! -d "${VERDANT_DATA:-../shared/data}" ]; then
    echo "note: ${VERDANT_DATA:-../shared/data} not found; Puget Sound cases will be skipped"
fi
exec cargo bench --bench terrain -- "$@"
