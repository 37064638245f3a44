"""scripts/shared_error.py's rotation analysis on trajectories with a known answer: two
estimators that see the same motion, against a reference whose first frames turn at a constant
rate instead (the KITTI 06 clip's case, docs/notes/2026-12-02-stereo-history.md,
*The rotation, axis by axis*)."""

import importlib.util
import re
import subprocess
import sys

import numpy as np

from conftest import REPO

SCRIPT = REPO / "scripts" / "shared_error.py"


def _module():
    spec = importlib.util.spec_from_file_location("shared_error", SCRIPT)
    mod = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(mod)
    return mod


def _yaw(deg: float) -> np.ndarray:
    c, s = np.cos(np.radians(deg)), np.sin(np.radians(deg))
    return np.array([[c, 0.0, s], [0.0, 1.0, 0.0], [-s, 0.0, c]])


def _chain(yaw_steps_deg, step_m=1.2) -> np.ndarray:
    """world_from_cam poses of a camera moving `step_m` forward a frame and turning by the steps."""
    poses = [np.eye(4)]
    for d in yaw_steps_deg:
        step = np.eye(4)
        step[:3, :3] = _yaw(d)
        step[2, 3] = step_m
        poses.append(poses[-1] @ step)
    return np.array(poses)


def _write(path, poses):
    np.savetxt(path, poses[:, :3, :].reshape(len(poses), 12), fmt="%.9e")


def _trajectories(tmp_path):
    rng = np.random.default_rng(3)
    n = 50
    seen = np.full(n, -0.04)
    seen[:10] = [0.1, 0.08, 0.06, 0.05, 0.05, 0.05, 0.05, 0.0, -0.07, -0.13]  # what the cameras see
    truth = np.full(n, -0.04)  # the reference's first frames: a constant rate
    paths = []
    for name, steps in (
        ("gt", truth),
        ("a", seen + rng.normal(0.0, 0.005, n)),
        ("b", seen + rng.normal(0.0, 0.005, n)),
    ):
        p = tmp_path / f"{name}.txt"
        _write(p, _chain(steps))
        paths.append(p)
    return paths


def test_log_rotation_gives_the_angle_and_axis():
    se = _module()
    w = se.log_rotation(_yaw(0.3))
    assert np.allclose(w, [0.0, np.radians(0.3), 0.0], atol=1e-12)
    assert np.allclose(se.log_rotation(np.eye(3)), 0.0)


def test_the_split_tells_a_reference_glitch_from_the_estimators(tmp_path):
    se = _module()
    gt_path, a_path, b_path = _trajectories(tmp_path)
    gt, a, b = se.load(gt_path), se.load(a_path), se.load(b_path)
    segs = se.segments(gt, [10.0, 20.0, 30.0])
    wa, wb = se.rotation_errors(gt, a, segs), se.rotation_errors(gt, b, segs)
    lengths = np.array([s[2] for s in segs])
    # the shared part is about the yaw axis, and the two agree there
    assert np.corrcoef(wa[:, 1], wb[:, 1])[0, 1] > 0.9
    later = [s for s in segs if s[0] >= 10]
    wl = se.rotation_errors(gt, a, later)
    ll = np.array([s[2] for s in later])
    assert se.r_err(wl, ll) < 0.2 * se.r_err(wa, lengths)
    # identical trajectories score zero
    assert se.r_err(se.rotation_errors(gt, gt, segs), lengths) < 1e-9
    out = subprocess.run(
        [sys.executable, str(SCRIPT), str(gt_path), str(a_path), str(b_path),
         "--lengths", "10,20,30", "--split", "10"],
        check=True, capture_output=True, text=True,
    ).stdout
    yaw_first = next(line for line in out.splitlines() if line.startswith("yaw frames 0-10"))
    # "rms a frame A - truth X, B - truth Y, A - B Z deg": the estimators agree, the truth differs
    rms_part = yaw_first.split("rms a frame")[1].split("summed")[0]
    a_truth, b_truth, a_b = (float(v) for v in re.findall(r"\d+\.\d+", rms_part))
    assert a_b < 0.25 * min(a_truth, b_truth)
    assert "segments starting at frame 10 or later" in out
