#!/usr/bin/env bash
# Orthoview impostors (issue 29), each figure against its peer in the same run:
#   - storage and build time: one fresh `horizon build` per world, whose report gives the
#     aggregates' and the impostors' bytes and seconds;
#   - download and fidelity: `horizon-lab fidelity --impostors` at the seeded views (street,
#     overhead, outside): each cut with impostors (drawn as splats) and the same cut without,
#     both ray-cast against the full world, with what the cut's objects alone cost (the
#     floor: objects that subtend min_solid_angle are always sent as themselves);
#   - handover: `fidelity --impostors --node N` for up to NODES (default 8) seeded nodes with
#     an impostor: impostor against aggregate, each alone, at the impostor's handover
#     distance for the renderer's pixel.
# Worlds are generated with seed 1 into WORK (default /tmp/horizon-impostors) and built there
# once (delete WORK/WORLD/.built to rebuild). Tables go to OUT/.
#
#   cargo build --release -p horizon-server && cargo build --release -p horizon-lab
#   bash lab/bench/impostors.sh lab/results/impostors
set -euo pipefail
OUT=${1:-lab/results/impostors}
WORK=${WORK:-/tmp/horizon-impostors}
H=${H:-target/release/horizon}
L=${L:-target/release/horizon-lab}
DISTINCT=${DISTINCT:-2000}
NODES=${NODES:-8}
WORLDS=${WORLDS:-city city-distinct}
mkdir -p "$OUT" "$WORK"
for world in $WORLDS; do
  dir="$WORK/$world"
  if [ ! -f "$dir/world.db" ]; then
    if [ "$world" = city-distinct ]; then
      "$L" gen world "$world" "$dir" --seed 1 --objects "$DISTINCT" > /dev/null
    else
      "$L" gen world "$world" "$dir" --seed 1 > /dev/null
    fi
  fi
  if [ ! -f "$dir/.built" ]; then
    /usr/bin/time -v "$H" build "$dir" > "$OUT/build_$world.txt" 2> "$WORK/build_$world.time"
    grep -E "Elapsed|Maximum resident" "$WORK/build_$world.time" >> "$OUT/build_$world.txt"
    touch "$dir/.built"
  fi
done
python3 - "$OUT" $WORLDS <<'EOF'
import pathlib, re, sys
out, worlds = pathlib.Path(sys.argv[1]), sys.argv[2:]
lines = ["| world | nodes | with an impostor | aggregates | impostors | storage impostors / aggregates | aggregate build s | impostor build s | time impostors / aggregates |",
         "|---|---|---|---|---|---|---|---|---|"]
for world in worlds:
    text = (out / f"build_{world}.txt").read_text()
    a = re.search(r"aggregates: (\d+) nodes.*?([0-9.]+) MB in all; ([0-9.]+) s", text)
    i = re.search(r"impostors: (\d+) nodes .*?([0-9.]+) MB in all .*?; ([0-9.]+) s", text)
    nodes, abytes, asec = int(a.group(1)), float(a.group(2)), float(a.group(3))
    inodes, ibytes, isec = int(i.group(1)), float(i.group(2)), float(i.group(3))
    # The build report's aggregate seconds include the impostors' (they run in its stage).
    asec -= isec
    lines.append(f"| {world} | {nodes} | {inodes} | {abytes:.1f} MB | {ibytes:.1f} MB | "
                 f"{ibytes / abytes:.3f}x | {asec:.1f} | {isec:.1f} | {isec / asec:.2f}x |")
(out / "cost.md").write_text("\n".join(lines) + "\n")
print("\n".join(lines))
EOF
for world in $WORLDS; do
  "$L" fidelity "$WORK/$world" --impostors > "$OUT/${world}_views.md"
  # Seeded impostor nodes of the published manifest.
  nodes=$(python3 - "$WORK/$world" "$NODES" <<'EOF'
import json, pathlib, random, sqlite3, sys
d, n = pathlib.Path(sys.argv[1]), int(sys.argv[2])
db = sqlite3.connect(f"file:{d / 'world.db'}?mode=ro", uri=True)
(pub,) = db.execute("SELECT value FROM world WHERE key = 'published'").fetchone()
m = json.loads(pub)["manifest"]
manifest = json.loads((d / "blobs" / m[:2] / m).read_bytes())
ids = sorted(int(k) for k in manifest.get("impostors", {}))
random.Random(1).shuffle(ids)
print(" ".join(str(k) for k in sorted(ids[:n])))
EOF
)
  : > "$OUT/${world}_handover.md"
  for node in $nodes; do
    "$L" fidelity "$WORK/$world" --impostors --node "$node" | tail -n 1 >> "$OUT/${world}_handover.md"
  done
done
