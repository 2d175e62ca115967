#!/usr/bin/env python3
"""Tabulates `horizon-lab load --json` reports, as `instances_load.sh` writes them
(DIR/stream_<mode>_<viewers>.json), one markdown row per report: camera-to-delta latency,
the server's cores, the views it coalesced, carried without planning and planned to no
change, deltas a second, stream bytes a second per viewer and the first cut.

    python3 lab/bench/load_table.py DIR [DIR ...]
"""
import glob
import json
import os
import sys


def rows(directory):
    def key(path):
        mode, viewers = os.path.basename(path)[len("stream_"):-len(".json")].rsplit("_", 1)
        return mode, int(viewers)

    for path in sorted(glob.glob(os.path.join(directory, "stream_*.json")), key=key):
        mode, viewers = key(path)
        with open(path) as f:
            r = json.load(f)
        cores = r.get("server_cpu_cores")
        fmt = lambda v: "-" if v is None else f"{v:,}"
        yield (
            f"| {os.path.basename(os.path.normpath(directory))} | {mode} | {viewers} "
            f"| {r['latency_ms']['p50']:.1f} / {r['latency_ms']['p99']:.1f} "
            f"| {'-' if cores is None else f'{cores:.2f}'} "
            f"| {fmt(r['views_sent'])} | {fmt(r.get('coalesced'))} | {fmt(r.get('carried'))} "
            f"| {fmt(r.get('planned_unchanged'))} | {r['deltas_per_second']:.1f} "
            f"| {r['bytes_per_second_per_viewer'] / 1e3:,.1f} "
            f"| {r['first_cut_ms']['p50']:.0f} |"
        )


def main():
    if len(sys.argv) < 2:
        sys.exit(__doc__)
    print("| run | mode | viewers | delta p50 / p99 ms | server cores | views | coalesced "
          "| carried | planned, unchanged | deltas/s | KB/s per viewer | first cut p50 ms |")
    print("|---|---|---|---|---|---|---|---|---|---|---|---|")
    for directory in sys.argv[1:]:
        for row in rows(directory):
            print(row)


if __name__ == "__main__":
    main()
