"""visnav.open_sequence: length, indexing, iteration, frames and camera; errors."""

from pathlib import Path

import numpy as np
import pytest

import visnav


def test_kitti_stereo_sequence(kitti06: Path) -> None:
    seq = visnav.open_sequence(kitti06)
    assert len(seq) == 51
    assert seq.has_stereo
    cam = seq.camera
    assert (cam.width, cam.height) == (1226, 370)
    # baseline = -P1[0][3] / P1[0][0] (the data README: 0.537 m)
    assert cam.baseline_m == pytest.approx(0.537, abs=1e-3)
    last = seq[-1]
    assert last.index == 50
    assert seq[50].index == 50
    assert last.left.dtype == np.uint8 and last.left.shape == (370, 1226)
    assert last.right is not None and last.right.shape == (370, 1226)
    # KITTI times.txt is relative: no dataset timestamps
    assert last.timestamp is None
    # the pixels are the PNG's (KITTI images are 8-bit grey: exact)
    png = visnav.load_image(kitti06 / "image_0" / "000050.png")
    np.testing.assert_array_equal(png, last.left.astype(np.float32))
    np.testing.assert_array_equal(last.left_f32, png)
    assert not np.array_equal(seq[0].left, seq[1].left)
    with pytest.raises(IndexError):
        seq[51]
    with pytest.raises(IndexError):
        seq[-52]


def test_iteration_yields_every_frame_in_order(kitti06: Path) -> None:
    seq = visnav.open_sequence(kitti06)
    indices = [f.index for f in seq]
    assert indices == list(range(51))


def test_euroc_has_timestamps_and_a_stereo_rig(data: Path) -> None:
    seq = visnav.open_sequence(data / "euroc" / "V1_01_easy_first40")
    assert len(seq) == 40
    assert seq.has_stereo and seq.camera.baseline_m is not None
    ts = [seq[i].timestamp for i in (0, 1)]
    assert ts[0] is not None and ts[1] is not None
    assert 0.0 < ts[1] - ts[0] < 0.2  # 20 Hz camera
    np.testing.assert_allclose(seq.timestamps[:2], ts)


def test_missing_paths_raise_file_not_found(tmp_path: Path) -> None:
    with pytest.raises(FileNotFoundError, match="nowhere"):
        visnav.open_sequence(tmp_path / "nowhere")
    with pytest.raises(FileNotFoundError, match="nope.png"):
        visnav.load_image(tmp_path / "nope.png")


def test_a_folder_without_camera_is_a_value_error(tmp_path: Path) -> None:
    (tmp_path / "junk.txt").write_text("not a sequence\n")
    with pytest.raises((ValueError, FileNotFoundError)):
        visnav.open_sequence(tmp_path)
