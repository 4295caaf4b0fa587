#!/usr/bin/env bash
# Scene build benchmark: the embedded demo and every shipped preset, each built from scratch (--force)
# into a temporary out dir and then rebuilt from the stage cache. Prints a table: seconds per stage
# (from report.json's timing section), the build's wall time and peak memory, then the cached rebuild's
# wall time and its ratio to the full build (the issue's target: under 5 %).
#
#   scripts/bench_build.sh [PRESET.toml ...]      default: the demo and presets/*.toml
#
# VERDANT_BIN=path/to/verdant uses that binary instead of building target/release/verdant.
# Peak memory: /usr/bin/time -v when present, else VmHWM polled from /proc/<pid>/status.
set -euo pipefail
cd "$(dirname "${BASH_SOURCE[0]}")/.."

if [ -n "${VERDANT_BIN:-}" ]; then
  BIN="$VERDANT_BIN"
else
  cargo build --release --quiet
  BIN="$PWD/target/release/verdant"
fi
PY="$(command -v python3)"

TMP="$(mktemp -d "${TMPDIR:-/tmp}/verdant-bench.XXXXXX")"
trap 'rm -rf "$TMP"' EXIT

if (($#)); then presets=("$@"); else presets=("" presets/*.toml); fi

now() { date +%s.%N; }

# run_measured LOGFILE CMD...: runs CMD; prints "WALL_SECONDS PEAK_KB"
run_measured() {
  local log="$1"; shift
  local t0 t1 peak=0
  t0="$(now)"
  if [ -x /usr/bin/time ]; then
    /usr/bin/time -v -o "$log.time" "$@" > "$log" 2>&1 || { cat "$log" >&2; return 1; }
    peak="$(awk -F': ' '/Maximum resident set size/ {print $2}' "$log.time")"
  else
    "$@" > "$log" 2>&1 &
    local pid=$! hwm
    while kill -0 "$pid" 2>/dev/null; do
      hwm="$(awk '/^VmHWM:/ {print $2}' "/proc/$pid/status" 2>/dev/null || true)"
      if [ -n "$hwm" ] && [ "$hwm" -gt "$peak" ]; then peak="$hwm"; fi
      sleep 0.02
    done
    wait "$pid" || { cat "$log" >&2; return 1; }
  fi
  t1="$(now)"
  echo "$("$PY" -c "print($t1 - $t0)") $peak"
}

echo "verdant $("$BIN" --version | awk '{print $2}'), $(nproc) cores; peak memory from $([ -x /usr/bin/time ] && echo '/usr/bin/time -v' || echo 'polled VmHWM')"
rows=()
for preset in "${presets[@]}"; do
  label="${preset:-(demo)}"
  out="$TMP/$(basename "${preset:-demo}" .toml)"
  args=(-q build)
  [ -n "$preset" ] && args+=("$preset")
  args+=(--out "$out")
  read -r full_s peak_kb < <(run_measured "$TMP/full.log" "$BIN" "${args[@]}" --force)
  read -r cached_s _ < <(run_measured "$TMP/cached.log" "$BIN" "${args[@]}")
  scene_dir="$(dirname "$(ls "$out"/*/report.json | head -1)")"
  rows+=("$("$PY" - "$scene_dir/report.json" "$label" "$full_s" "$peak_kb" "$cached_s" "$out/${scene_dir##*/}" <<'EOF'
import json, sys
report, label, full_s, peak_kb, cached_s, _ = sys.argv[1:]
# the cached rebuild rewrote report.json: its timing says cached, computed_in keeps the full run's seconds
r = json.load(open(report))
t = r["timing"]
terrain = t.get("terrain", {})
c = terrain.get("computed_in") or {}
assert terrain.get("cached") is True, f"{label}: the rebuild did not hit the terrain cache"
preview = t.get("preview", {}).get("computed_in")
tris = r["stages"].get("terrain", {}).get("output_triangles", 0)
full, cached = float(full_s), float(cached_s)
stage_total = (c.get("total") or 0) + (preview or 0)
cols = [r["scene"], label, str(tris)] + [f"{c.get(k, 0):.2f}" for k in ("decode", "mesh", "analyze", "build", "export", "lods")]
cols += [f"{c.get('total', 0):.2f}", f"{preview or 0:.2f}", f"{stage_total:.2f}", f"{full:.2f}",
         f"{int(peak_kb) / 1024:.0f}", f"{cached:.3f}", f"{100 * cached / full:.1f}%"]
print("\t".join(cols))
EOF
)")
done

header="scene\tpreset\ttriangles\tdecode\tmesh\tanalyze\tbuild\texport\tlods\tterrain\tpreview\tstages\twall s\tpeak MB\tcached s\tcached/full"
{ printf '%b\n' "$header"; printf '%s\n' "${rows[@]}"; } | column -t -s $'\t'
echo
echo "stage columns: seconds from report.json timing (terrain: decode … lods, its total; preview); 'stages' = terrain + preview;"
echo "wall s / peak MB: the whole \`verdant build --force\` process; cached s: the rebuild from the stage cache (target < 5 %)."
