#!/usr/bin/env bash
# Runs k8s-indexed-job.yaml: the shards' Indexed Job, waits for it to complete, then the merge Job
# (kubectl against a cluster of Kubernetes 1.29 or later: backoffLimitPerIndex).
#   scripts/shard/k8s-run.sh [NAMESPACE]
set -euo pipefail
ns=()
if [ -n "${1:-}" ]; then ns=(--namespace "$1"); fi
here="$(dirname "$0")"
# the two Jobs are the two documents of one file: apply the first, wait for it, apply the second
tmp="$(mktemp -d)"
trap 'rm -rf "$tmp"' EXIT
sed '/^---$/,$d' "$here/k8s-indexed-job.yaml" > "$tmp/shards.yaml"
sed '1,/^---$/d' "$here/k8s-indexed-job.yaml" > "$tmp/merge.yaml"
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
run verdant-shards "$tmp/shards.yaml"
run verdant-merge "$tmp/merge.yaml"
