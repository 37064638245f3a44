"""Issue 53: Ctrl-C, SIGTERM and SIGHUP stop ``run_odometry`` and ``run_manifest_line`` as they
stop ``visnav odometry`` and ``visnav batch``: after the frame in progress, with the frames done
kept. Before, Ctrl-C was noticed only when the whole run had ended and then failed with a
``PanicException`` (numpy's API loaded with the KeyboardInterrupt pending), and SIGTERM ended the
process at once (exit 143) with nothing returned or written.

Each case runs in a child Python that signals itself from a timer thread while the run is on."""

import json
import os
import signal
import subprocess
import sys
from pathlib import Path

import pytest

FRAMES = 120

CHILD = """
import json, os, signal, sys, threading
import visnav

what, sig, arg = sys.argv[1], getattr(signal, sys.argv[2]), sys.argv[3]
threading.Timer(1.5, lambda: os.kill(os.getpid(), sig)).start()
try:
    if what == "odometry":
        visnav.run_odometry(arg, "mono")
    else:
        visnav.run_manifest_line(arg, 0)
    print(json.dumps({"finished": True}))
except KeyboardInterrupt as e:
    print(json.dumps({
        "type": type(e).__name__,
        "message": str(e),
        "poses": len(e.poses) if hasattr(e, "poses") else None,
        "status": getattr(e, "status", None),
        "default_restored": signal.getsignal(signal.SIGTERM) == signal.SIG_DFL,
    }))
    sys.exit(3)
"""


@pytest.fixture(scope="module")
def long_sequence(tmp_path_factory, cli) -> Path:
    root = tmp_path_factory.mktemp("interrupt")
    seq = root / "seq"
    cli("synth", "--out", seq, "--frames", FRAMES, "--width", 320, "--height", 96)
    return seq


def _child(what: str, sig: str, arg: Path) -> dict:
    p = subprocess.run(
        [sys.executable, "-c", CHILD, what, sig, str(arg)],
        capture_output=True,
        text=True,
        timeout=600,
    )
    assert p.returncode == 3, f"exit {p.returncode}: {p.stdout} {p.stderr}"
    return json.loads(p.stdout.strip().splitlines()[-1])


@pytest.mark.parametrize("sig", ["SIGINT", "SIGTERM", "SIGHUP"])
def test_a_signal_stops_run_odometry_with_the_frames_done(long_sequence: Path, sig: str) -> None:
    if not hasattr(signal, sig):
        pytest.skip(f"no {sig} here")
    if signal.getsignal(getattr(signal, sig)) == signal.SIG_IGN:
        # under `nohup` (or a shell that ignores it) the child inherits SIG_IGN, which
        # run_odometry rightly leaves alone: the run is not meant to stop
        pytest.skip(f"{sig} is ignored in this environment (nohup?)")
    out = _child("odometry", sig, long_sequence)
    assert out["type"] == "Interrupted"
    assert 1 <= out["poses"] < FRAMES, out
    assert f"interrupted: {out['poses']} of {FRAMES} poses" in out["message"]
    assert out["default_restored"]


def test_sigterm_stops_a_manifest_line_with_an_interrupted_status(long_sequence: Path, tmp_path: Path) -> None:
    manifest = tmp_path / "runs.jsonl"
    manifest.write_text(json.dumps({"sequence": str(long_sequence), "mode": "mono", "output": "out"}) + "\n")
    out = _child("batch", "SIGTERM", manifest)
    status = json.loads((tmp_path / "out" / "status.json").read_text())
    assert status["status"] == "interrupted"
    assert out["status"] == status
    poses = (tmp_path / "out" / "poses.txt").read_text().splitlines()
    assert 1 <= len(poses) == status["frames"] < FRAMES
    assert json.loads((tmp_path / "out" / "report.json").read_text())["interrupted"] is True
    assert not os.path.exists(tmp_path / "out" / "poses.txt.partial")
