#!/usr/bin/env python3
"""Reproduces Table 3 of Azim et al. 2014 (instance-aware simplification) with four methods.

Every model is simplified to 20% of its expanded triangles by
  ias                  `horizon simplify --method ias`  (keeps the instancing)
  qem                  `horizon simplify --method qem`  (our engine on the expanded mesh)
  meshopt              `horizon simplify --method meshopt` (meshoptimizer, expanded and welded)
  fast-simplification  fast_simplification.simplify(agg=7) on the expanded mesh welded by
                       position, in its own Python process (lab/bench/fast_simplification_worker.py)
each in a subprocess, --runs times. Per method it records the median of the reported
simplification seconds and of the subprocess's peak RSS (os.wait4), the output GLB bytes (the
fast-simplification output is converted to GLB by `horizon mesh convert`), the expanded output
triangles (counted by tests/reference, independently of Horizon), the Hausdorff distance to the
input relative to the input's bounding-box diagonal by `horizon-lab distance` (ours) and by
pymeshlab's get_hausdorff_distance (both directions, vertex+edge+face samples), and the Khronos
glTF-Validator's errors for every GLB written. The models are maple-tree, village-mesh,
patio-chair and stonehenge from `horizon-lab gen model NAME OUT --seed 1`, the bunny, and every
model in assets/models with a mesh placed at least twice.

The product binary `horizon` (--horizon) runs simplify, mesh stats and mesh convert; the lab
binary `horizon-lab` (--lab, default: the `horizon-lab` beside the `horizon` binary) runs
gen model and distance.

Writes OUT/table3.json (all raw numbers, machine info) and OUT/table3.md (the tables and the
PASS/FAIL targets). Progress goes to stderr. Exit status 0 when the measurements ran (whatever
the targets say; --strict: 1 if a target fails)."""
import argparse
import collections
import datetime
import json
import os
import pathlib
import platform
import shutil
import statistics
import subprocess
import sys
import tempfile
import time

# Linux counts the memory a child had before exec in its ru_maxrss (exec_mmap keeps the old
# mm's high-water mark), and a child forked from this process starts as a copy of it: well over
# 100 MB once pymeshlab is loaded. So every measured command is forked by this small helper,
# started before numpy & co are imported; it runs one command per request line and answers with
# the os.wait4 rusage of that child. The floor this leaves is the helper's own RSS (~10 MB).
SPAWNER = r"""
import json, os, sys, time
for line in sys.stdin:
    req = json.loads(line)
    fds = [os.open(os.devnull, os.O_RDONLY)] + [
        os.open(req[k], os.O_WRONLY | os.O_CREAT | os.O_TRUNC, 0o644) for k in ("stdout", "stderr")]
    start = time.perf_counter()
    pid = os.fork()
    if pid == 0:
        try:
            for target, fd in enumerate(fds):
                os.dup2(fd, target)
            os.execvp(req["argv"][0], req["argv"])
        except BaseException as e:
            os.write(2, ("exec failed: %r" % e).encode())
        os._exit(127)
    _, status, usage = os.wait4(pid, 0)
    wall = time.perf_counter() - start
    for fd in fds:
        os.close(fd)
    print(json.dumps({"code": os.waitstatus_to_exitcode(status), "maxrss_kib": usage.ru_maxrss,
                      "wall": wall}), flush=True)
"""
_spawner = subprocess.Popen([sys.executable, "-S", "-c", SPAWNER], stdin=subprocess.PIPE,
                            stdout=subprocess.PIPE, text=True)

ROOT = pathlib.Path(__file__).resolve().parents[2]  # lab/bench/table3.py -> the repository
sys.path.insert(0, str(ROOT / "tests" / "reference"))
import check_simplify as cs  # noqa: E402
import gltf_reference as ref  # noqa: E402

RATIO = 0.2
# A method whose first run is shorter than this is run at least SHORT_RUNS times.
SHORT_SECONDS = 0.1
SHORT_RUNS = 9
GENERATED = ["maple-tree", "village-mesh", "patio-chair", "stonehenge"]
BUNNY = ROOT / "assets" / "models" / "bunny_trimesh" / "bunny.ply"
HORIZON_METHODS = ["ias", "qem", "meshopt"]
METHODS = HORIZON_METHODS + ["fast-simplification"]
SHORT = {"ias": "IAS", "qem": "QEM", "meshopt": "meshopt", "fast-simplification": "fast-simpl."}
WORKER = ROOT / "lab" / "bench" / "fast_simplification_worker.py"
VALIDATE_MJS = ROOT / "tests" / "reference" / "validate.mjs"


