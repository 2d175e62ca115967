"""An independent reading of glTF files for the reference checks: expanded triangle counts and
the world transform of every placed primitive, computed from the JSON with numpy and nothing of
Horizon's. Handles GLB and .gltf (data: URIs and files beside it), node hierarchies and
EXT_mesh_gpu_instancing (float or normalized-integer accessors). EXT_meshopt_compression
buffers are not decoded, so only triangle counts (which need no buffer data) are read from
compressed files."""
import base64
import json
import os
import pathlib
import struct
import subprocess
import urllib.parse

import numpy as np

COMPONENT = {5120: np.int8, 5121: np.uint8, 5122: np.int16, 5123: np.uint16, 5125: np.uint32, 5126: np.float32}
WIDTH = {"SCALAR": 1, "VEC2": 2, "VEC3": 3, "VEC4": 4, "MAT4": 16}


def load(path):
    """Returns (document, binary chunk or None)."""
    data = open(path, "rb").read()
    if data[:4] != b"glTF":
        return json.loads(data.decode("utf-8")), None
    _, length = struct.unpack_from("<II", data, 4)
    offset, doc, bin_chunk = 12, None, None
    while offset < length:
        size, kind = struct.unpack_from("<II", data, offset)
        chunk = data[offset + 8: offset + 8 + size]
        if kind == 0x4E4F534A:
            doc = json.loads(chunk.decode("utf-8"))
        elif kind == 0x004E4942:
            bin_chunk = chunk
        offset += 8 + size
    return doc, bin_chunk


class Asset:
    def __init__(self, path):
        self.path = path
        self.doc, self.bin = load(path)
        self._buffers = {}

    def buffer(self, i):
        if i not in self._buffers:
            uri = self.doc["buffers"][i].get("uri")
            if uri is None:
                self._buffers[i] = self.bin
            elif uri.startswith("data:"):
                self._buffers[i] = base64.b64decode(uri.split(",", 1)[1])
            else:
                folder = os.path.dirname(os.path.abspath(self.path))
                with open(os.path.join(folder, urllib.parse.unquote(uri)), "rb") as f:
                    self._buffers[i] = f.read()
        return self._buffers[i]

    def accessor(self, i):
        """Accessor i as float64 rows, normalized integers mapped to [0, 1] or [-1, 1]."""
        a = self.doc["accessors"][i]
        if "sparse" in a:
            raise ValueError("sparse accessors are not read by the reference")
        n, dtype = WIDTH[a["type"]], np.dtype(COMPONENT[a["componentType"]])
        view = self.doc["bufferViews"][a["bufferView"]]
        data = self.buffer(view["buffer"])
        stride = view.get("byteStride") or n * dtype.itemsize
        start = view.get("byteOffset", 0) + a.get("byteOffset", 0)
        rows = np.stack([
            np.frombuffer(data, dtype, count=n, offset=start + k * stride) for k in range(a["count"])
        ]) if a["count"] else np.zeros((0, n), dtype)
        rows = rows.astype(np.float64)
        if a.get("normalized"):
            rows = np.maximum(rows / np.iinfo(dtype).max, -1.0)
        return rows


def triangles(doc, primitive):
    mode = primitive.get("mode", 4)
    key = primitive["indices"] if "indices" in primitive else primitive["attributes"]["POSITION"]
    n = doc["accessors"][key]["count"]
    return n // 3 if mode == 4 else max(n - 2, 0) if mode in (5, 6) else 0


def quaternion_matrix(q):
    x, y, z, w = q / np.linalg.norm(q)
    return np.array([
        [1 - 2 * (y * y + z * z), 2 * (x * y - z * w), 2 * (x * z + y * w)],
        [2 * (x * y + z * w), 1 - 2 * (x * x + z * z), 2 * (y * z - x * w)],
        [2 * (x * z - y * w), 2 * (y * z + x * w), 1 - 2 * (x * x + y * y)],
    ])


def trs(t, r, s):
    m = np.eye(4)
    m[:3, :3] = quaternion_matrix(np.asarray(r, np.float64)) * np.asarray(s, np.float64)[None, :]
    m[:3, 3] = t
    return m


def local_matrix(node):
    if "matrix" in node:
        return np.asarray(node["matrix"], np.float64).reshape(4, 4).T
    return trs(node.get("translation", [0, 0, 0]), node.get("rotation", [0, 0, 0, 1]), node.get("scale", [1, 1, 1]))


