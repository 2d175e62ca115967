#!/usr/bin/env bash
# Progressive loading in `horizon-client walk` (issue 28, part 4) against its peer, loading in
# the order entries arrive (`--in-order`), on one server, alternating ROUNDS times: a 60 s walk
# at street level at 10 Mbit/s with a fresh cache each time. The default world is a
# city-distinct of 2,000 buildings (blocks of 3 x 3 lots of 32 m, 16 m streets, a pitch of
# 112 m); the walk goes along the street at x = 888 m, 2 m up. JSON reports go to OUT/,
# and a table to OUT/table.md.
#
#   cargo build --release -p horizon-server && cargo build --release -p horizon-lab \
#     && cargo build --release -p horizon-client
#   target/release/horizon-lab gen world city-distinct /tmp/cd2k --seed 1 --objects 2000
#   target/release/horizon build /tmp/cd2k
#   bash lab/bench/progressive_walk.sh /tmp/cd2k lab/results/levels/walk
set -euo pipefail
WORLD=${1:?a built world}
OUT=${2:-lab/results/levels/walk}
ROUNDS=${ROUNDS:-2}
BANDWIDTH=${BANDWIDTH:-1250000}
DURATION=${DURATION:-60}
PATH_JSON=${PATH_JSON:-'[[888, 2, 20], [888, 2, 1660]]'}
H=${H:-target/release/horizon}
C=${C:-target/release/horizon-client}
mkdir -p "$OUT"
source "$(dirname "${BASH_SOURCE[0]}")/lib.sh"
scratch
serve "$WORLD"
echo "$PATH_JSON" > "$work/path.json"
for round in $(seq "$ROUNDS"); do
  for mode in progressive in-order; do
    flag=()
    [ "$mode" = in-order ] && flag=(--in-order)
    echo "walk $round: $mode" >&2
    "$C" walk "$url" --path "$work/path.json" --duration "$DURATION" --bandwidth "$BANDWIDTH" \
      "${flag[@]}" --json > "$OUT/walk_${mode}_${round}.json"
  done
done
python3 - "$OUT" > "$OUT/table.md" <<'PY'
import glob, json, os, sys
out = sys.argv[1]
ms = lambda v: "never" if v is None else f"{v / 1000:.1f} s"
print("| walk | entries drawn, mean over frames | by screen size | first view with every entry drawn | first view loaded whole | frames with an entry not drawn | frames with an asset missing | MB fetched |")
print("|---|---|---|---|---|---|---|---|")
for path in sorted(glob.glob(os.path.join(out, "walk_*.json"))):
    r = json.load(open(path))
    name = os.path.basename(path)[len("walk_"):-len(".json")]
    print(f"| {name} | {100 * r['drawn_entries_share']:.1f}% | {100 * r['drawn_screen_share']:.1f}% "
          f"| {ms(r['first_drawn_ms'])} | {ms(r['first_complete_ms'])} "
          f"| {100 * r['hole_share']:.1f}% | {100 * r['incomplete_share']:.1f}% "
          f"| {r['bytes_fetched'] / 1e6:.1f} |")
PY
cat "$OUT/table.md"