def log(msg):
    print(f"[table3 {time.strftime('%H:%M:%S')}] {msg}", file=sys.stderr, flush=True)


def run_measured(cmd):
    """Runs cmd through the spawner; returns (exit code, stdout, stderr, peak RSS in KiB of that
    child as os.wait4 reports it, wall seconds)."""
    with tempfile.TemporaryDirectory() as tmp:
        out, err = pathlib.Path(tmp) / "stdout", pathlib.Path(tmp) / "stderr"
        _spawner.stdin.write(json.dumps({"argv": [str(c) for c in cmd], "stdout": str(out),
                                         "stderr": str(err)}) + "\n")
        _spawner.stdin.flush()
        answer = _spawner.stdout.readline()
        if not answer:
            raise SystemExit("error: the process spawner died")
        r = json.loads(answer)
        return r["code"], out.read_text(), err.read_text(), r["maxrss_kib"], r["wall"]


def last_json(text):
    return json.loads(text.strip().splitlines()[-1])


def machine_info(horizon, lab):
    cpu = "unknown"
    try:
        for line in open("/proc/cpuinfo"):
            if line.startswith("model name"):
                cpu = line.split(":", 1)[1].strip()
                break
    except OSError:
        pass
    mem_kb = None
    try:
        for line in open("/proc/meminfo"):
            if line.startswith("MemTotal"):
                mem_kb = int(line.split()[1])
    except OSError:
        pass

    def git(*args):
        r = subprocess.run(["git", "-C", str(ROOT), *args], capture_output=True, text=True)
        return r.stdout.strip() if r.returncode == 0 else None

    versions = {}
    for mod in ("numpy", "trimesh", "fast_simplification", "pymeshlab", "scipy"):
        try:
            from importlib.metadata import version
            versions[mod] = version(mod.replace("_", "-"))
        except Exception:  # noqa: BLE001
            versions[mod] = None

    def version_of(binary):
        try:
            r = subprocess.run([str(binary), "--version"], capture_output=True, text=True)
        except OSError:
            return None
        return r.stdout.strip() if r.returncode == 0 else None

    return {
        "nproc": len(os.sched_getaffinity(0)),
        "cpu_model": cpu,
        "mem_total_gib": round(mem_kb / 2**20, 1) if mem_kb else None,
        "date": datetime.datetime.now(datetime.timezone.utc).isoformat(timespec="seconds"),
        "hostname": platform.node(),
        "kernel": platform.release(),
        "python": sys.version.split()[0],
        "packages": versions,
        "horizon": str(horizon),
        "horizon_version": version_of(horizon),
        "horizon_lab": str(lab),
        "horizon_lab_version": version_of(lab),
        "git_commit": git("rev-parse", "HEAD"),
        "git_dirty": bool(git("status", "--porcelain", "--untracked-files=no")),
        "loadavg_start": list(os.getloadavg()),
    }


def instanced_asset_models():
    """Every glTF model in assets/models with a mesh placed at least twice (counted from the glTF
    by tests/reference), as {name: (path, largest placement count)}."""
    out = {}
    for folder in sorted((ROOT / "assets" / "models").iterdir()):
        if not folder.is_dir():
            continue
        for p in sorted(folder.iterdir()):
            if p.suffix.lower() in (".glb", ".gltf"):
                counts = collections.Counter(m for m, _ in ref.placements(ref.Asset(p), with_transforms=False))
                if counts and max(counts.values()) >= 2:
                    out[p.stem] = (p, max(counts.values()))
    return out


def image_bytes(glb):
    """Bytes of the images embedded in a GLB (bufferViews referenced by images)."""
    doc, _ = ref.load(glb)
    views = doc.get("bufferViews", [])
    return sum(views[i["bufferView"]]["byteLength"] for i in doc.get("images", []) if "bufferView" in i)


def median(xs):
    xs = [x for x in xs if x is not None]
    return statistics.median(xs) if xs else None


