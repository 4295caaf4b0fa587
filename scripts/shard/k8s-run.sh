#!/usr/bin/env bash
# Runs k8s-indexed-job.yaml: the shards' Indexed Job, waits for it to complete, then the second
# round's (the scene tiles), then the merge Job (kubectl against a cluster of Kubernetes 1.29 or
# later: backoffLimitPerIndex).
#   scripts/shard/k8s-run.sh [NAMESPACE]
set -euo pipefail
ns=()
if [ -n "${1:-}" ]; then ns=(--namespace "$1"); fi
here="$(dirname "$0")"
# the three Jobs are the three documents of one file: apply each, wait for it, apply the next
tmp="$(mktemp -d)"
trap 'rm -rf "$tmp"' EXIT
awk -v dir="$tmp" '/^---$/ { n++; next } { print > (dir "/job" n ".yaml") }' n=0 "$here/k8s-indexed-job.yaml"
# run JOB FILE: replaces a finished Job of that name (apply would leave it as it was) and waits until
# it is Complete (exit 0) or Failed (exit 1)
run() {
  kubectl ${ns[@]+"${ns[@]}"} delete job "$1" --ignore-not-found --wait=true
  kubectl ${ns[@]+"${ns[@]}"} apply -f "$2"
  while :; do
    state="$(kubectl ${ns[@]+"${ns[@]}"} get job "$1" \
      -o jsonpath='{range .status.conditions[?(@.status=="True")]}{.type} {end}')"
    case "$state" in
      *Complete*) return 0 ;;
      *Failed*) echo "k8s-run.sh: job $1 failed (kubectl logs job/$1)" >&2; return 1 ;;
    esac
    sleep 10
  done
}
run verdant-shards "$tmp/job0.yaml"
# (the second round is optional: where it fails, the merge writes those tiles itself)
run verdant-tiles "$tmp/job1.yaml" || echo "k8s-run.sh: the second round (scene tiles) failed; the merge writes the tiles" >&2
run verdant-merge "$tmp/job2.yaml"
