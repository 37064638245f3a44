#!/usr/bin/env python3
"""Side-by-side timing of GTSAM's Levenberg-Marquardt and `visnav posegraph` on g2o pose graphs.

Usage: python3 scripts/bench_gtsam.py [--visnav target/release/visnav] [--repeat 3] FILE.g2o ...

GTSAM (pip install gtsam) reads the file with readG2o (3-D), adds a tight prior on the first
vertex, starts from the file's poses and runs LevenbergMarquardtOptimizer with default parameters.
Its error is 1/2 sum of squared whitened errors. visnav runs `visnav posegraph FILE --json` with its
default configuration (chordal initialisation, pairwise-consistency preselection of loop closures, Levenberg-Marquardt; `--robust gnc-gm` or `none` select the other modes). Times are wall-clock
seconds of the optimisation alone (file reading excluded for both), best of --repeat runs.
"""

import argparse
import numpy as np
import json
import os
import subprocess
import sys
import tempfile
import time


def run_gtsam(path, repeat):
    import gtsam

    best = None
    for _ in range(repeat):
        graph, initial = gtsam.readG2o(path, True)
        prior = gtsam.noiseModel.Diagonal.Variances(np.full(6, 1e-6))
        first = min(initial.keys())
        graph.add(gtsam.PriorFactorPose3(first, initial.atPose3(first), prior))
        params = gtsam.LevenbergMarquardtParams()
        t0 = time.perf_counter()
        result = gtsam.LevenbergMarquardtOptimizer(graph, initial, params).optimize()
        elapsed = time.perf_counter() - t0
        error = graph.error(result)
        if best is None or elapsed < best[0]:
            best = (elapsed, error, graph.error(initial))
    return best


def run_visnav(binary, path, repeat, robust):
    best = None
    with tempfile.TemporaryDirectory() as tmp:
        out = os.path.join(tmp, "out.g2o")
        for _ in range(repeat):
            proc = subprocess.run(
                [binary, "--quiet", "posegraph", path, "--output", out, "--json", "--robust", robust],
                check=True,
                capture_output=True,
                text=True,
            )
            report = json.loads(proc.stdout)
            elapsed = report["timing"]["solve_ms"] / 1e3
            if best is None or elapsed < best[0]:
                best = (elapsed, report["objective_after"]["gtsam_error"], report)
    return best


def main():
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("files", nargs="+")
    parser.add_argument("--visnav", default="target/release/visnav")
    parser.add_argument("--repeat", type=int, default=3)
    parser.add_argument("--robust", default="pairwise", choices=["pairwise", "gnc-gm", "none"])
    args = parser.parse_args()
    print(f"{'graph':<22} {'GTSAM LM s':>11} {'GTSAM error':>14} {'visnav s':>9} {'visnav error':>14} {'iters':>6}")
    for path in args.files:
        name = os.path.basename(path)
        try:
            g_time, g_err, _ = run_gtsam(path, args.repeat)
        except ImportError:
            g_time, g_err = float("nan"), float("nan")
            print("gtsam not installed (pip install gtsam)", file=sys.stderr)
        v_time, v_err, report = run_visnav(args.visnav, path, args.repeat, args.robust)
        print(f"{name:<22} {g_time:>11.3f} {g_err:>14.6f} {v_time:>9.3f} {v_err:>14.6f} {report['iterations']:>6}")


if __name__ == "__main__":
    main()
