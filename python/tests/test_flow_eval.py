"""visnav.dense_flow against `visnav flow`'s files; visnav.kitti_errors against `visnav eval`."""

import json
from pathlib import Path

import numpy as np
import pytest

import visnav

from conftest import read_flo, read_kitti, read_pfm


def test_dense_flow_is_bit_identical_to_the_cli(data: Path, cli, tmp_path: Path) -> None:
    d = data / "flow" / "kitti2012" / "training" / "image_0"
    a, b = d / "000045_10.png", d / "000045_11.png"
    cli("flow", a, b, "-o", tmp_path / "f.flo", "--information", tmp_path / "i.pfm")
    f = visnav.dense_flow(visnav.load_image(a), visnav.load_image(b))
    assert f.flow.shape == (376, 1241, 2) and f.flow.dtype == np.float32
    assert f.information.shape == (376, 1241, 3) and f.information.dtype == np.float32
    assert f.valid.shape == (376, 1241) and f.valid.dtype == np.bool_
    np.testing.assert_array_equal(f.flow, read_flo(tmp_path / "f.flo"))
    np.testing.assert_array_equal(f.information, read_pfm(tmp_path / "i.pfm"))
    assert 0.3 < f.valid.mean() < 1.0
    # paths are loaded as the CLI loads them; uint8 arrays are the same grey values
    g = visnav.dense_flow(str(a), str(b))
    np.testing.assert_array_equal(g.flow, f.flow)
    # information matrices are symmetric positive definite where the flow is valid
    yxx, yxy, yyy = (f.information[..., k][f.valid] for k in range(3))
    assert np.all(yxx > 0) and np.all(yxx * yyy - yxy * yxy > 0)


def test_fast_dense_flow_is_bit_identical_to_the_cli(data: Path, cli, tmp_path: Path) -> None:
    d = data / "flow" / "kitti2012" / "training" / "image_0"
    a, b = d / "000045_10.png", d / "000045_11.png"
    cli("flow", a, b, "--method", "fast", "-o", tmp_path / "f.flo", "--information", tmp_path / "i.pfm")
    f = visnav.dense_flow(visnav.load_image(a), visnav.load_image(b), method="fast")
    np.testing.assert_array_equal(f.flow, read_flo(tmp_path / "f.flo"))
    np.testing.assert_array_equal(f.information, read_pfm(tmp_path / "i.pfm"))
    paper = visnav.dense_flow(visnav.load_image(a), visnav.load_image(b))
    # two flows of the same pair: close, not the same
    assert 0.05 < float(np.median(np.linalg.norm(f.flow - paper.flow, axis=2))) < 0.5
    # a FastFlowConfig key, and a key of the other method refused
    g = visnav.dense_flow(str(a), str(b), config={"iterations": 8}, method="fast")
    assert not np.array_equal(g.flow, f.flow)
    with pytest.raises(ValueError, match="flow config"):
        visnav.dense_flow(str(a), str(b), config={"scale": 3}, method="fast")
    with pytest.raises(ValueError, match="method"):
        visnav.dense_flow(str(a), str(b), method="fastest")


def test_dense_flow_bad_input() -> None:
    with pytest.raises(ValueError, match="same size"):
        visnav.dense_flow(np.zeros((40, 50), np.uint8), np.zeros((40, 51), np.uint8))
    with pytest.raises(ValueError, match="H×W"):
        visnav.dense_flow(np.zeros((40, 50, 3)), np.zeros((40, 50, 3)))
    with pytest.raises(ValueError, match="not finite"):
        visnav.dense_flow(np.full((40, 50), np.nan), np.zeros((40, 50)))


def test_kitti_errors_equal_visnav_eval(data: Path, cli, tmp_path: Path) -> None:
    ref = data / "kitti" / "odometry" / "reference" / "viso2s_06_first51.txt"
    gt = read_kitti(data / "kitti" / "odometry" / "poses" / "06.txt")[:51]
    est = read_kitti(ref)
    gt_file = tmp_path / "gt.txt"
    np.savetxt(gt_file, gt[:, :3, :].reshape(-1, 12), fmt="%.17g")
    lengths = [10.0, 20.0, 30.0, 40.0, 50.0]
    p = cli("eval", "--json", "--lengths", "10,20,30,40,50", gt_file, ref)
    want = json.loads(p.stdout)
    got = visnav.kitti_errors(gt, est, lengths=lengths)
    for key in ("t_err_percent", "r_err_deg_per_100m", "segments", "ate_se3_m", "ate_sim3_m", "lengths_m"):
        assert got[key] == want[key], key
    # the devkit's figures for this file (data README): 1.0251 %, 2.8211 deg/100 m, 15 segments
    assert round(got["t_err_percent"], 4) == 1.0251
    assert round(got["r_err_deg_per_100m"], 4) == 2.8211
    assert got["segments"] == 15
    # 3x4 input is the same
    again = visnav.kitti_errors(gt[:, :3, :], est[:, :3, :], lengths=lengths)
    assert again["t_err_percent"] == got["t_err_percent"]


def test_kitti_errors_bad_input() -> None:
    with pytest.raises(ValueError, match="N×4×4"):
        visnav.kitti_errors(np.zeros((3, 4)), np.zeros((3, 4, 4)))
    bad = np.tile(np.eye(4), (3, 1, 1))
    bad[1, 0, 3] = np.nan
    with pytest.raises(ValueError, match="not finite"):
        visnav.kitti_errors(np.tile(np.eye(4), (3, 1, 1)), bad)
    with pytest.raises(ValueError):
        visnav.kitti_errors(np.tile(np.eye(4), (3, 1, 1)), np.tile(np.eye(4), (3, 1, 1)), lengths=[-1.0])
