#!/usr/bin/env bash
# Sharded build benchmark (issue 18): each preset built whole, then in 2 and 4 shards run at the same
# time (GNU parallel, one process per shard, all on this machine) and in 3 shards one after another,
# then each split's second round (the shards' scene tiles, `--tiles`) the same way, then the merge.
# Prints per split: the shards' wall time, the slowest shard, the second round's wall time, the
# merge, the total, the peak memory of each shard, of each shard's second round and of the merge,
# the shard folders' and the scene's bytes, and whether the merged scene is byte-identical to the
# whole build (reports without timing).
#
#   scripts/bench_shards.sh [PRESET.toml ...]      default: presets/alpine.toml (10 km, ~600k instances)
#                                                  and presets/worlds/highlands.toml (8193² at 1 m, ~1.3 M)
#
# VERDANT_BIN=path/to/verdant uses that binary instead of building target/release/verdant. Needs GNU
# parallel and /usr/bin/time (apt `parallel`, `time`): installed from apt when missing.
set -euo pipefail
cd "$(dirname "${BASH_SOURCE[0]}")/.."
if [ -n "${VERDANT_BIN:-}" ]; then
  BIN="$VERDANT_BIN"
else
  cargo build --release --quiet
  BIN="$PWD/target/release/verdant"
fi
missing=()
command -v parallel > /dev/null || missing+=(parallel)
[ -x /usr/bin/time ] || missing+=(time)
if ((${#missing[@]})); then
  echo "bench_shards.sh: installing ${missing[*]} from apt" >&2
  SUDO=()
  if [ "$(id -u)" -ne 0 ]; then SUDO=(sudo); fi
  { "${SUDO[@]}" env DEBIAN_FRONTEND=noninteractive apt-get update -q &&
    "${SUDO[@]}" env DEBIAN_FRONTEND=noninteractive apt-get install -y -q --no-install-recommends "${missing[@]}"; } >&2 ||
    { echo "bench_shards.sh: cannot install ${missing[*]} (apt install ${missing[*]})" >&2; exit 2; }
fi
TMP="$(mktemp -d "${TMPDIR:-/tmp}/verdant-shards.XXXXXX")"
trap 'rm -rf "$TMP"' EXIT
if (($#)); then presets=("$@"); else presets=(presets/alpine.toml presets/worlds/highlands.toml); fi
now() { date +%s.%N; }
minus() { awk -v a="$1" -v b="$2" 'BEGIN { printf "%.3f", a - b }'; }
peak_mb() { awk -F': ' '/Maximum resident set size/ {printf "%.0f", $2 / 1024}' "$1"; }
bytes_mb() { du -sb "$1" | awk '{printf "%.1f", $1 / 1048576}'; }

printf '%-12s %6s %8s %9s %7s %7s %7s  %-20s %-20s %8s %9s %8s  %s\n' \
  preset shards "shards s" "slowest s" "tiles s" "merge s" "total s" "peak MB per shard" "tiles MB per shard" \
  "merge MB" "shards MB" "scene MB" identical
for preset in "${presets[@]}"; do
  name="$(basename "$preset" .toml)"
  whole="$TMP/$name-whole"
  t0="$(now)"
  /usr/bin/time -v -o "$TMP/whole.time" "$BIN" -q build "$preset" --out "$whole" > /dev/null
  t1="$(now)"
  scene="$(find "$whole" -mindepth 1 -maxdepth 1 -type d ! -name '.*' | head -1)"
  printf '%-12s %6s %8s %9s %7s %7s %7.1f  %-20s %-20s %8s %9s %8s  %s\n' "$name" 1 - - - - \
    "$(minus "$t1" "$t0")" "$(peak_mb "$TMP/whole.time") (whole)" - - - "$(bytes_mb "$scene")" -
  for split in "2 parallel" "4 parallel" "3 sequence"; do
    read -r n mode <<<"$split"
    out="$TMP/$name-$n-$mode"
    t0="$(now)"
    if [ "$mode" = parallel ]; then
      seq 0 $((n - 1)) | parallel --will-cite --halt now,fail=1 \
        "/usr/bin/time -v -o $out.{}.time $BIN -q build $preset --shard {}/$n --out $out/.shards/{} > /dev/null; date +%s.%N > $out.{}.end"
    else
      # one machine, one shard after another (issue 18 item 4): memory is the largest shard's or the merge's
      for i in $(seq 0 $((n - 1))); do
        /usr/bin/time -v -o "$out.$i.time" "$BIN" -q build "$preset" --shard "$i/$n" --out "$out/.shards/$i" > /dev/null
        date +%s.%N > "$out.$i.end"
      done
    fi
    t1="$(now)"
    mapfile -t dirs < <(seq -f "$out/.shards/%g" 0 $((n - 1)))
    # the second round: each shard's scene tiles, from every shard's folder
    if [ "$mode" = parallel ]; then
      seq 0 $((n - 1)) | parallel --will-cite --halt now,fail=1 \
        "/usr/bin/time -v -o $out.{}.tiles.time $BIN -q build $preset --shard {}/$n --tiles --out $out/.shards/{} --shards ${dirs[*]} > /dev/null"
    else
      for i in $(seq 0 $((n - 1))); do
        /usr/bin/time -v -o "$out.$i.tiles.time" "$BIN" -q build "$preset" --shard "$i/$n" --tiles \
          --out "$out/.shards/$i" --shards "${dirs[@]}" > /dev/null
      done
    fi
    t1b="$(now)"
    /usr/bin/time -v -o "$out.merge.time" "$BIN" -q merge "$preset" --shards "${dirs[@]}" --out "$out" > /dev/null
    t2="$(now)"
    slowest=0; peaks=(); tile_peaks=(); start="$t0"
    for i in $(seq 0 $((n - 1))); do
      e="$(cat "$out.$i.end")"
      d="$(minus "$e" "$start")"
      slowest="$(awk -v a="$d" -v b="$slowest" 'BEGIN { print (a > b ? a : b) }')"
      peaks+=("$(peak_mb "$out.$i.time")")
      tile_peaks+=("$(peak_mb "$out.$i.tiles.time")")
      [ "$mode" = sequence ] && start="$e"
    done
    merged="$out/$(basename "$scene")"
    same=yes
    python3 scripts/same_scene.py "$scene" "$merged" > /dev/null || same=NO
    label="$n"; [ "$mode" = sequence ] && label="$n seq"
    printf '%-12s %6s %8.1f %9.1f %7.1f %7.1f %7.1f  %-20s %-20s %8s %9s %8s  %s\n' "$name" "$label" \
      "$(minus "$t1" "$t0")" "$slowest" "$(minus "$t1b" "$t1")" "$(minus "$t2" "$t1b")" "$(minus "$t2" "$t0")" \
      "$(IFS=/; echo "${peaks[*]}")" "$(IFS=/; echo "${tile_peaks[*]}")" \
      "$(peak_mb "$out.merge.time")" "$(bytes_mb "$out/.shards")" "$(bytes_mb "$merged")" "$same"
    rm -rf "$out"
  done
  rm -rf "$whole"
done
echo "N: shards at the same time on this machine ($(nproc) cores); N seq: one after another (slowest = the longest shard);"
echo "a unit is a band of a chunked terrain (its meshes), the terrain stage of an unchunked one, or one plant species (docs/sharding.md);"
echo "tiles: the second round (each shard's scene tiles, after every shard); shards MB: both rounds' entries (links to other shards' not counted twice)"
