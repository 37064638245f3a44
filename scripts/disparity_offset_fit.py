#!/usr/bin/env python3
"""The stereo rig's disparity offset fitted with ground-truth poses
(docs/notes/2026-12-02-stereo-history.md, *The rig's disparity offset*).

Reads the tracks of a stereo run (`visnav odometry --mode stereo SEQ --save-tracks DIR`: each
frame's previous and current left pixel, the point's depth at the current frame and the inlier
flag), the ground-truth poses (KITTI format) and the sequence's calib.txt (P0, P1), and fits by
robust least squares the offset eps that, added to every disparity (z = f b / (d + eps)), best
explains the tracks' motion under the true poses, with a small rotation correction per frame
(the ground truth's own rotation noise) and, optionally, a scale kappa of the true translations
(a baseline or ground-truth scale error, which a constant offset is told apart from because far
and near points move differently). A last fit lets the offset vary linearly with the image row
(eps + rho (v - cy) / 100: a roll between the rectified cameras).

    python3 scripts/disparity_offset_fit.py TRACKS_DIR POSES.txt SEQUENCE_DIR
Needs numpy and scipy.
"""
import glob
import os
import sys

import numpy as np
from scipy.optimize import least_squares
from scipy.spatial.transform import Rotation


def load(tracks_dir, poses_path, seq_dir):
    rows = open(os.path.join(seq_dir, "calib.txt")).read().split("\n")
    p0 = np.array(rows[0].split()[1:], float).reshape(3, 4)
    p1 = np.array(rows[1].split()[1:], float).reshape(3, 4)
    f, cx, cy = p0[0, 0], p0[0, 2], p0[1, 2]
    baseline = -p1[0, 3] / p1[0, 0]
    gt = np.loadtxt(poses_path)

    def world_from_cam(i):
        m = np.eye(4)
        m[:3, :] = gt[i].reshape(3, 4)
        return m

    frames = []
    for path in sorted(glob.glob(os.path.join(tracks_dir, "*.tracks.csv"))):
        k = int(os.path.basename(path)[:6])
        a = np.loadtxt(path, delimiter=",", skiprows=1, ndmin=2)
        if a.size == 0:
            continue
        a = a[a[:, 5] > 0]
        prev_from_cur = np.linalg.inv(world_from_cam(k - 1)) @ world_from_cam(k)
        frames.append((a, prev_from_cur))
    return frames, (f, cx, cy, baseline)


def residuals(params, frames, camera, with_offset, with_scale, with_row=False):
    f, cx, cy, baseline = camera
    eps = params[0] if with_offset else 0.0
    kappa = params[1] if with_scale else 0.0
    rho = params[-1] if with_row else 0.0
    out = []
    for i, (a, m) in enumerate(frames):
        r = Rotation.from_rotvec(params[2 + 3 * i : 5 + 3 * i]).as_matrix() @ m[:3, :3]
        t = (1.0 + kappa) * m[:3, 3]
        offset = eps + rho * (a[:, 3] - cy) / 100.0
        z = f * baseline / (f * baseline / a[:, 4] + offset)
        x = np.stack([(a[:, 2] - cx) / f * z, (a[:, 3] - cy) / f * z, z], 1) @ r.T + t
        out.append(f * x[:, 0] / x[:, 2] + cx - a[:, 0])
        out.append(f * x[:, 1] / x[:, 2] + cy - a[:, 1])
    return np.concatenate(out)


def main():
    if len(sys.argv) != 4:
        sys.exit(__doc__)
    frames, camera = load(*sys.argv[1:4])
    start = np.zeros(2 + 3 * len(frames))
    n = sum(len(a) for a, _ in frames)
    print(f"{len(frames)} frames, {n} inlier tracks")
    for with_offset, with_scale in [(False, False), (True, False), (False, True), (True, True)]:
        fit = least_squares(
            lambda p: residuals(p, frames, camera, with_offset, with_scale),
            start,
            loss="huber",
            f_scale=0.5,
        )
        print(
            "offset %s scale %s: eps %+.4f px, kappa %+.5f, robust cost %.2f"
            % (
                "fitted" if with_offset else "0     ",
                "fitted" if with_scale else "1     ",
                fit.x[0] if with_offset else 0.0,
                fit.x[1] if with_scale else 0.0,
                fit.cost,
            )
        )
    fit = least_squares(
        lambda p: residuals(p, frames, camera, True, False, True),
        np.zeros(3 + 3 * len(frames)),
        loss="huber",
        f_scale=0.5,
    )
    print(
        "offset fitted, + row term: eps %+.4f px at the principal row, %+.4f px per 100 rows, "
        "robust cost %.2f" % (fit.x[0], fit.x[-1], fit.cost)
    )


if __name__ == "__main__":
    main()
