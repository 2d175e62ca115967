#!/usr/bin/env bash
# What standing queries cost when nothing changes, against walking: one server on a built world
# (the city: `horizon-lab gen world city DIR --seed 1` then `horizon build DIR`), without
# instances, `horizon-lab load` with 300 and 1,000 viewers standing still (`--speed 0`: every
# view carried, no delta), then 300 walking; the plan times the server recorded go to
# OUT/plan_seconds_walking_300.txt. Server and load share this machine; each report gives the
# server's cores and the load generator's own.
#
#   cargo build --release -p horizon-server && cargo build --release -p horizon-lab
#   bash lab/bench/floor_load.sh /tmp/city lab/results/query_api/floor
set -euo pipefail
WORLD=${1:?a built world}
OUT=${2:-lab/results/query_api/floor}
H=${H:-target/release/horizon}
L=${L:-target/release/horizon-lab}
mkdir -p "$OUT"
source "$(dirname "${BASH_SOURCE[0]}")/lib.sh"
scratch
serve "$WORLD"
for viewers in 300 1000; do
  echo "load: $viewers viewers standing still" >&2
  "$L" load "$url" --viewers "$viewers" --hz 10 --duration 20 --pid "$pid" --no-instances \
    --speed 0 --json > "$OUT/still_$viewers.json"
done
echo "load: 300 viewers walking" >&2
"$L" load "$url" --viewers 300 --hz 10 --duration 20 --pid "$pid" --no-instances --json \
  > "$OUT/walking_300.json"
curl -sf "$url/metrics" | grep horizon_stream_plan_seconds > "$OUT/plan_seconds_walking_300.txt"
echo "wrote $OUT" >&2
