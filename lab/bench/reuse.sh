#!/usr/bin/env bash
# Reuse-aware cuts (issue 26, part 3): the village, the city and a city-distinct of DISTINCT
# buildings (default 2,000), generated with seed 1 and built with the current code, then
# `horizon-lab fidelity --instances-peer` on each: every seeded view's cut (instances on, the
# default) and the same cut with every node as its aggregate, planned, rendered and measured in
# the same run against the full world (2 street-level views, one overhead, one outside;
# 960x540, 60 degrees, 4 rays per pixel; 0.001 sr, at most 4,000 entries). The city is measured
# again under a budget of 2,000 draw calls, and the village and the city with every object at
# its own level of detail. Tables go to OUT/<world>.md, JSON beside them.
# A world already generated in WORK is rebuilt (only what changed) unless marked .built.
#
#   cargo build --release -p horizon-server && cargo build --release -p horizon-lab
#   bash lab/bench/reuse.sh lab/results/reuse
set -euo pipefail
OUT=${1:-lab/results/reuse}
WORK=${WORK:-/tmp/horizon-reuse}
H=${H:-target/release/horizon}
L=${L:-target/release/horizon-lab}
DISTINCT=${DISTINCT:-2000}
mkdir -p "$OUT" "$WORK"
source "$(dirname "${BASH_SOURCE[0]}")/lib.sh"
for world in village city city-distinct; do
  dir="$WORK/$world"
  generate "$world" "$dir"
  if [ ! -f "$dir/.built" ]; then
    /usr/bin/time -v "$H" build "$dir" > "$OUT/build_$world.txt" 2> "$WORK/build_$world.time"
    grep -E "Elapsed|Maximum resident" "$WORK/build_$world.time" >> "$OUT/build_$world.txt"
    touch "$dir/.built"
  fi
  "$L" fidelity "$dir" --instances-peer --json-out "$OUT/$world.json" > "$OUT/$world.md"
done
"$L" fidelity "$WORK/city" --instances-peer --max-draw-calls 2000 \
  --json-out "$OUT/city_draw_calls_2000.json" > "$OUT/city_draw_calls_2000.md"
# Each object at its own level (a triangle budget that never binds turns off shared levels):
# fewer triangles, more assets and draw calls.
for world in village city; do
  "$L" fidelity "$WORK/$world" --instances-peer --max-triangles 1000000000000 \
    --json-out "$OUT/${world}_own_levels.json" > "$OUT/${world}_own_levels.md"
done
