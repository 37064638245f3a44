"""Type stubs of the visnav package (see the module docstring in __init__.py)."""

import os
from pathlib import Path
from typing import Any, Iterator, Mapping, Optional, Sequence as _Seq, Union

import numpy as np
import numpy.typing as npt

__version__: str

PathLike = Union[str, "os.PathLike[str]"]
Config = Union[None, Mapping[str, Any], PathLike]
Image = npt.NDArray[Any]

class Interrupted(KeyboardInterrupt):
    """A run stopped by Ctrl-C, SIGTERM or SIGHUP after the frame in progress (as ``visnav
    odometry`` stops); ``poses`` holds ``world_from_cam`` of the frames done, (K, 4, 4)."""

    poses: npt.NDArray[np.float64]

class Camera:
    """A rectified pinhole camera (pixels); ``baseline_m`` (metres) makes it the left camera of a
    rectified stereo rig (what ``StereoOdometry`` needs)."""

    fx: float
    fy: float
    cx: float
    cy: float
    width: int
    height: int
    baseline_m: Optional[float]
    def __init__(
        self,
        fx: float,
        fy: float,
        cx: float,
        cy: float,
        width: int,
        height: int,
        baseline_m: Optional[float] = None,
    ) -> None: ...

class Frame:
    """One frame of a sequence."""

    index: int
    left: npt.NDArray[np.uint8]
    """Left (or only) image, HxW uint8."""
    right: Optional[npt.NDArray[np.uint8]]
    left_f32: npt.NDArray[np.float32]
    """The exact grey values (0..255) the odometry sees (differ from ``left`` only for
    undistorted / rectified inputs such as EuRoC)."""
    right_f32: Optional[npt.NDArray[np.float32]]
    timestamp: Optional[float]
    """Seconds, when the dataset has its own timestamps (EuRoC, TUM); else None."""

class Sequence:
    """An opened input: ``len()``, indexing (negative too) and iteration yield ``Frame``s."""

    camera: Camera
    path: Path
    has_stereo: bool
    timestamps: npt.NDArray[np.float64]
    """Seconds, one per frame (KITTI: its relative times.txt, or index x 0.1 s)."""
    def __len__(self) -> int: ...
    def __getitem__(self, index: int) -> Frame: ...
    def __iter__(self) -> Iterator[Frame]: ...

class FrameResult:
    """The outcome of one frame."""

    position: int
    world_from_cam: npt.NDArray[np.float64]
    """4x4, metres; frame 0 = identity."""
    prev_from_cur: npt.NDArray[np.float64]
    prev_from_cur_covariance: Optional[npt.NDArray[np.float64]]
    """6x6 covariance of ``prev_from_cur``: a right perturbation in this frame's camera, x, y, z,
    rotation about x, y, z (metres, radians); None without an estimate of its own."""
    status: str
    """"ok", "low_parallax", "fallback" or "skipped"."""
    reason: Optional[str]
    timings: dict[str, float]
    """Milliseconds per stage, and "total_ms"."""
    timestamp: Optional[float]

class StereoOdometry:
    """Stereo odometry (RotROCC). ``camera``: a ``Camera`` with ``baseline_m`` (the ``.camera``
    of a stereo sequence). ``config``: None, a dict or a TOML file with the keys of
    ``visnav odometry --mode stereo --config``."""

    def __init__(self, camera: Camera, config: Config = None) -> None: ...
    def process(
        self, left: Image, right: Optional[Image] = None, timestamp: Optional[float] = None
    ) -> FrameResult: ...
    def trajectory(self) -> npt.NDArray[np.float64]:
        """(N, 4, 4) float64 ``world_from_cam`` of the frames processed so far."""

class MonoOdometry:
    """Monocular odometry from dense flow with uncertainty. ``config``: None, a dict or a TOML
    file with the keys of ``visnav odometry --mode mono --config`` (``[mono]``, ``[mono.flow]``);
    ``camera_height`` in metres overrides ``mono.scale.camera_height_m``. ``process`` returns the
    result of the frame given (synchronous mode; same poses as the CLI's pipelined run)."""

    def __init__(
        self,
        camera: Camera,
        config: Config = None,
        camera_height: Optional[float] = None,
        preset: Optional[str] = None,
    ) -> None:
        """``preset``: ``"paper"`` (default) or ``"realtime"`` (the fast flow), the defaults
        ``config`` is read over (``visnav odometry --preset``)."""
    def process(
        self, left: Image, right: Optional[Image] = None, timestamp: Optional[float] = None
    ) -> FrameResult:
        """``right`` must be None (a ValueError otherwise)."""
    def trajectory(self) -> npt.NDArray[np.float64]: ...

class DenseFlow:
    flow: npt.NDArray[np.float32]
    """HxWx2 (u, v), pixels, from the first image to the second."""
    information: npt.NDArray[np.float32]
    """HxWx3 (Yxx, Yxy, Yyy), 1/px^2."""
    valid: npt.NDArray[np.bool_]
    timings_ms: dict[str, float]

def open_sequence(path: PathLike, camera: Optional[PathLike] = None) -> Sequence: ...
def load_image(path: PathLike) -> npt.NDArray[np.float32]:
    """An image file as the CLI loads it: grey, HxW float32, 0..255."""

def run_odometry(
    path: PathLike,
    mode: str,
    camera: Optional[PathLike] = None,
    camera_height: Optional[float] = None,
    config: Config = None,
    max_frames: Optional[int] = None,
    preset: Optional[str] = None,
    covariance: bool = False,
) -> Any:
    """(N, 4, 4) ``world_from_cam``, one per input frame, as ``visnav odometry`` writes; with
    ``covariance=True`` a tuple of it and each step's 6x6 covariance, (N, 6, 6), NaN for a frame
    without one (``FrameResult.prev_from_cur_covariance``);
    ``preset`` as for ``MonoOdometry``. Ctrl-C, SIGTERM or SIGHUP stop the run after the frame
    in progress and raise ``Interrupted`` with the frames done (SIGTERM and SIGHUP when their
    handler is the default one: they raise ``KeyboardInterrupt`` for the length of the call)."""

def dense_flow(
    img1: Union[Image, PathLike],
    img2: Union[Image, PathLike],
    config: Optional[Mapping[str, Any]] = None,
    method: Optional[str] = None,
) -> DenseFlow:
    """``method``: ``"paper"`` (default, ``FlowConfig`` keys in ``config``) or ``"fast"`` (dense
    inverse search, ``FastFlowConfig`` keys), as ``visnav flow --method``."""
def kitti_errors(
    gt: npt.ArrayLike, est: npt.ArrayLike, lengths: Optional[_Seq[float]] = None
) -> dict[str, Any]:
    """KITTI devkit metric, ATE and RPE (``t_err_percent``, ``r_err_deg_per_100m``,
    ``segments``, ``ate_se3_m``, ...), as ``visnav eval --json``."""

def run_manifest_line(manifest: PathLike, index: int, skip_existing: bool = False) -> dict[str, Any]:
    """One line of a batch manifest, exactly as ``visnav batch MANIFEST --index N``; stopped by
    Ctrl-C, SIGTERM or SIGHUP it writes the frames done and ``status.json`` ("interrupted") and
    raises the ``KeyboardInterrupt`` with that status as its ``status``."""

def manifest_len(manifest: PathLike) -> int: ...
