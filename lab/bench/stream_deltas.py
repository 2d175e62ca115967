#!/usr/bin/env python3
"""One viewer's stream, classified: a street-level walk of STEPS views 0.14 m apart (10 Hz at
1.4 m/s, answered within 100 ms or taken as unanswered) along +z from (845, 2, 300) in the
city, at `max_entries` 4,000, with instances on (1) or off (0). Prints the reset's and the
deltas' bytes, and the deltas' additions by class with their placements and JSON bytes:
instances additions that reuse a held entry (`reuses`), that replace the same node with the
same objects at new levels whole, that replace another content of the same node, or that are
new nodes; other kinds by kind, replacing or not.

    pip install websockets
    python3 lab/bench/stream_deltas.py URL INSTANCES STEPS
"""
import asyncio
import collections
import json
import sys

import websockets


def classify(a):
    if a["kind"] != "instances":
        return a["kind"] + ("_replace" if a.get("replaces") else "_new")
    if a.get("reuses"):
        return "instances_reuse"
    node, rest = a["id"].split("@", 1)
    content = rest.split("/")[0]
    same = [r for r in a.get("replaces", []) if r.split("@")[0] == node]
    if not same:
        return "instances_new_node"
    if same[0].split("@", 1)[1].split("/")[0] == content:
        return "instances_relevel_whole"
    return "instances_content"


async def walk(url, instances, steps):
    stats = collections.Counter()
    async with websockets.connect(url.replace("http", "ws", 1) + "/v1/stream", max_size=None) as ws:
        x, z = 845.0, 300.0
        for i in range(steps):
            view = {"type": "view", "id": i + 1, "eye": [x, 2.0, z], "max_entries": 4000,
                    "instances": instances}
            await ws.send(json.dumps(view))
            z += 0.14
            try:
                while True:
                    text = await asyncio.wait_for(ws.recv(), timeout=30 if i == 0 else 0.1)
                    m = json.loads(text)
                    if m["type"] == "reset":
                        stats["reset_bytes"] += len(text)
                    elif m["type"] == "delta":
                        stats["deltas"] += 1
                        stats["delta_bytes"] += len(text)
                        for a in m["add"]:
                            c = classify(a)
                            stats[c + "_additions"] += 1
                            stats[c + "_placements"] += len(a.get("placements", []))
                            stats[c + "_bytes"] += len(json.dumps(a, separators=(",", ":")))
                        await ws.send(json.dumps({"type": "ack", "seq": m["seq"]}))
            except asyncio.TimeoutError:
                pass
    return stats


def main():
    if len(sys.argv) != 4:
        sys.exit(__doc__)
    stats = asyncio.run(walk(sys.argv[1], sys.argv[2] == "1", int(sys.argv[3])))
    for k in sorted(stats):
        print(f"{k}: {stats[k]:,}")


if __name__ == "__main__":
    main()
