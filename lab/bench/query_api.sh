#!/usr/bin/env bash
# The query API under load (DESIGN.md, "Service contract (v1)": /v1/cut and /v1/stream), on
# built worlds (`horizon-lab gen world city|city9 DIR --seed 1` then `horizon build DIR`):
#   1. standing queries on the city: `horizon-lab load` at 10 Hz per viewer, for a range of
#      viewer counts, without mutations and with 5 mutations/s (the rebuild worker on);
#   2. `GET /v1/cut` on city9 under `horizon-lab bench-cut` at 50 to 500 requests/s;
#   3. a 60 s `horizon-client walk` at street level along one of the city's roads, at
#      10 Mbit/s and unlimited.
# Server and load share this machine. Each JSON report goes to OUT/; the city is copied
# first, since the mutations change it.
#
#   cargo build --release -p horizon-server && cargo build --release -p horizon-lab \
#     && cargo build --release -p horizon-client
#   bash lab/bench/query_api.sh /tmp/city /tmp/city9 lab/results/query_api
set -euo pipefail
CITY=${1:?a built city}
CITY9=${2:?a built city9}
OUT=${3:-lab/results/query_api}
VIEWERS=${VIEWERS:-"10 25 50 100 200"}
MUTATING=${MUTATING:-"5 10 25 50 1000"}
SECONDS_EACH=${SECONDS_EACH:-20}
H=target/release/horizon
L=target/release/horizon-lab
C=target/release/horizon-client
mkdir -p "$OUT"
source "$(dirname "${BASH_SOURCE[0]}")/lib.sh"
scratch

echo "copying $CITY" >&2
cp -r "$CITY" "$work/city"
rm -f "$work/city/world.lock"
token=$("$H" token create "$work/city" --user loadbot)

serve "$work/city"
for n in $VIEWERS; do
  echo "load: $n viewers" >&2
  "$L" load "$url" --viewers "$n" --hz 10 --duration "$SECONDS_EACH" --pid "$pid" --json \
    > "$OUT/load_${n}.json"
done
for n in $MUTATING; do
  echo "load: $n viewers, 5 mutations/s" >&2
  "$L" load "$url" --viewers "$n" --hz 10 --duration "$SECONDS_EACH" --mutations 5 \
    --token "$token" --pid "$pid" --json > "$OUT/load_${n}_mutating.json"
done

# A walk along the road at z = 12 * 70 + 5, 2 m up.
echo '[[20, 2, 845], [1600, 2, 845]]' > "$work/road.json"
for bw in 1250000 0; do
  echo "walk: bandwidth $bw" >&2
  extra=()
  if [ "$bw" != 0 ]; then extra=(--bandwidth "$bw"); fi
  "$C" walk "$url" --path "$work/road.json" --duration 60 "${extra[@]}" --json \
    > "$OUT/walk_${bw}.json"
done
stop

serve "$CITY9"
for rate in 50 100 150 500; do
  echo "bench-cut on city9 at $rate/s" >&2
  "$L" bench-cut "$url" --rate "$rate" --seconds 30 > "$OUT/cut_city9_${rate}.json"
done
stop
echo "wrote $OUT" >&2
