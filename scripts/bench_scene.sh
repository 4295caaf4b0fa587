#!/usr/bin/env bash
# Scene budget benchmark (issue 14): the embedded demo and every shipped preset, each built from
# scratch (--force) into a temporary out dir. Prints per preset and view: triangles and draw calls
# drawn (scene.glb as drawn from the view) against the same scene at full detail, instances drawn and
# culled, the share of pixels that differ from the view rendered at full detail (--compare-full-detail:
# the project's rasterizer, 960×540 with 4×4 samples per pixel resolved, and in brackets the
# share of single samples; n/a above 5 G full-detail triangles), scene.glb's bytes and the
# whole scene's, and the build's wall time (comparison included). Targets: ≤ 2 M triangles, ≤ 200 draw
# calls and ≤ 2 % differing pixels per view.
#
#   scripts/bench_scene.sh [PRESET.toml ...]      default: the demo and presets/*.toml
#
# VERDANT_BIN=path/to/verdant uses that binary instead of building target/release/verdant.
set -euo pipefail
cd "$(dirname "${BASH_SOURCE[0]}")/.."

if [ -n "${VERDANT_BIN:-}" ]; then
  BIN="$VERDANT_BIN"
else
  cargo build --release --quiet
  BIN="$PWD/target/release/verdant"
fi
TMP="$(mktemp -d "${TMPDIR:-/tmp}/verdant-bench-scene.XXXXXX")"
trap 'rm -rf "$TMP"' EXIT
if (($#)); then presets=("$@"); else presets=("" presets/*.toml); fi

printf '%-14s %-8s %12s %6s %16s %6s %10s %10s %10s %10s %9s %9s %8s %s\n' preset view triangles calls "full-detail tris" calls ratio drawn "differing" "(samples)" "glb MB" "all MB" seconds targets
for p in "${presets[@]}"; do
  t0=$(date +%s.%N)
  if [ -z "$p" ]; then "$BIN" -q build --force --compare-full-detail --out "$TMP" >/dev/null; else "$BIN" -q build "$p" --force --compare-full-detail --out "$TMP" >/dev/null; fi
  t1=$(date +%s.%N)
  name=$(ls -t "$TMP" | grep -v '^\.' | head -1)
  python3 - "$TMP/$name/manifest.json" "$(echo "$t1 - $t0" | bc)" <<'PY'
import json, sys
m = json.load(open(sys.argv[1]))
secs = float(sys.argv[2])
v = m.get("view") or {}
for r in v.get("views", []):
    drawn = sum(s["drawn"] for s in r["species"])
    placed = sum(s["placed"] for s in r["species"])
    img = r.get("image") or {}
    diff = "n/a" if not img or img.get("skipped") else f"{100 * img['differing']:.2f} %"
    samples = "" if diff == "n/a" else f"({100 * img.get('differing_samples', 0):.2f} %)"
    ok = r["triangles"] <= 2_000_000 and r["draw_calls"] <= 200 and (diff == "n/a" or img["differing"] <= 0.02)
    print(f"{m['scene']:<14} {r['camera']['name']:<8} {r['triangles']:>12} {r['draw_calls']:>6} {r['full_detail_triangles']:>16} "
          f"{r['full_detail_draw_calls']:>6} {r['triangles'] / max(1, r['full_detail_triangles']):>10.2e} {drawn:>10} {diff:>10} {samples:>10} "
          f"{v['bytes'] / 1e6:>9.1f} {m['bytes']['total'] / 1e6:>9.1f} {secs:>8.1f} {'ok' if ok else 'OVER'} ({placed} placed)")
PY
done
