#!/usr/bin/env python3
"""Where the live rebuild's time goes, from a served world's log.

Reads the `published` lines that `horizon serve` logs at info level (bench-service writes
them with `--server-log FILE`) and summarises the builds whose generation lies in (LO, HI]:
how many placements each covered, wall seconds (all told, the build, its impostors, and the
time before, at and after publication) and each tree level's nodes and wall time. The first
build in the range is left out: it fills the proxy memo.

    python3 lab/bench/rebuild_log.py SERVER_LOG LO HI
"""
import re
import statistics as st
import sys

FIELDS = {
    "seconds": "all told",
    "build_seconds": "the build",
    "impostor_seconds": "of which impostors",
    "prepare_seconds": "before the build",
    "publish_seconds": "publication",
    "collect_seconds": "collection, after publication",
    "built": "aggregates built",
}


def builds(path):
    rows = []
    for line in open(path, encoding="utf-8", errors="replace"):
        line = re.sub(r"\x1b\[[0-9;]*m", "", line)
        if "published generation=" not in line:
            continue
        row = {}
        for key in list(FIELDS) + ["generation"]:
            m = re.search(r"\b" + key + r"=([\d.]+)", line)
            if m:
                row[key] = float(m.group(1))
        m = re.search(r"level_seconds=\[(.*?)\]", line)
        row["levels"] = {
            int(d): (int(n), float(s))
            for d, n, s in re.findall(r"\((\d+), (\d+), ([\d.]+)\)", m.group(1) if m else "")
        }
        rows.append(row)
    return rows


def quantile(xs, p):
    xs = sorted(xs)
    return xs[min(len(xs) - 1, int(p * len(xs)))]


def main():
    path, lo, hi = sys.argv[1], int(sys.argv[2]), int(sys.argv[3])
    rows = builds(path)
    chosen = []
    for before, row in zip(rows, rows[1:]):
        if lo < row["generation"] <= hi:
            row["covered"] = row["generation"] - before["generation"]
            chosen.append(row)
    chosen = chosen[1:]
    if not chosen:
        sys.exit(f"no builds published generations in ({lo}, {hi}] in {path}")
    print(f"| {len(chosen)} builds | mean | p50 | p90 | max |")
    print("|---|---|---|---|---|")
    covered = [r["covered"] for r in chosen]
    print(f"| placements covered | {st.mean(covered):.2f} | {quantile(covered, .5)} | "
          f"{quantile(covered, .9)} | {max(covered)} |")
    for key, name in FIELDS.items():
        xs = [r[key] for r in chosen if key in r]
        if xs:
            print(f"| {name} | {st.mean(xs):.3f} | {quantile(xs, .5):.3f} | "
                  f"{quantile(xs, .9):.3f} | {max(xs):.3f} |")
    print()
    print("| depth | nodes built (mean) | wall p50 (s) | wall p90 (s) |")
    print("|---|---|---|---|")
    for depth in range(max(max(r["levels"], default=0) for r in chosen) + 1):
        at = [r["levels"][depth] for r in chosen if depth in r["levels"]]
        if at:
            walls = [s for _, s in at]
            print(f"| {depth} | {st.mean(n for n, _ in at):.2f} | {quantile(walls, .5):.3f} | "
                  f"{quantile(walls, .9):.3f} |")


if __name__ == "__main__":
    main()
