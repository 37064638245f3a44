"""visnav.run_odometry and the frame-by-frame classes against `visnav odometry`."""

import json
from pathlib import Path

import numpy as np
import pytest

import visnav

from conftest import assert_equals_kitti_text, read_kitti


@pytest.fixture(scope="module")
def stereo06(kitti06: Path) -> np.ndarray:
    return visnav.run_odometry(kitti06, "stereo")


def test_stereo_run_equals_the_cli(kitti06: Path, stereo06: np.ndarray, cli, tmp_path: Path) -> None:
    out = tmp_path / "06.txt"
    cli("odometry", "--mode", "stereo", kitti06, "-o", out, "--json", tmp_path / "r.json")
    assert stereo06.shape == (51, 4, 4) and stereo06.dtype == np.float64
    assert_equals_kitti_text(stereo06, out)
    np.testing.assert_allclose(stereo06, read_kitti(out), rtol=0, atol=1e-7)
    report = json.loads((tmp_path / "r.json").read_text())
    assert report["frames"] == 51
    # the run moved: KITTI 06 drives about 60 m in these 51 frames
    assert 40.0 < np.linalg.norm(stereo06[-1, :3, 3]) < 80.0


def test_python_stereo_loop_equals_run_odometry(kitti06: Path, stereo06: np.ndarray) -> None:
    seq = visnav.open_sequence(kitti06)
    vo = visnav.StereoOdometry(seq.camera)
    poses = []
    for frame in seq:
        r = vo.process(frame.left, frame.right, frame.timestamp)
        assert r.world_from_cam.shape == (4, 4) and r.world_from_cam.dtype == np.float64
        assert r.status in ("ok", "low_parallax", "fallback", "skipped")
        assert "stereo.tracking_ms" in r.timings and r.timings["total_ms"] > 0.0
        poses.append(r.world_from_cam)
    np.testing.assert_array_equal(np.stack(poses), stereo06)
    np.testing.assert_array_equal(vo.trajectory(), stereo06)


def test_stereo_covariances_match_the_report_and_the_frames(kitti06: Path, cli, tmp_path: Path) -> None:
    poses, cov = visnav.run_odometry(kitti06, "stereo", max_frames=8, covariance=True)
    assert poses.shape == (8, 4, 4) and cov.shape == (8, 6, 6) and cov.dtype == np.float64
    cli("odometry", "--mode", "stereo", kitti06, "-o", tmp_path / "p.txt", "--json", tmp_path / "r.json",
        "--max-frames", "8")
    frames = json.loads((tmp_path / "r.json").read_text())["per_frame"]
    for k, f in enumerate(frames):
        if f["prev_from_cur_covariance"] is None:
            assert np.isnan(cov[k]).all()
        else:
            np.testing.assert_array_equal(cov[k], np.array(f["prev_from_cur_covariance"]))
    # the first frame has no step; every later one of this clean clip is estimated
    assert np.isnan(cov[0]).all() and not np.isnan(cov[1:]).any()
    assert all(np.all(np.linalg.eigvalsh(c) > 0) for c in cov[1:])
    seq = visnav.open_sequence(kitti06)
    vo = visnav.StereoOdometry(seq.camera)
    for k, frame in zip(range(8), seq):
        r = vo.process(frame.left, frame.right, frame.timestamp)
        if k == 0:
            assert r.prev_from_cur_covariance is None
        else:
            np.testing.assert_array_equal(r.prev_from_cur_covariance, cov[k])


def test_mono_run_equals_the_cli_and_the_python_loop(kitti00: Path, cli, tmp_path: Path) -> None:
    poses = visnav.run_odometry(kitti00, "mono", camera_height=1.7, max_frames=20)
    out = tmp_path / "00.txt"
    cli("odometry", "--mode", "mono", kitti00, "--camera-height", "1.7", "--max-frames", "20", "-o", out)
    assert poses.shape == (20, 4, 4)
    assert_equals_kitti_text(poses, out)
    # the synchronous Python loop gives the poses of the CLI's pipelined run
    seq = visnav.open_sequence(kitti00)
    vo = visnav.MonoOdometry(seq.camera, camera_height=1.7)
    loop = np.stack([vo.process(seq[i].left).world_from_cam for i in range(20)])
    np.testing.assert_allclose(loop, poses, rtol=0, atol=1e-9)
    assert np.linalg.norm(poses[-1, :3, 3]) > 5.0  # KITTI 00 drives ~14 m in 20 frames


