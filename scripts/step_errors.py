#!/usr/bin/env python3
"""Per-frame relative-pose errors of a trajectory against the ground truth, by windows of frames.

For each step k-1 -> k (both files: KITTI format, 12 numbers a line, world_from_cam, camera y
down): the length ratio of the estimated to the true step, the elevation of the true motion (its
angle to the world's up, degrees; positive climbing), the error of the estimated motion's
elevation, and the pitch error of the relative rotation (degrees a frame). Printed as means
(the ratio: median) over windows of frames, then the rms elevation error over the whole run. Written for the aerial
flights
(docs/notes/2026-12-02-aerial-history.md, round 4), where the translation direction's elevation is
what the tracked ground integrates into the camera height.

    python3 scripts/step_errors.py fl563/poses.txt estimate.txt [--window 40]

Needs numpy.
"""
import argparse

import numpy as np

from shared_error import load  # the KITTI trajectory reader beside this script


def elevation_deg(t, up):
    return np.degrees(np.arcsin(np.clip(t @ up / np.linalg.norm(t), -1.0, 1.0)))


def main():
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("truth")
    ap.add_argument("estimate")
    ap.add_argument("--window", type=int, default=40)
    args = ap.parse_args()
    truth, est = load(args.truth), load(args.estimate)
    n = min(len(truth), len(est))
    if n < 2:
        raise SystemExit(f"{args.estimate}: fewer than two poses")
    up_world = np.array([0.0, -1.0, 0.0])
    rows = []
    for k in range(1, n):
        # prev_from_cur: its translation is the motion, in the previous camera
        true_rel = np.linalg.inv(truth[k - 1]) @ truth[k]
        est_rel = np.linalg.inv(est[k - 1]) @ est[k]
        t_true, t_est = true_rel[:3, 3], est_rel[:3, 3]
        if np.linalg.norm(t_true) == 0.0 or np.linalg.norm(t_est) == 0.0:
            continue
        up = truth[k - 1][:3, :3].T @ up_world
        d_rot = est_rel[:3, :3] @ true_rel[:3, :3].T
        pitch = np.degrees((d_rot[2, 1] - d_rot[1, 2]) / 2.0)
        el_true = elevation_deg(t_true, up)
        rows.append((k, np.linalg.norm(t_est) / np.linalg.norm(t_true), el_true,
                     elevation_deg(t_est, up) - el_true, pitch))
    if not rows:
        raise SystemExit(f"{args.estimate}: no step with motion in both trajectories")
    r = np.array(rows)
    print("frames      step ratio  true elevation  elevation error  pitch error (deg/frame)")
    for a in range(0, n, args.window):
        w = r[(r[:, 0] >= a) & (r[:, 0] < a + args.window)]
        if len(w):
            print(f"{a:4d}-{min(a + args.window, n) - 1:4d}   {np.median(w[:, 1]):8.3f}"
                  f"  {np.mean(w[:, 2]):+12.2f}  {np.mean(w[:, 3]):+14.3f}  {np.mean(w[:, 4]):+14.4f}")
    print(f"rms elevation error {np.sqrt(np.mean(r[:, 3] ** 2)):.2f} deg over {len(r)} steps; "
          f"{int(np.sum(np.abs(r[:, 3]) > 10))} steps more than 10 deg off")


if __name__ == "__main__":
    main()
