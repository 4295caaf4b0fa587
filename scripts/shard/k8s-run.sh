#!/usr/bin/env bash
# Runs k8s-indexed-job.yaml: the shards' Indexed Job, waits for it to complete, then the merge Job
# (kubectl against a cluster of Kubernetes 1.29 or later: backoffLimitPerIndex).
#   scripts/shard/k8s-run.sh [NAMESPACE]
set -euo pipefail
ns=(${1:+--namespace "$1"})
here="$(dirname "$0")"
# the two Jobs are the two documents of one file: apply the first, wait for it, apply the second
tmp="$(mktemp -d)"
trap 'rm -rf "$tmp"' EXIT
sed '/^---$/,$d' "$here/k8s-indexed-job.yaml" > "$tmp/shards.yaml"
sed '1,/^---$/d' "$here/k8s-indexed-job.yaml" > "$tmp/merge.yaml"
kubectl "${ns[@]}" apply -f "$tmp/shards.yaml"
kubectl "${ns[@]}" wait --for=condition=complete --timeout=24h job/verdant-shards
kubectl "${ns[@]}" apply -f "$tmp/merge.yaml"
kubectl "${ns[@]}" wait --for=condition=complete --timeout=24h job/verdant-merge
