"""The experiment behind the aggregate triangle budget (aggregate/src/budget.rs): for each
pixels-per-triangle constant P, build every aggregate of a world (`horizon build`) and measure
the join download (`horizon-lab report`, the horizon-lab binary beside HORIZON_BINARY) and the
simplification error in pixels at each aggregate's nearest display distance (from the manifest's
per-aggregate stats). Writes lab/results/budget_<world>.md (or OUT_DIR/budget_<world>.md).

Usage: budget_sweep.py HORIZON_BINARY DIR [--p 4,16,64] [--out OUT_DIR]"""
import json
import pathlib
import statistics
import subprocess
import sys

import world_files

ROOT = pathlib.Path(__file__).resolve().parents[2]  # lab/bench/budget_sweep.py -> the repository


def run(cmd):
    out = subprocess.run(cmd, capture_output=True, text=True)
    if out.returncode != 0:
        sys.exit(f"{' '.join(cmd)} failed: {out.stderr.strip()}")
    return out.stdout


def main(horizon, d, ps, out_dir):
    lab = str(pathlib.Path(horizon).with_name("horizon-lab"))
    world = pathlib.Path(d)
    name = world_files.name(world)
    rows = []
    for p in ps:
        build = json.loads(run([horizon, "build", d, "--pixels-per-triangle", str(p), "--json"]))
        report = json.loads(run([lab, "report", d, "--views", "10", "--seed", "1", "--json"]))
        nodes = world_files.published_manifest(world)["nodes"].values()
        errors = sorted(e["stats"]["error_pixels"] for e in nodes if e["stats"]["error"] > 0)
        p95 = errors[int(0.95 * (len(errors) - 1))] if errors else 0.0
        rows.append(
            (p, report["join_bytes_mean"] / 1e6, report["unoptimized_join_bytes_mean"] / 1e6,
             statistics.median(errors) if errors else 0.0, p95, len(errors),
             build["aggregates"]["bytes_total"] / 1e6, build["aggregates"]["seconds"])
        )
        print(rows[-1], flush=True)
    lines = [
        f"# Aggregate triangle budget on {name}",
        "",
        f"`python3 lab/bench/budget_sweep.py target/release/horizon DIR --p {','.join(map(str, ps))}`,",
        "one run on this machine (2 cores). Error: the simplifier's RMS quadric error in pixels",
        "at each aggregate's nearest display distance (Omega_min 1e-3), over simplified aggregates.",
        "",
        "| pixels per triangle | join MB (ours) | join MB (unoptimised, same budget) | median error px | p95 error px | simplified aggregates | all aggregates MB | build s |",
        "|---|---|---|---|---|---|---|---|",
    ]
    for r in rows:
        lines.append("| {} | {:.2f} | {:.2f} | {:.3f} | {:.3f} | {} | {:.1f} | {:.1f} |".format(*r))
    out_dir.mkdir(parents=True, exist_ok=True)
    out = out_dir / f"budget_{name}.md"
    out.write_text("\n".join(lines) + "\n")
    print(f"wrote {out}")


if __name__ == "__main__":
    args = sys.argv[1:]
    if len(args) < 2:
        sys.exit(__doc__)
    ps, out_dir = [4.0, 16.0, 64.0], ROOT / "lab" / "results"
    rest = args[2:]
    while rest:
        if len(rest) >= 2 and rest[0] == "--p":
            ps = [float(x) for x in rest[1].split(",")]
        elif len(rest) >= 2 and rest[0] == "--out":
            out_dir = pathlib.Path(rest[1])
        else:
            sys.exit(__doc__)
        rest = rest[2:]
    main(args[0], args[1], ps, out_dir)
