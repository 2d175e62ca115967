#!/usr/bin/env bash
# Levels of detail per model (issue 28), measured against their peer in the same run:
#   - cost: `horizon build`'s descriptor and level stages on freshly generated worlds (time per
#     model of descriptors plus levels against descriptors alone), and the bytes of every
#     model's levels against the model's own (read from world.db);
#   - bytes and fidelity: `horizon-lab fidelity --levels-peer` on the village, the city and a
#     city-distinct of DISTINCT (default 2,000) buildings: each seeded view's cut with levels
#     of detail (at 1 and at 0.5 pixels of error) and without (every object at level 0), both
#     ray-cast against the full world, chosen for the renderer's own pixel.
# Worlds are generated with seed 1 into WORK (default /tmp/horizon-levels) unless there, and
# built unless marked .built. Tables go to OUT/.
#
#   cargo build --release -p horizon-server && cargo build --release -p horizon-lab
#   bash lab/bench/levels.sh lab/results/levels
set -euo pipefail
OUT=${1:-lab/results/levels}
WORK=${WORK:-/tmp/horizon-levels}
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
done
python3 - "$WORK" "$OUT" <<'EOF'
import json, pathlib, re, sqlite3, sys
work, out = pathlib.Path(sys.argv[1]), pathlib.Path(sys.argv[2])
lines = ["| world | models | descriptors s | levels s | (descriptors + levels) / descriptors | levels per model | model bytes | all levels' bytes | ratio |",
         "|---|---|---|---|---|---|---|---|---|"]
for world in ["village", "city", "city-distinct"]:
    text = (out / f"build_{world}.txt").read_text()
    m = re.search(r"(\d+) models .*descriptors ([0-9.]+) s, levels ([0-9.]+) s", text)
    models, d, l = int(m.group(1)), float(m.group(2)), float(m.group(3))
    db = sqlite3.connect(f"file:{work / world / 'world.db'}?mode=ro", uri=True)
    chains = [json.loads(t) for (t,) in db.execute(
        "SELECT l.levels FROM levels l JOIN (SELECT DISTINCT asset FROM models) m ON m.asset = l.asset")]
    own = sum(c[0]["bytes"] for c in chains)
    total = sum(sum(x["bytes"] for x in c) for c in chains)
    per = sum(len(c) for c in chains) / max(len(chains), 1)
    lines.append(f"| {world} | {models} | {d:.2f} | {l:.2f} | {(d + l) / d:.2f}x | {per:.1f} | "
                 f"{own / 1e6:.1f} MB | {total / 1e6:.1f} MB | {total / own:.2f}x |")
(out / "cost.md").write_text("\n".join(lines) + "\n")
print("\n".join(lines))
EOF
for world in village city city-distinct; do
  for e in 1 0.5; do
    "$L" fidelity "$WORK/$world" --levels-peer --max-pixel-error "$e" > "$OUT/${world}_e$e.md"
  done
done
