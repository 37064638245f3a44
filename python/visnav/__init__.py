"""visnav: robust visual navigation (stereo and monocular visual odometry, dense optical flow
with per-pixel uncertainty, KITTI scores) from Python.

The heavy lifting is the visnav Rust library; this package is a thin front end over it
(``visnav._visnav``): runs are set up by the same code as the ``visnav`` command-line tool, so
``run_odometry`` gives the trajectory ``visnav odometry`` writes, ``dense_flow`` the flow of
``visnav flow`` and ``kitti_errors`` the figures of ``visnav eval --json``.

Conventions: poses are 4x4 float64 matrices ``world_from_cam`` (the left camera of frame 0 is
the world; metres); images are HxW grey arrays (uint8, or float32 values 0..255).
"""

from ._visnav import (
    Camera,
    DenseFlow,
    Frame,
    FrameResult,
    Interrupted,
    MonoOdometry,
    Sequence,
    StereoOdometry,
    __version__,
    dense_flow,
    kitti_errors,
    load_image,
    manifest_len,
    open_sequence,
    run_manifest_line,
    run_odometry,
)

__all__ = [
    "Camera",
    "DenseFlow",
    "Frame",
    "FrameResult",
    "Interrupted",
    "MonoOdometry",
    "Sequence",
    "StereoOdometry",
    "__version__",
    "dense_flow",
    "kitti_errors",
    "load_image",
    "manifest_len",
    "open_sequence",
    "run_manifest_line",
    "run_odometry",
]
