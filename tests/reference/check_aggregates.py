"""Reference checks of the aggregates `horizon build` writes, with third-party tools:

  1. the Khronos glTF-Validator reports 0 errors for every aggregate GLB;
  2. trimesh loads every aggregate, with at least one triangle;
  3. every aggregate has exactly one material and one texture, read from the GLB's own JSON
     chunk here (not by Horizon's code), and that texture is at most 128 KiB;
  4. the published manifest names an aggregate for every node of the tree (as many as the build
     reported), and every blob it names exists;
  5. every model's levels of detail: each level's GLB passes the validator and has the
     triangles its row states (instances expanded, counted by gltf_reference), level 0 is the
     model's stored GLB, and along each chain the error does not fall while triangles do not
     rise and bytes fall. trimesh loads every level it can read: it has no decoder for
     EXT_meshopt_compression, so a compressed level is loaded by three.js in the browser tests
     (tests/web) instead.

The world's published record is read from its SQLite database with Python's own sqlite3 module,
and the manifest and aggregates from its blob folder (blobs/ab/<hash>), not through Horizon.

Usage: check_aggregates.py HORIZON_BINARY VALIDATE_MJS [--dir BUILT_WORLD]
Without --dir, generates the village world in a temporary folder with `horizon-lab gen world`
($HORIZON_LAB, else the horizon-lab beside HORIZON_BINARY) and builds it with `horizon build`
first.
Prints one line per failed check and a closing 'N passed, M failed' line; exits 1 on failure."""
import json
import pathlib
import shutil
import sqlite3
import struct
import subprocess
import sys
import tempfile

import trimesh

import gltf_reference as ref
from check_simplify import lab_binary


def glb_json(path):
    data = path.read_bytes()
    magic, _version, _length = struct.unpack_from("<4sII", data, 0)
    assert magic == b"glTF", f"{path}: not a GLB"
    chunk_length, chunk_type = struct.unpack_from("<II", data, 12)
    assert chunk_type == 0x4E4F534A, f"{path}: first chunk is not JSON"
    return json.loads(data[20 : 20 + chunk_length]), data


def image_bytes(doc, data):
    """Encoded sizes of every image, from its buffer view in the GLB's BIN chunk."""
    json_length = struct.unpack_from("<I", data, 12)[0]
    bin_offset = 20 + json_length + 8
    sizes = []
    for image in doc.get("images", []):
        view = doc["bufferViews"][image["bufferView"]]
        sizes.append(view["byteLength"])
        assert bin_offset + view.get("byteOffset", 0) + view["byteLength"] <= len(data)
    return sizes


def published_manifest(world):
    """The manifest the world publishes, read from world.db and the blob folder."""
    db = sqlite3.connect(f"file:{world / 'world.db'}?mode=ro", uri=True)
    try:
        (value,) = db.execute("SELECT value FROM world WHERE key = 'published'").fetchone()
    finally:
        db.close()
    return json.loads(blob(world, json.loads(value)["manifest"]).read_bytes())


def model_levels(world):
    """Every stored model's level list, from world.db's levels table."""
    db = sqlite3.connect(f"file:{world / 'world.db'}?mode=ro", uri=True)
    try:
        models = dict(db.execute("SELECT asset, name FROM models").fetchall())
        rows = db.execute("SELECT asset, levels FROM levels").fetchall()
    finally:
        db.close()
    return models, {asset: json.loads(text) for asset, text in rows}


def check_levels(check, validate_mjs, world):
    """Check 5; returns how many level GLBs were checked."""
    models, levels = model_levels(world)
    check("every model has levels", set(models) <= set(levels),
          f"{len(set(models) - set(levels))} models without")
    copies = tempfile.TemporaryDirectory()
    files = []
    for asset, chain in sorted(levels.items()):
        check(f"level 0 is the model {asset}", chain and chain[0]["asset"] == asset)
        for before, after in zip(chain, chain[1:]):
            ok = (after["error"] >= before["error"] and after["triangles"] <= before["triangles"]
                  and after["bytes"] < before["bytes"])
            check(f"chain of {models.get(asset, asset)}", ok, f"{before} then {after}")
        for k, level in enumerate(chain[1:], start=1):
            f = pathlib.Path(copies.name) / f"{level['asset']}.glb"
            if not f.exists():
                shutil.copyfile(blob(world, level["asset"]), f)
                files.append((f, level["triangles"], f"{models.get(asset, asset)} level {k}"))
    ref.check_valid(check, validate_mjs, [f for f, _, _ in files])
    for f, triangles, name in files:
        try:
            asset = ref.Asset(f)
            expanded = ref.expanded_triangles(asset)
        except Exception as e:  # noqa: BLE001 - any reading failure is a failed check
            check(f"triangles of {name}", False, repr(e))
            continue
        check(f"triangles of {name}", expanded == triangles, f"{expanded} against {triangles}")
        if "EXT_meshopt_compression" not in asset.doc.get("extensionsUsed", []):
            check_trimesh(check, name, f)
    copies.cleanup()
    return len(files)


