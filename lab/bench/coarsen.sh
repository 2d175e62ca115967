#!/usr/bin/env bash
# What the cut does where a byte, draw-call or triangle budget refuses a refinement, each way
# measured against the service's cut in the same run: `horizon-lab fidelity --coarsen-peer
# --stop-peer` plans each seeded view (street, overhead, outside) three times under one budget:
#   - the service's cut: levels as the view asks, refinement going on past every refusal;
#   - the same with the search that coarsens levels where the budget refuses (issue 28's
#     "coarser levels are chosen before anything is left out"; `Coarsening::Search`);
#   - the same stopped at the first refusal (`plan_stopping`, what the service did before);
# and ray-casts all three against the full world.
#
# Budgets: on city-distinct (DISTINCT buildings, default 2,000; its free cut downloads 53-89 MB)
# bytes of 20, 40, 60 and 80 MB and 1.5M triangles; on the city (reused models, drawn mostly as
# instances; its free cut downloads about 12 MB and draws 7-16M triangles) 2M and 4M triangles.
# Worlds are generated with seed 1 into WORK (default /tmp/horizon-coarsen) and built there
# once (delete WORK/WORLD/.built to rebuild). Tables and JSON go to OUT/.
#
#   cargo build --release -p horizon-server && cargo build --release -p horizon-lab
#   bash lab/bench/coarsen.sh lab/results/levels/coarsen
set -euo pipefail
OUT=${1:-lab/results/levels/coarsen}
WORK=${WORK:-/tmp/horizon-coarsen}
H=${H:-target/release/horizon}
L=${L:-target/release/horizon-lab}
DISTINCT=${DISTINCT:-2000}
mkdir -p "$OUT" "$WORK"
source "$(dirname "${BASH_SOURCE[0]}")/lib.sh"
for world in city city-distinct; do
  dir="$WORK/$world"
  generate "$world" "$dir"
  if [ ! -f "$dir/.built" ]; then
    "$H" build "$dir" > "$WORK/build_$world.txt"
    touch "$dir/.built"
  fi
done
run() {
  local world=$1 name=$2
  shift 2
  "$L" fidelity "$WORK/$world" --coarsen-peer --stop-peer "$@" --json-out "$OUT/${world}_$name.json" \
    > "$OUT/${world}_$name.md"
  echo "$world $name: $OUT/${world}_$name.md"
}
for mb in 20 40 60 80; do
  run city-distinct "bytes${mb}mb" --max-bytes "${mb}000000"
done
run city-distinct triangles1.5m --max-triangles 1500000
run city triangles2m --max-triangles 2000000
run city triangles4m --max-triangles 4000000
