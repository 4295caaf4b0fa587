#!/usr/bin/env bash
# Grass benchmark: seconds to generate and bake one grass species (all LoDs, 256-px atlas views,
# mips; target < 1 s), the image analyzer separately, triangles per LoD and the rasteriser's fill
# rate while baking. VERDANT_BENCH_RUNS sets the runs (best kept).
set -euo pipefail
cd "$(dirname "$0")/.."
exec cargo bench --bench grass -- "$@"
