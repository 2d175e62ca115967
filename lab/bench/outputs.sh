#!/usr/bin/env bash
# Writes Horizon's outputs into OUT and prints their digests (lab/bench/outputs_digest.py):
# every model in assets/models converted plain and compressed (`horizon mesh convert`), and the
# village, island and city at seed 1 generated (`horizon-lab gen world`) and built with every
# aggregate (`horizon build`). Two runs on two builds show a change byte-identical when their
# digests agree:
#
#   bash lab/bench/outputs.sh target/release/horizon target/release/horizon-lab /tmp/after
#   diff /tmp/before/digest.txt /tmp/after/digest.txt
#
# A build from before the product/lab split had every command in one binary: pass it twice.
# Takes about 5 minutes on 2 cores (the city's build is most of it).
set -euo pipefail
if [ $# -lt 3 ]; then
  echo "usage: $0 HORIZON HORIZON_LAB OUT [WORLD...]" >&2
  exit 2
fi
horizon=$(realpath "$1"); lab=$(realpath "$2"); out=$3; shift 3
worlds=("$@"); [ ${#worlds[@]} -gt 0 ] || worlds=(village island city)
root=$(cd "$(dirname "$0")/../.." && pwd)
mkdir -p "$out/conv"
find "$root/assets/models" -type f \( -name '*.glb' -o -name '*.gltf' -o -name '*.ply' -o -name '*.obj' -o -name '*.stl' \) | sort |
while read -r f; do
  name=$(echo "${f#"$root"/assets/models/}" | tr / _)
  "$horizon" mesh convert "$f" "$out/conv/$name.glb" >/dev/null
  "$horizon" mesh convert --compress "$f" "$out/conv/$name.c.glb" >/dev/null
done
dirs=("$out/conv")
for w in "${worlds[@]}"; do
  rm -rf "${out:?}/$w"
  (cd "$root" && "$lab" gen world "$w" "$out/$w" --seed 1 >/dev/null)
  "$horizon" build "$out/$w" --json >"$out/$w.build.json"
  dirs+=("$out/$w")
done
(cd "$out" && python3 "$root/lab/bench/outputs_digest.py" "${dirs[@]#"$out"/}") | tee "$out/digest.txt"
