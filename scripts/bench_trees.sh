#!/usr/bin/env bash
# Tree benchmark: `verdant tree` on trees3.ls and fern-plant.ls (lparser 4) and the stochastic bush
# (the thesis' format): expanded symbols, lparser string bytes, segments, triangles, and seconds from
# reading the file to the written LoD0 glb (parse + streaming expansion + mesh + export; the
# re-validation after it is not counted), best and median of VERDANT_BENCH_RUNS runs (default 5),
# plus the peak resident memory of one run. Target: trees3.ls LoD0 under 0.5 s.
# Then the full LoD chain (5 levels, 2048-px atlas, every glb and mip written and re-validated):
# best of VERDANT_BENCH_RUNS runs without the image analyzer, the analyzer's own seconds from one
# run, and peak memory. Target: trees3.ls full chain under 5 s.
#
# Uses ../shared/data/lsystems relative to the repo root (override with VERDANT_LSYSTEMS_DIR).
# Arguments go to every `verdant tree` run, e.g. `--radial-segments 12`.
set -euo pipefail
cd "$(dirname "$0")/.."
DATA=${VERDANT_LSYSTEMS_DIR:-../shared/data/lsystems}
RUNS=${VERDANT_BENCH_RUNS:-5}
if [ ! -d "$DATA" ]; then
    echo "bench_trees: $DATA not found; set VERDANT_LSYSTEMS_DIR to the folder with lparser-v4/ and stochastic/" >&2
    exit 2
fi
cargo build --release --quiet
BIN=target/release/verdant
OUT=$(mktemp -d)
trap 'rm -rf "$OUT"' EXIT

printf '%-16s %11s %12s %9s %10s %9s %9s %9s  %s\n' file symbols string_bytes segments triangles best_s median_s peak_MiB target
status=0
for file in "$DATA/lparser-v4/trees3.ls" "$DATA/lparser-v4/fern-plant.ls" "$DATA/stochastic/bush.ls"; do
    name=$(basename "$file" .ls)
    times=()
    for ((run = 0; run < RUNS; run++)); do
        "$BIN" --quiet tree "$file" -o "$OUT/$name.glb" --lods 1 --report "$OUT/$name.json" "$@"
        times+=("$(jq '.seconds.to_lod0' "$OUT/$name.json")")
    done
    read -r best median < <(printf '%s\n' "${times[@]}" | sort -g | awk '{ v[NR] = $1 } END { print v[1], v[int((NR + 1) / 2)] }')
    peak_kib=$( { /usr/bin/time -f '%M' "$BIN" --quiet tree "$file" -o "$OUT/$name.glb" --lods 1 "$@" ; } 2>&1 | tail -n 1)
    read -r symbols bytes segments triangles < <(jq -r '"\(.symbols) \(.string_bytes) \(.segments) \(.triangles)"' "$OUT/$name.json")
    target=""
    if [ "$name" = trees3 ]; then
        if awk -v t="$best" 'BEGIN { exit !(t < 0.5) }'; then target="LoD0 < 0.5 s: ok"; else target="LoD0 < 0.5 s: MISSED"; status=1; fi
    fi
    printf '%-16s %11s %12s %9s %10s %9.4f %9.4f %9.1f  %s\n' "$name.ls" "$symbols" "$bytes" "$segments" "$triangles" "$best" "$median" "$(awk -v k="$peak_kib" 'BEGIN { print k / 1024 }')" "$target"
done

echo
echo "full LoD chain, 2048-px atlas (seconds include writing and re-validating every file)"
printf '%-16s %-34s %9s %9s %10s %9s  %s\n' file triangles_LoD0..4 best_s median_s analyze_s peak_MiB target
for file in "$DATA/lparser-v4/trees3.ls" "$DATA/lparser-v4/fern-plant.ls" "$DATA/stochastic/bush.ls"; do
    name=$(basename "$file" .ls)
    times=()
    for ((run = 0; run < RUNS; run++)); do
        "$BIN" --quiet tree "$file" -o "$OUT/chain/$name.glb" --lods 5 --atlas-size 2048 --no-analysis --report "$OUT/$name.chain.json" "$@"
        times+=("$(jq '.seconds.total' "$OUT/$name.chain.json")")
    done
    read -r best median < <(printf '%s\n' "${times[@]}" | sort -g | awk '{ v[NR] = $1 } END { print v[1], v[int((NR + 1) / 2)] }')
    peak_kib=$( { /usr/bin/time -f '%M' "$BIN" --quiet tree "$file" -o "$OUT/chain/$name.glb" --lods 5 --atlas-size 2048 --no-analysis "$@" ; } 2>&1 | tail -n 1)
    "$BIN" --quiet tree "$file" -o "$OUT/chain/$name.glb" --lods 5 --atlas-size 2048 --report "$OUT/$name.analyzed.json" "$@"
    analyze=$(jq '.variants[0].seconds_analyze' "$OUT/$name.analyzed.json")
    tris=$(jq -r '[.variants[0].lods[].triangles] | map(tostring) | join("/")' "$OUT/$name.chain.json")
    target=""
    if [ "$name" = trees3 ]; then
        if awk -v t="$best" 'BEGIN { exit !(t < 5.0) }'; then target="chain < 5 s: ok"; else target="chain < 5 s: MISSED"; status=1; fi
    fi
    printf '%-16s %-34s %9.3f %9.3f %10.2f %9.1f  %s\n' "$name.ls" "$tris" "$best" "$median" "$analyze" "$(awk -v k="$peak_kib" 'BEGIN { print k / 1024 }')" "$target"
done
exit $status
