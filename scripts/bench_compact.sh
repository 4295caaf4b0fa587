#!/usr/bin/env bash
# Compact terrain outputs against gltfpack (npm `gltfpack`), on the same inputs, at equal or smaller
# error as written (issue 17 item 3). Every file's error is measured the same way, independently
# (scripts/check_terrain_bound.py: the stored vertices — f32, or 16-bit integers placed by their
# node — against the heightmap decoded in f64, at every sample).
#
# Per input and bound B: verdant's f32 file, `--quantize` (KHR_mesh_quantization) and `--compress`
# (+ EXT_meshopt_compression), all within B by construction; gltfpack run on verdant's f32 mesh
# with 16-bit positions (-vp 16: its default 14 bits breaks any bound finer than its grid step),
# uncompressed and with -c. gltfpack re-quantizes positions on one uniform grid over the whole
# bounding box, which moves vertices off their samples and so adds error: its input mesh is made
# finer (B·k for k = 1, 0.8, 0.6, …) until its output is within B. Ratios are verdant / gltfpack.
#
#   scripts/bench_compact.sh            (Fuji and Puget Sound from ../shared/data; skipped if absent)
#
# Installs gltfpack into .tools/gltfpack and numpy/pillow/pygltflib into .tools/bench-venv once.
# VERDANT_BIN=path/to/verdant uses that binary instead of building target/release/verdant.
set -euo pipefail
cd "$(dirname "${BASH_SOURCE[0]}")/.."
DATA="${VERDANT_DATA:-../shared/data}"

if [ -n "${VERDANT_BIN:-}" ]; then BIN="$VERDANT_BIN"; else cargo build --release --quiet; BIN="$PWD/target/release/verdant"; fi
GLTFPACK="$PWD/.tools/gltfpack/node_modules/.bin/gltfpack"
if [ ! -x "$GLTFPACK" ]; then
  echo "installing gltfpack 1.3.0 into .tools/gltfpack"
  npm install --silent --no-audit --no-fund --prefix .tools/gltfpack gltfpack@1.3.0 >/dev/null
fi
PY="$PWD/.tools/bench-venv/bin/python"
if [ -x "$PY" ] && ! "$PY" -c "import scipy" 2>/dev/null; then
  "$PY" -m pip install -q --disable-pip-version-check scipy==1.17.1
fi
if [ ! -x "$PY" ]; then
  echo "creating .tools/bench-venv (numpy, pillow, pygltflib)"
  python3 -m venv .tools/bench-venv
  "$PY" -m pip install -q --disable-pip-version-check numpy==2.4.6 pillow==12.3.0 pygltflib==1.16.5 scipy==1.17.1
fi
TMP="$(mktemp -d "${TMPDIR:-/tmp}/verdant-bench-compact.XXXXXX")"
trap 'rm -rf "$TMP"' EXIT

# name | file | verdant decode flags | bounds
cases=(
  "fuji|heightmaps/martini_fuji.png|--encoding terrain-rgb --cell-size 30|5 0.5"
  "puget|heightmaps/diligent_ps_height_1k.png|--encoding gray --height-scale 6553.5 --cell-size 160|10"
)

# error as written of FILE (prints the metres); $1 file, $2 map, $3 bound, rest: decode flags
measure() {
  local file="$1" map="$2" bound="$3"
  shift 3
  local enc=() cell=""
  while (($#)); do
    case "$1" in
      --encoding) enc+=(--encoding "$2"); shift 2 ;;
      --height-scale) enc+=(--height-scale "$2"); shift 2 ;;
      --cell-size) cell="$2"; shift 2 ;;
      *) shift ;;
    esac
  done
  "$PY" scripts/check_terrain_bound.py "$file" --heightmap "$map" "${enc[@]}" --cell-size "$cell" --max-error "$bound" \
    | sed -n 's/.*largest error as written \([^ ]*\) m.*/\1/p' || true   # (it exits 1 when over the bound)
}
triangles() { "$PY" -c "import pygltflib,sys; g=pygltflib.GLTF2().load(sys.argv[1]); print(sum(g.accessors[p.indices].count//3 for m in g.meshes for p in m.primitives))" "$1"; }