def check_trimesh(check, name, f):
    """trimesh loads `f` with at least one triangle."""
    try:
        scene = trimesh.load(f, force="scene")
        tris = sum(len(g.faces) for g in scene.geometry.values())
        check(f"trimesh {name}", tris > 0, f"{tris} triangles")
    except Exception as e:  # noqa: BLE001 - any loader failure is a failed check
        check(f"trimesh {name}", False, repr(e))


def blob(world, hash_):
    return world / "blobs" / hash_[:2] / hash_


def main(horizon, validate_mjs, world, nodes=None):
    passed, failed = 0, 0

    def check(name, ok, detail=""):
        nonlocal passed, failed
        if ok:
            passed += 1
        else:
            failed += 1
            print(f"FAIL {name} {detail}")

    manifest = published_manifest(world)
    check("manifest covers the tree", len(manifest["nodes"]) > 0 and nodes in (None, len(manifest["nodes"])),
          f"{len(manifest['nodes'])} nodes in the manifest, {nodes} in the build")
    hashes = sorted({e["glb"] for e in manifest["nodes"].values()})
    for h in hashes:
        check(f"exists {h}", blob(world, h).exists())
    # The tools below read a file's type from its name: copies named <hash>.glb.
    copies = tempfile.TemporaryDirectory()
    files = []
    for h in hashes:
        if blob(world, h).exists():
            f = pathlib.Path(copies.name) / f"{h}.glb"
            shutil.copyfile(blob(world, h), f)
            files.append(f)
    # 1. Khronos glTF-Validator.
    errors = ref.check_valid(check, validate_mjs, files)
    # 2-3. trimesh, and one material and one texture of at most 128 KiB.
    for f in files:
        doc, data = glb_json(f)
        check(f"one material {f.name}", len(doc.get("materials", [])) == 1, len(doc.get("materials", [])))
        check(f"one texture {f.name}", len(doc.get("textures", [])) == 1, len(doc.get("textures", [])))
        sizes = image_bytes(doc, data)
        check(f"texture <= 128 KiB {f.name}", len(sizes) == 1 and sizes[0] <= 128 * 1024, sizes)
        check_trimesh(check, f.name, f)
    copies.cleanup()
    print(f"{len(files)} aggregates checked, validator errors {errors}")
    # 5. Levels of detail.
    print(f"{check_levels(check, validate_mjs, world)} levels of detail checked")
    print(f"{passed} passed, {failed} failed")
    return 1 if failed else 0


if __name__ == "__main__":
    args = sys.argv[1:]
    if len(args) not in (2, 4):
        sys.exit(__doc__)
    horizon, validate_mjs = args[0], pathlib.Path(args[1]).resolve()
    if len(args) == 4 and args[2] == "--dir":
        sys.exit(main(horizon, validate_mjs, pathlib.Path(args[3])))
    lab = lab_binary(horizon)
    if not lab.is_file():
        sys.exit(f"error: no horizon-lab binary at {lab} (it generates the village); build it with"
                 " `cargo build --release -p horizon-lab`, after and apart from horizon-server,"
                 " or pass --dir BUILT_WORLD")
    with tempfile.TemporaryDirectory() as tmp:
        world = pathlib.Path(tmp) / "village"
        subprocess.run([str(lab), "gen", "world", "village", str(world)], check=True)
        built = subprocess.run([horizon, "build", str(world), "--json"], check=True,
                               capture_output=True, text=True)
        nodes = json.loads(built.stdout.strip().splitlines()[-1])["nodes"]
        sys.exit(main(horizon, validate_mjs, world, nodes))
