#!/usr/bin/env python3
"""The fast flow against OpenCV's DIS in one process, in the same run (issue 51).

Usage (the visnav Python module and OpenCV in one venv; scripts/bench.sh sets it up):
    python3 scripts/bench_fast_flow.py KITTI2012_PAIR_STEM [--repeat 9] [--config FILE.toml ...]

For 1 and 2 threads, times each method on the pair `STEM_10.png` -> `STEM_11.png` with the PNG
decoding included (`visnav.load_image` / `cv2.imread`), warm (the median of `--repeat` calls
after one unmeasured call): visnav's fast flow with its information matrix (defaults, and each
`--config`, a TOML file of `FastFlowConfig` keys) and OpenCV DIS ultrafast, fast and medium.
Prints a Markdown table with each time as a ratio to DIS medium of the same thread count.

The thread count is set per process (rayon's pool is made once): the script runs itself once
per thread count with RAYON_NUM_THREADS set.
"""

import argparse
import json
import os
import statistics
import subprocess
import sys
import time

try:
    import tomllib
except ImportError:  # pragma: no cover (Python < 3.11)
    tomllib = None


def median_ms(fn, repeat):
    fn()
    times = []
    for _ in range(repeat):
        t = time.perf_counter()
        fn()
        times.append(time.perf_counter() - t)
    return 1e3 * statistics.median(times)


def measure(stem, repeat, configs, threads):
    import cv2
    import visnav

    cv2.setNumThreads(threads)
    a, b = stem + "_10.png", stem + "_11.png"
    rows = {}
    for label, preset in (
        ("DIS ultrafast", cv2.DISOPTICAL_FLOW_PRESET_ULTRAFAST),
        ("DIS fast", cv2.DISOPTICAL_FLOW_PRESET_FAST),
        ("DIS medium", cv2.DISOPTICAL_FLOW_PRESET_MEDIUM),
    ):
        dis = cv2.DISOpticalFlow_create(preset)
        rows[label] = median_ms(lambda: dis.calc(cv2.imread(a, 0), cv2.imread(b, 0), None), repeat)
    for path in [None] + configs:
        cfg = None
        if path is not None:
            with open(path, "rb") as f:
                cfg = tomllib.load(f)
        label = "visnav fast" + ("" if path is None else f" ({os.path.basename(path)})")
        rows[label] = median_ms(
            lambda: visnav.dense_flow(visnav.load_image(a), visnav.load_image(b), config=cfg, method="fast"),
            repeat,
        )
    return rows


def main():
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("stem")
    ap.add_argument("--repeat", type=int, default=9)
    ap.add_argument("--config", action="append", default=[])
    ap.add_argument("--threads", type=int, help=argparse.SUPPRESS)
    args = ap.parse_args()
    if args.threads is not None:
        print(json.dumps(measure(args.stem, args.repeat, args.config, args.threads)))
        return
    table = {}
    for threads in (1, 2):
        env = dict(os.environ, RAYON_NUM_THREADS=str(threads))
        cmd = [sys.executable, __file__, args.stem, "--repeat", str(args.repeat), "--threads", str(threads)]
        for c in args.config:
            cmd += ["--config", c]
        out = subprocess.run(cmd, env=env, check=True, capture_output=True, text=True).stdout
        table[threads] = json.loads(out.strip().splitlines()[-1])
    print("| method | 1 thread, ms | / DIS medium | 2 threads, ms | / DIS medium |")
    print("| --- | --- | --- | --- | --- |")
    for label in table[1]:
        one, two = table[1][label], table[2][label]
        print(
            f"| {label} | {one:.1f} | {one / table[1]['DIS medium']:.2f} | {two:.1f} | {two / table[2]['DIS medium']:.2f} |"
        )


if __name__ == "__main__":
    main()
