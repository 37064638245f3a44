#!/usr/bin/env python3
"""Compare visnav flow with OpenCV DIS (medium preset) and Farneback on the same pairs.

Usage:
    pip install opencv-python-headless numpy
    python3 scripts/compare_flow_opencv.py DATASET_DIR [--visnav target/release/visnav] [--threads 1]

DATASET_DIR is a Middlebury (other-data + other-gt-flow) or KITTI 2012/2015 (training/image_0 +
flow_noc) layout, as for `visnav flow-eval`. The script runs `visnav flow-eval DATASET_DIR --json`,
then OpenCV on the same pairs (same grayscale images, same ground truth, same EPE definition:
mean over pixels with known ground truth, then over pairs), and prints EPE, Fl and time per pair
and the ratios visnav / OpenCV.
"""

import argparse
import json
import os
import subprocess
import sys
import time

import numpy as np

from flo import read_flo

try:
    import cv2
except ImportError:  # pragma: no cover
    sys.exit("needs OpenCV: pip install opencv-python-headless")


def read_kitti_flow(path):
    img = cv2.imread(path, cv2.IMREAD_UNCHANGED)  # BGR uint16
    if img is None:
        raise ValueError(f"cannot read {path}")
    b, g, r = img[..., 0], img[..., 1], img[..., 2]
    u = (r.astype(np.float64) - 32768.0) / 64.0
    v = (g.astype(np.float64) - 32768.0) / 64.0
    return np.stack([u, v], axis=2), b > 0


def pairs(root):
    if os.path.isdir(os.path.join(root, "other-data")):
        for seq in sorted(os.listdir(os.path.join(root, "other-data"))):
            gt = os.path.join(root, "other-gt-flow", seq, "flow10.flo")
            if os.path.isfile(gt):
                d = os.path.join(root, "other-data", seq)
                yield seq, os.path.join(d, "frame10.png"), os.path.join(d, "frame11.png"), read_flo(gt)
        return
    kroot = os.path.join(root, "training") if os.path.isdir(os.path.join(root, "training")) else root
    for img_dir in ("image_0", "image_2"):
        d = os.path.join(kroot, img_dir)
        if os.path.isdir(d):
            for name in sorted(os.listdir(d)):
                if name.endswith("_10.png"):
                    gt = os.path.join(kroot, "flow_noc", name)
                    if os.path.isfile(gt):
                        stem = name[: -len("_10.png")]
                        yield stem, os.path.join(d, name), os.path.join(d, stem + "_11.png"), read_kitti_flow(gt)
            return
    sys.exit(f"{root}: no Middlebury or KITTI layout")


def score(flow, gt, known):
    err = np.linalg.norm(flow - gt, axis=2)[known]
    mag = np.linalg.norm(gt, axis=2)[known]
    return float(err.mean()), float(100.0 * ((err > 3.0) & (err > 0.05 * mag)).mean())


def main():
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("dataset")
    ap.add_argument("--visnav", default="target/release/visnav")
    ap.add_argument("--threads", type=int, default=1, help="OpenCV threads (the reference figures use 1)")
    args = ap.parse_args()
    cv2.setNumThreads(args.threads)

    out = subprocess.run([args.visnav, "flow-eval", args.dataset, "--json"], check=True, capture_output=True, text=True)
    ours = {p["name"]: p for p in json.loads(out.stdout)["pairs"]}

    dis = cv2.DISOpticalFlow_create(cv2.DISOPTICAL_FLOW_PRESET_MEDIUM)
    rows = []
    for name, p1, p2, (gt, known) in pairs(args.dataset):
        a = cv2.imread(p1, cv2.IMREAD_GRAYSCALE)
        b = cv2.imread(p2, cv2.IMREAD_GRAYSCALE)
        t = time.perf_counter()
        f_dis = dis.calc(a, b, None)
        t_dis = 1e3 * (time.perf_counter() - t)
        t = time.perf_counter()
        f_fb = cv2.calcOpticalFlowFarneback(a, b, None, 0.5, 5, 15, 3, 7, 1.5, 0)
        t_fb = 1e3 * (time.perf_counter() - t)
        e_dis, fl_dis = score(f_dis.astype(np.float64), gt, known)
        e_fb, fl_fb = score(f_fb.astype(np.float64), gt, known)
        o = ours.get(name)
        if o is None:
            continue
        rows.append((name, o["metrics"]["mean_epe_px"], o["metrics"]["fl_percent"], o["time_ms"], e_dis, fl_dis, t_dis, e_fb, t_fb))

    print(f"{'pair':<14}{'visnav EPE':>11}{'Fl%':>7}{'ms':>7} | {'DIS EPE':>8}{'Fl%':>7}{'ms':>7} | {'Farneback EPE':>14}{'ms':>7}")
    for r in rows:
        print(f"{r[0]:<14}{r[1]:>11.3f}{r[2]:>7.2f}{r[3]:>7.0f} | {r[4]:>8.3f}{r[5]:>7.2f}{r[6]:>7.0f} | {r[7]:>14.3f}{r[8]:>7.0f}")
    m = np.array([r[1:] for r in rows]).mean(axis=0)
    print(f"{'mean':<14}{m[0]:>11.3f}{m[1]:>7.2f}{m[2]:>7.0f} | {m[3]:>8.3f}{m[4]:>7.2f}{m[5]:>7.0f} | {m[6]:>14.3f}{m[7]:>7.0f}")
    print(f"ratios visnav/DIS: EPE {m[0] / m[3]:.3f}, time {m[2] / m[5]:.2f}; visnav/Farneback: EPE {m[0] / m[6]:.3f}, time {m[2] / m[7]:.2f}")


if __name__ == "__main__":
    main()
