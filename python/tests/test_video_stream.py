"""Video is streamed from ffmpeg's pipe: peak memory and temporary disk do not grow with the
video's length (a 300-frame and a 3,000-frame video of the same frames, decoded through the
prefetching source every run uses, by `visnav info --check`)."""

from __future__ import annotations

import json
import os
import shutil
import subprocess
import threading
from pathlib import Path

import pytest

from test_rosbag import visnav_bin

CAMERA = (
    "cam0:\n  camera_model: pinhole\n  intrinsics: [300.0, 300.0, 159.5, 119.5]\n"
    "  distortion_model: radtan\n  distortion_coeffs: [0.0, 0.0, 0.0, 0.0]\n"
    "  resolution: [320, 240]\n"
)


def make_video(path: Path, frames: int) -> None:
    if not shutil.which("ffmpeg"):
        pytest.fail("ffmpeg is needed (scripts/setup.sh installs it)")
    subprocess.run(
        ["ffmpeg", "-v", "error", "-nostdin", "-f", "lavfi", "-i", "testsrc=size=320x240:rate=30",
         "-frames:v", str(frames), "-pix_fmt", "gray", "-c:v", "libx264", "-g", "30", str(path)],
        check=True,
    )


def du(path: Path) -> int:
    return sum(f.stat().st_size for f in path.rglob("*") if f.is_file())


def check_run(video: Path, camera: Path, tmpdir: Path) -> tuple[int, int, dict]:
    """Peak RSS (kB) and peak temporary disk (bytes) of `visnav info --check`."""
    env = dict(os.environ, TMPDIR=str(tmpdir))
    p = subprocess.Popen(
        [visnav_bin(), "--quiet", "info", str(video), "--camera", str(camera), "--check", "--json"],
        stdout=subprocess.PIPE, stderr=subprocess.PIPE, env=env,
    )
    peak_disk = 0
    done = threading.Event()

    def watch():
        nonlocal peak_disk
        while not done.wait(0.05):
            peak_disk = max(peak_disk, du(tmpdir))

    t = threading.Thread(target=watch)
    t.start()
    out = p.stdout.read()
    err = p.stderr.read()
    _, status, usage = os.wait4(p.pid, 0)
    done.set()
    t.join()
    assert os.waitstatus_to_exitcode(status) == 0, err
    return usage.ru_maxrss, max(peak_disk, du(tmpdir)), json.loads(out)


def test_memory_and_disk_do_not_grow_with_the_video(tmp_path):
    camera = tmp_path / "camera.yaml"
    camera.write_text(CAMERA)
    runs = {}
    for n in (300, 3000):
        video = tmp_path / f"v{n}.mp4"
        make_video(video, n)
        tmp = tmp_path / f"tmp{n}"
        tmp.mkdir()
        rss_kb, disk, summary = check_run(video, camera, tmp)
        assert summary["sequence"]["frames"] == n and summary["check"]["failed"] == []
        runs[n] = (rss_kb, disk)
    (short_kb, short_disk), (long_kb, long_disk) = runs[300], runs[3000]
    # decoded frames would be 300 x 77 kB = 23 MB vs 230 MB if they were kept
    assert long_kb <= short_kb * 1.15 + 8 * 1024, runs
    assert short_disk == 0 and long_disk == 0, runs
