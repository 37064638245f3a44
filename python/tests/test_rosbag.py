"""ROS 2 bags written by the independent `rosbags` package, read by `visnav odometry`.

* KITTI 06 stereo clip as raw `sensor_msgs/msg/Image` (mono8) + `CameraInfo` (rectified: `P`
  from `calib.txt`): the trajectory from the bag equals the one from the folder to 1e-9 m.
* EuRoC V1_01 sample as `sensor_msgs/msg/CompressedImage` (JPEG) + `CameraInfo` carrying the
  distortion and the stereo rectification (`R`, `P` from OpenCV's `stereoRectify`): the
  trajectory from the bag is within 1 % of the path of the folder's (JPEG is lossy).
* `visnav info` lists the topics; bad bags give clear errors, never a crash.
"""

from __future__ import annotations

import json
import os
import shutil
import subprocess
from pathlib import Path

import numpy as np
import pytest

import cv2  # opencv-python-headless, python/requirements-test.txt
from rosbags.rosbag2 import StoragePlugin, Writer
from rosbags.typesys import Stores, get_typestore

TYPESTORE = get_typestore(Stores.ROS2_HUMBLE)
Image = TYPESTORE.types["sensor_msgs/msg/Image"]
CompressedImage = TYPESTORE.types["sensor_msgs/msg/CompressedImage"]
CameraInfo = TYPESTORE.types["sensor_msgs/msg/CameraInfo"]
Header = TYPESTORE.types["std_msgs/msg/Header"]
Time = TYPESTORE.types["builtin_interfaces/msg/Time"]
ROI = TYPESTORE.types["sensor_msgs/msg/RegionOfInterest"]


def data_dir() -> Path:
    d = os.environ.get("VISNAV_DATA")
    if not d:
        if os.environ.get("VISNAV_REQUIRE_DATA") == "1":
            pytest.fail("VISNAV_DATA is not set and VISNAV_REQUIRE_DATA=1")
        pytest.skip("VISNAV_DATA not set")
    return Path(d)


def visnav_bin() -> str:
    b = os.environ.get("VISNAV_BIN")
    if b:
        return b
    root = Path(__file__).resolve().parents[2]
    for cand in (root / "target/release/visnav", root / "target/debug/visnav"):
        if cand.exists():
            return str(cand)
    found = shutil.which("visnav")
    if not found:
        pytest.fail("no visnav binary: set VISNAV_BIN")
    return found


def run(*args: str, ok: bool = True) -> subprocess.CompletedProcess:
    p = subprocess.run([visnav_bin(), "--quiet", *args], capture_output=True, text=True)
    if ok:
        assert p.returncode == 0, p.stderr
    return p


