"""Digests of what Horizon writes, to show that a change leaves its outputs byte-identical.

For each argument: a world directory, or a folder of GLB files (each file's digest). A world of
format 2 (world.db and blobs/) is digested by its models (ids and assets), its objects (id,
model, owner, transform), its descriptors, and its published manifest's node entries (key, GLB,
parts, part list, size), leaving out timings; a world of format 1 (world.json, objects.json,
models/, aggregates/) by its files, as before. One line per item: "<folder>/<item> <16 hex
digits of sha256>". Run by lab/bench/outputs.sh.

Usage: outputs_digest.py DIR [DIR...]"""
import hashlib
import json
import pathlib
import sys

import world_files


def h(b):
    return hashlib.sha256(b).hexdigest()[:16]


def manifest_digest(j):
    nodes = {k: [v["key"], v["glb"], v.get("parts"), v["part_keys"], v["stats"].get("bytes")]
             for k, v in j["nodes"].items()}
    return h(json.dumps([j["format"], j["options"], j["atlas"], j["root_key"], nodes], sort_keys=True).encode())


def world_v2(d):
    q = lambda sql: world_files.query(d, sql)  # noqa: E731
    out = {
        "models": h(json.dumps(q("SELECT number, id, asset, name FROM models ORDER BY number")).encode()),
        "objects": h(json.dumps([[i, m, o, t.hex()] for i, m, t, o in
                                 q("SELECT id, model, transform, owner FROM objects ORDER BY id")]).encode()),
        "descriptors": h(json.dumps([[a, z.hex(), c.hex()] for a, z, c in
                                     q("SELECT asset, zernike, csd FROM descriptors ORDER BY asset")]).encode()),
    }
    m = world_files.published_manifest(d)
    if m:
        out["manifest"] = manifest_digest(m)
    return out


def world_v1(d):
    out = {}
    for name in ["world.json", "objects.json", "descriptors.json", "bvh.json"]:
        p = d / name
        if p.exists():
            out[name] = h(p.read_bytes())
    for sub in ["models", "aggregates", "aggregates/parts"]:
        files = sorted(p.name for p in (d / sub).glob("*.glb")) if (d / sub).is_dir() else []
        out[sub] = h("\n".join(files).encode()) + f" ({len(files)} files)"
    m = d / "aggregates" / "manifest.json"
    if m.exists():
        out["manifest"] = manifest_digest(json.loads(m.read_bytes()))
    return out


for arg in sys.argv[1:]:
    p = pathlib.Path(arg)
    if (p / "world.db").exists():
        items = world_v2(p)
    elif (p / "world.json").exists():
        items = world_v1(p)
    else:
        items = {f.name: h(f.read_bytes()) for f in sorted(p.glob("*.glb"))}
    for k, v in items.items():
        print(f"{p.name}/{k} {v}")
