"""Figure 6 of the core paper: average join download over mu and w, next to the query cost.

For each world directory given (generated with `horizon-lab gen world`), and each (mu, w) of
the grid, builds the BVH and every aggregate (`horizon build --mu --omega`), then measures the
join download of ten seeded viewpoints (`horizon-lab report --json`), with the query cost of the
same cuts (entries and aggregates per cut; `horizon-lab sweep` gives nodes visited over the full
grid, in lab/results/figure5.md). Writes lab/results/NAME.{md,json} (NAME default figure6).
HORIZON_BINARY is the product binary; the horizon-lab binary beside it runs `report`.

Usage: figure6.py HORIZON_BINARY DIR [DIR...] [--mu 0,0.4,0.8,1] [--w 0.2] [--name NAME]
       [--rows FILE]   (start from the rows of an earlier run's JSON, e.g. to render it again)
       [--out DIR]     (write NAME.{md,json} there instead of lab/results)"""
import json
import pathlib
import subprocess
import sys
import time

import world_files

ROOT = pathlib.Path(__file__).resolve().parents[2]  # lab/bench/figure6.py -> the repository
RESULTS = ROOT / "lab" / "results"


def run(cmd):
    out = subprocess.run(cmd, capture_output=True, text=True)
    if out.returncode != 0:
        sys.exit(f"{' '.join(cmd)} failed: {out.stderr.strip()}")
    return out.stdout


def main(argv):
    horizon, rest = argv[0], argv[1:]
    lab = str(pathlib.Path(horizon).with_name("horizon-lab"))
    mus, ws, dirs, out_name, rows_from = [0.0, 0.4, 0.8, 1.0], [0.2], [], "figure6", None
    out = RESULTS
    k = 0
    while k < len(rest):
        if rest[k] == "--out":
            out = pathlib.Path(rest[k + 1])
            k += 2
        elif rest[k] == "--rows":
            rows_from = rest[k + 1]
            k += 2
        elif rest[k] == "--name":
            out_name = rest[k + 1]
            k += 2
        elif rest[k] == "--mu":
            mus = [float(x) for x in rest[k + 1].split(",")]
            k += 2
        elif rest[k] == "--w":
            ws = [float(x) for x in rest[k + 1].split(",")]
            k += 2
        else:
            dirs.append(rest[k])
            k += 1
    rows = json.loads(pathlib.Path(rows_from).read_text()) if rows_from else []
    for d in dirs:
        name = world_files.name(d)
        for mu in mus:
            for w in ws:
                t = time.time()
                build = json.loads(
                    run([horizon, "build", d, "--mu", str(mu), "--omega", str(w), "--json"])
                )
                report = json.loads(run([lab, "report", d, "--views", "10", "--seed", "1", "--json"]))
                row = {
                    "world": name,
                    "mu": mu,
                    "w": w,
                    "join_bytes_mean": report["join_bytes_mean"],
                    "unoptimized_join_bytes_mean": report["unoptimized_join_bytes_mean"],
                    "naive_bytes": report["naive_bytes"],
                    "entries_mean": report["entries_mean"],
                    "aggregates_mean": report["aggregates_mean"],
                    "draw_calls_mean": report["draw_calls_mean"],
                    "build_seconds": build["aggregates"]["seconds"],
                    "seconds": time.time() - t,
                }
                rows.append(row)
                print(json.dumps(row), flush=True)
    out.mkdir(parents=True, exist_ok=True)
    # Next to the query cost of the BVH sweep (lab/results/figure5.md, `horizon-lab sweep`),
    # where it has the same world and (mu, w).
    cost = figure5_costs(RESULTS / "figure5.md")
    for r in rows:
        r["nodes_visited"] = cost.get((r["world"], r["mu"], r["w"]))
    (out / f"{out_name}.json").write_text(json.dumps(rows, indent=1))
    lines = [
        "# Figure 6: join download over mu and w",
        "",
        f"`python3 lab/bench/figure6.py target/release/horizon DIR... --mu {','.join(map(str, mus))} --w {','.join(map(str, ws))}`, one run on this machine (2 cores);",
        "10 seeded viewpoints, Omega_min 1e-3, at most 4000 entries per cut. Query cost: nodes",
        "visited per cut of the same (world, mu, w) tree in the BVH sweep (figure5.md, 100",
        "viewpoints), and entries and aggregates of these cuts. Build seconds are not comparable",
        "between rows: a build reuses every aggregate whose inputs the previous (mu, w) shared.",
        "",
        "| world | mu | w | join MB (ours) | join MB (unoptimised) | naive MB | nodes visited/cut (figure5.md) | entries/cut | aggregates/cut | draw calls/cut | aggregate build s |",
        "|---|---|---|---|---|---|---|---|---|---|---|",
    ]
    for r in rows:
        lines.append(
            f"| {r['world']} | {r['mu']} | {r['w']} | {r['join_bytes_mean']/1e6:.2f} | "
            f"{r['unoptimized_join_bytes_mean']/1e6:.2f} | {r['naive_bytes']/1e6:.2f} | "
            f"{'-' if r['nodes_visited'] is None else format(r['nodes_visited'], '.1f')} | "
            f"{r['entries_mean']:.0f} | {r['aggregates_mean']:.0f} | {r['draw_calls_mean']:.0f} | {r['build_seconds']:.1f} |"
        )
    (out / f"{out_name}.md").write_text("\n".join(lines) + "\n")


def figure5_costs(path):
    """(world, mu, w) -> mean nodes visited per cut of the similarity tree, from figure5.md."""
    cost = {}
    if not path.exists():
        return cost
    for line in path.read_text().splitlines():
        cells = [c.strip() for c in line.strip().strip("|").split("|")]
        if len(cells) >= 8 and cells[1] == "similarity":
            try:
                cost[(cells[0], float(cells[2]), float(cells[3]))] = float(cells[7])
            except ValueError:
                pass
    return cost


if __name__ == "__main__":
    if len(sys.argv) < 3:
        sys.exit(__doc__)
    main(sys.argv[1:])
