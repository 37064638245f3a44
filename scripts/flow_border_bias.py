#!/usr/bin/env python3
"""How much of the true flow `visnav flow` finds, by distance from the image border.

On a rendered sequence (`visnav synth ...`: `image_0/` and the exact flow `flow/NNNNNN.flo`
from frame N to N+1), every chosen pair's flow is computed with a flow configuration and
compared with the truth: per pixel the projection of the estimate on the true flow,
`r = f . g / |g|^2` (1 = the whole flow, 0.95 = 5 % short along the true direction), with
pixels whose true target leaves the image and true flows under 1 px left out. The median of
`r` is printed by distance from the nearest image border and by the true flow's length.

    python3 scripts/flow_border_bias.py SEQ FLOW_CONFIG.toml 40,120,200 [--visnav PATH] [--keep DIR]

A flow that falls short near the border shortens a forward flight's scale: every point moves
outwards along such a flight (docs/notes/2026-12-02-aerial-history.md, rounds 6 and 8).

`--inset N` measures the distances from a rectangle N pixels inside the image instead of from
its border, and keeps only the pixels inside it whose true target stays inside it. On a flight
rendered 2N pixels wider and higher than another (`visnav synth` keeps KITTI's horizontal field
of view, so the focal length grows a little with the width) the rectangle sees nearly the other
render's field of view, but with real image content beyond its border: is a shortfall the image
border's, or the scene's at those pixels?
"""

import argparse
import os
import subprocess
import sys
import tempfile

import numpy as np

from flo import read_flo

BANDS = [0, 5, 10, 25, 50, 100000]
LENGTHS = [1.0, 3.0, 6.0, 12.0, 1e9]


def ratios(est, truth, inset=0):
    """Per-pixel `r`, the border distance and the true length of the usable pixels
    (`est`, `truth`: `read_flo`'s flow and known mask); distances from the rectangle `inset`
    pixels inside the image, whose pixels with a target inside it are the usable ones."""
    (est, est_known), (truth, truth_known) = est, truth
    h, w, _ = truth.shape
    yy, xx = np.mgrid[0:h, 0:w]
    xi, yi, wi, hi = xx - inset, yy - inset, w - 2 * inset, h - 2 * inset
    edge = np.minimum(np.minimum(xi, wi - 1 - xi), np.minimum(yi, hi - 1 - yi))
    tx, ty = xi + truth[..., 0], yi + truth[..., 1]
    inside = (edge >= 0) & (tx >= 0) & (ty >= 0) & (tx <= wi - 1) & (ty <= hi - 1)
    known = est_known & truth_known & inside
    n2 = (truth**2).sum(axis=2)
    use = known & (n2 >= 1.0)
    r = (est * truth).sum(axis=2) / np.where(use, n2, 1.0)
    return r[use], edge[use], np.sqrt(n2[use])


def table(samples):
    r = np.concatenate([s[0] for s in samples])
    edge = np.concatenate([s[1] for s in samples])
    length = np.concatenate([s[2] for s in samples])
    head = " | ".join(f"{a:g}-{b:g} px" if b < 1e9 else f">= {a:g} px" for a, b in zip(LENGTHS, LENGTHS[1:]))
    print(f"| border distance | all | {head} |")
    print("| --- " * (len(LENGTHS) + 1) + "|")
    for a, b in zip(BANDS, BANDS[1:]):
        band = (edge >= a) & (edge < b)
        cells = [f"{np.median(r[band]):.3f} ({band.sum()})" if band.sum() > 50 else "-"]
        for la, lb in zip(LENGTHS, LENGTHS[1:]):
            m = band & (length >= la) & (length < lb)
            cells.append(f"{np.median(r[m]):.3f}" if m.sum() > 50 else "-")
        name = f"{a}-{b} px" if b < 100000 else f">= {a} px"
        print(f"| {name} | " + " | ".join(cells) + " |")


def main():
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("sequence")
    ap.add_argument("config", help="flow configuration (TOML, as `visnav flow --config` reads it)")
    ap.add_argument("frames", help="comma-separated first frames of the pairs, e.g. 40,120,200")
    ap.add_argument("--visnav", default="visnav", help="the visnav binary (default: on PATH)")
    ap.add_argument("--keep", help="directory for the computed .flo files (default: a temporary one)")
    ap.add_argument("--inset", type=int, default=0,
                    help="distances from a rectangle this many pixels inside the image (default 0)")
    a = ap.parse_args()
    if a.inset < 0:
        sys.exit(f"--inset {a.inset}: must be >= 0")
    try:
        frames = [int(v) for v in a.frames.split(",")]
    except ValueError:
        sys.exit(f"frames: expected comma-separated frame numbers, got {a.frames!r}")
    out = a.keep or tempfile.mkdtemp(prefix="flow_border_")
    os.makedirs(out, exist_ok=True)
    samples = []
    for i in frames:
        im1 = os.path.join(a.sequence, "image_0", f"{i:06d}.png")
        im2 = os.path.join(a.sequence, "image_0", f"{i + 1:06d}.png")
        truth = os.path.join(a.sequence, "flow", f"{i:06d}.flo")
        for p in (im1, im2, truth):
            if not os.path.exists(p):
                sys.exit(f"{p}: missing (is {a.sequence} a sequence rendered by `visnav synth`?)")
        est = os.path.join(out, f"{i:06d}.flo")
        cmd = [a.visnav, "flow", im1, im2, "-o", est, "--config", a.config, "-q"]
        subprocess.run(cmd, check=True)
        samples.append(ratios(read_flo(est), read_flo(truth), a.inset))
    print(f"median share of the true flow found, {len(frames)} pairs of {a.sequence} ({a.config})")
    table(samples)


if __name__ == "__main__":
    main()
