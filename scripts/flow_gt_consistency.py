#!/usr/bin/env python3
"""How far the ground truth itself limits the flow-uncertainty figures of `visnav flow-eval`.

Usage:
    pip install opencv-python-headless numpy
    python3 scripts/flow_gt_consistency.py DATASET_DIR [DATASET_DIR ...] [--visnav target/release/visnav]

For every pair (Middlebury or KITTI layout, as for `visnav flow-eval`) it runs `visnav flow` (flow
and information matrix) and OpenCV's DIS (medium preset) and Farneback, then looks at the pixels
where two independent methods, visnav and DIS, agree to within 0.05 px. Where they agree, both are
most likely right, so the ground truth's difference from them there is mostly the ground truth's
own error. Per pair it prints:

* `agree`: the share of pixels with ground truth where visnav and DIS agree;
* `offset` and `spread`: the median and the robust (MAD) standard deviation, per axis, of
  visnav minus ground truth on those pixels, px;
* `floor/mean`: their mean end-point error over the pair's mean end-point error. The 50 % most
  certain pixels cannot be expected to do much better than this ratio, however well the
  uncertainty ranks visnav's own errors;
* `consensus`: the share of pixels where visnav, DIS and Farneback agree with each other to within
  0.2 px but all differ from the ground truth by more than 0.5 px (a moving object in a
  static-scene ground truth, for instance), and their mean error vector;
* `1s/2s`: the shares of ground truth inside visnav's 1- and 2-sigma ellipses as `flow-eval`
  computes them, then with the ground truth's own spread (the `spread` above) added to visnav's
  covariance: a diagnostic of how much of the shortfall is the reference's, not a figure to
  report as visnav's calibration.
"""

import argparse
import os
import subprocess
import sys
import tempfile

import numpy as np

sys.path.insert(0, os.path.dirname(os.path.abspath(__file__)))
from compare_flow_opencv import pairs, read_flo  # noqa: E402

try:
    import cv2
except ImportError:  # pragma: no cover
    sys.exit("needs OpenCV: pip install opencv-python-headless")


def read_pfm(path):
    with open(path, "rb") as f:
        if f.readline().strip() != b"PF":
            raise ValueError(f"{path}: not a 3-channel PFM")
        w, h = map(int, f.readline().split())
        scale = float(f.readline())
        if scale >= 0:
            raise ValueError(f"{path}: not little-endian")
        data = np.frombuffer(f.read(12 * w * h), dtype="<f4").reshape(h, w, 3)
    return data[::-1].astype(np.float64)  # PFM rows run bottom to top


def shares(err, info, extra_var=(0.0, 0.0)):
    """Shares (percent) of errors inside the 1- and 2-sigma ellipses of the information matrices,
    optionally with a diagonal variance added to each covariance."""
    a, b, c = info[:, 0], info[:, 1], info[:, 2]
    det = a * c - b * b
    cxx, cxy, cyy = c / det + extra_var[0], -b / det, a / det + extra_var[1]
    det2 = cxx * cyy - cxy * cxy
    u, v = err[:, 0], err[:, 1]
    d2 = (cyy * u * u - 2 * cxy * u * v + cxx * v * v) / det2
    return 100.0 * (d2 <= 1).mean(), 100.0 * (d2 <= 4).mean()


def main():
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("datasets", nargs="+")
    ap.add_argument("--visnav", default="target/release/visnav")
    args = ap.parse_args()
    dis = cv2.DISOpticalFlow_create(cv2.DISOPTICAL_FLOW_PRESET_MEDIUM)
    print(
        f"{'pair':<12} {'agree':>6} {'offset u,v':>15} {'spread u,v':>13} {'floor/mean':>10} "
        f"{'consensus':>9} {'its error u,v':>15} {'1s/2s':>11} {'+GT spread':>11}"
    )
    with tempfile.TemporaryDirectory() as tmp:
        for root in args.datasets:
            for name, p1, p2, (gt, known) in pairs(root):
                flo, pfm = os.path.join(tmp, "f.flo"), os.path.join(tmp, "i.pfm")
                subprocess.run(
                    [args.visnav, "flow", p1, p2, "-o", flo, "--information", pfm, "-q"], check=True
                )
                ours, _ = read_flo(flo)
                info = read_pfm(pfm)
                g1, g2 = cv2.imread(p1, cv2.IMREAD_GRAYSCALE), cv2.imread(p2, cv2.IMREAD_GRAYSCALE)
                fd = dis.calc(g1, g2, None).astype(np.float64)
                ff = cv2.calcOpticalFlowFarneback(g1, g2, None, 0.5, 5, 15, 5, 7, 1.5, 0).astype(np.float64)
                dist = lambda a, b: np.linalg.norm(a - b, axis=2)  # noqa: E731
                err = ours - gt
                epe = np.linalg.norm(err, axis=2)
                agree = known & (dist(ours, fd) < 0.05)
                e_ag = err[agree]
                offset = np.median(e_ag, axis=0)
                spread = 1.4826 * np.median(np.abs(e_ag - offset), axis=0)
                floor = epe[agree].mean() / epe[known].mean()
                consensus = (
                    known
                    & (dist(ours, fd) < 0.2)
                    & (dist(ours, ff) < 0.2)
                    & (dist(fd, ff) < 0.2)
                    & (epe > 0.5)
                )
                c_err = err[consensus].mean(axis=0) if consensus.any() else np.zeros(2)
                s1, s2 = shares(err[known], info[known])
                g1s, g2s = shares(err[known], info[known], tuple(spread**2))
                print(
                    f"{name:<12} {100 * agree.sum() / known.sum():5.1f}% "
                    f"{offset[0]:+7.3f},{offset[1]:+7.3f} {spread[0]:6.3f},{spread[1]:6.3f} "
                    f"{floor:10.2f} {100 * consensus.sum() / known.sum():8.2f}% "
                    f"{c_err[0]:+7.3f},{c_err[1]:+7.3f} {s1:5.1f}/{s2:5.1f} {g1s:5.1f}/{g2s:5.1f}"
                )


if __name__ == "__main__":
    main()