class Bench:
    def __init__(self, args, work):
        self.args = args
        self.horizon = pathlib.Path(args.horizon).resolve()
        self.lab = lab_binary(args).resolve()
        self.work = work
        self.has_distance = cs.has_command(self.lab, "distance")
        self.has_gen = cs.has_command(self.lab, "gen", "model")

    # -- inputs ---------------------------------------------------------------------------------

    def model_source(self, name, instanced):
        if name in GENERATED:
            out = self.work / f"{name}.glb"
            if not out.exists():
                log(f"[{name}] horizon-lab gen model {name} --seed 1")
                code, _, err, rss, wall = run_measured([self.lab, "gen", "model", name, out, "--seed", "1"])
                if code != 0:
                    raise SystemExit(f"error: `horizon-lab gen model {name}` failed: {err.strip()[:500]}")
                self.gen_seconds = wall
            return out, "horizon-lab gen model --seed 1"
        if name == "bunny":
            return BUNNY, str(BUNNY.relative_to(ROOT))
        return instanced[name][0], str(instanced[name][0].relative_to(ROOT))

    # -- one model ------------------------------------------------------------------------------

    def model(self, name, instanced):
        self.gen_seconds = None
        path, source = self.model_source(name, instanced)
        entry = {"source": source, "file": str(path), "input_bytes": path.stat().st_size,
                 "gen_seconds": self.gen_seconds}
        entry["stats"] = cs.horizon_json(self.horizon, "mesh", "stats", path)
        log(f"[{name}] expanding the input (tests/reference)")
        v, f = cs.expand(path)
        entry["reference_triangles_expanded"] = int(len(f))
        vw, fw = cs.weld(v, f)
        del v, f
        entry["diagonal"] = cs.diagonal(vw)
        entry["welded"] = {"vertices": int(len(vw)), "triangles": int(len(fw))}
        npz = self.work / f"{name}.welded.npz"
        import numpy as np
        np.savez(npz, v=vw, f=fw)
        entry["methods"] = {}
        for method in METHODS:
            entry["methods"][method] = self.method(name, path, method, npz, vw, fw)
        glbs = [path] if path.suffix == ".glb" and name in GENERATED else []
        glbs += [pathlib.Path(m["glb"]) for m in entry["methods"].values() if m.get("glb")]
        log(f"[{name}] glTF-Validator on {len(glbs)} files")
        reports = ref.validate(VALIDATE_MJS, glbs)
        entry["validator"] = {pathlib.Path(k).name: v for k, v in reports.items()}
        for p in glbs:
            if str(p) not in reports:
                entry["validator"][p.name] = {"errors": None, "warnings": None, "messages": ["no report"]}
        if name in GENERATED:
            entry["input_validator_errors"] = entry["validator"].get(path.name, {}).get("errors")
        for m in entry["methods"].values():
            if m.get("glb"):
                m["validator_errors"] = entry["validator"].get(pathlib.Path(m["glb"]).name, {}).get("errors")
        return entry

    def method(self, name, path, method, npz, vw, fw):
        runs = []
        if method == "fast-simplification":
            ply = self.work / f"{name}.{method}.ply"
            glb = self.work / f"{name}.{method}.glb"
            cmd = [self.args.python, WORKER, npz, ply, RATIO]
        else:
            glb = self.work / f"{name}.{method}.glb"
            cmd = [self.horizon, "simplify", path, glb, "--ratio", RATIO, "--method", method, "--json"]
        total = self.args.runs
        k = 0
        while k < total:
            code, out, err, rss, wall = run_measured(cmd)
            if code != 0:
                raise SystemExit(f"error: {method} on {name} failed ({code}): {err.strip()[:800]}")
            report = last_json(out)
            runs.append({"seconds": report["seconds"], "peak_rss_kib": rss, "wall_seconds": wall,
                         "report": report})
            if k == 0 and report["seconds"] < SHORT_SECONDS:
                # Scheduling noise is as large as the differences a run this short measures.
                total = max(total, SHORT_RUNS)
            log(f"[{name}] {method} run {k + 1}/{total}: {report['seconds']:.4f} s simplify,"
                f" {rss / 1024:.0f} MB peak, {wall:.2f} s wall")
            k += 1
        res = {"command": [str(c) for c in cmd], "runs": runs,
               "seconds": median(r["seconds"] for r in runs),
               "peak_mb": median(r["peak_rss_kib"] for r in runs) / 1024,
               "report": runs[-1]["report"]}
        if method == "fast-simplification":
            code, _, err, _, _ = run_measured([self.horizon, "mesh", "convert", ply, glb])
            if code != 0:
                raise SystemExit(f"error: horizon mesh convert {ply} failed: {err.strip()[:500]}")
            res["triangles_in"] = runs[-1]["report"]["triangles_in"]
            res["triangles_out_reported"] = runs[-1]["report"]["triangles_out"]
        else:
            res["triangles_in"] = runs[-1]["report"]["triangles_in"]
            res["triangles_out_reported"] = runs[-1]["report"]["triangles_out"]
            res["triangles_target"] = runs[-1]["report"]["triangles_target"]
            res["output_bytes_reported"] = runs[-1]["report"]["output_bytes"]
            sizes = {r["report"]["output_bytes"] for r in runs}
            res["deterministic_size"] = len(sizes) == 1
        res["glb"] = str(glb)
        res["glb_bytes"] = glb.stat().st_size
        res["image_bytes"] = image_bytes(glb)
        res["triangles_out"] = ref.expanded_triangles(ref.Asset(glb))
        res["throughput_tris_per_s"] = (res["triangles_in"] / res["seconds"]) if res["seconds"] else None

        log(f"[{name}] {method}: Hausdorff (pymeshlab, {self.args.samples} samples)")
        ov, of = cs.weld(*cs.expand(glb))
        t = time.perf_counter()
        res["hausdorff_pymeshlab"] = cs.pymeshlab_hausdorff(vw, fw, ov, of, self.args.samples)
        res["hausdorff_pymeshlab"]["seconds"] = time.perf_counter() - t
        if self.has_distance:
            log(f"[{name}] {method}: horizon-lab distance")
            t = time.perf_counter()
            res["hausdorff_ours"] = cs.horizon_json(self.lab, "distance", path, glb,
                                                    "--samples", self.args.samples)
            res["hausdorff_ours"]["wall_seconds"] = time.perf_counter() - t
        else:
            res["hausdorff_ours"] = None
        return res


