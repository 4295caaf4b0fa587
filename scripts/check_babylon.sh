#!/usr/bin/env bash
# Babylon.js or three.js in headless Chromium on glb files (check.sh step 5e runs it on every species file).
#
#   bash scripts/check_babylon.sh [--engine babylon|three] [--thumbs DIR] [--no-range-requests] [--green] [--view] [--draw-limit N] [--lit-against REF.glb] FILE.glb...
#
# Installs Debian's chromium with apt when missing and Babylon.js 9.28, three.js 0.187 and
# puppeteer-core into scripts/engines/node_modules (git-ignored), then runs scripts/engines/check_babylon.mjs.
set -euo pipefail
cd "$(dirname "${BASH_SOURCE[0]}")/.."
if ! command -v chromium >/dev/null 2>&1; then
  SUDO=(); if [ "$(id -u)" -ne 0 ]; then SUDO=(sudo); fi
  "${SUDO[@]}" env DEBIAN_FRONTEND=noninteractive apt-get update -q
  "${SUDO[@]}" env DEBIAN_FRONTEND=noninteractive apt-get install -y -q --no-install-recommends chromium
fi
if [ ! -f scripts/engines/node_modules/babylonjs/package.json ] || [ ! -f scripts/engines/node_modules/three/package.json ]; then
  (cd scripts/engines && npm ci --no-audit --no-fund --loglevel=error)
fi
files=()
for a in "$@"; do case "$a" in --*|babylon|three) files+=("$a") ;; *) files+=("$(realpath -m "$a")") ;; esac; done
exec node scripts/engines/check_babylon.mjs "${files[@]}"
