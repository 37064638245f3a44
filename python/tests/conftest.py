"""Shared fixtures: the data directory (VISNAV_DATA), the visnav CLI binary (VISNAV_BIN), and
helpers to run it and read its outputs.

Data tests skip when VISNAV_DATA is not set, and fail instead when VISNAV_REQUIRE_DATA=1 (CI).
Tests that compare with the CLI need VISNAV_BIN (scripts/test.sh sets it); without it they look
for target/release/visnav, and skip (fail under VISNAV_REQUIRE_DATA=1) when it is missing.
"""

from __future__ import annotations

import os
import struct
import subprocess
from pathlib import Path

import numpy as np
import pytest

REPO = Path(__file__).resolve().parents[2]


def _require() -> bool:
    return os.environ.get("VISNAV_REQUIRE_DATA") == "1"


def _missing(what: str) -> None:
    if _require():
        pytest.fail(f"{what} (VISNAV_REQUIRE_DATA=1)")
    pytest.skip(what)


@pytest.fixture(scope="session")
def data() -> Path:
    root = os.environ.get("VISNAV_DATA")
    if not root:
        _missing("VISNAV_DATA is not set")
    path = Path(root).resolve()
    if not (path / "kitti" / "odometry").is_dir():
        _missing(f"VISNAV_DATA={root} has no kitti/odometry")
    return path


@pytest.fixture(scope="session")
def kitti06(data: Path) -> Path:
    return data / "kitti" / "odometry" / "sequences" / "06"


@pytest.fixture(scope="session")
def kitti00(data: Path) -> Path:
    return data / "kitti" / "odometry" / "sequences" / "00"


@pytest.fixture(scope="session")
def visnav_bin() -> Path:
    given = os.environ.get("VISNAV_BIN")
    candidates = [Path(given)] if given else []
    target = os.environ.get("CARGO_TARGET_DIR", str(REPO / "target"))
    candidates.append(Path(target) / "release" / "visnav")
    for c in candidates:
        if c.is_file() and os.access(c, os.X_OK):
            return c
    _missing(f"no visnav CLI binary (set VISNAV_BIN; tried {', '.join(map(str, candidates))})")
    raise AssertionError("unreachable")


@pytest.fixture(scope="session")
def cli(visnav_bin: Path):
    """Runs `visnav -q ARGS...` and returns its completed process (asserting success)."""

    def run(*args: object, check: bool = True) -> subprocess.CompletedProcess[str]:
        cmd = [str(visnav_bin), "-q", *map(str, args)]
        p = subprocess.run(cmd, capture_output=True, text=True)
        if check:
            assert p.returncode == 0, f"{cmd} failed ({p.returncode}): {p.stderr}"
        return p

    return run


def read_kitti(path: Path) -> np.ndarray:
    """A KITTI trajectory file as (N, 4, 4) float64."""
    rows = np.loadtxt(path, ndmin=2).reshape(-1, 3, 4)
    out = np.tile(np.eye(4), (rows.shape[0], 1, 1))
    out[:, :3, :] = rows
    return out


def assert_equals_kitti_text(poses: np.ndarray, path: Path) -> None:
    """`poses` printed as the CLI prints them (`{:.9e}`, 10 significant digits, correctly
    rounded in both languages) are the numbers of `path`: equal to the precision written."""
    written = np.loadtxt(path, ndmin=2)
    assert written.shape == (poses.shape[0], 12), (written.shape, poses.shape)
    rounded = np.vectorize(lambda x: float(f"{x:.9e}"))(poses[:, :3, :].reshape(-1, 12))
    np.testing.assert_array_equal(rounded, written)
    np.testing.assert_array_equal(poses[:, 3, :], np.tile([0.0, 0.0, 0.0, 1.0], (len(poses), 1)))


def read_flo(path: Path) -> np.ndarray:
    """A Middlebury .flo file as HxWx2 float32."""
    raw = path.read_bytes()
    magic, w, h = struct.unpack("<fii", raw[:12])
    assert magic == 202021.25
    return np.frombuffer(raw[12:], dtype="<f4").reshape(h, w, 2)


def read_pfm(path: Path) -> np.ndarray:
    """A PFM file as HxWxC float32, top row first (the file stores rows bottom to top)."""
    raw = path.read_bytes()
    parts = raw.split(b"\n", 3)
    channels = 3 if parts[0].strip() == b"PF" else 1
    w, h = map(int, parts[1].split())
    scale = float(parts[2])
    dtype = "<f4" if scale < 0 else ">f4"
    data = np.frombuffer(parts[3], dtype=dtype).reshape(h, w, channels)
    return data[::-1].astype(np.float32)
