#!/usr/bin/env bash
# A sharded build with GNU parallel: N shards of the given presets (none: the embedded demo), then the
# merge into OUT. On this machine by default; on ssh hosts with PARALLEL_SSHLOGIN (GNU parallel's
# --sshlogin list, e.g. "2/node1,2/node2"), which must see this folder at the same path (a shared
# file system: the shard folders are written there and the merge reads them back).
#
#   scripts/shard/parallel.sh N OUT [PRESET...]
#   VERDANT=target/release/verdant scripts/shard/parallel.sh 4 out presets/alpine.toml
#
# Each shard is `verdant build PRESET... --shard i/N --out OUT/.shards/i`, then (once every shard is
# done) its second round, the scene tiles of its share (`[scene] tile`; nothing to do without):
# `verdant build PRESET... --shard i/N --tiles --shards OUT/.shards/* --out OUT/.shards/i`; the merge
# is `verdant merge PRESET... --shards OUT/.shards/* --out OUT`. A shard failing stops the run
# (--halt now,fail=1) before the second round; the second round failing only leaves its tiles to the
# merge.
set -euo pipefail
if [ $# -lt 2 ]; then
  echo "usage: $0 N OUT [PRESET...]" >&2
  exit 2
fi
n="$1"; out="$2"; shift 2
verdant="${VERDANT:-verdant}"
shards="$out/.shards"
remote=()
if [ -n "${PARALLEL_SSHLOGIN:-}" ]; then
  remote=(--sshlogin "$PARALLEL_SSHLOGIN" --workdir "$PWD")
fi
# -q: each argument quoted as given (preset paths with spaces); ${remote[@]+…}: bash < 4.4 with set -u
seq 0 $((n - 1)) | parallel --will-cite -q --halt now,fail=1 ${remote[@]+"${remote[@]}"} \
  "$verdant" -q build "$@" --shard "{}/$n" --out "$shards/{}"
mapfile -t dirs < <(seq -f "$shards/%g" 0 $((n - 1)))
# (the second round is optional: where it fails, the merge writes those tiles itself)
seq 0 $((n - 1)) | parallel --will-cite -q --halt now,fail=1 ${remote[@]+"${remote[@]}"} \
  "$verdant" -q build "$@" --shard "{}/$n" --tiles --out "$shards/{}" --shards "${dirs[@]}" ||
  echo "parallel.sh: the second round (scene tiles) failed; the merge writes the tiles" >&2
"$verdant" merge "$@" --shards "${dirs[@]}" --out "$out"
