"""One fast-simplification run for lab/bench/table3.py, in a process of its own so that its peak RSS
is measured apart from the benchmark's: loads the expanded, position-welded mesh from IN.npz
(arrays v, f), times only the fast_simplification.simplify call (agg=7, target_reduction =
1 - RATIO), writes the result as OUT.ply and prints one JSON line
{triangles_in, vertices_in, triangles_out, vertices_out, seconds}.

Usage: fast_simplification_worker.py IN.npz OUT.ply RATIO"""
import json
import pathlib
import sys
import time

import fast_simplification  # noqa: F401 - imported before the clock starts
import numpy as np

# lab/bench/fast_simplification_worker.py -> the repository's tests/reference
sys.path.insert(0, str(pathlib.Path(__file__).resolve().parents[2] / "tests" / "reference"))
import check_simplify as cs  # noqa: E402


def main(inp, out_ply, ratio):
    data = np.load(inp)
    v, f = np.ascontiguousarray(data["v"], np.float64), np.ascontiguousarray(data["f"], np.int64)
    start = time.perf_counter()
    out_v, out_f = cs.fast_simplify(v, f, float(ratio))
    seconds = time.perf_counter() - start
    cs.write_ply(out_ply, out_v, out_f)
    print(json.dumps({"triangles_in": int(len(f)), "vertices_in": int(len(v)),
                      "triangles_out": int(len(out_f)), "vertices_out": int(len(out_v)),
                      "seconds": seconds}))
    return 0


if __name__ == "__main__":
    if len(sys.argv) != 4:
        sys.exit(__doc__)
    sys.exit(main(*sys.argv[1:4]))
