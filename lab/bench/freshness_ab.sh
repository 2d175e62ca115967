#!/usr/bin/env bash
# Freshness of two `horizon` binaries on one built world, interleaved A B A B so that the
# machine's drift falls on both: each run is `horizon-lab bench-service` with 100 placements at
# 1 per second and the other parts cut to a token size. Reports and server logs go to OUT/;
# OUT/summary has each run's p50, p99 and max, and `lab/bench/rebuild_log.py` reads the logs.
#
#   A=/tmp/horizon-before B=target/release/horizon bash lab/bench/freshness_ab.sh /tmp/city OUT
set -euo pipefail
WORLD=${1:?a built world}
OUT=${2:?an output folder}
A=${A:?the first horizon binary}
B=${B:?the second horizon binary}
RUNS=${RUNS:-2}
PLACEMENTS=${PLACEMENTS:-100}
L=${L:-target/release/horizon-lab}
mkdir -p "$OUT"
: > "$OUT/summary"
for i in $(seq "$RUNS"); do
  for v in A B; do
    bin=${!v}
    "$L" bench-service "$WORLD" --horizon "$bin" --models 5 --placements "$PLACEMENTS" \
      --sustain-seconds 1 --load-seconds 1 --out "$OUT/$v-$i.md" \
      --server-log "$OUT/$v-$i.log" > /dev/null
    echo "$v ($bin) run $i: $(grep -o 'p50 [0-9]* ms, p99 [0-9]* ms, max [0-9]* ms' "$OUT/$v-$i.md")" \
      | tee -a "$OUT/summary"
  done
done