def roots(doc):
    scenes = doc.get("scenes", [])
    if "scene" in doc:
        return list(scenes[doc["scene"]].get("nodes", []))
    return [n for s in scenes for n in s.get("nodes", [])]


def placements(asset, with_transforms=True):
    """Yields (mesh index, world matrix or None) for every placed mesh, GPU instances included."""
    doc = asset.doc
    stack = [(n, np.eye(4)) for n in roots(doc)]
    while stack:
        i, parent = stack.pop()
        node = doc["nodes"][i]
        world = parent @ local_matrix(node)
        stack.extend((c, world) for c in node.get("children", []))
        if "mesh" not in node:
            continue
        ext = node.get("extensions", {}).get("EXT_mesh_gpu_instancing")
        if not ext:
            yield node["mesh"], world
            continue
        attrs = ext["attributes"]
        count = doc["accessors"][next(iter(attrs.values()))]["count"]
        if not with_transforms:
            for _ in range(count):
                yield node["mesh"], None
            continue
        t = asset.accessor(attrs["TRANSLATION"]) if "TRANSLATION" in attrs else np.zeros((count, 3))
        r = asset.accessor(attrs["ROTATION"]) if "ROTATION" in attrs else np.tile([0, 0, 0, 1.0], (count, 1))
        s = asset.accessor(attrs["SCALE"]) if "SCALE" in attrs else np.ones((count, 3))
        for k in range(count):
            yield node["mesh"], world @ trs(t[k], r[k], s[k])


def expanded_triangles(asset):
    doc = asset.doc
    per_mesh = [sum(triangles(doc, p) for p in m["primitives"]) for m in doc.get("meshes", [])]
    return sum(per_mesh[m] for m, _ in placements(asset, with_transforms=False))


def placed_primitives(asset):
    """(triangle count, world matrix) for every placed triangle primitive, sorted."""
    doc = asset.doc
    out = []
    for m, world in placements(asset):
        for p in doc["meshes"][m]["primitives"]:
            if triangles(doc, p) > 0:
                out.append((triangles(doc, p), tuple(world.flatten())))
    out.sort()
    return out


def validator_dir():
    """GLTF_VALIDATOR_DIR if set, else the tools tests/run.sh installs, else ~/.cache/reftools."""
    if os.environ.get("GLTF_VALIDATOR_DIR"):
        return os.environ["GLTF_VALIDATOR_DIR"]
    tools = pathlib.Path(os.environ.get("HORIZON_TOOLS", pathlib.Path.home() / ".cache" / "horizon-tools"))
    for d in (tools / "npm", pathlib.Path.home() / ".cache" / "reftools" / "npm"):
        if (d / "node_modules" / "gltf-validator").is_dir():
            return str(d)
    return str(tools / "npm")


def validate(validate_mjs, files, batch=200):
    """Runs the Khronos glTF-Validator (`validate_mjs`, in batches of `batch` files); returns
    {file: {errors, warnings, messages}}, keyed by the path as given. A file the validator did
    not report on is missing, so a caller checks every file it passed; a run that reported on
    nothing raises RuntimeError."""
    out = {}
    files = [str(f) for f in files]
    for k in range(0, len(files), batch):
        run = subprocess.run(["node", str(validate_mjs), *files[k:k + batch]], capture_output=True, text=True,
                             env={**os.environ, "GLTF_VALIDATOR_DIR": validator_dir()})
        reported = [json.loads(line) for line in run.stdout.splitlines()]
        if run.returncode not in (0, 1) or not reported:
            raise RuntimeError(f"glTF-Validator failed ({run.returncode}): {run.stderr.strip()[-500:]}")
        out.update((r["file"], r) for r in reported)
    return out


def check_valid(check, validate_mjs, files):
    """One check per file, through `check(name, ok, detail)`: the validator reported on it with
    0 errors (a file without a report fails, and so does a validator that cannot run). Returns
    the errors reported in all."""
    files = list(files)
    try:
        reports = validate(validate_mjs, files)
    except RuntimeError as e:
        check("glTF-Validator ran", False, str(e))
        return 0
    errors = 0
    for f in files:
        r = reports.get(str(f))
        check(f"glTF-Validator {pathlib.Path(f).name}", r is not None and r["errors"] == 0,
              "no report" if r is None else f"{r['errors']} errors, {r['warnings']} warnings {r['messages'][:3]}")
        errors += 0 if r is None else r["errors"]
    return errors
