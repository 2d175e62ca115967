#!/usr/bin/env bash
# Instances entries under load, on one server and a built world (the city: `horizon-lab gen
# world city DIR --seed 1` then `horizon build DIR`), each figure with instances then without,
# back to back:
#   1. `GET /v1/cut` at seeded street-level eyes, open loop (`horizon-lab bench-cut`), plain
#      JSON and zstd-compressed (`Accept-Encoding: zstd`, as the viewer's browser asks);
#   2. standing queries at 10 Hz per viewer, no mutations (`horizon-lab load`).
# Server and load share this machine. JSON reports go to OUT/. RATES, ENCODINGS and VIEWERS
# choose the figures (empty: none of that kind), MODES the modes of the standing queries
# ("instances aggregates"); H and L the binaries.
#
#   cargo build --release -p horizon-server && cargo build --release -p horizon-lab
#   bash lab/bench/instances_load.sh /tmp/city lab/results/reuse/load
set -euo pipefail
WORLD=${1:?a built world}
OUT=${2:-lab/results/reuse/load}
RATES=${RATES-"5 20 50"}
ENCODINGS=${ENCODINGS-"identity zstd"}
VIEWERS=${VIEWERS-"10 50"}
MODES=${MODES-"instances aggregates"}
SECONDS_EACH=${SECONDS_EACH:-20}
H=${H:-target/release/horizon}
L=${L:-target/release/horizon-lab}
mkdir -p "$OUT"
source "$(dirname "${BASH_SOURCE[0]}")/lib.sh"
scratch
serve "$WORLD"
for encoding in $ENCODINGS; do
  for rate in $RATES; do
    for mode in instances aggregates; do
      flag=""
      [ "$mode" = aggregates ] && flag="--no-instances"
      [ "$encoding" != identity ] && flag="$flag --accept-encoding $encoding"
      echo "bench-cut at $rate/s, $mode, $encoding" >&2
      "$L" bench-cut "$url" --rate "$rate" --seconds "$SECONDS_EACH" $flag \
        > "$OUT/cut_${mode}_${encoding}_${rate}.json"
    done
  done
done
for viewers in $VIEWERS; do
  for mode in $MODES; do
    flag=""
    [ "$mode" = aggregates ] && flag="--no-instances"
    echo "load: $viewers viewers at 10 Hz, $mode" >&2
    "$L" load "$url" --viewers "$viewers" --hz 10 --duration "$SECONDS_EACH" --pid "$pid" $flag --json \
      > "$OUT/stream_${mode}_${viewers}.json"
  done
done
echo "wrote $OUT" >&2
