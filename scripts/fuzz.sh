#!/usr/bin/env bash
# Runs every cargo-fuzz target of fuzz/ for a given time and prints a table of executions.
#
#   scripts/fuzz.sh [SECONDS_PER_TARGET] [TARGET...]     (default 60 s, every target)
#
# Installs cargo-fuzz into .tools/cargo-fuzz (git-ignored) from crates.io; libFuzzer needs a nightly
# toolchain (`rustup toolchain install nightly` where rustup can reach its server; this script uses
# one already installed and says so when there is none). Seed corpora are written by
# scripts/fuzz_seeds.py into fuzz/corpus/<target>/ (git-ignored; what the fuzzer adds stays there
# between runs). Limits as in the issue: -rss_limit_mb=4096 -timeout=10; inputs up to 64 KiB. A crash, timeout or
# out-of-memory leaves its input in fuzz/artifacts/<target>/ and fails the run: turn it into a
# regression test in tests/suite/fuzz_regressions.rs (docs/fuzzing.md).
set -euo pipefail
cd "$(dirname "$0")/.."
ROOT=$PWD
SECONDS_PER_TARGET=${1:-60}
shift || true
ALL=(lsystem heightmap preset obj gltf placements placements_bin)
TARGETS=("${@:-${ALL[@]}}")
[ ${#TARGETS[@]} -eq 0 ] && TARGETS=("${ALL[@]}")

if ! rustup toolchain list 2>/dev/null | grep -q '^nightly'; then
    echo "fuzz.sh: libFuzzer needs a nightly toolchain and none is installed; run 'rustup toolchain install nightly' (needs static.rust-lang.org) and try again" >&2
    exit 2
fi
export PATH="$ROOT/.tools/cargo-fuzz/bin:$PATH"
if ! command -v cargo-fuzz >/dev/null; then
    echo "== installing cargo-fuzz into .tools/cargo-fuzz"
    cargo install cargo-fuzz --locked --root "$ROOT/.tools/cargo-fuzz"
fi

echo "== seed corpora"
cargo build --release --quiet
python3 scripts/fuzz_seeds.py target/release/verdant fuzz/corpus

echo "== building the targets (nightly, address sanitizer)"
cargo +nightly fuzz build

LOGS=$ROOT/fuzz/logs
mkdir -p "$LOGS"
status=0
rows=()
for t in "${TARGETS[@]}"; do
    echo "== fuzzing $t for ${SECONDS_PER_TARGET}s"
    log="$LOGS/$t.log"
    if cargo +nightly fuzz run "$t" "fuzz/corpus/$t" -- \
        -max_total_time="$SECONDS_PER_TARGET" -max_len=65536 -rss_limit_mb=4096 -timeout=10 -print_final_stats=1 >"$log" 2>&1; then
        result=ok
    else
        result="FAIL (see $log, fuzz/artifacts/$t/)"
        status=1
    fi
    execs=$(grep -o 'stat::number_of_executed_units: *[0-9]*' "$log" | grep -o '[0-9]*$' | tail -1)
    rate=$(grep -o 'stat::average_exec_per_sec: *[0-9]*' "$log" | grep -o '[0-9]*$' | tail -1)
    corpus=$(ls "fuzz/corpus/$t" | wc -l)
    rows+=("$(printf '%-11s %12s %10s %8s %s' "$t" "${execs:-?}" "${rate:-?}" "$corpus" "$result")")
done

echo
printf '%-11s %12s %10s %8s %s\n' target executions "execs/s" corpus result
printf '%s\n' "${rows[@]}"
echo "(${SECONDS_PER_TARGET} s per target, -rss_limit_mb=4096 -timeout=10)"
exit $status
