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
#     distance for the renderer's pixel;
#   - walking: a 60 s `horizon-client walk` on each world from street level (the middle of
#     its near edge, 2 m up) out to the outside view (0.9 extents out, 0.2 up), with and
#     without impostors, its bytes split by the kind of entry that asked for them: the far
#     field's bytes per second against those of the objects near the walker.
# Worlds are generated with seed 1 into WORK (default /tmp/horizon-impostors) and built there
# once (delete WORK/WORLD/.built to rebuild). Tables go to OUT/.
#
#   cargo build --release -p horizon-server && cargo build --release -p horizon-lab \
#     && cargo build --release -p horizon-client
#   bash lab/bench/impostors.sh lab/results/impostors
set -euo pipefail
OUT=${1:-lab/results/impostors}
WORK=${WORK:-/tmp/horizon-impostors}
H=${H:-target/release/horizon}
L=${L:-target/release/horizon-lab}
C=${C:-target/release/horizon-client}
DISTINCT=${DISTINCT:-2000}
NODES=${NODES:-8}
WORLDS=${WORLDS:-village city city-distinct}
mkdir -p "$OUT" "$WORK"
source "$(dirname "${BASH_SOURCE[0]}")/lib.sh"
for world in $WORLDS; do
  dir="$WORK/$world"
  generate "$world" "$dir"
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

# The walks, each world served on its own.
trap stop EXIT
for world in $WORLDS; do
  dir="$WORK/$world"
  rm -f "$dir/world.lock"
  serve "$dir" "$WORK"
  python3 - "$url" > "$WORK/path_$world.json" <<'EOF'
import json, sys, urllib.request
b = json.load(urllib.request.urlopen(sys.argv[1] + "/v1/world"))["bounds"]
lo, hi = b["min"], b["max"]
cx, cz = (lo[0] + hi[0]) / 2, (lo[2] + hi[2]) / 2
extent = max(hi[0] - lo[0], hi[2] - lo[2])
print(json.dumps([[cx, 2.0, lo[2] + 2.0], [cx, 0.2 * extent, cz - 0.9 * extent]]))
EOF
  speed=$(python3 -c "import json,math,sys; p=json.load(open(sys.argv[1])); print(math.dist(p[0], p[1]) / 60)" "$WORK/path_$world.json")
  for mode in with without; do
    extra=()
    if [ "$mode" = without ]; then extra=(--no-impostors); fi
    "$C" walk "$url" --path "$WORK/path_$world.json" --speed "$speed" --duration 60 "${extra[@]}" \
      --json > "$OUT/${world}_walk_$mode.json"
  done
  stop
done
python3 - "$OUT" $WORLDS <<'EOF'
import json, pathlib, sys
out, worlds = pathlib.Path(sys.argv[1]), sys.argv[2:]
lines = ["| world | impostors | bytes/s in all | objects | aggregates | impostors | all / objects | incomplete frames |",
         "|---|---|---|---|---|---|---|---|"]
for world in worlds:
    for mode in ["without", "with"]:
        r = json.loads((out / f"{world}_walk_{mode}.json").read_text())
        s = max(r["seconds"], 1e-9)
        rate = lambda k: r[k] / s / 1e6
        lines.append(f"| {world} | {mode} | {rate('bytes_fetched'):.2f} MB/s | {rate('bytes_objects'):.2f} | "
                     f"{rate('bytes_aggregates'):.2f} | {rate('bytes_impostors'):.2f} | "
                     f"{r['bytes_fetched'] / max(r['bytes_objects'], 1):.2f}x | {r['incomplete_share'] * 100:.1f}% |")
(out / "walk.md").write_text("\n".join(lines) + "\n")
print("\n".join(lines))
EOF
