#!/usr/bin/env python3
"""NEES of each step's covariance (issue 55 item 5) from a `visnav odometry --json` report.

    scripts/step_nees.py REPORT.json POSES.txt GROUND_TRUTH.txt [--scale-free] [--inflation F]

For every frame with a covariance, e = log(gt_prev_from_cur^-1 * est_prev_from_cur) (se(3),
translation part first, as visnav_core::se3::se3_log) and NEES = e^T S^-1 e. The estimate's
step comes from consecutive lines of POSES.txt (world_from_cam, KITTI format), the truth's from
GROUND_TRUTH.txt (first lines). Prints the mean NEES, the share above chi2_6's 95 % quantile
(12.59) and the count; `--inflation F` divides every NEES by F (a covariance scaled by F).
"""
import json
import sys

import numpy as np

CHI2_6_95 = 12.592


def read_kitti(path):
    rows = [list(map(float, l.split())) for l in open(path) if l.strip()]
    out = []
    for r in rows:
        m = np.eye(4)
        m[:3, :] = np.array(r).reshape(3, 4)
        out.append(m)
    return out


def so3_log(r):
    c = max(-1.0, min(1.0, (np.trace(r) - 1.0) / 2.0))
    a = np.arccos(c)
    w = np.array([r[2, 1] - r[1, 2], r[0, 2] - r[2, 0], r[1, 0] - r[0, 1]])
    if a < 1e-9:
        return 0.5 * w
    return a / (2.0 * np.sin(a)) * w


def skew(v):
    return np.array([[0, -v[2], v[1]], [v[2], 0, -v[0]], [-v[1], v[0], 0]])


def se3_log(m):
    w = so3_log(m[:3, :3])
    a = np.linalg.norm(w)
    k = skew(w)
    if a < 1e-9:
        v_inv = np.eye(3) - 0.5 * k
    else:
        v_inv = np.eye(3) - 0.5 * k + (1.0 / a**2) * (1 - a * np.sin(a) / (2 * (1 - np.cos(a)))) * k @ k
    return np.concatenate([v_inv @ m[:3, 3], w])


def nees(report, est, gt):
    frames = json.load(open(report))["per_frame"]
    values = []
    for f in frames:
        cov = f.get("prev_from_cur_covariance")
        i = f["step"]
        if cov is None or i == 0 or i >= len(gt):
            continue
        est_step = np.linalg.inv(est[i - 1]) @ est[i]
        gt_step = np.linalg.inv(gt[i - 1]) @ gt[i]
        e = se3_log(np.linalg.inv(gt_step) @ est_step)
        s = np.array(cov)
        values.append(float(e @ np.linalg.solve(s, e)))
    return np.array(values)


def main():
    args = sys.argv[1:]
    inflation = 1.0
    if "--inflation" in args:
        k = args.index("--inflation")
        inflation = float(args[k + 1])
        del args[k : k + 2]
    report, poses, truth = args
    v = nees(report, read_kitti(poses), read_kitti(truth)) / inflation
    print(
        json.dumps(
            {
                "steps": int(v.size),
                "mean_nees": float(v.mean()) if v.size else None,
                "median_nees": float(np.median(v)) if v.size else None,
                "share_above_12_6": float((v > CHI2_6_95).mean()) if v.size else None,
            }
        )
    )


if __name__ == "__main__":
    main()
