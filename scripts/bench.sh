#!/usr/bin/env bash
# make bench: every benchmark in bench/ (long; not part of make test). Usage: bench.sh SPY TPY
set -euo pipefail
SPY=$1; TPY=$2
mkdir -p bench/results
for b in bench/bench_*.py; do
    case "$b" in
        *surrogate*) "$TPY" "$b" | tee "bench/results/$(basename "$b" .py).txt" ;;
        *) "$SPY" "$b" | tee "bench/results/$(basename "$b" .py).txt" ;;
    esac
done
