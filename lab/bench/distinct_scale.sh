#!/usr/bin/env bash
# city-distinct at scale (issue 26 part 2, issue 28's scale goal): a world of N distinct
# buildings per size (default 15,000 and 60,000; the same density, one building per 32 m
# lot), generated with seed 1 and built with the current code under /usr/bin/time (wall time
# and peak memory), then `horizon-lab fidelity --no-render` on each: the seeded views (2
# street-level, overhead, outside) planned by the product's planner at 0.001 sr with at most
# 4,000 entries, their download against naive (every model once), and every aggregate's
# bounds IoU. Full detail is not rendered: 60,000 buildings' textures do not fit the CPU
# renderer's memory. A world already generated in WORK is rebuilt (only what changed).
#
#   cargo build --release -p horizon-server && cargo build --release -p horizon-lab
#   bash lab/bench/distinct_scale.sh lab/results/distinct_scale
set -euo pipefail
OUT=${1:-lab/results/distinct_scale}
WORK=${WORK:-/tmp/horizon-distinct}
SIZES=${SIZES:-15000 60000}
H=target/release/horizon
L=target/release/horizon-lab
mkdir -p "$OUT" "$WORK"
for n in $SIZES; do
  dir="$WORK/cd$n"
  if [ ! -f "$dir/world.db" ]; then
    /usr/bin/time -v "$L" gen world city-distinct "$dir" --seed 1 --objects "$n" \
      > "$OUT/gen_$n.txt" 2> "$WORK/gen_$n.time"
    grep -E "Elapsed|Maximum resident" "$WORK/gen_$n.time" >> "$OUT/gen_$n.txt"
  fi
  /usr/bin/time -v "$H" build "$dir" > "$OUT/build_$n.txt" 2> "$WORK/build_$n.time"
  grep -E "Elapsed|Maximum resident" "$WORK/build_$n.time" >> "$OUT/build_$n.txt"
  du -sb "$dir" >> "$OUT/build_$n.txt"
  "$L" fidelity "$dir" --no-render > "$OUT/views_$n.md"
  "$L" fidelity "$dir" --no-render --json > "$OUT/views_$n.json" 2> /dev/null
done
