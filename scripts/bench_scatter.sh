#!/usr/bin/env bash
# Scatter benchmark: jittered grass and Poisson trees on the TIN of a 2049² fBm terrain with a varied
# density map (instances/s for generate / + CSV format / + file write through the product's own
# export::table writer, best of VERDANT_BENCH_RUNS with CPU time, memory per instance), and
# scipy's qmc.PoissonDisk on the same area and radius as a peer (needs .venv with scipy; skipped
# with a message otherwise). Arguments go to the bench, e.g. `--no-scipy`.
set -euo pipefail
cd "$(dirname "$0")/.."
if [ ! -x .venv/bin/python ] || ! .venv/bin/python -c "import scipy" 2>/dev/null; then
    echo "note: .venv/bin/python with scipy not found; the scipy peer will be skipped"
    echo "      (python3 -m venv .venv && .venv/bin/pip install scipy numpy)"
fi
exec cargo bench --bench scatter -- "$@"
