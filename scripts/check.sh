#!/usr/bin/env bash
# verdant end-to-end check: set up the checking tools, run the Rust tests, export sample terrains with the
# CLI, build the embedded demo and presets/*.toml with `verdant build` into out/check/build/, and check
# every output three ways (verdant validate, trimesh/pyrender re-import + report cross-check,
# Khronos glTF Validator). Exits non-zero on any failure.
#
#   bash scripts/check.sh               everything
#   bash scripts/check.sh --setup-only  only install the tools (venv, npm, apt libs)
#   bash scripts/check.sh --no-tests    skip `cargo test` (quick loop on the outputs)
#
# VERDANT_BIN=path/to/verdant uses that binary instead of building target/release/verdant.
#
# Everything it installs goes into git-ignored folders: .venv/ and scripts/node_modules/.
set -euo pipefail

cd "$(dirname "${BASH_SOURCE[0]}")/.."
ROOT="$(pwd)"

SETUP_ONLY=0
RUN_TESTS=1
for arg in "$@"; do
  case "$arg" in
    --setup-only) SETUP_ONLY=1 ;;
    --no-tests) RUN_TESTS=0 ;;
    -h|--help) sed -n '2,13p' "$0"; exit 0 ;;
    *) echo "check.sh: unknown argument '$arg' (try --help)" >&2; exit 2 ;;
  esac
done

# Pinned checking tools. pyopengl is installed in a second step, after pyrender, because pyrender pins
# PyOpenGL 3.1.0, which fails under EGL on these machines.
# rtree: trimesh's pure-Python ray caster (trimesh.ray.ray_triangle) needs its R-tree of triangle bounds.
PY_PKGS=(trimesh==5.2.0 pyrender==0.1.45 pygltflib==1.16.5 numpy==2.4.6 pillow==12.3.0 scipy==1.17.1 networkx==3.6.1 rtree==1.4.1 gdtoolkit==4.3.3 unreal-stub==0.3)
PY_PKGS_AFTER=(pyopengl==3.1.10)
# libopengl0 / libgl1 give PyOpenGL the desktop GL library it loads first (else it falls back to GLES).
# chromium: Babylon.js renders the species files headless (WebGL through SwiftShader), step 5e.
# mono-mcs: the Unity import script's data side is compiled and run on the built scenes, step 5g3.
# parallel: GNU parallel runs the sharded build's recipe (scripts/shard/parallel.sh), step 3c.
APT_PKGS=(libegl1 libegl-mesa0 libgl1-mesa-dri libopengl0 libgl1 chromium mono-mcs parallel)

export PYOPENGL_PLATFORM=egl
VENV="$ROOT/.venv"
PY="$VENV/bin/python"
OUT="$ROOT/out/check"
SHARED="$ROOT/../shared"
SCRIPT_START=$SECONDS

# section TITLE: starts a section; the time each took is listed at the end (the budget is 10 minutes)
SECTION_TITLE=""
SECTION_START=$SECONDS
SECTION_TIMES=()
section() {
  if [ -n "$SECTION_TITLE" ]; then SECTION_TIMES+=("$(printf '%5ss  %s' "$((SECONDS - SECTION_START))" "${SECTION_TITLE:0:90}")"); fi
  SECTION_TITLE="$*"
  SECTION_START=$SECONDS
  printf '\n========== %s ==========\n' "$*"
}
elapsed() { echo "$(( SECONDS - $1 ))s"; }

