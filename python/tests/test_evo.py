"""evo (an independent trajectory evaluation package) agrees with visnav: its APE after SE(3)
alignment equals visnav's ATE on a visnav KITTI output, and it reads visnav's TUM output."""

import json
from pathlib import Path

import numpy as np
import pytest

import visnav

evo_fi = pytest.importorskip("evo.tools.file_interface")
from evo import main_ape  # noqa: E402
from evo.core import metrics, sync  # noqa: E402


def _ape_rmse(ref, est) -> float:
    result = main_ape.ape(
        ref, est, pose_relation=metrics.PoseRelation.translation_part, align=True, correct_scale=False
    )
    return float(result.stats["rmse"])


def test_evo_ape_equals_visnav_ate_on_kitti_06(data: Path, kitti06: Path, cli, tmp_path: Path) -> None:
    est_file = tmp_path / "06.txt"
    cli("odometry", "--mode", "stereo", kitti06, "-o", est_file)
    gt = np.loadtxt(data / "kitti" / "odometry" / "poses" / "06.txt")[:51]
    gt_file = tmp_path / "gt06.txt"
    np.savetxt(gt_file, gt, fmt="%.17g")
    ours = json.loads(cli("eval", "--json", gt_file, est_file).stdout)["ate_se3_m"]
    evo_rmse = _ape_rmse(evo_fi.read_kitti_poses_file(str(gt_file)), evo_fi.read_kitti_poses_file(str(est_file)))
    assert ours > 0.0
    assert abs(evo_rmse - ours) < 1e-6, (evo_rmse, ours)
    # and the Python API's score is the same
    est = visnav.run_odometry(kitti06, "stereo")
    gt44 = np.tile(np.eye(4), (51, 1, 1))
    gt44[:, :3, :] = gt.reshape(-1, 3, 4)
    assert abs(visnav.kitti_errors(gt44, est)["ate_se3_m"] - evo_rmse) < 1e-6


def test_evo_reads_the_tum_output_of_a_euroc_run(data: Path, cli, tmp_path: Path) -> None:
    euroc = data / "euroc" / "V1_01_easy_first40"
    out = tmp_path / "v101.txt"
    cli("odometry", "--mode", "stereo", euroc, "-o", out)
    tum = tmp_path / "v101.tum.txt"
    assert tum.is_file()
    traj = evo_fi.read_tum_trajectory_file(str(tum))
    seq = visnav.open_sequence(euroc)
    assert traj.num_poses == len(seq) == 40
    np.testing.assert_allclose(traj.timestamps, seq.timestamps, rtol=0, atol=1e-6)
    # evo's APE against the EuRoC ground truth (body frame, associated by time) equals visnav's
    ref = evo_fi.read_tum_trajectory_file(str(euroc / "groundtruth_body_tum.txt"))
    ref, est = sync.associate_trajectories(ref, traj, max_diff=0.01)
    evo_rmse = _ape_rmse(ref, est)
    ours = json.loads(cli("eval", "--json", euroc / "groundtruth_body_tum.txt", tum).stdout)["ate_se3_m"]
    assert abs(evo_rmse - ours) < 1e-6, (evo_rmse, ours)
