#!/usr/bin/env bash
# Cut fidelity (issue: cuts that beat the naive world): the village, the city and a
# city-distinct of DISTINCT buildings (default 2,000), generated with seed 1 and built with the
# current code, then `horizon-lab fidelity` on
# each (2 street-level views, one overhead, one outside; 960x540, 60 degrees, 4 rays per
# pixel; cut at 0.001 sr with at most 4,000 entries), and on the city the overhead view again
# with the entry budget lifted. Tables and JSON go to OUT/, renders to OUT/images/ (not kept
# in git). A world already generated in WORK is rebuilt (only what changed) unless marked
# .built.
#
#   cargo build --release -p horizon-server && cargo build --release -p horizon-lab
#   bash lab/bench/fidelity.sh lab/results/fidelity
set -euo pipefail
OUT=${1:-lab/results/fidelity}
WORK=${WORK:-/tmp/horizon-fidelity}
H=target/release/horizon
L=target/release/horizon-lab
mkdir -p "$OUT" "$WORK"
DISTINCT=${DISTINCT:-2000}
for world in village city city-distinct; do
  dir="$WORK/$world"
  if [ ! -f "$dir/world.db" ]; then
    if [ "$world" = city-distinct ]; then
      "$L" gen world "$world" "$dir" --seed 1 --objects "$DISTINCT" > "$OUT/gen_$world.txt"
    else
      "$L" gen world "$world" "$dir" --seed 1 > /dev/null
    fi
  fi
  if [ ! -f "$dir/.built" ]; then
    /usr/bin/time -v "$H" build "$dir" > "$OUT/build_$world.txt" 2> "$WORK/build_$world.time"
    grep -E "Elapsed|Maximum resident" "$WORK/build_$world.time" >> "$OUT/build_$world.txt"
    touch "$dir/.built"
  fi
  "$L" fidelity "$dir" --images "$WORK/images/$world" > "$OUT/$world.md"
  "$L" fidelity "$dir" --json > "$OUT/$world.json" 2> /dev/null
done
for entries in 8000 16000 32000; do
  "$L" fidelity "$WORK/city" --max-entries "$entries" > "$OUT/city_entries_$entries.md"
done
