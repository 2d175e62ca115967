"""Reference checks of `horizon simplify` against third-party tools, on small models: bunny,
SimpleInstancing, NegativeScaleTest, CesiumMilkTruck, and patio-chair and stonehenge from
`horizon-lab gen model` when the lab binary has it. Each model is simplified by IAS to ratio 0.2 (the
bunny by QEM too) and each output must:

  1. have 0 errors from the Khronos glTF-Validator;
  2. load in trimesh, with the unique triangle count Horizon reports;
  3. have an expanded triangle count (read here from the glTF, with numpy) equal to the reported
     `triangles_out`, no larger than the input's, and within 10% of the target, or of the
     floor of 4 triangles per closed component when that is larger;
  4. have a Hausdorff distance to the input (pymeshlab's Metro-style sampler, both directions,
     relative to the input's bounding-box diagonal) at most 1.5x that of fast-simplification
     (agg=7) on the expanded, position-welded input at the same ratio;
  5. have `horizon-lab distance` agree with pymeshlab within 25% on the same pair, when the
     lab binary has that command.

The helpers (expand, weld, pymeshlab_hausdorff, fast_simplify, validate) are also used by
lab/bench/table3.py.

Usage: check_simplify.py HORIZON_BINARY VALIDATE_MJS
The lab binary is $HORIZON_LAB, else the `horizon-lab` beside HORIZON_BINARY (cargo build
--release -p horizon-lab, after and apart from horizon-server); without it the generated models
and check 5 are skipped.
Prints one line per check and a closing 'N passed, M failed' line; exits 1 on any failure."""
import json
import os
import pathlib
import subprocess
import sys
import tempfile
import time

import numpy as np

import gltf_reference as ref

ROOT = pathlib.Path(__file__).resolve().parents[2]
MODELS = ROOT / "assets" / "models"
RATIO = 0.2
SAMPLES = 100_000
ASSET_MODELS = {
    "bunny": MODELS / "bunny_trimesh" / "bunny.ply",
    "SimpleInstancing": MODELS / "SimpleInstancing" / "SimpleInstancing.glb",
    "NegativeScaleTest": MODELS / "NegativeScaleTest" / "NegativeScaleTest.glb",
    "CesiumMilkTruck": MODELS / "CesiumMilkTruck" / "CesiumMilkTruck.glb",
}
GENERATED_MODELS = ["patio-chair", "stonehenge"]


# ---------------------------------------------------------------------------------------------
# Helpers shared with lab/bench/table3.py

def accessor(asset, i):
    """Accessor i as float64 rows (a strided view, so large accessors read fast); normalized
    integers mapped to [0, 1] or [-1, 1]. Same semantics as gltf_reference.Asset.accessor."""
    a = asset.doc["accessors"][i]
    if "sparse" in a:
        raise ValueError("sparse accessors are not read by the reference")
    n, dtype = ref.WIDTH[a["type"]], np.dtype(ref.COMPONENT[a["componentType"]])
    if a["count"] == 0 or "bufferView" not in a:
        return np.zeros((a["count"], n))
    view = asset.doc["bufferViews"][a["bufferView"]]
    if "EXT_meshopt_compression" in view.get("extensions", {}):
        raise ValueError("EXT_meshopt_compression buffers are not decoded by the reference")
    data = asset.buffer(view["buffer"])
    stride = view.get("byteStride") or n * dtype.itemsize
    start = view.get("byteOffset", 0) + a.get("byteOffset", 0)
    rows = np.ndarray((a["count"], n), dtype, buffer=data, offset=start, strides=(stride, dtype.itemsize))
    rows = rows.astype(np.float64)
    if a.get("normalized"):
        rows = np.maximum(rows / np.iinfo(dtype).max, -1.0)
    return rows


