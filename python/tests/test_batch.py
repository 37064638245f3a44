"""visnav.run_manifest_line and the Ray example against `visnav batch`: three short runs (KITTI 06
stereo, KITTI 00 mono, a rendered stereo drive) give the same files."""

import json
import os
import subprocess
import sys
from pathlib import Path

import pytest

import visnav

EXAMPLE = Path(__file__).resolve().parents[1] / "examples" / "ray_batch.py"


def _manifest(root: Path, data: Path, rendered: Path, out: str) -> Path:
    k = data / "kitti" / "odometry" / "sequences"
    lines = [
        {"sequence": str(k / "06"), "mode": "stereo", "output": f"{out}/s06", "max_frames": 10},
        {"sequence": str(k / "00"), "mode": "mono", "output": f"{out}/m00", "max_frames": 8, "camera_height": 1.7},
        {"sequence": "rendered", "mode": "stereo", "output": f"{out}/r", "config": {"outlier": "re"}},
    ]
    path = root / f"{out}.jsonl"
    path.write_text("".join(json.dumps(line) + "\n" for line in lines))
    return path


@pytest.fixture(scope="module")
def batch_root(tmp_path_factory, data: Path, cli) -> Path:
    root = tmp_path_factory.mktemp("batch")
    cli("synth", "--stereo", "--out", root / "rendered", "--frames", "6", "--width", "320", "--height", "120")
    m = _manifest(root, data, root / "rendered", "cli")
    cli("batch", m, "--all")
    return root


def _same_run(a: Path, b: Path) -> None:
    assert (a / "poses.txt").read_bytes() == (b / "poses.txt").read_bytes()
    ra, rb = (json.loads((d / "report.json").read_text()) for d in (a, b))
    for key in ("frames", "input_frames", "mode", "config", "ok_frames", "failed_frames"):
        assert ra[key] == rb[key], key
    sa, sb = (json.loads((d / "status.json").read_text()) for d in (a, b))
    assert sa["status"] == sb["status"] == "ok"
    for key in ("frames", "config_hash", "version", "mode", "index"):
        assert sa[key] == sb[key], key


def test_run_manifest_line_writes_what_visnav_batch_writes(batch_root: Path, data: Path) -> None:
    m = _manifest(batch_root, data, batch_root / "rendered", "py")
    assert visnav.manifest_len(m) == 3
    for i in range(3):
        status = visnav.run_manifest_line(m, i)
        assert status["status"] == "ok" and status["index"] == i
    for name in ("s06", "m00", "r"):
        _same_run(batch_root / "cli" / name, batch_root / "py" / name)
    assert visnav.run_manifest_line(m, 0, skip_existing=True)["status"] == "skipped"


def test_run_manifest_line_errors(tmp_path: Path) -> None:
    m = tmp_path / "m.jsonl"
    m.write_text('{"sequence": "nowhere", "mode": "stereo", "output": "o"}\n{"mode": "stereo"}\n')
    with pytest.raises(ValueError, match=r"m\.jsonl:2:"):
        visnav.run_manifest_line(m, 0)
    m.write_text('{"sequence": "nowhere", "mode": "stereo", "output": "o"}\n')
    with pytest.raises(FileNotFoundError, match="nowhere"):
        visnav.run_manifest_line(m, 0)
    assert json.loads((tmp_path / "o" / "status.json").read_text())["status"] == "failed"
    with pytest.raises(ValueError, match="out of range"):
        visnav.run_manifest_line(m, 3)
    with pytest.raises(FileNotFoundError):
        visnav.manifest_len(tmp_path / "missing.jsonl")


def test_ray_example_writes_what_visnav_batch_writes(batch_root: Path, data: Path) -> None:
    pytest.importorskip("ray")
    m = _manifest(batch_root, data, batch_root / "rendered", "ray")
    # a local Ray instance (Ray 2.5x has no local mode), no usage reporting
    env = dict(os.environ, RAY_USAGE_STATS_ENABLED="0")
    p = subprocess.run(
        [sys.executable, str(EXAMPLE), str(m), "--num-cpus", "2"],
        capture_output=True,
        text=True,
        env=env,
        timeout=600,
    )
    assert p.returncode == 0, p.stderr
    assert p.stdout.count(": ok,") == 3, p.stdout
    for name in ("s06", "m00", "r"):
        _same_run(batch_root / "cli" / name, batch_root / "ray" / name)
