#!/usr/bin/env python3
"""How much of two trajectories' error against a ground truth do they share?

Usage:
    pip install numpy
    python3 scripts/shared_error.py GROUND_TRUTH A B [--lengths 10,20,30,40,50]

GROUND_TRUTH, A and B are KITTI trajectory files (12 numbers a line, world_from_cam), one line
per frame, compared on their common prefix. Segments are the KITTI devkit's (a start every 10
frames, a segment of length L ends at the first frame whose ground-truth path distance exceeds
start + L). For each segment the translation error vector `e = (gt_rel^-1 est_rel).t` is taken
for A and for B. The script prints:

* the devkit t_err (mean of |e| / L, %) of A and of B against the ground truth, of their mean
  `(e_A + e_B) / 2` (the part they share) and of their difference `e_A - e_B` (the part that
  tells them apart, A against B);
* the correlation of e_A and e_B per axis (x right, y down, z forward in the segment's start
  camera);
* a constant pitch and yaw between the ground truth's camera frame and the camera, fitted on B
  alone (least squares over B's segment errors, Gauss-Newton with a numerical Jacobian), and A's
  t_err against the ground truth so rotated: when independent estimators share most of their
  error, that error is in the reference or the common input (calibration), not in the estimator;
* the same for the rotation: each segment's rotation error `(est_rel^-1 gt_rel).R` (the
  devkit's) as an axis-angle vector (x pitch, y yaw, z roll in the segment's start camera),
  the devkit r_err (mean of its angle / L, deg/100 m) of A, B, their mean and their
  difference, the per-axis correlation and rms, and A's r_err with B's error about one axis
  taken out of A's (what A would score if that axis's shared part were the reference's);
* with `--split K`: per axis, the rms of the frame-to-frame rotation differences (A − truth,
  B − truth, A − B, degrees a frame) over frames `0..K` and `K..`, with each one's summed
  rotation, and both scores over the segments that start at frame K or later (where the
  estimators agree with each other far better than with the reference in the first frames, the
  reference is what differs there), also against the reference turned by a pitch and yaw
  fitted on B over those segments.
"""

import argparse

import numpy as np


def load(path):
    """A KITTI trajectory as N 4x4 matrices; a clear error naming the file for a bad one."""
    try:
        rows = np.loadtxt(path, ndmin=2)
    except ValueError as e:
        raise SystemExit(f"{path}: {e}")
    if rows.size and rows.shape[1] != 12:
        raise SystemExit(f"{path}: {rows.shape[1]} numbers a line, expected 12 (KITTI poses)")
    t = np.zeros((len(rows), 4, 4))
    t[:, :3, :] = rows.reshape(-1, 3, 4)
    t[:, 3, 3] = 1.0
    return t


def rotation(w):
    th = np.linalg.norm(w)
    if th < 1e-15:
        return np.eye(3)
    k = w / th
    kx = np.array([[0, -k[2], k[1]], [k[2], 0, -k[0]], [-k[1], k[0], 0]])
    return np.eye(3) + np.sin(th) * kx + (1 - np.cos(th)) * kx @ kx


def segments(gt, lengths):
    dist = np.concatenate([[0.0], np.cumsum(np.linalg.norm(np.diff(gt[:, :3, 3], axis=0), axis=1))])
    out = []
    for s in range(0, len(gt), 10):
        for length in lengths:
            e = int(np.searchsorted(dist, dist[s] + length))
            if e < len(gt):
                out.append((s, e, length))
    return out


def motions(gt, est, segs):
    """Each segment's motion `(gt_rel, est_rel)`, start camera from end camera."""
    for s, t, _ in segs:
        yield np.linalg.inv(gt[s]) @ gt[t], np.linalg.inv(est[s]) @ est[t]


def errors(gt, est, segs):
    """Translation error vector of each segment, metres, and the segment lengths."""
    e = [(np.linalg.inv(g) @ x)[:3, 3] for g, x in motions(gt, est, segs)]
    return np.array(e), np.array([length for _, _, length in segs], dtype=float)


def log_rotation(m):
    """Axis-angle vector of a rotation matrix, radians: the devkit's angle
    `acos((trace - 1) / 2)` (so that the norms give its r_err to the digit), about the axis of
    the antisymmetric part."""
    th = np.arccos(np.clip((np.trace(m) - 1.0) / 2.0, -1.0, 1.0))
    w = np.array([m[2, 1] - m[1, 2], m[0, 2] - m[2, 0], m[1, 0] - m[0, 1]])
    n = np.linalg.norm(w)
    return w * (th / n) if n > 0.0 else np.zeros(3)


def rotation_errors(gt, est, segs):
    """Rotation error of each segment, the devkit's error pose `inv(est_rel) gt_rel`, as an
    axis-angle vector, radians."""
    pairs = motions(gt, est, segs)
    return np.array([log_rotation((np.linalg.inv(x) @ g)[:3, :3]) for g, x in pairs])


def r_err(w, lengths):
    """Devkit r_err, deg/100 m, of axis-angle errors `w`."""
    return 100.0 * np.degrees(np.mean(np.linalg.norm(w, axis=1) / lengths))


def t_err(e, lengths):
    return 100.0 * np.mean(np.linalg.norm(e, axis=1) / lengths)


def rotated(gt, pitch_yaw):
    r = np.eye(4)
    r[:3, :3] = rotation(np.array([pitch_yaw[0], pitch_yaw[1], 0.0]))
    return np.array([g @ r for g in gt])