def primitive_mesh(asset, primitive):
    """(vertices, faces) of one triangle primitive in its mesh's frame, unreferenced vertices
    dropped; None for points and lines."""
    mode = primitive.get("mode", 4)
    if mode not in (4, 5, 6):
        return None
    v = accessor(asset, primitive["attributes"]["POSITION"])
    idx = (accessor(asset, primitive["indices"])[:, 0].astype(np.int64) if "indices" in primitive
           else np.arange(len(v), dtype=np.int64))
    if mode == 4:
        f = idx[: len(idx) // 3 * 3].reshape(-1, 3)
    elif mode == 5:  # strip: odd triangles swap their first two corners
        k = np.arange(max(len(idx) - 2, 0))
        f = np.stack([idx[k], idx[k + 1], idx[k + 2]], axis=1)
        f[1::2, :2] = f[1::2, 1::-1]
    else:  # fan
        k = np.arange(max(len(idx) - 2, 0))
        f = np.stack([idx[k + 1], idx[k + 2], np.full_like(k, idx[0])], axis=1)
    used, inverse = np.unique(f.ravel(), return_inverse=True)
    return v[used], inverse.reshape(-1, 3)


def compact(v, f):
    used, inverse = np.unique(f.ravel(), return_inverse=True)
    return v[used], inverse.reshape(-1, 3)


def expand(path):
    """The expanded (vertices float64, faces int64) of a model: for glTF every placed primitive
    (node hierarchy and EXT_mesh_gpu_instancing) in world space, mirrored placements with their
    winding flipped; PLY/OBJ/STL through trimesh."""
    path = pathlib.Path(path)
    if path.suffix.lower() not in (".glb", ".gltf"):
        import trimesh
        m = trimesh.load(path, process=False, force="mesh")
        return compact(np.asarray(m.vertices, np.float64), np.asarray(m.faces, np.int64))
    asset = ref.Asset(path)
    meshes = {}
    vs, fs, offset = [], [], 0
    for m, world in ref.placements(asset):
        if m not in meshes:
            prims = (primitive_mesh(asset, p) for p in asset.doc["meshes"][m]["primitives"])
            meshes[m] = [p for p in prims if p is not None and len(p[1])]
        linear, mirrored = world[:3, :3], np.linalg.det(world[:3, :3]) < 0
        for v, f in meshes[m]:
            vs.append(v @ linear.T + world[:3, 3])
            fs.append((f[:, [0, 2, 1]] if mirrored else f) + offset)
            offset += len(v)
    if not vs:
        return np.zeros((0, 3)), np.zeros((0, 3), np.int64)
    return np.concatenate(vs), np.concatenate(fs)


def weld(v, f):
    """Merges vertices by position (trimesh merge_vertices), as the baselines expect."""
    import trimesh
    m = trimesh.Trimesh(vertices=v, faces=f, process=False)
    m.merge_vertices()
    return np.asarray(m.vertices, np.float64), np.asarray(m.faces, np.int64)


def closed_component_floor(f):
    """A lower bound on the triangles a simplifier that never deletes a connected component nor
    makes it non-manifold can reach: 4 per closed component (a tetrahedron), 1 per open one.
    Components are taken over the welded faces; a component is closed when every one of its
    edges is shared by exactly two of its faces."""
    from scipy.sparse import coo_matrix
    from scipy.sparse.csgraph import connected_components
    if len(f) == 0:
        return 0
    n = int(f.max()) + 1
    rows = np.concatenate([f[:, 0], f[:, 1], f[:, 2]])
    cols = np.concatenate([f[:, 1], f[:, 2], f[:, 0]])
    graph = coo_matrix((np.ones(len(rows)), (rows, cols)), shape=(n, n))
    count, label = connected_components(graph, directed=False)
    edges = np.sort(np.stack([rows, cols], axis=1), axis=1)
    _, edge_id, uses = np.unique(edges, axis=0, return_inverse=True, return_counts=True)
    open_edge = uses[edge_id.ravel()] != 2
    component_of_edge = label[edges[:, 0]]
    is_open = np.zeros(count, bool)
    is_open[component_of_edge[open_edge]] = True
    used = np.zeros(count, bool)
    used[label[f[:, 0]]] = True
    return int(4 * np.count_nonzero(used & ~is_open) + np.count_nonzero(used & is_open))


def diagonal(v):
    return float(np.linalg.norm(v.max(0) - v.min(0))) if len(v) else 0.0


def pymeshlab_hausdorff(va, fa, vb, fb, samples=SAMPLES):
    """Symmetric Hausdorff distance by pymeshlab's get_hausdorff_distance (Metro-style: vertex,
    edge and face samples), relative to A's bounding-box diagonal. samplenum is the number of
    vertex samples and again of edge and of face samples; below the sampled mesh's vertex count
    pymeshlab samples a subset of the vertices (and misses maxima that sit on vertices), so each
    direction uses max(samples, vertices of the sampled mesh), like MeshLab's default of the
    vertex count. maxdist is a cut-off, so it is set to twice the larger diagonal."""
    import pymeshlab
    diag_a, diag_b = diagonal(va), diagonal(vb)
    ms = pymeshlab.MeshSet()
    ms.add_mesh(pymeshlab.Mesh(vertex_matrix=np.ascontiguousarray(va, np.float64),
                               face_matrix=np.ascontiguousarray(fa, np.int32)), "A")
    ms.add_mesh(pymeshlab.Mesh(vertex_matrix=np.ascontiguousarray(vb, np.float64),
                               face_matrix=np.ascontiguousarray(fb, np.int32)), "B")
    sides = []
    for s, t, vertices in ((0, 1, len(va)), (1, 0, len(vb))):
        r = ms.apply_filter("get_hausdorff_distance", sampledmesh=s, targetmesh=t, samplevert=True,
                            sampleedge=True, sampleface=True, samplenum=int(max(samples, vertices)),
                            maxdist=pymeshlab.PureValue(2.0 * max(diag_a, diag_b)))
        sides.append({"max": float(r["max"]), "mean": float(r["mean"]), "rms": float(r["RMS"]),
                      "n": int(r["n_samples"])})
    h = max(sides[0]["max"], sides[1]["max"])
    return {"forward": sides[0], "backward": sides[1], "hausdorff": h, "diagonal": diag_a,
            "hausdorff_rel_diag": h / diag_a if diag_a > 0 else float("nan")}


def fast_simplify(v, f, ratio):
    """fast_simplification on an already welded mesh, keeping `ratio` of its triangles."""
    import fast_simplification
    out_v, out_f = fast_simplification.simplify(np.ascontiguousarray(v, np.float64),
                                                np.ascontiguousarray(f, np.int64),
                                                target_reduction=1.0 - ratio, agg=7)
    return np.asarray(out_v, np.float64), np.asarray(out_f, np.int64)


def write_ply(path, v, f):
    """Binary little-endian PLY with float32 positions and int32 triangle lists."""
    v = np.ascontiguousarray(v, "<f4")
    faces = np.empty(len(f), dtype=[("n", "u1"), ("i", "<i4", (3,))])
    faces["n"], faces["i"] = 3, f
    with open(path, "wb") as out:
        out.write((f"ply\nformat binary_little_endian 1.0\nelement vertex {len(v)}\n"
                   "property float x\nproperty float y\nproperty float z\n"
                   f"element face {len(f)}\nproperty list uchar int vertex_indices\nend_header\n").encode())
        out.write(v.tobytes())
        out.write(faces.tobytes())


def lab_binary(horizon):
    """The horizon-lab binary: $HORIZON_LAB if set, else the one beside the given horizon
    binary (both are built into one target folder)."""
    override = os.environ.get("HORIZON_LAB")
    return pathlib.Path(override) if override else pathlib.Path(horizon).with_name("horizon-lab")


def has_command(binary, *words):
    """Whether the binary exists and has the subcommand `words` (its --help exits 0)."""
    try:
        run = subprocess.run([str(binary), *words, "--help"], capture_output=True, text=True)
    except OSError:
        return False
    return run.returncode == 0


def horizon_json(binary, *args):
    """Runs `binary ARGS --json` (horizon or horizon-lab) and returns its last JSON line."""
    run = subprocess.run([str(binary), *map(str, args), "--json"], capture_output=True, text=True)
    if run.returncode != 0:
        raise RuntimeError(f"{pathlib.Path(binary).name} {' '.join(map(str, args))} failed:"
                           f" {run.stderr.strip()[:500]}")
    return json.loads(run.stdout.strip().splitlines()[-1])


def unique_triangles_trimesh(path):
    import trimesh
    scene = trimesh.load(path, force="scene", process=False)
    return sum(len(g.faces) for g in scene.geometry.values() if hasattr(g, "faces"))


# ---------------------------------------------------------------------------------------------

def main(horizon, validate_mjs):
    started = time.perf_counter()
    results = []

    def check(name, ok, detail=""):
        results.append(ok)
        print(f"{'ok  ' if ok else 'FAIL'} {name}{': ' + detail if detail else ''}", flush=True)

    def note(text):
        print(f"skip {text}", flush=True)

    with tempfile.TemporaryDirectory() as tmp:
        tmp = pathlib.Path(tmp)
        models = dict(ASSET_MODELS)
        lab = lab_binary(horizon)
        if has_command(lab, "gen", "model"):
            for name in GENERATED_MODELS:
                out = tmp / f"{name}.glb"
                run = subprocess.run([str(lab), "gen", "model", name, str(out), "--seed", "1"],
                                     capture_output=True, text=True)
                check(f"gen model {name}", run.returncode == 0 and out.exists(), run.stderr.strip()[:300])
                if out.exists():
                    models[name] = out
        else:
            note(f"{', '.join(GENERATED_MODELS)}: no horizon-lab with `gen model` at {lab}")
        distance = has_command(lab, "distance")
        if not distance:
            note(f"`horizon-lab distance` agreement: no horizon-lab with `distance` at {lab}")

        outputs = []  # (label, path, report, input path, input arrays, fast-simplification error)
        for name, path in models.items():
            v_in, f_in = weld(*expand(path))
            fs_v, fs_f = fast_simplify(v_in, f_in, RATIO)
            fs_error = pymeshlab_hausdorff(v_in, f_in, fs_v, fs_f)
            for method in (["ias", "qem"] if name == "bunny" else ["ias"]):
                label = f"{name} {method}"
                out = tmp / f"{name}.{method}.glb"
                run = subprocess.run([horizon, "simplify", str(path), str(out), "--ratio", str(RATIO),
                                      "--method", method, "--json"], capture_output=True, text=True)
                check(f"simplify {label}", run.returncode == 0 and out.exists(), run.stderr.strip()[:300])
                if run.returncode != 0 or not out.exists():
                    continue
                report = json.loads(run.stdout.strip().splitlines()[-1])
                outputs.append(out)

                try:
                    loaded = unique_triangles_trimesh(out)
                    check(f"trimesh loads {label}", loaded == report["unique_triangles_out"],
                          f"{loaded} unique triangles, reported {report['unique_triangles_out']}")
                except Exception as e:  # noqa: BLE001 - any loader failure is the finding
                    check(f"trimesh loads {label}", False, repr(e)[:300])

                got = ref.expanded_triangles(ref.Asset(out))
                expected_in = (len(f_in) if path.suffix == ".ply"
                               else ref.expanded_triangles(ref.Asset(path)))
                target = report["triangles_target"]
                check(f"expanded triangles {label} = reported", got == report["triangles_out"],
                      f"{got} counted, {report['triangles_out']} reported")
                check(f"expanded triangles {label} <= input", got <= expected_in, f"{got} vs input {expected_in}")
                # A closed component cannot shrink below a tetrahedron, so the reachable target is
                # the larger of the requested count and that floor (SimpleInstancing: 125 cubes).
                reachable = max(target, closed_component_floor(f_in))
                check(f"expanded triangles {label} within 10% of target",
                      abs(got - reachable) <= 0.1 * reachable,
                      f"{got} vs target {target}, reachable {reachable}"
                      f" ({got / max(reachable, 1):.2f}x) of {expected_in};"
                      f" {report['collapses']} collapses, reported error_rel_diag {report['error_rel_diag']:.3g}")

                v_out, f_out = weld(*expand(out))
                ours_pm = pymeshlab_hausdorff(v_in, f_in, v_out, f_out)
                a, b = ours_pm["hausdorff_rel_diag"], fs_error["hausdorff_rel_diag"]
                check(f"hausdorff {label} <= 1.5x fast-simplification", a <= 1.5 * b,
                      f"{a:.4g} vs {b:.4g} (fast-simplification kept {len(fs_f)} of {len(f_in)} welded"
                      f" triangles; {method} kept {len(f_out)}) relative to the diagonal")
                if distance:
                    d = horizon_json(lab, "distance", str(path), str(out),
                                     "--samples", str(SAMPLES))
                    h = float(d["hausdorff_rel_diag"])
                    check(f"distance {label} agrees with pymeshlab within 25%",
                          abs(h - a) <= 0.25 * a + 1e-6,
                          f"horizon {h:.4g}, pymeshlab {a:.4g} relative to the diagonal")

        ref.check_valid(check, validate_mjs, outputs)
    passed = sum(results)
    print(f"{passed} passed, {len(results) - passed} failed ({time.perf_counter() - started:.0f} s)")
    return 0 if all(results) and results else 1


if __name__ == "__main__":
    if len(sys.argv) != 3:
        sys.exit(__doc__)
    sys.exit(main(*sys.argv[1:3]))