printf '%-6s %6s  %-34s %10s %12s %8s %14s  %s\n' input bound file triangles bytes ratio "as written m" "within bound"
for c in "${cases[@]}"; do
  IFS='|' read -r name file flags bounds <<<"$c"
  map="$DATA/$file"
  if [ ! -f "$map" ]; then echo "skip $name: $map not found (set VERDANT_DATA)"; continue; fi
  read -ra decode <<<"$flags"
  for b in $bounds; do
    row() { # label file [bytes of ours to compare with] [uncompressed twin: meshopt is lossless, the twin is measured]
      local err; err=$(measure "${4:-$2}" "$map" "$b" "${decode[@]}")
      # (within 1e-12 relative: float64 evaluation noise, see check_terrain_bound.py)
      local ok; ok=$(awk -v e="$err" -v b="$b" 'BEGIN { print (e <= b * (1 + 1e-12)) ? "yes" : "NO" }')
      if ! [[ $err =~ ^[0-9.eE+-]+$ ]]; then err=nan; ok="ERROR: not measured"; fi
      local bytes; bytes=$(stat -c %s "$2")
      local ratio="-"
      if [ -n "${3:-}" ]; then ratio=$(awk -v a="$3" -v g="$bytes" 'BEGIN { printf "%.3f", a / g }'); fi
      printf '%-6s %6s  %-34s %10s %12s %8s %14.7f  %s\n' "$name" "$b" "$1" "$(triangles "${4:-$2}")" "$bytes" "$ratio" "$err" "$ok"
    }
    "$BIN" -q terrain "$map" "${decode[@]}" --max-error "$b" -o "$TMP/f32.glb"
    "$BIN" -q terrain "$map" "${decode[@]}" --max-error "$b" --quantize -o "$TMP/q.glb"
    "$BIN" -q terrain "$map" "${decode[@]}" --max-error "$b" --compress -o "$TMP/c.glb"
    row "verdant (f32)" "$TMP/f32.glb"
    row "verdant --quantize" "$TMP/q.glb"
    row "verdant --compress" "$TMP/c.glb" "" "$TMP/q.glb"
    # gltfpack on the same mesh, then on finer meshes until its output keeps the bound
    for k in 1 0.8 0.6 0.5 0.4 0.3; do
      bk=$(awk -v b="$b" -v k="$k" 'BEGIN { print b * k }')
      "$BIN" -q terrain "$map" "${decode[@]}" --max-error "$bk" -o "$TMP/in.glb"
      "$GLTFPACK" -i "$TMP/in.glb" -o "$TMP/gp.glb" -vp 16 >/dev/null
      "$GLTFPACK" -i "$TMP/in.glb" -o "$TMP/gpc.glb" -vp 16 -c >/dev/null
      err=$(measure "$TMP/gp.glb" "$map" "$b" "${decode[@]}")
      within=$(awk -v e="$err" -v b="$b" 'BEGIN { print (e <= b * (1 + 1e-12)) ? 1 : 0 }')
      if ! [[ $err =~ ^[0-9.eE+-]+$ ]]; then within=0; fi
      if [ "$k" = 1 ] || [ "$within" = 1 ]; then
        row "gltfpack -vp 16 (input at ${bk} m)" "$TMP/gp.glb" "$(stat -c %s "$TMP/q.glb")"
        row "gltfpack -vp 16 -c (input ${bk} m)" "$TMP/gpc.glb" "$(stat -c %s "$TMP/c.glb")" "$TMP/gp.glb"
      fi
      if [ "$within" = 1 ]; then break; fi
    done
  done
done
echo "ratio: verdant --quantize / gltfpack -vp 16 and verdant --compress / gltfpack -vp 16 -c, bytes"