def fit_pitch_yaw(gt, est, segs):
    """Pitch and yaw (rad) of the ground truth's camera frame minimising est's segment errors."""
    def residual(p):
        e, lengths = errors(rotated(gt, p), est, segs)
        return (e / lengths[:, None]).ravel()

    p = np.zeros(2)
    for _ in range(20):
        r = residual(p)
        jac = np.stack([(residual(p + h) - r) / 1e-6 for h in np.eye(2) * 1e-6], axis=1)
        step = np.linalg.lstsq(jac, -r, rcond=None)[0]
        p += step
        if np.linalg.norm(step) < 1e-10:
            break
    return p


def turned_scores(gt, a, b, segs):
    """The pitch and yaw of the ground truth fitted on B over `segs`, and A's and B's t_err (%)
    against the ground truth so turned."""
    p = fit_pitch_yaw(gt, b, segs)
    g2 = rotated(gt, p)
    return p, t_err(*errors(g2, a, segs)), t_err(*errors(g2, b, segs))


def main():
    ap = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    ap.add_argument("ground_truth")
    ap.add_argument("a")
    ap.add_argument("b")
    ap.add_argument("--lengths", default="10,20,30,40,50")
    ap.add_argument("--split", type=int, help="compare the frames before and after this one")
    args = ap.parse_args()
    lengths = [float(v) for v in args.lengths.split(",")]
    gt, a, b = load(args.ground_truth), load(args.a), load(args.b)
    n = min(len(gt), len(a), len(b))
    gt, a, b = gt[:n], a[:n], b[:n]
    segs = segments(gt, lengths)
    if not segs:
        raise SystemExit(f"no segment of lengths {args.lengths} m in {n} frames")
    ea, ls = errors(gt, a, segs)
    eb, _ = errors(gt, b, segs)
    print(f"{len(segs)} segments, lengths {args.lengths} m, {n} frames")
    print(f"t_err %: A {t_err(ea, ls):.4f}  B {t_err(eb, ls):.4f}  "
          f"shared (A+B)/2 {t_err((ea + eb) / 2, ls):.4f}  A - B {t_err(ea - eb, ls):.4f}")
    for axis, name in enumerate("xyz"):
        c = np.corrcoef(ea[:, axis], eb[:, axis])[0, 1]
        print(f"axis {name}: correlation {c:.3f}, mean error A {ea[:, axis].mean():+.4f} m, "
              f"B {eb[:, axis].mean():+.4f} m")
    p, ta, tb = turned_scores(gt, a, b, segs)
    print(f"pitch, yaw of the ground truth fitted on B: {np.degrees(p[0]):+.4f}, "
          f"{np.degrees(p[1]):+.4f} deg; t_err % against the rotated ground truth: "
          f"A {ta:.4f}  B {tb:.4f}")
    wa, wb = rotation_errors(gt, a, segs), rotation_errors(gt, b, segs)
    print(f"r_err deg/100 m: A {r_err(wa, ls):.4f}  B {r_err(wb, ls):.4f}  "
          f"shared (A+B)/2 {r_err((wa + wb) / 2, ls):.4f}  A - B {r_err(wa - wb, ls):.4f}")
    for axis, name in enumerate(["x (pitch)", "y (yaw)", "z (roll)"]):
        c = np.corrcoef(wa[:, axis], wb[:, axis])[0, 1]
        rms = lambda w: np.degrees(np.sqrt(np.mean(w[:, axis] ** 2)))  # noqa: E731
        only = np.zeros(3)
        only[axis] = 1.0
        print(f"axis {name}: correlation {c:.3f}, rms error A {rms(wa):.4f} deg, "
              f"B {rms(wb):.4f} deg; A's r_err without B's error about it "
              f"{r_err(wa - wb * only, ls):.4f}, "
              f"without any about it {r_err(wa * (1 - only), ls):.4f}")
    if args.split is not None:
        split_report(gt, a, b, segs, args.split)


def split_report(gt, a, b, segs, k):
    """The `--split` comparison (module docs)."""
    if not 0 < k < len(gt) - 1:
        raise SystemExit(f"--split {k}: must lie inside the {len(gt)} frames")

    def steps(poses):
        return np.degrees([log_rotation((np.linalg.inv(poses[i]) @ poses[i + 1])[:3, :3])
                           for i in range(len(poses) - 1)])

    sg, sa, sb = steps(gt), steps(a), steps(b)
    for axis, name in enumerate(["pitch", "yaw", "roll"]):
        for lo, hi in ((0, k), (k, len(sg))):
            part = slice(lo, hi)
            rms = lambda d: np.sqrt(np.mean(d[part, axis] ** 2))  # noqa: E731
            print(f"{name} frames {lo}-{hi}: rms a frame A - truth {rms(sa - sg):.4f}, "
                  f"B - truth {rms(sb - sg):.4f}, A - B {rms(sa - sb):.4f} deg; summed: truth "
                  f"{sg[part, axis].sum():+.3f}, A {sa[part, axis].sum():+.3f}, "
                  f"B {sb[part, axis].sum():+.3f} deg")
    later = [seg for seg in segs if seg[0] >= k]
    if later:
        ea, ls = errors(gt, a, later)
        eb, _ = errors(gt, b, later)
        wa, wb = rotation_errors(gt, a, later), rotation_errors(gt, b, later)
        print(f"the {len(later)} segments starting at frame {k} or later: t_err % / r_err "
              f"deg/100 m A {t_err(ea, ls):.4f} / {r_err(wa, ls):.4f}, "
              f"B {t_err(eb, ls):.4f} / {r_err(wb, ls):.4f}")
        p, ta, tb = turned_scores(gt, a, b, later)
        print(f"  the same against the ground truth turned by the pitch, yaw fitted on B over "
              f"them ({np.degrees(p[0]):+.3f}, {np.degrees(p[1]):+.3f} deg): t_err % "
              f"A {ta:.4f}  B {tb:.4f}")


if __name__ == "__main__":
    main()