def header(stamp_ns: int, frame: str):
    return Header(stamp=Time(sec=stamp_ns // 10**9, nanosec=stamp_ns % 10**9), frame_id=frame)


def camera_info(stamp_ns, frame, w, h, model, d, k, r, p):
    return CameraInfo(
        header=header(stamp_ns, frame),
        height=h,
        width=w,
        distortion_model=model,
        d=np.asarray(d, dtype=np.float64),
        k=np.asarray(k, dtype=np.float64).reshape(9),
        r=np.asarray(r, dtype=np.float64).reshape(9),
        p=np.asarray(p, dtype=np.float64).reshape(12),
        binning_x=0,
        binning_y=0,
        roi=ROI(x_offset=0, y_offset=0, height=0, width=0, do_rectify=False),
    )


def write(writer, conn, msg, stamp_ns):
    writer.write(conn, stamp_ns, TYPESTORE.serialize_cdr(msg, msg.__msgtype__))


def read_kitti_poses(path: Path) -> np.ndarray:
    return np.loadtxt(path).reshape(-1, 3, 4)


def kitti_calib(seq: Path) -> dict[str, np.ndarray]:
    out = {}
    for line in (seq / "calib.txt").read_text().splitlines():
        if ":" in line:
            k, v = line.split(":", 1)
            out[k.strip()] = np.array([float(x) for x in v.split()])
    return out


@pytest.fixture(scope="module")
def kitti06_bag(tmp_path_factory) -> tuple[Path, Path]:
    seq = data_dir() / "kitti/odometry/sequences/06"
    bag = tmp_path_factory.mktemp("bags") / "kitti06"
    calib = kitti_calib(seq)
    times = np.loadtxt(seq / "times.txt")
    lefts = sorted((seq / "image_0").glob("*.png"))
    t0 = 1_700_000_000 * 10**9
    with Writer(bag, version=9, storage_plugin=StoragePlugin.MCAP) as w:
        conns = {
            side: (
                w.add_connection(f"/{side}/image_raw", Image.__msgtype__, typestore=TYPESTORE),
                w.add_connection(f"/{side}/camera_info", CameraInfo.__msgtype__, typestore=TYPESTORE),
            )
            for side in ("left", "right")
        }
        for i, left in enumerate(lefts):
            stamp = t0 + int(round(times[i] * 1e9))
            for side, folder, p in (("left", "image_0", calib["P0"]), ("right", "image_1", calib["P1"])):
                img = cv2.imread(str(seq / folder / left.name), cv2.IMREAD_UNCHANGED)
                h, wd = img.shape
                frame = f"cam_{side}"
                msg = Image(
                    header=header(stamp, frame),
                    height=h,
                    width=wd,
                    encoding="mono8",
                    is_bigendian=0,
                    step=wd,
                    data=img.reshape(-1),
                )
                k = p.reshape(3, 4)[:, :3]
                info = camera_info(stamp, frame, wd, h, "plumb_bob", [0.0] * 5, k, np.eye(3), p)
                write(w, conns[side][0], msg, stamp)
                write(w, conns[side][1], info, stamp)
    return seq, bag


@pytest.fixture(scope="module")
def kitti06_jpeg_bag(tmp_path_factory) -> tuple[Path, Path]:
    """The KITTI 06 clip as CompressedImage (JPEG quality 95) with rectified CameraInfo."""
    seq = data_dir() / "kitti/odometry/sequences/06"
    bag = tmp_path_factory.mktemp("bags") / "kitti06_jpeg"
    calib = kitti_calib(seq)
    times = np.loadtxt(seq / "times.txt")
    lefts = sorted((seq / "image_0").glob("*.png"))
    with Writer(bag, version=9, storage_plugin=StoragePlugin.MCAP) as w:
        conns = {
            side: (
                w.add_connection(f"/{side}/image_raw/compressed", CompressedImage.__msgtype__, typestore=TYPESTORE),
                w.add_connection(f"/{side}/camera_info", CameraInfo.__msgtype__, typestore=TYPESTORE),
            )
            for side in ("left", "right")
        }
        for i, left in enumerate(lefts):
            stamp = 10**18 + int(round(times[i] * 1e9))
            for side, folder, p in (("left", "image_0", calib["P0"]), ("right", "image_1", calib["P1"])):
                img = cv2.imread(str(seq / folder / left.name), cv2.IMREAD_GRAYSCALE)
                ok, jpg = cv2.imencode(".jpg", img, [cv2.IMWRITE_JPEG_QUALITY, 95])
                assert ok
                h, wd = img.shape
                write(w, conns[side][0], CompressedImage(header=header(stamp, side), format="jpeg", data=jpg.reshape(-1)), stamp)
                info = camera_info(stamp, side, wd, h, "plumb_bob", [0.0] * 5, p.reshape(3, 4)[:, :3], np.eye(3), p)
                write(w, conns[side][1], info, stamp)
    return seq, bag


def kitti_errors(gt: Path, est: Path) -> tuple[float, float]:
    d = json.loads(run("eval", str(gt), str(est), "--lengths", "10,20,30,40,50", "--json").stdout)
    return d["t_err_percent"], d["r_err_deg_per_100m"]


def test_jpeg_stereo_bag_scores_like_the_folder(kitti06_jpeg_bag, tmp_path):
    """JPEG at quality 95 moves the KITTI score of the clip by about 1 % of itself (t_err 0.8435 →
    0.8516, +0.96 %, with points to 80 m; 0.8422 → 0.8507, +1.01 %, to 400 m; r_err +1.6 % and
    +1.5 %): t_err within 2 % and r_err within 3 %, about twice what compression did."""
    seq, bag = kitti06_jpeg_bag
    gt = data_dir() / "kitti/odometry/poses/06.txt"
    run("odometry", "--mode", "stereo", str(seq), "-o", str(tmp_path / "folder.txt"))
    run("odometry", "--mode", "stereo", str(bag), "--topic", "/left/image_raw/compressed",
        "--right-topic", "/right/image_raw/compressed", "-o", str(tmp_path / "bag.txt"))
    t_folder, r_folder = kitti_errors(gt, tmp_path / "folder.txt")
    t_bag, r_bag = kitti_errors(gt, tmp_path / "bag.txt")
    print(f"t_err folder {t_folder:.4f} bag {t_bag:.4f}; r_err folder {r_folder:.4f} bag {r_bag:.4f}")
    assert abs(t_bag - t_folder) <= 0.02 * t_folder, (t_folder, t_bag)
    assert abs(r_bag - r_folder) <= 0.03 * r_folder, (r_folder, r_bag)


def test_info_lists_the_topics(kitti06_bag):
    seq, bag = kitti06_bag
    topics = json.loads(run("info", str(bag), "--json").stdout)
    by_name = {t["topic"]: t for t in topics}
    n = len(list((seq / "image_0").glob("*.png")))
    assert by_name["/left/image_raw"]["message_type"] == "sensor_msgs/msg/Image"
    assert by_name["/left/image_raw"]["count"] == n
    assert by_name["/right/image_raw"]["encodings"] == ["mono8"]
    assert by_name["/left/camera_info"]["count"] == n
    table = run("info", str(bag)).stdout
    assert "/right/camera_info" in table


def test_lossless_stereo_bag_equals_the_folder(kitti06_bag, tmp_path):
    seq, bag = kitti06_bag
    run("odometry", "--mode", "stereo", str(seq), "-o", str(tmp_path / "folder.txt"))
    run(
        "odometry", "--mode", "stereo", str(bag), "--topic", "/left/image_raw",
        "--right-topic", "/right/image_raw", "-o", str(tmp_path / "bag.txt"),
        "--output-mcap", str(tmp_path / "poses.mcap"),
    )
    a = read_kitti_poses(tmp_path / "folder.txt")
    b = read_kitti_poses(tmp_path / "bag.txt")
    assert a.shape == b.shape and a.shape[0] == len(list((seq / "image_0").glob("*.png")))
    assert np.abs(a - b).max() <= 1e-9
    # the output MCAP holds one PoseStamped and one nav_msgs/Odometry a frame, read back by rosbags
    from rosbags.highlevel import AnyReader

    with AnyReader([tmp_path / "poses.mcap"], default_typestore=TYPESTORE) as reader:
        msgs = [(c.msgtype, reader.deserialize(raw, c.msgtype)) for c, _, raw in reader.messages()]
    poses = [m for t, m in msgs if t == "geometry_msgs/msg/PoseStamped"]
    odometry = [m for t, m in msgs if t == "nav_msgs/msg/Odometry"]
    assert len(poses) == len(odometry) == a.shape[0] and len(msgs) == 2 * a.shape[0]
    assert poses[0].header.frame_id == "visnav_world"
    last = poses[-1].pose.position
    assert np.allclose([last.x, last.y, last.z], b[-1][:, 3], atol=1e-12)
    last = odometry[-1].pose.pose.position
    assert np.allclose([last.x, last.y, last.z], b[-1][:, 3], atol=1e-12)
    # a stereo step's covariance: symmetric, positive definite (the first frame's is unknown)
    cov = odometry[-1].pose.covariance.reshape(6, 6)
    assert np.allclose(cov, cov.T) and np.all(np.linalg.eigvalsh(cov) > 0)


def test_mono_bag_picks_the_only_image_topic_when_asked_and_lists_them(kitti06_bag, tmp_path):
    _, bag = kitti06_bag
    p = run("odometry", "--mode", "mono", str(bag), "-o", str(tmp_path / "m.txt"), ok=False)
    assert p.returncode != 0
    assert "/left/image_raw" in p.stderr and "--topic" in p.stderr
    p = run("odometry", "--mode", "stereo", str(bag), "--topic", "/nope", "-o", str(tmp_path / "m.txt"), ok=False)
    assert "no topic /nope" in p.stderr and "/right/image_raw" in p.stderr
    p = run("odometry", "--mode", "stereo", str(bag), "--topic", "/left/camera_info", "-o", str(tmp_path / "m.txt"), ok=False)
    assert "not images" in p.stderr


def test_unpaired_left_frame_keeps_its_place(tmp_path):
    """A right image missing from the bag: every left frame still gets a pose."""
    seq = data_dir() / "kitti/odometry/sequences/06"
    calib = kitti_calib(seq)
    lefts = sorted((seq / "image_0").glob("*.png"))[:8]
    bag = tmp_path / "gap"
    with Writer(bag, version=9, storage_plugin=StoragePlugin.MCAP) as w:
        c = {
            n: w.add_connection(n, t.__msgtype__, typestore=TYPESTORE)
            for n, t in (
                ("/l/image", Image), ("/l/camera_info", CameraInfo),
                ("/r/image", Image), ("/r/camera_info", CameraInfo),
            )
        }
        for i, left in enumerate(lefts):
            stamp = (10 + i) * 10**8
            for side, folder, p in (("l", "image_0", calib["P0"]), ("r", "image_1", calib["P1"])):
                if side == "r" and i == 4:
                    continue
                img = cv2.imread(str(seq / folder / left.name), cv2.IMREAD_UNCHANGED)
                h, wd = img.shape
                msg = Image(header=header(stamp, side), height=h, width=wd, encoding="mono8",
                            is_bigendian=0, step=wd, data=img.reshape(-1))
                write(w, c[f"/{side}/image"], msg, stamp)
                info = camera_info(stamp, side, wd, h, "", [], p.reshape(3, 4)[:, :3], np.eye(3), p)
                write(w, c[f"/{side}/camera_info"], info, stamp)
    out = tmp_path / "gap.txt"
    p = run("odometry", "--mode", "stereo", str(bag), "--topic", "/l/image", "--right-topic", "/r/image",
            "-o", str(out), "--json", str(tmp_path / "gap.json"))
    assert read_kitti_poses(out).shape[0] == len(lefts)
    report = json.loads((tmp_path / "gap.json").read_text())
    statuses = [f["status"] for f in report["per_frame"]]
    assert "skipped" in json.dumps(statuses[4]) and all("skipped" not in json.dumps(s) for s in statuses[:4])


def test_a_bag_whose_camera_info_baseline_is_in_millimetres_is_named(tmp_path):
    """Issue 53: a right `CameraInfo` whose `P[0][3]` is -fx·b with b in millimetres (KITTI's
    0.537 m rig as 537 m) warns naming the field and the likely unit; in metres, no warning."""
    seq = data_dir() / "kitti/odometry/sequences/06"
    calib = kitti_calib(seq)
    left = sorted((seq / "image_0").glob("*.png"))[0]
    for name, scale in (("mm", 1000.0), ("m", 1.0)):
        bag = tmp_path / name
        with Writer(bag, version=9, storage_plugin=StoragePlugin.MCAP) as w:
            c = {
                n: w.add_connection(n, t.__msgtype__, typestore=TYPESTORE)
                for n, t in (
                    ("/l/image", Image), ("/l/camera_info", CameraInfo),
                    ("/r/image", Image), ("/r/camera_info", CameraInfo),
                )
            }
            for i in range(2):
                stamp = (10 + i) * 10**8
                for side, folder, p in (("l", "image_0", calib["P0"]), ("r", "image_1", calib["P1"])):
                    p = p.reshape(3, 4).copy()
                    p[0, 3] *= scale
                    img = cv2.imread(str(seq / folder / left.name), cv2.IMREAD_UNCHANGED)
                    h, wd = img.shape
                    msg = Image(header=header(stamp, side), height=h, width=wd, encoding="mono8",
                                is_bigendian=0, step=wd, data=img.reshape(-1))
                    write(w, c[f"/{side}/image"], msg, stamp)
                    info = camera_info(stamp, side, wd, h, "", [], p[:, :3], np.eye(3), p.reshape(-1))
                    write(w, c[f"/{side}/camera_info"], info, stamp)
        p = run("info", "--check", str(bag), "--topic", "/l/image", "--right-topic", "/r/image")
        if scale > 1.0:
            assert "the right CameraInfo's P[0][3] (frame_id `r`): stereo baseline" in p.stderr, p.stderr
            assert "impossible" in p.stderr and "millimetres (0.5372 m)?" in p.stderr, p.stderr
        else:
            assert "impossible" not in p.stderr, p.stderr


def euroc_rig(root: Path):
    import yaml

    def sensor(cam):
        y = yaml.safe_load((root / f"mav0/{cam}/sensor.yaml").read_text().replace("%YAML:1.0", ""))
        fx, fy, cx, cy = y["intrinsics"]
        k = np.array([[fx, 0, cx], [0, fy, cy], [0, 0, 1.0]])
        t_bs = np.array(y["T_BS"]["data"]).reshape(4, 4)
        return k, np.array(y["distortion_coefficients"] + [0.0]), t_bs, tuple(y["resolution"])

    k0, d0, tb0, size = sensor("cam0")
    k1, d1, tb1, _ = sensor("cam1")
    cam1_from_cam0 = np.linalg.inv(tb1) @ tb0
    r1, r2, p1, p2, *_ = cv2.stereoRectify(
        k0, d0, k1, d1, size, cam1_from_cam0[:3, :3].copy(), cam1_from_cam0[:3, 3].reshape(3, 1).copy(), alpha=0
    )
    return size, (k0, d0, r1, p1), (k1, d1, r2, p2)


def test_jpeg_stereo_bag_with_distortion_matches_the_folder(tmp_path):
    root = data_dir() / "euroc/V1_01_easy_first40"
    size, left_cal, right_cal = euroc_rig(root)
    bag = tmp_path / "euroc"
    rows = {
        cam: [l.split(",") for l in (root / f"mav0/{cam}/data.csv").read_text().splitlines() if not l.startswith("#")]
        for cam in ("cam0", "cam1")
    }
    with Writer(bag, version=9, storage_plugin=StoragePlugin.MCAP) as w:
        c = {}
        for ns in ("cam0", "cam1"):
            c[ns] = (
                w.add_connection(f"/{ns}/image_raw/compressed", CompressedImage.__msgtype__, typestore=TYPESTORE),
                w.add_connection(f"/{ns}/camera_info", CameraInfo.__msgtype__, typestore=TYPESTORE),
            )
        for ns, cal in (("cam0", left_cal), ("cam1", right_cal)):
            k, d, r, p = cal
            for t_ns, name in rows[ns]:
                stamp = int(t_ns)
                img = cv2.imread(str(root / f"mav0/{ns}/data" / name.strip()), cv2.IMREAD_GRAYSCALE)
                ok, jpg = cv2.imencode(".jpg", img, [cv2.IMWRITE_JPEG_QUALITY, 95])
                assert ok
                msg = CompressedImage(header=header(stamp, ns), format="jpeg", data=jpg.reshape(-1))
                write(w, c[ns][0], msg, stamp)
                info = camera_info(stamp, ns, size[0], size[1], "plumb_bob", d, k, r, p)
                write(w, c[ns][1], info, stamp)
    # frame-to-frame (--no-ba): every frame's features are detected afresh in both runs, so their
    # depths compare the rectification alone; the window's persistent tracks depend on which
    # tracks survived the JPEG noise of the earlier frames
    run("odometry", "--mode", "stereo", str(root), "-o", str(tmp_path / "folder.txt"),
        "--no-ba", "--save-tracks", str(tmp_path / "tracks_folder"))
    run("odometry", "--mode", "stereo", str(bag), "--topic", "/cam0/image_raw/compressed",
        "--right-topic", "/cam1/image_raw/compressed", "-o", str(tmp_path / "bag.txt"),
        "--no-ba", "--save-tracks", str(tmp_path / "tracks_bag"))
    a = read_kitti_poses(tmp_path / "folder.txt")
    b = read_kitti_poses(tmp_path / "bag.txt")
    assert a.shape == b.shape and a.shape[0] == len(rows["cam0"])
    # The sample's first 40 frames hardly move (a few mm), so the poses alone cannot show a wrong
    # rectification: the stereo depth of the tracked features does. Both runs rectify with the
    # same rig (the bag's from K, D, R and P): the median depth agrees within 1 %, and the
    # positions within 1 cm.
    def median_depth(d: Path) -> float:
        rows_ = [np.loadtxt(f, delimiter=",", skiprows=1, ndmin=2) for f in sorted(d.glob("*.csv"))]
        depth = np.concatenate([r[:, 4] for r in rows_ if r.size])
        return float(np.median(depth[np.isfinite(depth)]))

    da, db = median_depth(tmp_path / "tracks_folder"), median_depth(tmp_path / "tracks_bag")
    assert 0.5 < da < 20.0
    assert abs(da - db) <= 0.01 * da, (da, db)
    assert np.linalg.norm(a[:, :, 3] - b[:, :, 3], axis=1).max() <= 0.01


def test_bad_bags_give_clear_errors(tmp_path):
    db3 = tmp_path / "old"
    db3.mkdir()
    (db3 / "metadata.yaml").write_text("rosbag2_bagfile_information: {}\n")
    (db3 / "old_0.db3").write_bytes(b"SQLite format 3\x00")
    p = run("info", str(db3), ok=False)
    assert p.returncode != 0 and "ros2 bag convert" in p.stderr
    junk = tmp_path / "junk.mcap"
    junk.write_bytes(b"not an mcap file at all")
    p = run("info", str(junk), ok=False)
    assert p.returncode != 0 and "MCAP" in p.stderr and "panicked" not in p.stderr


def test_a_bag_cut_short_keeps_the_frames_before_the_cut(kitti06_bag, tmp_path):
    """A recorder killed mid-write leaves an MCAP without its end: the frames before the cut are
    read (with a warning), never a crash."""
    seq, bag = kitti06_bag
    (mcap,) = sorted(bag.glob("*.mcap"))
    data = mcap.read_bytes()
    cut = tmp_path / "cut.mcap"
    cut.write_bytes(data[: len(data) // 2])
    p = run("odometry", "--mode", "stereo", str(cut), "--topic", "/left/image_raw",
            "--right-topic", "/right/image_raw", "-o", str(tmp_path / "cut.txt"), ok=False)
    assert "panicked" not in p.stderr
    assert p.returncode == 0, p.stderr
    n_cut = read_kitti_poses(tmp_path / "cut.txt").shape[0]
    n_all = len(list((seq / "image_0").glob("*.png")))
    assert 0 < n_cut < n_all
    assert "cut short" in p.stderr
