"""Middlebury `.flo` reading shared by the scripts (numpy only)."""

import struct

import numpy as np


def read_flo(path):
    """The flow `(h, w, 2)` as float64 and the mask of its known pixels (unknown: |u| or |v| >= 1e9)."""
    with open(path, "rb") as f:
        magic = struct.unpack("<f", f.read(4))[0]
        if abs(magic - 202021.25) > 1e-3:
            raise ValueError(f"{path}: bad .flo magic")
        w, h = struct.unpack("<ii", f.read(8))
        raw = f.read(8 * w * h)
        if len(raw) != 8 * w * h:
            raise ValueError(f"{path}: {len(raw) // 8} of {w}x{h} flow vectors")
        data = np.frombuffer(raw, dtype="<f4").reshape(h, w, 2)
    known = (np.abs(data) < 1e9).all(axis=2) & np.isfinite(data).all(axis=2)
    return data.astype(np.float64), known
