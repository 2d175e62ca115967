"""Reference checks of `horizon mesh convert` against third-party tools, on every model in
assets/models (the real third-party models the project carries):

  1. the Khronos glTF-Validator reports 0 errors for the plain and the compressed output;
  2. the expanded triangle count of the output equals the input's, both counted here from the
     glTF JSON (or by trimesh for PLY), independently of Horizon's code;
  3. every placed primitive's world transform survives a plain round trip within 1e-5 relative;
  4. trimesh loads every plain output, with the unique triangle count of the input.

Usage: check_models.py HORIZON_BINARY VALIDATE_MJS
Prints one line per check and a closing 'N passed, M failed' line; exits 1 on any failure."""
import json
import pathlib
import subprocess
import sys
import tempfile

import numpy as np
import trimesh

import gltf_reference as ref

ROOT = pathlib.Path(__file__).resolve().parents[2]


def models():
    out = []
    for folder in sorted((ROOT / "assets" / "models").iterdir()):
        out += sorted(p for p in folder.iterdir() if p.suffix in (".glb", ".gltf", ".ply"))
    return out


def input_triangles(path):
    if path.suffix == ".ply":
        return len(trimesh.load(path, process=False).faces)
    return ref.expanded_triangles(ref.Asset(path))


def relative_difference(a, b):
    a, b = np.asarray(a), np.asarray(b)
    return np.max(np.abs(a - b)) / max(np.max(np.abs(a)), np.max(np.abs(b)), 1e-30)


def worst_match(a, b):
    """Pairs each input placement with the nearest unused output placement of the same
    triangle count (output order need not follow input order) and returns the worst relative
    difference over the pairs."""
    unused = list(b)
    worst = 0.0
    for tris, x in a:
        candidates = [k for k, (t, _) in enumerate(unused) if t == tris]
        k = min(candidates, key=lambda k: relative_difference(x, unused[k][1]))
        worst = max(worst, relative_difference(x, unused.pop(k)[1]))
    return worst


def main(horizon, validate_mjs):
    results = []

    def check(name, ok, detail=""):
        results.append(ok)
        print(f"{'ok  ' if ok else 'FAIL'} {name}{': ' + detail if detail else ''}", flush=True)

    with tempfile.TemporaryDirectory() as tmp:
        outputs = []
        for model in models():
            plain = pathlib.Path(tmp) / f"{model.stem}.glb"
            packed = pathlib.Path(tmp) / f"{model.stem}.compressed.glb"
            for out, flags in ((plain, []), (packed, ["--compress"])):
                run = subprocess.run([horizon, "mesh", "convert", str(model), str(out), *flags],
                                     capture_output=True, text=True)
                check(f"convert {model.name} {' '.join(flags)}".strip(), run.returncode == 0, run.stderr.strip())
            if not (plain.exists() and packed.exists()):
                continue
            outputs += [plain, packed]
            expected = input_triangles(model)
            for out in (plain, packed):
                got = ref.expanded_triangles(ref.Asset(out))
                check(f"expanded triangles {out.name}", got == expected, f"{got} vs input {expected}")
            if model.suffix != ".ply":
                a = ref.placed_primitives(ref.Asset(model))
                b = ref.placed_primitives(ref.Asset(plain))
                same_shape = sorted(t for t, _ in a) == sorted(t for t, _ in b)
                worst = worst_match(a, b) if same_shape else float("inf")
                check(f"transforms {model.name}", same_shape and worst <= 1e-5,
                      f"{len(a)} placements, worst relative difference {worst:.2e}")
            scene = trimesh.load(plain, force="scene", process=False)
            loaded = sum(len(g.faces) for g in scene.geometry.values())
            unique = json.loads(subprocess.run([horizon, "mesh", "stats", "--json", str(model)],
                                               capture_output=True, text=True, check=True).stdout)["triangles_unique"]
            check(f"trimesh loads {plain.name}", loaded == unique, f"{loaded} unique triangles, expected {unique}")
        ref.check_valid(check, validate_mjs, outputs)
    passed = sum(results)
    print(f"{passed} passed, {len(results) - passed} failed")
    return 0 if all(results) and results else 1


if __name__ == "__main__":
    sys.exit(main(*sys.argv[1:3]))