# ---------------------------------------------------------------------------------------------------------
section "1. Set-up (apt libs, Python venv, npm, bpy)"
# Blender as a Python module (PyPI bpy): its venv, used by steps 5d and 5d2 (set here, outside
# setup_tools, which may run in a background subshell whose variables do not come back)
BPY_PKG="bpy==4.5.15"
BVENV="$ROOT/.venv-blender"
BPY="$BVENV/bin/python"
setup_tools() {
setup_start=$SECONDS

# apt: only when something is missing (a fresh CI machine may lack the EGL/Mesa libraries).
missing_apt=()
for pkg in "${APT_PKGS[@]}"; do
  if ! dpkg-query -W -f='${Status}' "$pkg" 2>/dev/null | grep -q 'install ok installed'; then
    missing_apt+=("$pkg")
  fi
done
if ((${#missing_apt[@]})); then
  echo "apt: installing ${missing_apt[*]}"
  SUDO=()
  if [ "$(id -u)" -ne 0 ]; then SUDO=(sudo); fi
  "${SUDO[@]}" env DEBIAN_FRONTEND=noninteractive apt-get update -q
  "${SUDO[@]}" env DEBIAN_FRONTEND=noninteractive apt-get install -y -q --no-install-recommends "${missing_apt[@]}"
else
  echo "apt: ${APT_PKGS[*]} already installed"
fi

# Python venv: reinstall only when the pinned list changed (stamp file inside the venv).
py_stamp="$VENV/.verdant-check-deps"
py_want="${PY_PKGS[*]} | ${PY_PKGS_AFTER[*]}"
if [ -x "$PY" ] && [ -f "$py_stamp" ] && [ "$(cat "$py_stamp")" = "$py_want" ]; then
  echo "venv: up to date ($VENV)"
else
  t=$SECONDS
  if [ ! -x "$PY" ]; then
    echo "venv: creating $VENV"
    python3 -m venv "$VENV"
  fi
  echo "pip: installing ${PY_PKGS[*]}"
  # pip byte-compiles what it installs: keep it (machines that set PYTHONDONTWRITEBYTECODE would
  # otherwise recompile trimesh/scipy/numpy from source in every one of the many Python runs below)
  "$PY" -m pip install -q --disable-pip-version-check "${PY_PKGS[@]}"
  echo "pip: installing ${PY_PKGS_AFTER[*]} (after pyrender, which pins an older PyOpenGL)"
  "$PY" -m pip install -q --disable-pip-version-check "${PY_PKGS_AFTER[@]}"
  echo "(pip's note that pyrender requires PyOpenGL==3.1.0 is expected: 3.1.10 is the one that works with EGL)"
  echo "$py_want" > "$py_stamp"
  echo "venv: ready in $(elapsed "$t")"
fi

# npm_ci DIR PACKAGE LABEL: `npm ci` in DIR from its committed lock file, only when the lock changed
# (a stamp file in DIR/node_modules) or PACKAGE is missing.
npm_ci() {
  local dir="$ROOT/$1" stamp="$ROOT/$1/node_modules/.verdant-check-lock" sum t
  sum="$(sha256sum "$dir/package-lock.json" | cut -d' ' -f1)"
  if [ -f "$stamp" ] && [ "$(cat "$stamp")" = "$sum" ] && [ -f "$dir/node_modules/$2/package.json" ]; then
    echo "npm: $3 up to date ($1/node_modules)"
  else
    t=$SECONDS
    echo "npm: npm ci in $1/"
    (cd "$dir" && npm ci --no-audit --no-fund --loglevel=error)
    echo "$sum" > "$stamp"
    echo "npm: $3 ready in $(elapsed "$t")"
  fi
}
# the Khronos glTF Validator; Babylon.js + puppeteer-core for the engine check (step 5e)
npm_ci scripts gltf-validator gltf-validator
npm_ci scripts/engines babylonjs Babylon.js

# Blender as a Python module (PyPI bpy) for the import checks; its wheel needs CPython 3.11, so it gets
# a venv of its own (.venv-blender), made with a python3.11 from PATH or pyenv.
bpy_stamp="$BVENV/.verdant-check-deps"
if [ -x "$BPY" ] && [ -f "$bpy_stamp" ] && [ "$(cat "$bpy_stamp")" = "$BPY_PKG" ]; then
  echo "blender venv: up to date ($BVENV)"
else
  t=$SECONDS
  py311=""
  for cand in python3.11 "$(pyenv root 2>/dev/null)/versions/3.11"*/bin/python3.11 python3; do
    if command -v "$cand" >/dev/null 2>&1 && "$cand" -c 'import sys; sys.exit(sys.version_info[:2] != (3, 11))' 2>/dev/null; then
      py311="$cand"; break
    fi
  done
  if [ -z "$py311" ]; then
    echo "check.sh: $BPY_PKG needs CPython 3.11 (install it, e.g. with pyenv or apt python3.11)" >&2
    exit 1
  fi
  echo "blender venv: creating $BVENV with $py311, pip: installing $BPY_PKG"
  "$py311" -m venv "$BVENV"
  "$BPY" -m pip install -q --disable-pip-version-check "$BPY_PKG"
  echo "$BPY_PKG" > "$bpy_stamp"
  echo "blender venv: ready in $(elapsed "$t")"
fi

# Smoke-test the tools, so a broken set-up fails here with a clear message rather than mid-check.
"$PY" -c 'import trimesh, pygltflib, pyrender, OpenGL, numpy, PIL, scipy.spatial, rtree
print(f"python tools: trimesh {trimesh.__version__}, pyrender {pyrender.__version__}, "
      f"PyOpenGL {OpenGL.__version__}, numpy {numpy.__version__}")'
node -e 'const v=require(process.argv[1]); console.log("node tools: gltf-validator " + v.version())' \
  "$ROOT/scripts/node_modules/gltf-validator"
"$BPY" -c 'import bpy; print("blender tools: bpy " + bpy.app.version_string)' 2>/dev/null
echo "set-up took $(elapsed "$setup_start")"
}

# With the tests, the set-up (downloads, unpacking, mostly waiting on the network and the disk) runs
# in the background while cargo compiles; its output is shown when both are done.
SETUP_PID=""
SETUP_LOG="$ROOT/target/check-setup.log"
if ((RUN_TESTS)) && ! ((SETUP_ONLY)); then
  mkdir -p "$ROOT/target"
  echo "set-up runs in the background while cargo compiles the tests (output: $SETUP_LOG, shown after the compile)"
  setup_tools > "$SETUP_LOG" 2>&1 &
  SETUP_PID=$!
else
  setup_tools
fi

section "1c. cargo fmt --check (rustfmt.toml)"
if ! cargo fmt --version >/dev/null 2>&1; then rustup component add rustfmt; fi
if ! cargo fmt --check; then echo "!! code is not rustfmt-formatted: run \`cargo fmt\` and commit" >&2; exit 1; fi

# ---------------------------------------------------------------------------------------------------------
# Release for both: the tests then share compiled dependencies with the release build (one compile of
# the dependency tree instead of two on 2 cores), and property tests and big maps run fast.
# The tests are compiled first, then run in the background while the output checks below use the
# binary they built: on 2 cores the two overlap where either waits (processes, files, the browser).
TEST_PID=""
TEST_LOG="$ROOT/target/check-cargo-test.log"
if ((RUN_TESTS)); then
  section "2a. cargo test --release --no-run (compile the tests and the binary)"
  t=$SECONDS
  cargo test --release --no-run
  echo "compiling took $(elapsed "$t")"
fi

if [ -n "$SETUP_PID" ]; then
  section "1. Set-up (apt libs, Python venv, npm, bpy), what of it the compile did not hide"
  setup_rc=0
  wait "$SETUP_PID" || setup_rc=$?
  cat "$SETUP_LOG"
  if ((setup_rc)); then echo "check.sh: the set-up failed (exit $setup_rc; see above)" >&2; exit 1; fi
fi

section "1b. Self-test of check_outputs.py (good samples pass, broken ones fail)"
"$PY" scripts/check_outputs.py --self-test

if ((SETUP_ONLY)); then exit 0; fi

if ((RUN_TESTS)); then
  section "2b. cargo test --release: the tests start in the background (their log follows the output checks)"
  TEST_START=$SECONDS
  cargo test --release > "$TEST_LOG" 2>&1 &
  TEST_PID=$!
  echo "cargo test is running (pid $TEST_PID, log $TEST_LOG)"
else
  section "2. cargo test (skipped: --no-tests)"
fi

# ---------------------------------------------------------------------------------------------------------
section "3. Build and export samples into out/check/"
if [ -n "${VERDANT_BIN:-}" ]; then
  BIN="$VERDANT_BIN"
  echo "using VERDANT_BIN=$BIN (no cargo build)"
elif ((RUN_TESTS)) && [ -x "$ROOT/target/release/verdant" ]; then
  # the integration tests ran this very binary (cargo test builds it for them); `cargo build` would
  # compile it again only because dev-dependencies widen a shared crate's features (54 s for nothing)
  BIN="$ROOT/target/release/verdant"
  echo "using $BIN as cargo test built it"
else
  t=$SECONDS
  cargo build --release
  BIN="$ROOT/target/release/verdant"
  echo "cargo build took $(elapsed "$t")"
fi
rm -rf "$OUT"
mkdir -p "$OUT/thumbs"

declare -A EXPORTED=() VALIDATED=() CHECKED=() KHRONOS=()
FILES=()        # outputs to check, in order
declare -A REPORT_OF=() WATERTIGHT=() SIDES=()
PASSED=0
FAILED=0
pass() { PASSED=$((PASSED + 1)); }
fail() { FAILED=$((FAILED + 1)); echo "!! $*" >&2; }

# export NAME FILE [--watertight] -- CLI ARGS...: run the CLI, record the file for the checks below.
export_sample() {
  local name="$1" file="$2"; shift 2
  local solid=0
  if [ "$1" = "--watertight" ]; then solid=1; shift; fi
  [ "$1" = "--" ] && shift
  local t=$SECONDS
  echo "\$ verdant $*"
  local rc=0
  "$BIN" "$@" || rc=$?
  if [ "$rc" -eq 0 ]; then
    if [ -f "$OUT/$file" ] && [ -f "$OUT/$name.json" ]; then
      EXPORTED[$file]="ok $(elapsed "$t")"
      pass
    else
      EXPORTED[$file]="FAIL"
      fail "verdant exited 0 but did not write $OUT/$file and $OUT/$name.json"
    fi
  else
    EXPORTED[$file]="FAIL"
    fail "export of $file failed (verdant exited with $rc)"
  fi
  FILES+=("$file")
  REPORT_OF[$file]="$OUT/$name.json"
  WATERTIGHT[$file]=$solid
  # skirts and the solid's walls/bottom are not terrain surface: they face sideways or down
  case " $* " in *" --skirt "*|*" --base "*) SIDES[$file]=1 ;; *) SIDES[$file]=0 ;; esac
}

export_sample demo demo.glb -- \
  terrain --demo -o out/check/demo.glb --report out/check/demo.json
export_sample demo_chunks demo_chunks.gltf -- \
  terrain --demo --max-error 2 --chunk 64 --skirt 5 -o out/check/demo_chunks.gltf --report out/check/demo_chunks.json
export_sample demo_solid demo_solid.glb --watertight -- \
  terrain --demo --base 20 -o out/check/demo_solid.glb --report out/check/demo_solid.json
export_sample demo_grid demo_grid.obj -- \
  terrain --demo --mode grid --grid-step 4 -o out/check/demo_grid.obj --report out/check/demo_grid.json
FUJI="$SHARED/data/heightmaps/martini_fuji.png"
if [ -f "$FUJI" ]; then
  export_sample fuji fuji.glb -- \
    terrain "$FUJI" --encoding terrain-rgb --cell-size 30 --max-error 5 -o out/check/fuji.glb --report out/check/fuji.json
else
  echo "skip: $FUJI not found (../shared missing?), no fuji.glb sample"
fi
for f in demo_chunks.gltf demo_grid.obj; do
  companion="${f%.*}.$([ "${f##*.}" = gltf ] && echo bin || echo mtl)"
  if [ "${EXPORTED[$f]%% *}" = ok ] && [ ! -f "$OUT/$companion" ]; then
    EXPORTED[$f]="FAIL"; PASSED=$((PASSED - 1))
    fail "$f was written without its companion $companion"
  fi
done

# ---------------------------------------------------------------------------------------------------------
section "3b. verdant build: the embedded demo and presets/*.toml into out/check/build/"
BUILD_OUT="$OUT/build"
declare -A IS_BUILD=() SCENE_OF=()
SCENES=()          # scene folders under $BUILD_OUT, in order
declare -A SCENE_BUILT=() SCENE_SECONDS=() SCENE_CHECKED=() SCENE_PLACEMENTS=()
build_scenes() {   # build_scenes LABEL ARGS...: run `verdant build ARGS --out $BUILD_OUT`
  local label="$1"; shift
  local t=$SECONDS rc=0
  echo "\$ verdant build${*:+ $*} --out out/check/build"
  "$BIN" build "$@" --out "$BUILD_OUT" || rc=$?
  echo "($label: exit $rc, $(elapsed "$t"))"
  return "$rc"
}
build_rc=0
build_scenes "demo" || build_rc=$?
presets=(presets/*.toml)
t=$SECONDS
build_scenes "presets" "${presets[@]}" --jobs 2 || build_rc=$?
presets_seconds="$(elapsed "$t")"
if [ "$build_rc" -ne 0 ]; then fail "verdant build exited with $build_rc"; else pass; fi
# scene names: the demo is `demo`, each preset's [scene] name is read from its manifest
for dir in "$BUILD_OUT"/*/; do
  [ -f "$dir/manifest.json" ] || continue
  scene="$(basename "$dir")"
  SCENES+=("$scene")
  SCENE_BUILT[$scene]=ok
  while IFS= read -r -d '' f; do
    rel="${f#"$OUT"/}"
    FILES+=("$rel")
    IS_BUILD[$rel]=1
    SCENE_OF[$rel]="$scene"
    EXPORTED[$rel]="ok build"
    SIDES[$rel]=1       # chunk skirts face sideways: no --up-facing
    WATERTIGHT[$rel]=0
  done < <(find "$dir" -type f \( -name '*.glb' -o -name '*.gltf' -o -name '*.obj' \) -print0 | sort -z)
done
# a scene with species must have written its instanced scene.glb and a placement table per species
for scene in "${SCENES[@]}"; do
  m="$BUILD_OUT/$scene/manifest.json"
  if grep -q '"scatter"' "$m"; then
    if [ -z "${IS_BUILD[build/$scene/scene.glb]:-}" ]; then
      fail "$scene: the manifest has a scatter section but build/$scene/scene.glb was not written"
    fi
    SCENE_PLACEMENTS[$scene]="FAIL (not checked)"
  else
    SCENE_PLACEMENTS[$scene]="- (no species)"
  fi
done
expected_scenes=$((1 + ${#presets[@]}))
if [ "${#SCENES[@]}" -ne "$expected_scenes" ]; then
  fail "verdant build produced ${#SCENES[@]} scene folders (${SCENES[*]:-none}), expected $expected_scenes"
fi
if find "$BUILD_OUT" -maxdepth 1 -name '.*.building-*' | grep -q .; then
  fail "temporary .NAME.building-* folders left in $BUILD_OUT"
fi
echo "built ${#SCENES[@]} scenes (${SCENES[*]}); presets took $presets_seconds"

# ---------------------------------------------------------------------------------------------------------
section "3c. Sharded build: the demo in 2 shards under GNU parallel, merged, against 3b's demo"
# scripts/shard/parallel.sh as a user runs it; the merged scene must equal the single build byte for
# byte (report.json/report.md without their timing sections, the only place runs may differ).
SHARD_OUT="$OUT/sharded"
rm -rf "$SHARD_OUT"
t=$SECONDS
if VERDANT="$BIN" bash scripts/shard/parallel.sh 2 "$SHARD_OUT" > "$OUT/sharded.log" 2>&1; then
  if "$PY" scripts/same_scene.py "$BUILD_OUT/demo" "$SHARD_OUT/demo"
  then pass; else fail "the sharded demo differs from the single build"; fi
else
  fail "scripts/shard/parallel.sh 2 exited non-zero: $(tail -5 "$OUT/sharded.log")"
fi
echo "(sharded demo: $(elapsed "$t"))"

# ---------------------------------------------------------------------------------------------------------
section "3d. World preset shard by shard: presets/worlds/highlands.toml (8193² at 1 m) in 3 shards in sequence, merged"
# Issue 18 item 4: the world-sized preset built on one machine by running its shards one after another
# and merging them; each shard's record and the merged report give their peak memory, which must stay
# under WORLD_PEAK_MIB (measured: the shard of terrain bands 0.10 GB, the species' 0.22 and 0.30 GB;
# the merge 0.82 GB, its terrain stage (which runs there for a terrain sharded by bands), the view
# stage 0.78 GB drawing
# 1.3 million instances over a 1.6-million-triangle terrain; it was 1.3 GB before the GLB writer streamed
# the level buffers and the view stage stopped copying terrain chunks and holding the placements twice).
WORLD_PEAK_MIB=1024
WORLD_OUT="$OUT/world"
rm -rf "$WORLD_OUT"
t=$SECONDS
world_ok=1
for i in 0 1 2; do
  # (--threads 2: the bound was measured with 2 worker threads; more threads measure more LoD
  # levels at once)
  if ! "$BIN" -q --threads 2 build presets/worlds/highlands.toml --shard "$i/3" --out "$WORLD_OUT/shards/$i" > "$OUT/world_shard_$i.log" 2>&1; then
    fail "highlands shard $i/3 (see $OUT/world_shard_$i.log)"; world_ok=0
  fi
done
# the second round, one shard after another: each shard's share of the 16 scene tiles
if [ "$world_ok" = 1 ]; then
  for i in 0 1 2; do
    if ! "$BIN" -q --threads 2 build presets/worlds/highlands.toml --shard "$i/3" --tiles --out "$WORLD_OUT/shards/$i" \
        --shards "$WORLD_OUT"/shards/{0,1,2} > "$OUT/world_tiles_$i.log" 2>&1; then
      fail "highlands shard $i/3's scene tiles (see $OUT/world_tiles_$i.log)"; world_ok=0
    fi
  done
fi
if [ "$world_ok" = 1 ]; then
  if "$BIN" -q --threads 2 merge presets/worlds/highlands.toml --shards "$WORLD_OUT"/shards/{2,0,1} --out "$WORLD_OUT/merged" > "$OUT/world_merge.log" 2>&1; then
    if "$PY" - "$WORLD_OUT" "$WORLD_PEAK_MIB" <<'PYEOF'
import json, sys
from pathlib import Path
out, bound = Path(sys.argv[1]), float(sys.argv[2])
rows, bad = [], []
for i in range(3):
    rec = json.loads((out / "shards" / str(i) / "highlands.shard.json").read_text())
    units = ", ".join(rec["units"][k]["name"] for k in rec["built"]) or "none"
    peak = rec.get("peak_memory_mib")
    rows.append(f"shard {i}/3 ({units}): peak {peak} MiB")
    if peak is None or peak > bound:
        bad.append(f"shard {i}: peak {peak}")
    tiles = json.loads((out / "shards" / str(i) / "highlands.tiles.json").read_text())
    peak = tiles.get("peak_memory_mib")
    rows.append(f"shard {i}/3, second round ({len(tiles['tiles'])} scene tiles, {len(tiles['left'])} left): peak {peak} MiB")
    if peak is None or peak > bound:
        bad.append(f"shard {i}'s second round: peak {peak}")
timing = json.loads((out / "merged" / "highlands" / "report.json").read_text())["timing"]
peak = timing.get("process_peak_memory_mib")
stages = ", ".join(f"{k} {v['peak_memory_mib']:.0f}" for k, v in timing.items() if isinstance(v, dict) and "peak_memory_mib" in v)
rows.append(f"merge: peak {peak} MiB (stages, MiB: {stages})")
if peak is None or peak > bound:
    bad.append(f"merge: peak {peak}")
print("\n".join(rows))
if bad:
    sys.exit(f"over {bound:.0f} MiB or not reported: {bad}")
PYEOF
    then pass; else fail "highlands: peak memory over $WORLD_PEAK_MIB MiB or not reported"; fi
    hl="$WORLD_OUT/merged/highlands"
    if "$BIN" validate --quiet "$hl/scene.glb" "$hl"/terrain/terrain.glb; then pass; else fail "verdant validate highlands"; fi
    # its scene tiles ([scene] tile = 2048: 16 GLBs and scene_tiles.json): valid, the chunks and the
    # tables' rows each in one tile; one tile kept for the engines (5f2)
    if "$BIN" validate --quiet "$hl"/tiles/*.glb; then pass; else fail "verdant validate highlands' tiles"; fi
    if "$PY" scripts/check_outputs.py --tiles "$hl"; then pass; else fail "check_outputs.py --tiles highlands"; fi
    # every tile is the one a shard's second round made (its bytes as the shard's record says), none
    # written by the merge
    if "$PY" - "$WORLD_OUT" <<'PYEOF'
import hashlib, json, sys
from pathlib import Path
out = Path(sys.argv[1])
made = {}
for i in range(3):
    rec = json.loads((out / "shards" / str(i) / "highlands.tiles.json").read_text())
    if rec["left"] or rec.get("no_units"):
        sys.exit(f"shard {i} left tiles to the merge: {rec['left']} {rec.get('no_units')}")
    for t, entry in rec["tiles"]:
        for f, digest in rec["digests"][entry].items():
            if f.startswith("tiles/"):
                made[f] = digest
index = json.loads((out / "merged" / "highlands" / "scene_tiles.json").read_text())
files = [t["file"] for t in index["tiles"]]
if sorted(files) != sorted(made):
    sys.exit(f"the index lists {sorted(files)}, the shards made {sorted(made)}")
for f in files:
    got = hashlib.sha256((out / "merged" / "highlands" / f).read_bytes()).hexdigest()
    if got != made[f]:
        sys.exit(f"{f} is not the shards' tile")
print(f"{len(files)} scene tiles, each the one a shard made")
PYEOF
    then pass; else fail "highlands: the merged tiles are not the shards'"; fi
    # the check itself must fail on a tampered index: a count one off; two tiles' files swapped (each
    # tile's instances then outside the square listed)
    for tamper in count swap; do
      cp "$hl/scene_tiles.json" "$OUT/scene_tiles.good.json"
      "$PY" - "$hl/scene_tiles.json" "$tamper" <<'PYEOF'
import json, sys
p, how = sys.argv[1], sys.argv[2]
index = json.load(open(p))
t = index["tiles"]
if how == "count":
    name = next(iter(t[0]["instances"]))
    t[0]["instances"][name] += 1
else:
    for k in ("file", "bytes"):
        t[0][k], t[5][k] = t[5][k], t[0][k]
json.dump(index, open(p, "w"))
PYEOF
      if "$PY" scripts/check_outputs.py --tiles "$hl" > "$OUT/tiles_tampered_$tamper.log" 2>&1; then
        fail "check_outputs.py --tiles passed a tampered index ($tamper)"
      else
        pass
      fi
      cp "$OUT/scene_tiles.good.json" "$hl/scene_tiles.json"
    done
    cp "$hl/tiles/tile_1_2.glb" "$OUT/world_tile_1_2.glb" || fail "highlands wrote no tiles/tile_1_2.glb"
  else
    fail "verdant merge highlands (see $OUT/world_merge.log)"
  fi
fi
rm -rf "$WORLD_OUT"   # 1 GB of shard caches and scene: nothing later reads them
echo "(world shard by shard: $(elapsed "$t"))"

# ---------------------------------------------------------------------------------------------------------
section "4. verdant validate (re-import + invariants; --up-facing except with skirts or a base)"
for f in "${FILES[@]}"; do
  if [ "${EXPORTED[$f]%% *}" != ok ]; then VALIDATED[$f]="-"; continue; fi
  up=(--up-facing)
  if [ "${SIDES[$f]}" = 1 ]; then up=(); fi  # skirts, walls and bottom face sideways/down
  echo "\$ verdant validate out/check/$f ${up[*]}"
  if "$BIN" validate "$OUT/$f" "${up[@]}"; then VALIDATED[$f]=ok; pass; else VALIDATED[$f]=FAIL; fail "verdant validate $f"; fi
done

# ---------------------------------------------------------------------------------------------------------
section "5. check_outputs.py (trimesh/pygltflib re-import, report cross-check, thumbnails)"
: > "$OUT/check_outputs.tsv"
for f in "${FILES[@]}"; do
  if [ -n "${IS_BUILD[$f]:-}" ]; then continue; fi   # scene outputs: checked per scene below
  if [ "${EXPORTED[$f]%% *}" != ok ]; then CHECKED[$f]="-"; continue; fi
  extra=()
  if [ "${WATERTIGHT[$f]}" = 1 ]; then extra=(--watertight); fi
  if "$PY" scripts/check_outputs.py "$OUT/$f" --report "${REPORT_OF[$f]}" "${extra[@]}" \
       --thumb "$OUT/thumbs/${f%.*}.png" --summary-tsv "$OUT/check_outputs.tsv"; then
    pass
  else
    fail "check_outputs.py $f"
  fi
done
while IFS=$'\t' read -r name status tris verts; do
  if [ "$status" = ok ]; then CHECKED[$name]="ok $tris tris $verts verts"; else CHECKED[$name]="FAIL"; fi
done < "$OUT/check_outputs.tsv"

section "5a2. the terrain bound holds in the bytes written, f32 and quantized (check_terrain_bound.py: stored vertices vs the map decoded in f64); --quantize/--compress files validate (verdant, Khronos) and load in three.js and Babylon.js"
# Terrain-RGB decimetres are not f32 values: the bound must hold for the file, not for the f32 rounding;
# a quantized file holds 16-bit vertices placed by the node's scale and translation.
if [ -f "$FUJI" ]; then
  compact=()
  for variant in "5" "0.5" "0.5 --quantize" "0.5 --compress"; do
    read -r bound flag <<<"$variant"
    name="fuji_bound_$bound${flag:+_${flag#--}}"
    if ! "$BIN" terrain "$FUJI" --encoding terrain-rgb --cell-size 30 --max-error "$bound" ${flag:+"$flag"} \
         -o "$OUT/$name.glb" --report "$OUT/$name.json" --quiet; then
      fail "verdant terrain $name failed"; continue
    fi
    if [ -n "$flag" ]; then
      compact+=("$OUT/$name.glb")
      if "$BIN" validate --quiet --up-facing "$OUT/$name.glb"; then pass; else fail "verdant validate $name.glb"; fi
    fi
    # the python check reads float and quantized positions; a --compress file is checked equal to
    # its --quantize twin by the Rust tests (terrain_cases::quantized_and_compressed_…)
    if [ "$flag" = "--compress" ]; then continue; fi
    if "$PY" scripts/check_terrain_bound.py "$OUT/$name.glb" --heightmap "$FUJI" --encoding terrain-rgb \
         --cell-size 30 --max-error "$bound" --expect-report "$OUT/$name.json"; then
      pass
    else
      fail "the terrain bound $bound m does not hold in $name.glb"
    fi
  done
  if node scripts/gltf_validate.mjs "${compact[@]}"; then pass; else fail "Khronos glTF Validator on ${compact[*]##*/}"; fi
  for engine in babylon three; do
    log="$OUT/check_${engine}_terrain.log"
    node scripts/engines/check_babylon.mjs --engine "$engine" --thumbs "$OUT/engines" "$OUT/fuji_bound_0.5.glb" "${compact[@]}" > "$log" 2>&1 || true
    sed 's|'"$OUT"'/||' "$log" || true
    n=$((1 + ${#compact[@]})); oks=$(grep -c '^ok ' "$log" || true)
    if [ "$oks" -eq "$n" ]; then pass; else fail "$engine: $((n - oks)) of $n terrain files (f32, --quantize, --compress) failed (see $log)"; fi
    # lit as the f32 file (Babylon.js bent the normal-map frame of a non-uniformly scaled terrain
    # that carried TANGENT: quantized terrains are written without it)
    pairs=()
    for f in "${compact[@]}"; do pairs+=("$f=$OUT/fuji_bound_0.5.glb"); done
    if "$PY" scripts/same_frames.py "$log" "${pairs[@]}"; then pass; else fail "$engine: a quantized terrain does not look like the f32 one"; fi
  done
else
  echo "skip: $FUJI not found, no bound-as-written check"
fi

section "5a3. compact species (verdant tree|mesh --quantize/--compress): every vertex within the quantization the report states of the f32 file (compact_stats.py), files valid (verdant, Khronos), and three.js and Babylon.js show the frame the f32 file shows"
sp="$OUT/compact_species"
mkdir -p "$sp"
species_compact=()
for src in "tree builtin:broadleaf" "mesh presets/models/boulder.obj"; do
  read -r cmd input <<<"$src"
  name=$(basename "${input#builtin:}" .obj)
  for variant in f32 quantize compress; do
    flag=()
    if [ "$variant" != f32 ]; then flag=(--"$variant"); fi
    if ! "$BIN" -q "$cmd" "$input" -o "$sp/${name}_$variant.glb" --report "$sp/${name}_$variant.json" "${flag[@]}"; then
      fail "verdant $cmd $input ${flag[*]}"; continue
    fi
    pass
    if [ "$variant" = f32 ]; then continue; fi
    species_compact+=("$sp/${name}_$variant.glb" "$sp/${name}_${variant}_LOD0.glb")
    for f in "$sp/${name}_$variant"{,_LOD0,_LOD1}.glb; do
      if "$BIN" validate --quiet "$f"; then pass; else fail "verdant validate ${f##*/}"; fi
    done
    # meshopt is lossless: the compressed files are the quantized ones, checked by the Rust tests
    # (compact_species); here the quantized files' vertices against the f32 files'
    if [ "$variant" = quantize ]; then
      for level in "" _LOD0 _LOD1; do
        if "$PY" - "$sp/${name}_quantize$level.glb" "$sp/${name}_f32$level.glb" "$sp/${name}_quantize.json" <<'PYEOF'
import json, subprocess, sys
q, f, report = sys.argv[1:4]
got = json.loads(subprocess.run([sys.executable, "scripts/compact_stats.py", q, "--reference", f, "--json"],
                                check=True, capture_output=True, text=True).stdout)
def values(x):
    if isinstance(x, dict):
        for k, v in x.items():
            if k == "quantization_m":
                yield v
            else:
                yield from values(v)
    elif isinstance(x, list):
        for v in x:
            yield from values(v)
stated = max(values(json.load(open(report))))
ok = 0 < stated < 1e-2 and got["position_error_m"] <= stated * (1 + 1e-6) + 1e-7
print(f"{'ok' if ok else 'FAIL'}  {q.split('/')[-1]}: vertices within {got['position_error_m']:.7f} m of the f32 file's, the report states {stated:.7f} m")
# wind data (docs/wind.md): bytes of value / range, each component within half a step of the f32 file's
for name, err in got["custom_error"].items():
    r = got["custom_range"].get(name)
    wind_ok = r is not None and all(e <= x / 510 * (1 + 1e-6) for e, x in zip(err, r))
    if name.startswith("_WIND") or r is not None:
        print(f"{'ok' if wind_ok else 'FAIL'}  {q.split('/')[-1]}: {name} within {err} of the f32 file's (half steps {[x / 510 for x in r] if r else 'none: stored as floats'})")
        ok = ok and wind_ok
sys.exit(0 if ok else 1)
PYEOF
        then pass; else fail "${name}_quantize$level.glb: vertices further from the f32 file than the report states"; fi
      done
    fi
  done
done
if ((${#species_compact[@]})); then
  if node scripts/gltf_validate.mjs "${species_compact[@]}"; then pass; else fail "Khronos glTF Validator on the compact species files"; fi
  for engine in babylon three; do
    log="$OUT/check_${engine}_species_compact.log"
    node scripts/engines/check_babylon.mjs --engine "$engine" "${species_compact[@]}" "$sp"/*_f32.glb "$sp"/*_f32_LOD0.glb > "$log" 2>&1 || true
    sed 's|'"$OUT"'/||' "$log" || true
    n=$((${#species_compact[@]} + 4)); oks=$(grep -c '^ok ' "$log" || true)
    if [ "$oks" -eq "$n" ]; then pass; else fail "$engine: $((n - oks)) of $n species files failed (see $log)"; fi
    # what a person sees: the compact file's frame as the f32 file's (coverage and mean colour)
    pairs=()
    for f in "${species_compact[@]}"; do pairs+=("$f=$(sed -E 's/_(quantize|compress)/_f32/' <<<"$f")"); done
    if "$PY" scripts/same_frames.py "$log" "${pairs[@]}"; then pass; else fail "$engine: a compact species file does not look like its f32 file"; fi
  done
fi

# a scene with `compact = "compress"` (meadow): species, scene.glb and scene_lod.glb compressed; the
# files valid (verdant, Khronos) and scene.glb drawn by three.js and Babylon.js from its first view
# with exactly the triangles and draw calls the view stage reported, looking as the f32 meadow does
if [ -f "$BUILD_OUT/meadow/scene.glb" ]; then
  # (its L-system path made absolute: the preset is written beside the outputs)
  sed -e 's/^name = "meadow"/name = "meadow_compact"/' -e 's/^formats = \["glb"\]/formats = ["glb"]\ncompact = "compress"/' \
    -e 's|^lsystem = "lsystems/|lsystem = "'"$ROOT"'/presets/lsystems/|' presets/meadow.toml > "$OUT/meadow_compact.toml"
  if "$BIN" -q build "$OUT/meadow_compact.toml" --out "$OUT/build_compact" > "$OUT/build_compact.log" 2>&1; then
    pass
    mc="$OUT/build_compact/meadow_compact"
    if "$BIN" validate --quiet "$mc"/scene.glb "$mc"/scene_lod.glb "$mc"/species/*.glb; then pass; else fail "verdant validate meadow_compact"; fi
    if node scripts/gltf_validate.mjs "$mc"/scene.glb "$mc"/scene_lod.glb "$mc"/species/*.glb > "$OUT/khronos_meadow_compact.log" 2>&1; then
      pass; tail -1 "$OUT/khronos_meadow_compact.log"
    else
      fail "Khronos glTF Validator on meadow_compact (see $OUT/khronos_meadow_compact.log)"
    fi
    "$PY" -c "import json,sys; v=json.load(open(sys.argv[1]))['stages']['view']; print(f\"meadow_compact: scene.glb {v['scene_bytes']} bytes, scene_lod.glb {v['lod_scene_bytes']}; vertices moved up to {v['quantization_m']:.5f} m, terrain {v['terrain_quantization_m']:.5f} m\")" "$mc/report.json" || true
    for engine in three babylon; do
      log="$OUT/check_${engine}_meadow_compact.log"
      node scripts/engines/check_babylon.mjs --engine "$engine" --view "$mc/scene.glb" "$BUILD_OUT/meadow/scene.glb" > "$log" 2>&1 || true
      sed 's|'"$OUT"'/||' "$log" | cut -c1-300 || true
      if [ "$(grep -c '^ok ' "$log" || true)" -eq 2 ]; then pass; else fail "$engine: meadow_compact's or meadow's view (see $log)"; fi
      if "$PY" scripts/same_frames.py "$log" "$mc/scene.glb=$BUILD_OUT/meadow/scene.glb"; then
        pass
      else
        fail "$engine: meadow_compact does not look like meadow"
      fi
    done
  else
    fail "verdant build meadow with compact = \"compress\" (see $OUT/build_compact.log)"
  fi
fi

# The scene-level engine checks (5f, 5f2, 5f3 below) need only the built scenes: they run in the
# background, one after another, beside the Python and Blender checks (5b-5e, mostly one core), and
# are reported at their places. Each writes its own log.
scene_files=()
lod_files=()
babylon_lod_files=()
lit_dirs=()
for dir in "$OUT"/build/*/; do
  [ -f "$dir/scene.glb" ] && scene_files+=("$dir/scene.glb")
  if [ -f "$dir/scene_lod.glb" ]; then
    lod_files+=("$dir/scene_lod.glb")
    # Babylon's glTF loader ignores MSFT_screencoverage: it ends with every chain at LoD0, the
    # whole scene at full detail (demo: 122 M triangles), which it is not asked to draw
    # (--draw-limit; SwiftShader took 120 s over that one frame). alpine's 77 MB file did not
    # load in headless Babylon within 240 s.
    if [ "$(stat -c %s "$dir/scene_lod.glb")" -lt 50000000 ]; then babylon_lod_files+=("$dir/scene_lod.glb"); fi
  fi
  # scene tiles ([scene] tile): every tile to three.js, the smallest to Babylon.js (under 50 MB)
  if [ -d "$dir/tiles" ]; then
    smallest=""
    for tile in "$dir"/tiles/*.glb; do
      lod_files+=("$tile")
      if [ -z "$smallest" ] || [ "$(stat -c %s "$tile")" -lt "$(stat -c %s "$smallest")" ]; then smallest="$tile"; fi
    done
    if [ -n "$smallest" ] && [ "$(stat -c %s "$smallest")" -lt 50000000 ]; then babylon_lod_files+=("$smallest"); fi
  fi
  levels=("$dir"/terrain/terrain_LOD[1-9]*.glb)
  if [ -f "$dir/terrain/terrain_LOD0.glb" ] && [ -f "${levels[0]}" ]; then lit_dirs+=("$dir"); fi
done
# a tile of the world preset (3d)
if [ -f "$OUT/world_tile_1_2.glb" ]; then lod_files+=("$OUT/world_tile_1_2.glb"); fi
(
  if ((${#scene_files[@]})); then
    for engine in three babylon; do
      node scripts/engines/check_babylon.mjs --engine "$engine" --view --thumbs "$OUT/engines/views" "${scene_files[@]}" \
        > "$OUT/check_${engine}_views.log" 2>&1 || true
    done
  fi
  if ((${#babylon_lod_files[@]})); then
    node scripts/engines/check_babylon.mjs --engine babylon --no-range-requests "${babylon_lod_files[@]}" > "$OUT/check_babylon_scene_lod.log" 2>&1 || true
  fi
  if ((${#lod_files[@]})); then
    node scripts/engines/check_babylon.mjs --engine three --no-range-requests "${lod_files[@]}" > "$OUT/check_three_scene_lod.log" 2>&1 || true
  fi
  for dir in "${lit_dirs[@]}"; do
    levels=("$dir"/terrain/terrain_LOD[1-9]*.glb)
    node scripts/engines/check_babylon.mjs --engine three --lit-against "$dir/terrain/terrain_LOD0.glb" "${levels[@]}" \
      > "$OUT/check_three_terrain_lit_$(basename "$dir").log" 2>&1 || true
  done
  if ((${#lit_dirs[@]})); then
    node scripts/engines/terrain_seams.mjs "${lit_dirs[@]}" > "$OUT/check_three_terrain_seams.log" 2>&1 || true
  fi
) &
scene_engines_pid=$!

# The engine import scripts that cannot run here (Unreal, Unity: 5g2, 5g3) are checked on the built
# scenes in the background as well. No Unreal or Unity on the registries these machines reach: the
# Unreal script's editor part is looked up in the engine's API listing and its reading and
# converting part run; the Unity data side is compiled with Mono and run, its engine side parsed.
unreal_stub=$(ls "$VENV"/lib/python3*/site-packages/unreal/unreal.py 2>/dev/null | head -1)
unity_exe="$OUT/check_unity_data.exe"
scene_dirs=()
for dir in "$OUT"/build/*/; do [ -f "$dir/manifest.json" ] && scene_dirs+=("${dir%/}"); done
(
  # winter_valley again with binary placement tables: both scripts must read them as the CSV rows
  pair=()
  if [ -d "$BUILD_OUT/winter_valley" ]; then
    sed -e 's/^name = "winter_valley"/name = "winter_valley_binary"/' -e 's/^\[scatter\]/[scatter]\ntable = "binary"/' \
      presets/winter_valley.toml > "$OUT/winter_valley_binary.toml"
    if "$BIN" build "$OUT/winter_valley_binary.toml" --out "$OUT/build_binary" > "$OUT/build_binary.log" 2>&1; then
      pair=(--pair "$BUILD_OUT/winter_valley" "$OUT/build_binary/winter_valley_binary")
    fi
  fi
  if [ -n "$unreal_stub" ]; then
    { "$PY" scripts/check_engine_scripts.py --unreal-stub "$unreal_stub" "${pair[@]}" "${scene_dirs[@]}"; echo "rc=$?"; } \
      > "$OUT/check_unreal_script.log" 2>&1
    if [ ${#pair[@]} -eq 0 ]; then echo "FAIL the binary-table build of winter_valley (see $OUT/build_binary.log)" >> "$OUT/check_unreal_script.log"; echo "rc=1" >> "$OUT/check_unreal_script.log"; fi
  fi
  if command -v mcs > /dev/null && command -v mono > /dev/null; then
    {
      mcs -nologo -out:"$unity_exe" scripts/engines/unity/VerdantData.cs scripts/engines/unity/check/CheckVerdantData.cs \
        && mcs --parse scripts/engines/unity/VerdantInstances.cs \
        && mcs --parse scripts/engines/unity/Editor/VerdantImporter.cs \
        && mono "$unity_exe" "${pair[@]}" "${scene_dirs[@]}"
      echo "rc=$?"
    } > "$OUT/check_unity_script.log" 2>&1
  fi
) &
engine_scripts_pid=$!

# the log of a background engine run: printed, each `ok` line a pass, short of `want` a failure
engine_log() {
  local log="$1" want="$2" what="$3"
  if [ ! -f "$log" ]; then fail "$what: no log ($log)"; return; fi
  sed 's|'"$OUT"'/||' "$log" | cut -c1-400 || true
  local oks
  oks=$(grep -c '^ok ' "$log" || true)
  for _ in $(seq 1 "$oks"); do pass; done
  if [ "$oks" -ne "$want" ]; then fail "$what: $((want - oks)) of $want failed (see $log)"; fi
}

section "5b. check_outputs.py --scene (manifest sha256/sizes, triangle counts, bounds, LoDs, thumbnail, preview; placements vs scene.glb instancing, ray-cast onto the terrain, spacing)"
: > "$OUT/check_scenes.tsv"
for scene in "${SCENES[@]}"; do
  if "$PY" scripts/check_outputs.py --scene "$BUILD_OUT/$scene" --thumb "$OUT/thumbs/build_$scene.png" \
       --summary-tsv "$OUT/check_scenes.tsv"; then pass; else fail "check_outputs.py --scene $scene"; fi
done
while IFS=$'\t' read -r name status tris verts placements; do
  if [ "$status" = ok ]; then SCENE_CHECKED[$name]="ok $tris tris $verts verts"; else SCENE_CHECKED[$name]="FAIL"; fi
  if [ "${placements:--}" != "-" ]; then
    if [ "$status" = ok ]; then SCENE_PLACEMENTS[$name]="ok $placements"; else SCENE_PLACEMENTS[$name]="FAIL"; fi
  elif [ "$status" != ok ] && [ "${SCENE_PLACEMENTS[$name]:0:4}" = FAIL ]; then
    SCENE_PLACEMENTS[$name]="FAIL (see the scene check)"
  fi
done < "$OUT/check_scenes.tsv"
section "5c. check_species.py (generated grass and flowers: LoD triangles, wind attributes, MSFT_lod, pyrender silhouettes per LoD vs LoD0, mip coverage)"
: > "$OUT/check_species.tsv"
for scene in "${SCENES[@]}"; do
  if "$PY" scripts/check_species.py "$BUILD_OUT/$scene" --summary-tsv "$OUT/check_species.tsv"; then pass; else fail "check_species.py $scene"; fi
done
declare -A SPECIES_CHECKED=()
while IFS=$'\t' read -r name status; do SPECIES_CHECKED[$name]="$status"; done < "$OUT/check_species.tsv"

section "5d. Blender (bpy) imports every species file (LoD chains and flowers): one level visible, no repeated materials"
chain_files=()
for f in "${FILES[@]}"; do
  case "$f" in */species/*_LOD*.glb|*/species/*_far.glb) ;; */species/*.glb) chain_files+=("$OUT/$f") ;; esac
done
BLENDER_TSV="$OUT/check_blender.tsv"
: > "$BLENDER_TSV"
if ((${#chain_files[@]})); then
  # the importer logs every node it creates at INFO level: keep only the check's own lines
  if "$BPY" scripts/check_blender.py --summary-tsv "$BLENDER_TSV" "${chain_files[@]}" 2>&1 | grep -v ' | INFO: \|^$'; then
    :
  fi
  while IFS=$'\t' read -r file status visible objects; do
    if [ "$status" = ok ]; then pass; else fail "Blender import of ${file#"$OUT"/}: see the table above"; fi
  done < "$BLENDER_TSV"
  if [ "$(wc -l < "$BLENDER_TSV")" -ne "${#chain_files[@]}" ]; then fail "check_blender.py did not report every chain file"; fi
else
  fail "no species chain files to import into Blender"
fi

section "5d2. Blender (bpy) imports every scene through scripts/blender_import.py: one object per mesh, every placement an instance, positions and frames as the tables say; it renders the first view (Cycles, out/check/engines/views/blender_<scene>.png) showing the scene, its snow, its green grass"
mkdir -p "$OUT/engines/views"
for scene in "${SCENES[@]}"; do
  dir="$BUILD_OUT/$scene"
  [ -f "$dir/scene.glb" ] || continue
  "$BPY" scripts/blender_import.py "$dir" --check --render "$OUT/engines/views/blender_$scene.png" 2>&1 \
    | grep -v ' | INFO: \|^$\|^Fra:\|^Saved: \|^Time: ' > "$OUT/blender_import_$scene.log" || true
  cat "$OUT/blender_import_$scene.log"
  if [ "$(grep -c '^ok ' "$OUT/blender_import_$scene.log")" -ge 2 ] && ! grep -q '^FAIL' "$OUT/blender_import_$scene.log"; then
    pass
  else
    fail "blender_import.py $scene (see $OUT/blender_import_$scene.log)"
  fi
done

section "5e. Babylon.js (default loader options) and three.js (GLTFLoader + three_msft_lod.js) in headless Chromium load every species file without an error or warning, show LoD0 (Babylon: MSFT_lod levels in order; three.js: each level shown with exactly its triangles inside its screen-coverage range), and see the grass green"
# thumbnails of what each engine drew go to out/check/engines/
green_files=()
other_files=()
for f in "${FILES[@]}"; do
  case "$f" in
    */species/*_far.glb) ;;
    # grass levels: LoD3 is one horizontal card of the top view, whose thin blade tips a near,
    # oblique camera hardly sees (an engine shows it far away): loaded and drawn, not judged by colour
    */species/*_LOD3.glb) if [ -f "$OUT/${f%_LOD*}_far.glb" ]; then other_files+=("$OUT/$f"); fi ;;
    */species/*_LOD*.glb) if [ -f "$OUT/${f%_LOD*}_far.glb" ]; then green_files+=("$OUT/$f"); fi ;;
    */species/*.glb) if [ -f "$OUT/${f%.glb}_far.glb" ]; then green_files+=("$OUT/$f"); else other_files+=("$OUT/$f"); fi ;;
  esac
done
if ((${#green_files[@]})) && ((${#other_files[@]})); then
  # the two engines load in parallel (each browser mostly waits on one core), then the logs are read in order
  engine_pids=()
  for engine in babylon three; do
    (
      for group in green other; do
        if [ "$group" = green ]; then args=(--green "${green_files[@]}"); else args=("${other_files[@]}"); fi
        # Babylon's defaults (no range requests): what a user gets loading the file as it is
        node scripts/engines/check_babylon.mjs --engine "$engine" --no-range-requests --thumbs "$OUT/engines" "${args[@]}" \
          > "$OUT/check_${engine}_$group.log" 2>&1 || true
      done
    ) &
    engine_pids+=($!)
  done
  # these two only: a bare `wait` would also wait for the tests running in the background
  wait "${engine_pids[@]}"
  for engine in babylon three; do
    for group in green other; do
      if [ "$group" = green ]; then n=${#green_files[@]}; else n=${#other_files[@]}; fi
      log="$OUT/check_${engine}_$group.log"
      sed 's|'"$OUT"'/||' "$log" || true
      oks=$(grep -c '^ok ' "$log" || true)
      for _ in $(seq 1 "$oks"); do pass; done
      if [ "$oks" -ne "$n" ]; then fail "$engine: $((n - oks)) of $n $group species files failed (see $log)"; fi
    done
  done
else
  fail "no grass or other species files to load in Babylon.js"
fi

section "5f. three.js and Babylon.js draw every scene.glb from its first [[view]] with exactly the triangles and draw calls the view stage reported (three.js renderer.info; Babylon active indices, draw calls)"
wait "$scene_engines_pid"
if ((${#scene_files[@]})); then
  for engine in three babylon; do
    engine_log "$OUT/check_${engine}_views.log" "${#scene_files[@]}" "$engine views: scenes drawn unlike the report"
  done
else
  fail "no scene.glb to draw"
fi

for f in "${FILES[@]}"; do
  if [ -z "${IS_BUILD[$f]:-}" ]; then continue; fi
  scene="${SCENE_OF[$f]}"
  case "${SCENE_CHECKED[$scene]:-FAIL}" in
    FAIL) CHECKED[$f]="FAIL (scene $scene)" ;;
    *) case "$f" in
         */terrain_LOD*) CHECKED[$f]="ok (LoD, scene check)" ;;
         */species/*|*/atlases/*)
           sp="$(basename "$f" .glb)"; sp="${sp%_LOD*}"; sp="${sp%_far}"
           # a tree species' variants (<name>_v<k>…) are checked under the species' name
           if [ -z "${SPECIES_CHECKED[$scene/$sp]:-}" ] && [[ "$sp" =~ ^(.+)_v[0-9]+$ ]]; then sp="${BASH_REMATCH[1]}"; fi
           st="${SPECIES_CHECKED[$scene/$sp]:-FAIL (not checked)}"
           if [ "$st" = ok ]; then CHECKED[$f]="ok (species check)"; else CHECKED[$f]="FAIL (species $sp: $st)"; fi ;;
         */scene.glb) CHECKED[$f]="ok (placements, scene check)" ;;
         *) CHECKED[$f]="ok (scene) ${SCENE_CHECKED[$scene]#ok }" ;;
       esac ;;
  esac
done

# ---------------------------------------------------------------------------------------------------------
section "5f2. scene_lod.glb and every scene tile (each terrain chunk and placement tile an MSFT_lod chain) load in three.js through three_msft_lod.js (each chain shows one level; levels drawn with exactly their triangles inside their coverage ranges, on a sample of 32 chains) and, under 50 MB (a scene's smallest tile), in Babylon.js with its defaults (levels in order, exactly the default scene's LoD0 triangles enabled at the end)"
if ((${#lod_files[@]})); then
  engine_log "$OUT/check_babylon_scene_lod.log" "${#babylon_lod_files[@]}" "babylon: scene_lod.glb and tile files"
  engine_log "$OUT/check_three_scene_lod.log" "${#lod_files[@]}" "three: scene_lod.glb and tile files"
else
  fail "no scene_lod.glb to load"
fi

section "5f3. three.js lights every scene's terrain levels like its LoD0 through their normal maps (TANGENT + normalTexture; top-down under a low sun: mean luminance difference under 4 of 255 and under half of what the vertex normals alone give)"
for dir in "${lit_dirs[@]}"; do
  levels=("$dir"/terrain/terrain_LOD[1-9]*.glb)
  engine_log "$OUT/check_three_terrain_lit_$(basename "$dir").log" "${#levels[@]}" "$(basename "$dir"): terrain levels not lit like LoD0"
done
if ((${#lit_dirs[@]} == 0)); then fail "no scene with terrain levels to light"; fi

section "5f4. three.js shows every scene's terrain chunks at mixed levels without holes (chunk (i, j) at level (i + j + s) mod the levels, every s: no sky through the ground from above, at most 4 px at 35° where each level alone draws ground)"
if ((${#lit_dirs[@]})); then
  engine_log "$OUT/check_three_terrain_seams.log" "${#lit_dirs[@]}" "terrain chunks at mixed levels"
fi

section "5g. the Godot 4 import script (scripts/engines/godot/verdant_scene.gd) parses and passes gdtoolkit's lint and format check"
# no Godot on the registries these machines reach: the script is checked statically only
if "$VENV/bin/gdparse" scripts/engines/godot/verdant_scene.gd > /dev/null \
  && "$VENV/bin/gdlint" scripts/engines/godot/verdant_scene.gd \
  && "$VENV/bin/gdformat" --check scripts/engines/godot/verdant_scene.gd; then
  pass
else
  fail "scripts/engines/godot/verdant_scene.gd: gdtoolkit found problems (see above)"
fi

section "5g2. the Unreal Engine 5 import script (scripts/engines/unreal/verdant_unreal.py): every Unreal name it uses is in the UE 5.6 Python API (PyPI unreal-stub); on every built scene it places each table row once, with the chain's LODs and screen sizes, at C M C^-1 of its glTF transform; it reads binary tables as their CSV rows"
wait "$engine_scripts_pid"
script_log() {
  local log="$1" what="$2"
  if [ ! -f "$log" ]; then fail "$what: no log ($log)"; return; fi
  grep -v '^rc=' "$log" | sed 's|'"$OUT"'/||' || true
  if [ "$(tail -1 "$log")" = "rc=0" ]; then pass; else fail "$what: see the errors or FAIL lines above"; fi
}
if [ -z "$unreal_stub" ]; then
  fail "unreal-stub is not installed in $VENV"
else
  script_log "$OUT/check_unreal_script.log" "scripts/engines/unreal/verdant_unreal.py"
fi

section "5g3. the Unity import scripts (scripts/engines/unity/): VerdantData.cs compiled with Mono and run on every built scene (each table row planned once, LODGroup transitions strictly decreasing from the screen sizes, one sphere behind them, Unity transforms = F M F of the glTF ones; binary tables read as their CSV rows); the UnityEngine/UnityEditor files parse"
if ! command -v mcs > /dev/null || ! command -v mono > /dev/null; then
  fail "Mono (apt mono-mcs) is not installed"
else
  script_log "$OUT/check_unity_script.log" "scripts/engines/unity/"
fi

section "6. Khronos glTF Validator (0 errors, 0 warnings; infos and hints allowed)"
gltf_files=()
for f in "${FILES[@]}"; do
  if [ -n "${IS_BUILD[$f]:-}" ]; then continue; fi   # per scene below (basenames repeat across scenes)
  case "$f" in
    *.glb|*.gltf) if [ "${EXPORTED[$f]%% *}" = ok ]; then gltf_files+=("$OUT/$f"); else KHRONOS[$f]="-"; fi ;;
    *) KHRONOS[$f]="n/a (obj)" ;;
  esac
done
: > "$OUT/gltf_validate.tsv"
if ((${#gltf_files[@]})); then
  node scripts/gltf_validate.mjs --summary-tsv "$OUT/gltf_validate.tsv" "${gltf_files[@]}" || true
  while IFS=$'\t' read -r name status counts; do
    if [ "$status" = ok ]; then KHRONOS[$name]="ok E/W/I/H $counts"; pass
    else KHRONOS[$name]="FAIL E/W/I/H $counts"; fail "gltf-validator $name"; fi
  done < "$OUT/gltf_validate.tsv"
  for f in "${gltf_files[@]}"; do
    b="$(basename "$f")"
    if [ -z "${KHRONOS[$b]:-}" ]; then KHRONOS[$b]="FAIL (no result)"; fail "gltf-validator gave no result for $b"; fi
  done
fi

# the scene outputs, one validator run per scene (file names are unique within a scene)
for scene in "${SCENES[@]}"; do
  scene_gltf=()
  for f in "${FILES[@]}"; do
    [ "${SCENE_OF[$f]:-}" = "$scene" ] || continue
    case "$f" in *.glb|*.gltf) scene_gltf+=("$OUT/$f") ;; *) KHRONOS[$f]="n/a (obj)" ;; esac
  done
  ((${#scene_gltf[@]})) || continue
  tsv="$OUT/gltf_validate_$scene.tsv"
  : > "$tsv"
  node scripts/gltf_validate.mjs --summary-tsv "$tsv" "${scene_gltf[@]}" || true
  while IFS=$'\t' read -r name status counts; do
    f="$(printf '%s\n' "${scene_gltf[@]}" | grep -F "/$name" | head -1)"
    f="${f#"$OUT"/}"
    if [ "$status" = ok ]; then KHRONOS[$f]="ok E/W/I/H $counts"; pass
    else KHRONOS[$f]="FAIL E/W/I/H $counts"; fail "gltf-validator $f"; fi
  done < "$tsv"
  for f in "${scene_gltf[@]}"; do
    rel="${f#"$OUT"/}"
    if [ -z "${KHRONOS[$rel]:-}" ]; then KHRONOS[$rel]="FAIL (no result)"; fail "gltf-validator gave no result for $rel"; fi
  done
done

# ---------------------------------------------------------------------------------------------------------
TEST_RC=0
if [ -n "$TEST_PID" ]; then
  section "2c. cargo test --release: the tests' log (they ran alongside the output checks)"
  wait "$TEST_PID" || TEST_RC=$?
  cat "$TEST_LOG"
  echo "cargo test ran for $(elapsed "$TEST_START") (exit $TEST_RC)"
fi

# ---------------------------------------------------------------------------------------------------------
section "Summary"
printf '%-38s | %-10s | %-16s | %-40s | %s\n' file export "verdant validate" "check_outputs" "gltf-validator"
printf '%s\n' "---------------------------------------+------------+------------------+------------------------------------------+---------------------"
for f in "${FILES[@]}"; do
  printf '%-38s | %-10s | %-16s | %-40s | %s\n' "$f" "${EXPORTED[$f]:--}" "${VALIDATED[$f]:--}" \
    "${CHECKED[$f]:--}" "${KHRONOS[$f]:--}"
done
echo
printf '%-12s | %-6s | %-40s | %s\n' scene build "check_outputs --scene (sha256, LoDs, ...)" \
  "placements (glb instancing = CSV/JSON, ray-cast, spacing)"
for scene in "${SCENES[@]}"; do
  printf '%-12s | %-6s | %-40s | %s\n' "$scene" "${SCENE_BUILT[$scene]:--}" "${SCENE_CHECKED[$scene]:--}" \
    "${SCENE_PLACEMENTS[$scene]:--}"
done
section "Time per section"
printf '%s\n' "${SECTION_TIMES[@]}"
echo "thumbnails: out/check/thumbs/   total time: $(elapsed "$SCRIPT_START")"
echo "outputs: $PASSED passed, $FAILED failed"
if ((TEST_RC)); then
  echo "cargo test: FAILED (exit $TEST_RC; its log is in section 2c above and in $TEST_LOG)" >&2
else
  echo "cargo test: passed"
fi
if ((FAILED)) || ((TEST_RC)); then
  echo "check.sh: FAILED ($FAILED output checks failed; see the '!!' lines above$( ((TEST_RC)) && echo '; cargo test failed'))" >&2
  exit 1
fi
echo "check.sh: all checks passed"