# -- tables and targets ---------------------------------------------------------------------------

def fmt_s(x):
    if x is None:
        return "—"
    return f"{x * 1000:.1f} ms" if x < 1 else f"{x:.2f} s"


def fmt_bytes(x):
    if x is None:
        return "—"
    if x >= 2**20:
        return f"{x / 2**20:.2f} MB"
    return f"{x / 1024:.1f} KB" if x >= 1024 else f"{x} B"


def fmt_ratio(a, b):
    if a is None or b is None:
        return "—"
    if b == 0:
        return "0" if a == 0 else "∞"
    return f"{a / b:.3g}"


def fmt_err(x):
    return "—" if x is None else f"{x:.4g}"


def get(models, name, method, key):
    m = models.get(name, {}).get("methods", {}).get(method)
    if not m:
        return None
    if key == "error":
        return m["hausdorff_pymeshlab"]["hausdorff_rel_diag"]
    if key == "error_ours":
        return m["hausdorff_ours"]["hausdorff_rel_diag"] if m.get("hausdorff_ours") else None
    return m.get(key)


def targets(models):
    """[(label, PASS/FAIL/n/a, detail)] for the issue's targets."""
    out = []

    def at_most(model, what, a_method, b_method, key, factor, show):
        a, b = get(models, model, a_method, key), get(models, model, b_method, key)
        label = f"{model}: {what}"
        if a is None or b is None:
            out.append((label, "n/a", "not measured"))
            return
        ok = a <= factor * b
        out.append((label, "PASS" if ok else "FAIL",
                    f"{show(a)} vs {show(b)}: ratio {fmt_ratio(a, b)} (target ≤ {factor:g})"))

    fast, qem, meshopt = "fast-simplification", "qem", "meshopt"
    m = "maple-tree"
    at_most(m, "IAS time ≤ 1/10 of fast-simplification's", "ias", fast, "seconds", 0.1, fmt_s)
    at_most(m, "IAS time ≤ 1/10 of meshopt's", "ias", meshopt, "seconds", 0.1, fmt_s)
    at_most(m, "IAS GLB ≤ 2% of QEM GLB", "ias", qem, "glb_bytes", 0.02, fmt_bytes)
    at_most(m, "IAS Hausdorff ≤ 1.25× fast-simplification's", "ias", fast, "error", 1.25, fmt_err)
    at_most(m, "IAS peak memory ≤ 1/4 of QEM's", "ias", qem, "peak_mb", 0.25, lambda x: f"{x:.0f} MB")
    m = "village-mesh"
    at_most(m, "IAS time ≤ 1/3 of fast-simplification's", "ias", fast, "seconds", 1 / 3, fmt_s)
    at_most(m, "IAS GLB ≤ 25% of QEM GLB", "ias", qem, "glb_bytes", 0.25, fmt_bytes)
    at_most(m, "IAS Hausdorff ≤ 1.25× fast-simplification's", "ias", fast, "error", 1.25, fmt_err)
    for m in ("patio-chair", "stonehenge"):
        at_most(m, "IAS GLB ≤ QEM GLB", "ias", qem, "glb_bytes", 1.0, fmt_bytes)
        at_most(m, "IAS Hausdorff ≤ 1.25× fast-simplification's", "ias", fast, "error", 1.25, fmt_err)
    m = "bunny"
    at_most(m, "IAS time ≤ 1.2× our QEM's", "ias", qem, "seconds", 1.2, fmt_s)
    at_most(m, "IAS time ≤ 1.5× fast-simplification's", "ias", fast, "seconds", 1.5, fmt_s)
    at_most(m, "IAS Hausdorff ≤ 1.1× fast-simplification's", "ias", fast, "error", 1.1, fmt_err)

    a = get(models, "maple-tree", qem, "throughput_tris_per_s")
    b = get(models, "maple-tree", fast, "throughput_tris_per_s")
    label = "maple-tree: our QEM throughput (input triangles/s, expanded) ≥ fast-simplification's"
    if a is None or b is None:
        out.append((label, "n/a", "not measured"))
    else:
        out.append((label, "PASS" if a >= b else "FAIL",
                    f"{a / 1e6:.3g} M/s vs {b / 1e6:.3g} M/s: ratio {a / b:.3g} (target ≥ 1)"))

    errors, files, unreported = 0, 0, 0
    for entry in models.values():
        for r in entry.get("validator", {}).values():
            files += 1
            if r["errors"] is None:
                unreported += 1
            else:
                errors += r["errors"]
    ok = files > 0 and errors == 0 and unreported == 0
    out.append(("every GLB written has 0 glTF-Validator errors", "PASS" if ok else "FAIL",
                f"{errors} errors in {files} files" + (f", {unreported} not reported" if unreported else "")))
    return out