# Species: LoD chains of `verdant tree` and `verdant mesh`, each level's file and the MSFT_lod chain
# file. gltfpack runs on verdant's f32 files with -kn (keep every level's node: it does not know
# MSFT_lod and would drop the coarser levels otherwise) and -vp 16; it drops custom attributes
# (verdant's _WIND and _WIND_BRANCH, application data every engine script reads: 8 bytes a vertex in compact files, normalized bytes of their ranges (docs/wind.md)),
# so sizes are compared both as written and without those bytes ("w/o _attrs"). Errors: the largest
# distance from a stored vertex to the nearest f32 vertex, world space, the same measure for both
# (scripts/compact_stats.py; a compressed file is measured by its uncompressed twin, meshopt being
# lossless). Images (the atlases, PNG) are the same bytes in both and counted in the totals.
echo
printf '%-22s %-9s %-24s %10s %10s %10s %8s %8s %12s  %s\n' case file writer bytes "w/o _attrs" images ratio "ratio w/o" "error m" "wind error / step"
species=(
  "broadleaf|tree builtin:broadleaf"
  "conifer-type-tree|tree $DATA/lsystems/lparser-v4/conifer-type-tree.ls --height 12"
  "tree1|tree $DATA/lsystems/lparser-v5/tree1.ls --height 10"
  "boulder|mesh presets/models/boulder.obj"
)
field() { "$PY" -c "import json,sys; print(json.loads(sys.argv[1])[sys.argv[2]])" "$1" "$2"; }
# the wind's largest error as a share of its step (range / 255), from compact_stats.py --reference:
# at most 0.5 for bytes of their ranges, 0 for floats, "dropped" when the file has no wind
wind_error() {
  "$PY" -c "
import json, sys
s = json.loads(sys.argv[1])
e = {k: v for k, v in s.get('custom_error', {}).items() if k.startswith('_WIND')}
if not e:
    print('dropped' if sys.argv[2] == 'yes' else '-')
else:
    r = s.get('custom_range', {})
    print(f\"{max(x / (g / 255) if k in r else 0.0 for k, v in e.items() for x, g in zip(v, r.get(k, [1] * 4))):.3f}\")
" "$1" "$2"
}
# compare CASE FILE DIR SUFFIX QLABEL CLABEL: rows for DIR/{q,c,gp,gpc}SUFFIX.glb against DIR/fSUFFIX.glb
# (a compressed file's error is its uncompressed twin's: meshopt is lossless)
compare() {
  local name="$1" label="$2" d="$3" level="$4" qlabel="$5" clabel="$6"
  declare -A got=() err=()
  local w twin
  for w in q c gp gpc; do
    twin="$w"; [ "$w" = c ] && twin=q; [ "$w" = gpc ] && twin=gp
    got[$w]=$("$PY" scripts/compact_stats.py "$d/$w$level.glb" --json)
    err[$w]=$("$PY" scripts/compact_stats.py "$d/$twin$level.glb" --reference "$d/f$level.glb" --json)
  done
  local pair peer label_w bytes custom images e ratio ratio2 pb
  for pair in "q gp $qlabel" "gp - gltfpack -vp 16" "c gpc $clabel" "gpc - gltfpack -vp 16 -c"; do
    read -r w peer label_w <<<"$pair"
    bytes=$(field "${got[$w]}" bytes); custom=$(field "${got[$w]}" custom_bytes); images=$(field "${got[$w]}" image_bytes)
    e=$(field "${err[$w]}" position_error_m)
    ratio="-"; ratio2="-"
    if [ "$peer" != - ]; then
      pb=$(field "${got[$peer]}" bytes)
      ratio=$(awk -v a="$bytes" -v b="$pb" 'BEGIN { printf "%.3f", a / b }')
      ratio2=$(awk -v a="$bytes" -v c="$custom" -v b="$pb" 'BEGIN { printf "%.3f", (a - c) / b }')
    fi
    local has_wind=no
    if [ "$(field "${err[q]}" custom_error)" != "{}" ]; then has_wind=yes; fi
    printf '%-22s %-9s %-24s %10s %10s %10s %8s %8s %12.7f  %s\n' "$name" "$label" "$label_w" "$bytes" $((bytes - custom)) "$images" "$ratio" "$ratio2" "$e" "$(wind_error "${err[$w]}" "$has_wind")"
  done
}
for c in "${species[@]}"; do
  IFS='|' read -r name cmd <<<"$c"
  read -ra args <<<"$cmd"
  if [[ "${args[1]}" == "$DATA"/* && ! -f "${args[1]}" ]]; then echo "skip $name: ${args[1]} not found"; continue; fi
  d="$TMP/$name"; mkdir -p "$d"
  "$BIN" -q "${args[@]}" -o "$d/f.glb"
  "$BIN" -q "${args[@]}" -o "$d/q.glb" --quantize
  "$BIN" -q "${args[@]}" -o "$d/c.glb" --compress
  for level in _LOD0 _LOD1 ""; do
    [ -f "$d/f$level.glb" ] || continue
    "$GLTFPACK" -i "$d/f$level.glb" -o "$d/gp$level.glb" -kn -vp 16 >/dev/null 2>&1
    "$GLTFPACK" -i "$d/f$level.glb" -o "$d/gpc$level.glb" -kn -vp 16 -c >/dev/null 2>&1
    label="${level#_}"; label="${label:-chain}"
    compare "$name" "$label" "$d" "$level" "verdant --quantize" "verdant --compress"
  done
done
echo "ratio: verdant / gltfpack in bytes as written; 'ratio w/o': verdant without the custom attributes gltfpack drops"

# A scene: presets/meadow.toml built with compact = "none", "quantize", "compress"; its scene.glb
# (instanced species, chunked terrain) against gltfpack on the f32 scene.glb. gltfpack puts every
# mesh of a file on one grid over the whole scene (1 km here: 1.6 cm steps for grass blades too);
# verdant gives each species family its own and the terrain's chunks one, so its error is smaller.
echo
printf '%-22s %-9s %-24s %10s %10s %10s %8s %8s %12s  %s\n' case file writer bytes "w/o _attrs" images ratio "ratio w/o" "error m" "wind error / step"
for c in none quantize compress; do
  sed -e "s/^name = \"meadow\"/name = \"meadow_$c\"/" -e "s/^formats = \\[\"glb\"\\]/formats = [\"glb\"]\ncompact = \"$c\"/" \
    -e "s|^lsystem = \"lsystems/|lsystem = \"$PWD/presets/lsystems/|" presets/meadow.toml > "$TMP/meadow_$c.toml"
  "$BIN" -q build "$TMP/meadow_$c.toml" --out "$TMP/scenes"
done
s="$TMP/scenes"
cp "$s/meadow_none/scene.glb" "$s/f.glb"; cp "$s/meadow_quantize/scene.glb" "$s/q.glb"; cp "$s/meadow_compress/scene.glb" "$s/c.glb"
"$GLTFPACK" -i "$s/f.glb" -o "$s/gp.glb" -kn -vp 16 >/dev/null 2>&1
"$GLTFPACK" -i "$s/f.glb" -o "$s/gpc.glb" -kn -vp 16 -c >/dev/null 2>&1
compare meadow scene "$s" "" "verdant compact=quantize" "verdant compact=compress"
echo "(scene errors: the farthest a vertex of the first instance of each node lies from the f32 scene's nearest)"
