#!/usr/bin/env python3
"""The OpenCV monocular VO users reach for first, as the baseline of `scripts/bench.sh`:
Shi-Tomasi corners tracked by pyramidal KLT, the essential matrix by RANSAC (5-point),
`recoverPose`, and the scale of each step from the ground truth (the usual
"monoVO-python" recipe; it needs ground truth, so it flatters OpenCV's accuracy).

Usage:
    python3 scripts/opencv_vo.py SEQUENCE_DIR GROUND_TRUTH.txt --max-frames 300 -o out.txt

Writes one KITTI pose line per frame (camera-to-world of the left camera) and prints JSON
{"frames", "wall_s", "ms_per_frame"} (PNG decoding included, one thread).
"""

import argparse
import json
import sys
import time
from pathlib import Path

import numpy as np

try:
    import cv2
except ImportError:  # pragma: no cover
    sys.exit("needs OpenCV: pip install opencv-python-headless numpy")


def main() -> None:
    ap = argparse.ArgumentParser()
    ap.add_argument("sequence", type=Path)
    ap.add_argument("ground_truth", type=Path)
    ap.add_argument("--max-frames", type=int, default=None)
    ap.add_argument("-o", "--output", type=Path, required=True)
    args = ap.parse_args()
    cv2.setNumThreads(1)
    p0 = next(l for l in (args.sequence / "calib.txt").read_text().splitlines() if l.startswith("P0:"))
    p = np.array([float(x) for x in p0.split()[1:]]).reshape(3, 4)
    k = p[:, :3]
    gt = np.loadtxt(args.ground_truth).reshape(-1, 3, 4)
    images = sorted((args.sequence / "image_0").glob("*.png"))[: args.max_frames]
    start = time.perf_counter()
    world_from_cam = np.eye(4)
    poses = [world_from_cam[:3].copy()]
    prev = cv2.imread(str(images[0]), cv2.IMREAD_GRAYSCALE)
    pts = cv2.goodFeaturesToTrack(prev, 2000, 0.01, 7)
    for i in range(1, len(images)):
        cur = cv2.imread(str(images[i]), cv2.IMREAD_GRAYSCALE)
        nxt, st, _ = cv2.calcOpticalFlowPyrLK(prev, cur, pts, None, winSize=(21, 21), maxLevel=3)
        good = st.reshape(-1) == 1
        a, b = pts[good].reshape(-1, 2), nxt[good].reshape(-1, 2)
        if len(a) >= 8:
            e, mask = cv2.findEssentialMat(b, a, k, cv2.RANSAC, 0.999, 1.0)
            if e is not None and e.shape == (3, 3):
                _, r, t, _ = cv2.recoverPose(e, b, a, k, mask=mask)
                scale = np.linalg.norm(gt[i][:, 3] - gt[i - 1][:, 3])
                # recoverPose(E, b, a) gives x_a = R x_b + t: prev_from_cur
                step = np.eye(4)
                step[:3, :3] = r
                step[:3, 3] = t.reshape(3) * scale
                world_from_cam = world_from_cam @ step
        poses.append(world_from_cam[:3].copy())
        prev = cur
        pts = b.reshape(-1, 1, 2) if len(b) >= 1500 else cv2.goodFeaturesToTrack(cur, 2000, 0.01, 7)
    wall = time.perf_counter() - start
    np.savetxt(args.output, np.array(poses).reshape(-1, 12), fmt="%.9e")
    print(json.dumps({"frames": len(images), "wall_s": wall, "ms_per_frame": 1e3 * wall / len(images)}))


if __name__ == "__main__":
    main()