def markdown(result):
    models, mach, cfg = result["models"], result["machine"], result["config"]
    names = list(models)
    L = []
    L.append("# Table 3: instance-aware simplification (Azim et al. 2014), reproduced\n")
    L.append(f"Generated by `lab/bench/table3.py` on {mach['date']}: {mach['cpu_model']}, {mach['nproc']} CPUs"
             f" (`nproc`), {mach['mem_total_gib']} GiB; load average {mach['loadavg_start'][0]:.2f} at the"
             f" start, {mach['loadavg_end'][0]:.2f} at the end. Horizon binary {mach['horizon']}"
             f" (`{mach['horizon_version']}`), lab binary {mach['horizon_lab']}"
             f" (`{mach['horizon_lab_version']}`), commit {(mach['git_commit'] or '?')[:10]}{', dirty tree' if mach['git_dirty'] else ''}.\n")
    L.append(f"Every model is simplified to {cfg['ratio']:.0%} of its expanded triangles. Times are the median"
             f" of {cfg['runs']} runs (at least {SHORT_RUNS} for a method whose first run took under"
             f" {SHORT_SECONDS * 1000:.0f} ms) of the simplification proper as each method reports it (IAS: on the"
             " instanced mesh; QEM: on the already-expanded mesh; meshopt: the meshopt_simplify call on the"
             " expanded, welded mesh; fast-simplification: the `simplify` call on the expanded mesh welded by"
             " position). Peak memory is the median peak RSS of the whole subprocess (the `horizon` process"
             " including import and export; for fast-simplification a Python process that loads the"
             " pre-expanded arrays). Errors are the symmetric Hausdorff distance between the expanded input"
             " and the expanded output relative to the input's bounding-box diagonal, written ours /"
             f" pymeshlab. Both sample every vertex, then area-uniform face samples and edge samples:"
             f" ours {cfg['samples']} each per direction; pymeshlab max({cfg['samples']}, vertex count of the"
             " sampled mesh) each.\n")

    L.append("## Models (cf. Table 2)\n")
    L.append("| Model | Source | Submeshes | Instances | Unique triangles | Expanded triangles | Target (20%) |")
    L.append("|---|---|--:|--:|--:|--:|--:|")
    for n in names:
        e = models[n]
        s = e["stats"]
        tgt = e["methods"]["ias"].get("triangles_target")
        L.append(f"| {n} | {e['source']} | {s.get('submeshes')} | {s.get('instances')} |"
                 f" {s.get('triangles_unique')} | {e['reference_triangles_expanded']} | {tgt} |")

    def table(title, key, show, ratios, extra=(), note=None):
        L.append(f"\n## {title}\n")
        if note:
            L.append(note + "\n")
        head = ["Model"] + [SHORT[m] for m in METHODS] + [f"{SHORT[a]}/{SHORT[b]}" for a, b in ratios]
        head += [h for h, _ in extra]
        L.append("| " + " | ".join(head) + " |")
        L.append("|---|" + "--:|" * (len(head) - 1))
        for n in names:
            cells = [n] + [show(n, m) for m in METHODS]
            cells += [fmt_ratio(get(models, n, a, key), get(models, n, b, key)) for a, b in ratios]
            cells += [fn(n) for _, fn in extra]
            L.append("| " + " | ".join(cells) + " |")

    fast = "fast-simplification"
    table("Time (median, simplification proper)", "seconds",
          lambda n, m: fmt_s(get(models, n, m, "seconds")),
          [("ias", "qem"), ("ias", "meshopt"), ("ias", fast)],
          [("QEM/fast-simpl. throughput", lambda n: fmt_ratio(get(models, n, "qem", "throughput_tris_per_s"),
                                                              get(models, n, fast, "throughput_tris_per_s")))])
    table("Peak memory (median peak RSS of the subprocess)", "peak_mb",
          lambda n, m: f"{get(models, n, m, 'peak_mb'):.0f} MB", [("ias", "qem"), ("ias", fast)])
    table("Output GLB size", "glb_bytes",
          lambda n, m: fmt_bytes(get(models, n, m, "glb_bytes")), [("ias", "qem"), ("ias", fast)],
          [("images in IAS/QEM GLB", lambda n: fmt_bytes(get(models, n, "ias", "image_bytes")))],
          "IAS and QEM keep normals, texture coordinates, materials and embedded images; meshopt and"
          " fast-simplification outputs carry positions only, so on textured models their GLBs are"
          " not comparable with IAS/QEM (the last column shows the image bytes inside the IAS GLB).")
    table("Hausdorff / diagonal (ours / pymeshlab; ratios from pymeshlab)", "error",
          lambda n, m: f"{fmt_err(get(models, n, m, 'error_ours'))} / {fmt_err(get(models, n, m, 'error'))}",
          [("ias", "qem"), ("ias", fast)])
    table("Expanded output triangles (counted by tests/reference) and glTF-Validator errors", "triangles_out",
          lambda n, m: f"{get(models, n, m, 'triangles_out')} ({get(models, n, m, 'validator_errors')} err)",
          [])
    misses = []
    for n in names:
        target = models[n]["methods"]["ias"].get("triangles_target")
        for m in METHODS:
            got = get(models, n, m, "triangles_out")
            if target and got is not None and abs(got - target) > 0.1 * target:
                misses.append(f"{n} {SHORT[m]}: {got} triangles for a target of {target}"
                              f" ({got / target:.2f}×)")
    if misses:
        L.append("\nOutputs more than 10% away from the target (their time, size and error are not for"
                 " 20%): " + "; ".join(misses) + ".")
    L.append("\n## Targets\n")
    for label, status, detail in result["targets"]:
        L.append(f"- **{status}** {label} — {detail}")
    L.append("")
    return "\n".join(L)