def test_realtime_preset_equals_the_cli(kitti00: Path, cli, tmp_path: Path) -> None:
    poses = visnav.run_odometry(kitti00, "mono", camera_height=1.7, max_frames=12, preset="realtime")
    out = tmp_path / "rt.txt"
    cli("odometry", "--mode", "mono", kitti00, "--camera-height", "1.7", "--max-frames", "12",
        "--preset", "realtime", "-o", out)
    assert_equals_kitti_text(poses, out)
    seq = visnav.open_sequence(kitti00)
    vo = visnav.MonoOdometry(seq.camera, camera_height=1.7, preset="realtime")
    loop = np.stack([vo.process(seq[i].left).world_from_cam for i in range(12)])
    np.testing.assert_allclose(loop, poses, rtol=0, atol=1e-9)
    paper = visnav.run_odometry(kitti00, "mono", camera_height=1.7, max_frames=12)
    assert not np.array_equal(paper, poses)  # another flow: other (close) poses
    assert np.linalg.norm(poses[-1, :3, 3] - paper[-1, :3, 3]) < 0.5
    with pytest.raises(ValueError, match="preset"):
        visnav.run_odometry(kitti00, "mono", preset="fastest")


def test_config_dict_file_and_cli_agree(kitti06: Path, cli, tmp_path: Path) -> None:
    toml = tmp_path / "stereo.toml"
    toml.write_text('outlier = "re"\n')
    from_dict = visnav.run_odometry(kitti06, "stereo", config={"outlier": "re"}, max_frames=12)
    from_file = visnav.run_odometry(kitti06, "stereo", config=str(toml), max_frames=12)
    np.testing.assert_array_equal(from_dict, from_file)
    out = tmp_path / "re.txt"
    cli("odometry", "--mode", "stereo", kitti06, "--config", toml, "--max-frames", "12", "-o", out)
    assert_equals_kitti_text(from_dict, out)
    default = visnav.run_odometry(kitti06, "stereo", max_frames=12)
    assert not np.array_equal(default, from_dict)  # the configuration took effect
    seq = visnav.open_sequence(kitti06)
    vo = visnav.StereoOdometry(seq.camera, config={"outlier": "re"})
    loop = np.stack([vo.process(seq[i].left, seq[i].right).world_from_cam for i in range(12)])
    np.testing.assert_array_equal(loop, from_dict)


def test_bad_input_raises(kitti06: Path, tmp_path: Path) -> None:
    seq = visnav.open_sequence(kitti06)
    mono_cam = visnav.Camera(700.0, 700.0, 600.0, 180.0, 1226, 370)
    with pytest.raises(ValueError, match="baseline"):
        visnav.StereoOdometry(mono_cam)
    with pytest.raises(ValueError):
        visnav.Camera(-1.0, 700.0, 600.0, 180.0, 1226, 370)
    vo = visnav.StereoOdometry(seq.camera)
    with pytest.raises(ValueError, match="right"):
        vo.process(seq[0].left)
    with pytest.raises(ValueError, match="H×W"):
        vo.process(np.zeros((4, 4, 3)), np.zeros((4, 4, 3)))
    with pytest.raises(ValueError, match="right image"):
        vo.process(seq[0].left, seq[0].left[:, :100])
    with pytest.raises(ValueError, match="mode"):
        visnav.run_odometry(kitti06, "sideways")
    with pytest.raises(ValueError, match="camera_height"):
        visnav.run_odometry(kitti06, "stereo", camera_height=1.7)
    with pytest.raises(FileNotFoundError, match="missing.toml"):
        visnav.run_odometry(kitti06, "stereo", config=str(tmp_path / "missing.toml"))
    with pytest.raises(ValueError, match="unknown field"):
        visnav.StereoOdometry(seq.camera, config={"no_such_key": 1})
    bad = tmp_path / "bad.toml"
    bad.write_text("outlier = [\n")
    with pytest.raises(ValueError, match="bad.toml"):
        visnav.run_odometry(kitti06, "stereo", config=str(bad))
    with pytest.raises(FileNotFoundError):
        visnav.run_odometry(tmp_path / "nothing", "mono")
    with pytest.raises(ValueError, match="one image"):
        visnav.MonoOdometry(seq.camera).process(seq[0].left, seq[0].right)
