"""Digests of what Horizon writes, to show that a change leaves its outputs byte-identical.

For each argument: a world directory (world.json, objects.json, descriptors.json, bvh.json,
the names of its content-addressed model, aggregate and parts files, and the manifest's keys,
hashes and sizes, leaving out its timings), or a folder of GLB files (each file's digest).
One line per item: "<folder>/<item> <16 hex digits of sha256>". Run by lab/bench/outputs.sh.

Usage: outputs_digest.py DIR [DIR...]"""
import hashlib, json, pathlib, sys

def h(b): return hashlib.sha256(b).hexdigest()[:16]

def world(d):
    out = {}
    for name in ["world.json", "objects.json", "descriptors.json", "bvh.json"]:
        p = d / name
        if p.exists(): out[name] = h(p.read_bytes())
    for sub in ["models", "aggregates", "aggregates/parts"]:
        files = sorted(p.name for p in (d / sub).glob("*.glb")) if (d / sub).is_dir() else []
        out[sub] = h("\n".join(files).encode()) + f" ({len(files)} files)"
    m = d / "aggregates" / "manifest.json"
    if m.exists():
        j = json.loads(m.read_bytes())
        nodes = {k: [v["key"], v["glb"], v.get("parts"), v["part_keys"], v["stats"].get("bytes")] for k, v in j["nodes"].items()}
        out["manifest"] = h(json.dumps([j["format"], j["options"], j["atlas"], j["root_key"], nodes], sort_keys=True).encode())
    return out

for arg in sys.argv[1:]:
    p = pathlib.Path(arg)
    if (p / "world.json").exists():
        for k, v in world(p).items(): print(f"{p.name}/{k} {v}")
    else:
        for f in sorted(p.glob("*.glb")): print(f"{p.name}/{f.name} {h(f.read_bytes())}")
