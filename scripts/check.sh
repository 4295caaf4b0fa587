#!/usr/bin/env bash
# verdant end-to-end check: set up the checking tools, run the Rust tests, export sample terrains with the
# CLI, and check every output three ways (verdant validate, trimesh/pyrender re-import + report cross-check,
# Khronos glTF Validator). Exits non-zero on any failure.
#
#   bash scripts/check.sh               everything
#   bash scripts/check.sh --setup-only  only install the tools (venv, npm, apt libs)
#   bash scripts/check.sh --no-tests    skip `cargo test` (quick loop on the outputs)
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
    -h|--help) sed -n '2,10p' "$0"; exit 0 ;;
    *) echo "check.sh: unknown argument '$arg' (try --help)" >&2; exit 2 ;;
  esac
done

# Pinned checking tools. pyopengl is installed in a second step, after pyrender, because pyrender pins
# PyOpenGL 3.1.0, which fails under EGL on these machines.
PY_PKGS=(trimesh==5.2.0 pyrender==0.1.45 pygltflib==1.16.5 numpy==2.4.6 pillow==12.3.0 scipy==1.17.1 networkx==3.6.1)
PY_PKGS_AFTER=(pyopengl==3.1.10)
APT_PKGS=(libegl1 libegl-mesa0 libgl1-mesa-dri)

export PYOPENGL_PLATFORM=egl
VENV="$ROOT/.venv"
PY="$VENV/bin/python"
OUT="$ROOT/out/check"
SHARED="$ROOT/../shared"
SCRIPT_START=$SECONDS

section() { printf '\n========== %s ==========\n' "$*"; }
elapsed() { echo "$(( SECONDS - $1 ))s"; }

# ---------------------------------------------------------------------------------------------------------
section "1. Set-up (apt libs, Python venv, npm gltf-validator)"
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
  "$PY" -m pip install -q --disable-pip-version-check "${PY_PKGS[@]}"
  echo "pip: installing ${PY_PKGS_AFTER[*]} (after pyrender, which pins an older PyOpenGL)"
  "$PY" -m pip install -q --disable-pip-version-check "${PY_PKGS_AFTER[@]}"
  echo "$py_want" > "$py_stamp"
  echo "venv: ready in $(elapsed "$t")"
fi

# npm: gltf-validator from the committed lock file; `npm ci` only when the lock changed.
npm_stamp="$ROOT/scripts/node_modules/.verdant-check-lock"
lock_sum="$(sha256sum "$ROOT/scripts/package-lock.json" | cut -d' ' -f1)"
if [ -f "$npm_stamp" ] && [ "$(cat "$npm_stamp")" = "$lock_sum" ] \
   && [ -f "$ROOT/scripts/node_modules/gltf-validator/package.json" ]; then
  echo "npm: gltf-validator up to date (scripts/node_modules)"
else
  t=$SECONDS
  echo "npm: npm ci in scripts/"
  (cd "$ROOT/scripts" && npm ci --no-audit --no-fund --loglevel=error)
  echo "$lock_sum" > "$npm_stamp"
  echo "npm: ready in $(elapsed "$t")"
fi

# Smoke-test the tools, so a broken set-up fails here with a clear message rather than mid-check.
"$PY" -c 'import trimesh, pygltflib, pyrender, OpenGL, numpy, PIL
print(f"python tools: trimesh {trimesh.__version__}, pyrender {pyrender.__version__}, "
      f"PyOpenGL {OpenGL.__version__}, numpy {numpy.__version__}")'
node -e 'const v=require(process.argv[1]); console.log("node tools: gltf-validator " + v.version())' \
  "$ROOT/scripts/node_modules/gltf-validator"
echo "set-up took $(elapsed "$setup_start")"

if ((SETUP_ONLY)); then exit 0; fi