def lab_binary(args):
    """The horizon-lab binary: --lab, else the one beside the horizon binary."""
    return pathlib.Path(args.lab) if args.lab else cs.lab_binary(args.horizon)


def main():
    p = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    p.add_argument("--horizon", default=str(ROOT / "target" / "release" / "horizon"),
                   help="the product binary (simplify, mesh stats, mesh convert)")
    p.add_argument("--lab", help="the lab binary (gen model, distance; default: the horizon-lab"
                                 " beside --horizon)")
    p.add_argument("--python", default=sys.executable,
                   help="interpreter for the fast-simplification subprocess (default: this one)")
    p.add_argument("--models", help="comma-separated subset (default: all)")
    p.add_argument("--runs", type=int, default=3)
    p.add_argument("--samples", type=int, default=100_000, help="Hausdorff samples per direction")
    p.add_argument("--out", default=str(ROOT / "lab" / "results"))
    p.add_argument("--work", help="folder for temporary files (default: a fresh temporary folder)")
    p.add_argument("--strict", action="store_true", help="exit 1 if a target fails")
    p.add_argument("--allow-missing", action="store_true",
                   help="development only: skip generated models and our distance when the lab"
                        " binary is missing or lacks `gen model` / `distance` instead of failing")
    args = p.parse_args()
    if args.runs < 1:
        p.error("--runs must be at least 1")

    horizon = pathlib.Path(args.horizon)
    if not horizon.is_file():
        raise SystemExit(f"error: no horizon binary at {horizon}; build it with"
                         " `cargo build --release -p horizon-server`")
    if shutil.which("node") is None:
        raise SystemExit("error: node is not on PATH (needed for the Khronos glTF-Validator)")
    if not (pathlib.Path(ref.validator_dir()) / "node_modules" / "gltf-validator").is_dir():
        raise SystemExit(f"error: no gltf-validator under {ref.validator_dir()}; run tests/run.sh once"
                         " or set GLTF_VALIDATOR_DIR")
    check = subprocess.run([args.python, "-c", "import fast_simplification, numpy"], capture_output=True)
    if check.returncode != 0:
        raise SystemExit(f"error: {args.python} cannot import fast_simplification; pass --python")

    instanced = instanced_asset_models()
    all_names = GENERATED + ["bunny"] + list(instanced)
    names = all_names if not args.models else [n.strip() for n in args.models.split(",") if n.strip()]
    unknown = [n for n in names if n not in all_names]
    if unknown:
        raise SystemExit(f"error: unknown models {unknown}; known: {', '.join(all_names)}")

    with tempfile.TemporaryDirectory(prefix="horizon-table3-") as tmp:
        work = pathlib.Path(args.work) if args.work else pathlib.Path(tmp)
        work.mkdir(parents=True, exist_ok=True)
        bench = Bench(args, work)
        missing = []
        if not bench.has_gen and any(n in GENERATED for n in names):
            missing.append("`gen model` (for " + ", ".join(n for n in names if n in GENERATED) + ")")
        if not bench.has_distance:
            missing.append("`distance` (our Hausdorff column)")
        if missing:
            lab = bench.lab
            msg = (f"{lab} lacks " if lab.is_file() else f"no horizon-lab binary at {lab}, needed for ")
            msg += " and ".join(missing)
            if not args.allow_missing:
                raise SystemExit(f"error: {msg}; build it (`cargo build --release -p horizon-lab`,"
                                 " after and apart from horizon-server) or pass --lab")
            log(f"warning: {msg}; skipping (--allow-missing)")
            if not bench.has_gen:
                names = [n for n in names if n not in GENERATED]

        result = {"config": {"ratio": RATIO, "runs": args.runs, "samples": args.samples,
                             "models": names, "python": args.python,
                             "lab_has_distance": bench.has_distance, "lab_has_gen": bench.has_gen,
                             "shared_instanced_models": {k: {"file": str(v[0].relative_to(ROOT)),
                                                             "max_placements_of_a_mesh": v[1]}
                                                         for k, v in instanced.items()}},
                  "machine": machine_info(horizon.resolve(), bench.lab), "models": {}}
        started = time.perf_counter()
        for name in names:
            t = time.perf_counter()
            result["models"][name] = bench.model(name, instanced)
            result["models"][name]["bench_seconds"] = time.perf_counter() - t
            log(f"[{name}] done in {time.perf_counter() - t:.0f} s")
        result["machine"]["loadavg_end"] = list(os.getloadavg())
        result["total_seconds"] = time.perf_counter() - started
        result["targets"] = targets(result["models"])

    out = pathlib.Path(args.out)
    out.mkdir(parents=True, exist_ok=True)
    (out / "table3.json").write_text(json.dumps(result, indent=1) + "\n")
    (out / "table3.md").write_text(markdown(result))
    log(f"wrote {out / 'table3.json'} and {out / 'table3.md'} ({result['total_seconds']:.0f} s)")
    for label, status, detail in result["targets"]:
        print(f"{status:4} {label} — {detail}")
    return 1 if args.strict and any(s == "FAIL" for _, s, _ in result["targets"]) else 0


if __name__ == "__main__":
    sys.exit(main())
