//! Live input (issue 55): a stream sent with `ffmpeg -re` to a loopback UDP port is read as it
//! comes, poses go out as JSON lines as they happen, a slow odometry drops frames (counted) and
//! still covers the clip with the true time steps, a lost stream is a gap with reconnections,
//! bad live input is a clear error and never a hang, SIGTERM ends a live run with every output.
//!
//! ffmpeg is installed by `scripts/setup.sh`: without it these tests are skipped, and fail under
//! `VISNAV_REQUIRE_DATA=1` (CI), as the video tests do.
#![allow(clippy::unwrap_used)]

mod common;

use std::net::UdpSocket;
use std::path::{Path, PathBuf};
use std::process::{Child, Command, Output, Stdio};
use std::time::{Duration, Instant};

use common::{run_err, run_ok, synth_sequence, visnav};
use visnav_core::testdata::shared_data;
use visnav_pipeline::PoseLine;
use visnav_pipeline::report::RunReport;

/// The tests here measure real time (a stream's pace against the odometry's): one at a time.
static SERIAL: std::sync::Mutex<()> = std::sync::Mutex::new(());

/// Holds [`SERIAL`] for a test (a failed test's poison is ignored).
fn serial() -> std::sync::MutexGuard<'static, ()> {
    SERIAL
        .lock()
        .unwrap_or_else(std::sync::PoisonError::into_inner)
}

/// `true` when ffmpeg runs; skips (or panics under `VISNAV_REQUIRE_DATA=1`) otherwise.
fn have_ffmpeg() -> bool {
    let ok = Command::new("ffmpeg")
        .arg("-version")
        .stdout(Stdio::null())
        .status()
        .is_ok_and(|s| s.success());
    let required = std::env::var("VISNAV_REQUIRE_DATA").is_ok_and(|v| v == "1");
    assert!(
        ok || !required,
        "VISNAV_REQUIRE_DATA=1 but ffmpeg is missing (scripts/setup.sh installs it)"
    );
    if !ok {
        eprintln!("skipping: ffmpeg not found");
    }
    ok
}

/// A loopback UDP port free now.
fn free_port() -> u16 {
    UdpSocket::bind("127.0.0.1:0")
        .unwrap()
        .local_addr()
        .unwrap()
        .port()
}

/// Waits until something (visnav's ffmpeg) listens on the loopback UDP `port`.
fn wait_listening(port: u16, receiver: &mut Child) {
    let start = Instant::now();
    while UdpSocket::bind(("127.0.0.1", port)).is_ok() {
        assert!(
            receiver.try_wait().unwrap().is_none(),
            "visnav ended before listening"
        );
        assert!(start.elapsed() < Duration::from_secs(60), "nobody listens");
        std::thread::sleep(Duration::from_millis(50));
    }
}

/// `ffmpeg -v error -nostdin ARGS`, asserting success.
fn ffmpeg(args: &[&str]) {
    let status = Command::new("ffmpeg")
        .args(["-v", "error", "-nostdin", "-y"])
        .args(args)
        .status()
        .unwrap();
    assert!(status.success(), "ffmpeg {args:?}");
}

/// Sends `clip` in real time (`-re`) to the loopback UDP `port`.
fn send(clip: &Path, port: u16) {
    ffmpeg(&[
        "-re",
        "-i",
        clip.to_str().unwrap(),
        "-c",
        "copy",
        "-f",
        "mpegts",
        &format!("udp://127.0.0.1:{port}"),
    ]);
}

/// A Kalibr camera file for a pinhole camera without distortion.
fn camera_file(path: &Path, [fx, fy]: [f64; 2], cx: f64, cy: f64, size: (usize, usize)) {
    let text = format!(
        "cam0:\n  camera_model: pinhole\n  intrinsics: [{fx}, {fy}, {cx}, {cy}]\n  distortion_model: radtan\n  distortion_coeffs: [0.0, 0.0, 0.0, 0.0]\n  resolution: [{}, {}]\n",
        size.0, size.1
    );
    std::fs::write(path, text).unwrap();
}

/// Starts `visnav odometry --mode mono udp://127.0.0.1:PORT` with `args`, pose lines on stdout.
fn start_live(port: u16, camera: &Path, out: &Path, args: &[&str]) -> Child {
    visnav()
        .args(["odometry", "--mode", "mono"])
        .arg(format!("udp://127.0.0.1:{port}"))
        .arg("--camera")
        .arg(camera)
        .arg("-o")
        .arg(out)
        .arg("--json")
        .arg(out.with_extension("json"))
        .args(["--poses-out", "-"])
        .args(args)
        .stdout(Stdio::piped())
        .stderr(Stdio::piped())
        .spawn()
        .unwrap()
}

/// The pose lines of a run's stdout (every line must be one).
fn pose_lines(out: &Output) -> Vec<PoseLine> {
    String::from_utf8_lossy(&out.stdout)
        .lines()
        .map(|l| serde_json::from_str(l).unwrap_or_else(|e| panic!("not a pose line: {l}: {e}")))
        .collect()
}

/// Waits for a run, asserting success; its output.
fn finished(child: Child) -> Output {
    let out = child.wait_with_output().unwrap();
    assert!(
        out.status.success(),
        "live run failed: {}",
        String::from_utf8_lossy(&out.stderr)
    );
    out
}

/// The 3x4 poses of a KITTI pose file.
fn kitti_poses(path: &Path) -> Vec<[f64; 12]> {
    std::fs::read_to_string(path)
        .unwrap()
        .lines()
        .map(|l| {
            let v: Vec<f64> = l.split_whitespace().map(|x| x.parse().unwrap()).collect();
            v.try_into().unwrap()
        })
        .collect()
}

fn flat(p: &PoseLine) -> [f64; 12] {
    let m = p.world_from_cam;
    std::array::from_fn(|k| m[k / 4][k % 4])
}

/// A sequence's left images (`image_0/%06d.png`) encoded with H.264 (high quality, CRF 12, a
/// keyframe a second) in MPEG-TS at 10 fps, at `size`.
fn h264_clip(dir: &Path, seq: &Path, name: &str, size: (usize, usize)) -> PathBuf {
    let clip = dir.join(format!("{name}.ts"));
    let pattern = seq.join("image_0/%06d.png");
    ffmpeg(&[
        "-framerate",
        "10",
        "-i",
        pattern.to_str().unwrap(),
        "-vf",
        &format!("scale={}:{}:flags=area", size.0, size.1),
        "-c:v",
        "libx264",
        "-preset",
        "ultrafast",
        "-pix_fmt",
        "gray",
        "-crf",
        "12",
        "-g",
        "10",
        "-tune",
        "zerolatency",
        "-f",
        "mpegts",
        clip.to_str().unwrap(),
    ]);
    clip
}

/// KITTI 06's 51 frames as [`h264_clip`] encodes them, at `size`; the camera file of that size
/// beside it.
fn kitti_clip(dir: &Path, seq: &Path, name: &str, size: (usize, usize)) -> (PathBuf, PathBuf) {
    let clip = h264_clip(dir, seq, name, size);
    // KITTI 06's P0 scaled to the size (pixel centres: (c + 0.5) s - 0.5)
    let s = size.0 as f64 / 1226.0;
    let camera = dir.join(format!("{name}.yaml"));
    camera_file(
        &camera,
        [707.0912 * s; 2],
        (601.8873 + 0.5) * s - 0.5,
        (183.1104 + 0.5) * s - 0.5,
        size,
    );
    (clip, camera)
}

#[test]
fn a_udp_stream_of_kitti_06_gives_the_file_runs_poses_and_drops_frames_when_slow() {
    let _serial = serial();
    let Some(seq) = shared_data("kitti/odometry/sequences/06") else {
        return;
    };
    if !have_ffmpeg() {
        return;
    }
    let dir = tempfile::tempdir().unwrap();
    let d = dir.path();
    // 1. every frame (policy all, the real-time preset at half size): the poses of the run on
    // the recorded stream, exactly: the same H.264 bitstream decoded by the same decoder gives
    // the same images (a lost UDP packet would change a frame and fail this)
    let (half, half_cam) = kitti_clip(d, &seq, "half", (613, 185));
    let file_out = d.join("file.txt");
    run_ok(
        visnav()
            .args(["-q", "odometry", "--mode", "mono", "--preset", "realtime"])
            .arg(&half)
            .arg("--camera")
            .arg(&half_cam)
            .arg("-o")
            .arg(&file_out),
    );
    let port = free_port();
    let live_out = d.join("live.txt");
    let mut rx = start_live(
        port,
        &half_cam,
        &live_out,
        &[
            "--preset",
            "realtime",
            "--frames-policy",
            "all",
            "--reconnect",
            "0",
            "--stream-timeout",
            "1",
        ],
    );
    wait_listening(port, &mut rx);
    send(&half, port);
    let out = finished(rx);
    let lines = pose_lines(&out);
    assert_eq!(lines.len(), 51);
    let file = kitti_poses(&file_out);
    assert_eq!(
        kitti_poses(&live_out),
        file,
        "live poses differ from the file run's"
    );
    for (k, l) in lines.iter().enumerate() {
        assert_eq!((l.step, l.index, l.dropped_before), (k, k, 0));
        // the stream's presentation times (90 kHz clock), not arrival times
        assert!(
            (l.timestamp_s.unwrap() - 0.1 * k as f64).abs() < 1e-4,
            "{l:?}"
        );
        for (a, b) in flat(l).iter().zip(&file[k]) {
            assert!((a - b).abs() <= 1e-9 * (1.0 + b.abs()), "frame {k}");
        }
    }
    let report = RunReport::read(&live_out.with_extension("json")).unwrap();
    let live = report.live.as_ref().unwrap();
    assert_eq!((live.frames_received, report.dropped_frames), (51, 0));
    assert!(
        report
            .latency
            .is_some_and(|l| l.median_ms > 0.0 && l.p95_ms >= l.median_ms)
    );

    // 2. a slower odometry (the real-time preset on full-size frames, several times the
    // camera's 100 ms) with the default policy: frames are dropped and counted, and the
    // trajectory spans the clip at the stream's times
    let (full, full_cam) = kitti_clip(d, &seq, "full", (1226, 370));
    let port = free_port();
    let slow_out = d.join("slow.txt");
    let mut rx = start_live(
        port,
        &full_cam,
        &slow_out,
        &[
            "--preset",
            "realtime",
            "--reconnect",
            "0",
            "--stream-timeout",
            "1",
        ],
    );
    wait_listening(port, &mut rx);
    send(&full, port);
    let out = finished(rx);
    let lines = pose_lines(&out);
    let report = RunReport::read(&slow_out.with_extension("json")).unwrap();
    let live = report.live.as_ref().unwrap();
    assert_eq!(live.frames_received, 51);
    assert!(report.dropped_frames > 0, "no frame dropped");
    assert_eq!(report.dropped_frames + lines.len(), 51);
    assert_eq!(
        lines.iter().map(|l| l.dropped_before).sum::<usize>(),
        report.dropped_frames
    );
    assert_eq!(lines[0].index, 0);
    // the last frame is never dropped: no later frame replaces it
    assert_eq!(lines.last().unwrap().index, 50);
    for w in lines.windows(2) {
        assert_eq!(w[1].index - w[0].index - 1, w[1].dropped_before);
        let dt = w[1].timestamp_s.unwrap() - w[0].timestamp_s.unwrap();
        assert!((dt - 0.1 * (w[1].index - w[0].index) as f64).abs() < 1e-4);
    }
    // where the poses end is the estimator's matter, not the policy's: with the odometry a few
    // camera intervals behind (an idle machine) the end point lands within 2 m of KITTI's
    // ground truth (58.1 of 59.8 m), but on a loaded machine the gaps grow to 10-20 frames,
    // beyond what the frame-to-frame flow matches (docs/guide/live.md); the prediction over the
    // true time step is tested in visnav-pipeline/tests/live_time_step.rs
}

/// Encodes `seconds` of ffmpeg's moving test pattern (160x120, 10 fps, H.264, a keyframe every
/// 5 frames) into `clip`.
fn test_pattern(clip: &Path, seconds: f64) {
    ffmpeg(&[
        "-f",
        "lavfi",
        "-i",
        "testsrc=size=160x120:rate=10",
        "-t",
        &seconds.to_string(),
        "-c:v",
        "libx264",
        "-pix_fmt",
        "gray",
        "-g",
        "5",
        "-tune",
        "zerolatency",
        "-f",
        "mpegts",
        clip.to_str().unwrap(),
    ]);
}

#[test]
fn a_stream_that_stops_and_returns_is_a_gap_then_a_reconnection() {
    let _serial = serial();
    if !have_ffmpeg() {
        return;
    }
    let dir = tempfile::tempdir().unwrap();
    let d = dir.path();
    let (first, second) = (d.join("a.ts"), d.join("b.ts"));
    test_pattern(&first, 1.5);
    test_pattern(&second, 3.0);
    let cam = d.join("cam.yaml");
    camera_file(&cam, [150.0; 2], 79.5, 59.5, (160, 120));
    let port = free_port();
    let out_path = d.join("poses.txt");
    let mut rx = start_live(
        port,
        &cam,
        &out_path,
        &[
            "--preset",
            "realtime",
            "--frames-policy",
            "all",
            "--reconnect",
            "2",
            "--stream-timeout",
            "1",
        ],
    );
    wait_listening(port, &mut rx);
    send(&first, port);
    // the lost stream: ffmpeg ends at its timeout, and listens again after the backoff
    let start = Instant::now();
    while UdpSocket::bind(("127.0.0.1", port)).is_err() {
        assert!(
            start.elapsed() < Duration::from_secs(60),
            "never reconnects"
        );
        std::thread::sleep(Duration::from_millis(20));
    }
    wait_listening(port, &mut rx);
    send(&second, port);
    let out = finished(rx);
    let stderr = String::from_utf8_lossy(&out.stderr);
    assert!(stderr.contains("reconnecting in"), "{stderr}");
    let lines = pose_lines(&out);
    let report = RunReport::read(&out_path.with_extension("json")).unwrap();
    let live = report.live.as_ref().unwrap();
    assert!(live.reconnects >= 1);
    assert!(
        live.end
            .as_deref()
            .unwrap()
            .contains("2 reconnection attempts")
    );
    // frames of both connections, times increasing with the gap between them
    assert!(lines.len() > 15, "{} frames", lines.len());
    let times: Vec<f64> = lines.iter().map(|l| l.timestamp_s.unwrap()).collect();
    assert!(times.windows(2).all(|w| w[1] > w[0]), "{times:?}");
    assert!(times.windows(2).any(|w| w[1] - w[0] > 1.0), "{times:?}");
    assert_eq!(kitti_poses(&out_path).len(), lines.len());
}

#[test]
fn bad_live_input_is_a_clear_error_and_never_a_hang() {
    let _serial = serial();
    if !have_ffmpeg() {
        return;
    }
    let dir = tempfile::tempdir().unwrap();
    let d = dir.path();
    let cam = d.join("cam.yaml");
    camera_file(&cam, [150.0; 2], 79.5, 59.5, (160, 120));
    let out = d.join("poses.txt");
    let odometry = |input: &str| {
        let mut c = visnav();
        c.args(["odometry", "--mode", "mono", input, "-o"])
            .arg(&out);
        c
    };
    // no camera file
    let e = run_err(&mut odometry("udp://127.0.0.1:9"));
    assert!(
        e.contains("udp://127.0.0.1:9") && e.contains("--camera"),
        "{e}"
    );
    // a port nobody sends to: ffmpeg's timeout, one reconnection, then an error naming it
    let port = free_port();
    let url = format!("udp://127.0.0.1:{port}");
    let start = Instant::now();
    let e = run_err(odometry(&url).arg("--camera").arg(&cam).args([
        "--stream-timeout",
        "0.5",
        "--reconnect",
        "1",
    ]));
    assert!(
        start.elapsed() < Duration::from_secs(30),
        "took {:?}",
        start.elapsed()
    );
    assert!(
        e.contains(&url) && e.contains("lost") && e.contains("1 reconnection"),
        "{e}"
    );
    // an unreachable RTSP server (connection refused)
    let e = run_err(
        odometry("rtsp://127.0.0.1:9/stream")
            .arg("--camera")
            .arg(&cam)
            .args(["--stream-timeout", "1", "--reconnect", "0"]),
    );
    assert!(e.contains("rtsp://127.0.0.1:9/stream"), "{e}");
    // a stream of another size than the camera file's
    let clip = d.join("p.ts");
    test_pattern(&clip, 3.0);
    let wrong = d.join("wrong.yaml");
    camera_file(&wrong, [150.0; 2], 49.5, 49.5, (100, 100));
    let port = free_port();
    let mut rx = visnav()
        .args(["odometry", "--mode", "mono"])
        .arg(format!("udp://127.0.0.1:{port}"))
        .arg("--camera")
        .arg(&wrong)
        .arg("-o")
        .arg(&out)
        .stderr(Stdio::piped())
        .spawn()
        .unwrap();
    wait_listening(port, &mut rx);
    send(&clip, port);
    let o = rx.wait_with_output().unwrap();
    let e = String::from_utf8_lossy(&o.stderr);
    assert!(!o.status.success());
    assert!(
        e.contains("wrong.yaml") && e.contains("100x100") && e.contains("160x120"),
        "{e}"
    );
    // options a live input cannot take
    for (args, what) in [
        (&["--mode", "stereo"][..], "--mode stereo"),
        (&["--loop-closure"][..], "loop closure"),
        (&["--report"][..], "--report"),
    ] {
        let mode: &[&str] = if args[0] == "--mode" {
            &[]
        } else {
            &["--mode", "mono"]
        };
        let e = run_err(
            visnav()
                .args(["odometry", "udp://127.0.0.1:9", "--camera"])
                .arg(&cam)
                .arg("-o")
                .arg(&out)
                .args(mode)
                .args(args),
        );
        assert!(e.contains(what), "{args:?}: {e}");
    }
}

#[test]
fn sigterm_ends_a_live_run_with_every_output_written() {
    let _serial = serial();
    if !have_ffmpeg() {
        return;
    }
    let dir = tempfile::tempdir().unwrap();
    let d = dir.path();
    let cam = d.join("cam.yaml");
    camera_file(&cam, [150.0; 2], 79.5, 59.5, (160, 120));
    let port = free_port();
    let out_path = d.join("poses.txt");
    let mut rx = start_live(port, &cam, &out_path, &["--preset", "realtime"]);
    wait_listening(port, &mut rx);
    // an endless stream
    let mut tx = Command::new("ffmpeg")
        .args(["-v", "error", "-nostdin", "-re", "-f", "lavfi", "-i"])
        .args([
            "testsrc=size=160x120:rate=10",
            "-c:v",
            "libx264",
            "-pix_fmt",
            "gray",
        ])
        .args(["-g", "5", "-tune", "zerolatency", "-f", "mpegts"])
        .arg(format!("udp://127.0.0.1:{port}"))
        .spawn()
        .unwrap();
    let partial = d.join("poses.txt.partial");
    let start = Instant::now();
    while std::fs::read_to_string(&partial).map_or(0, |t| t.lines().count()) < 5 {
        assert!(start.elapsed() < Duration::from_secs(120), "no poses");
        std::thread::sleep(Duration::from_millis(100));
    }
    let ok = Command::new("kill")
        .args(["-TERM", &rx.id().to_string()])
        .status()
        .unwrap()
        .success();
    assert!(ok);
    let out = finished(rx);
    tx.kill().unwrap();
    tx.wait().unwrap();
    let lines = pose_lines(&out);
    let report = RunReport::read(&out_path.with_extension("json")).unwrap();
    assert!(report.interrupted);
    assert!(lines.len() >= 5);
    assert_eq!(report.frames, lines.len());
    assert_eq!(kitti_poses(&out_path).len(), lines.len());
    assert!(!partial.exists());
    assert!(d.join("poses.tum.txt").exists());
}

#[test]
fn poses_out_works_for_recordings_on_stdout_and_as_datagrams() {
    let _serial = serial();
    let dir = tempfile::tempdir().unwrap();
    let seq = dir.path().join("seq");
    synth_sequence(&seq, 6, 160, 96);
    let out_path = dir.path().join("poses.txt");
    let run = |target: &str| {
        run_ok(
            visnav()
                .args(["odometry", "--mode", "mono", "--preset", "realtime"])
                .arg(&seq)
                .arg("-o")
                .arg(&out_path)
                .args(["--poses-out", target]),
        )
    };
    // standard output: the pose lines only (the summary goes to stderr)
    let out = run("-");
    let lines = pose_lines(&out);
    assert_eq!(lines.len(), 6);
    assert!(String::from_utf8_lossy(&out.stderr).contains("poses:"));
    let poses = kitti_poses(&out_path);
    for (l, p) in lines.iter().zip(&poses) {
        for (a, b) in flat(l).iter().zip(p) {
            assert!((a - b).abs() <= 1e-9 * (1.0 + b.abs()));
        }
        assert!(l.latency_ms >= 0.0);
    }
    // UDP: one datagram a frame
    let socket = UdpSocket::bind("127.0.0.1:0").unwrap();
    socket
        .set_read_timeout(Some(Duration::from_secs(2)))
        .unwrap();
    let port = socket.local_addr().unwrap().port();
    run(&format!("udp://127.0.0.1:{port}"));
    let mut buf = [0u8; 65536];
    let mut got = Vec::new();
    while let Ok(n) = socket.recv(&mut buf) {
        let line: PoseLine = serde_json::from_slice(&buf[..n]).unwrap();
        got.push(line);
    }
    assert_eq!(got.len(), 6);
    assert_eq!(
        got.iter().map(|l| l.step).collect::<Vec<_>>(),
        [0, 1, 2, 3, 4, 5]
    );
    // a target that is neither
    let e = run_err(
        visnav()
            .args(["odometry", "--mode", "mono"])
            .arg(&seq)
            .arg("-o")
            .arg(&out_path)
            .args(["--poses-out", "tcp://127.0.0.1:9"]),
    );
    assert!(e.contains("--poses-out tcp://127.0.0.1:9"), "{e}");
    let e = run_err(
        visnav()
            .args(["odometry", "--mode", "mono"])
            .arg(&seq)
            .arg("-o")
            .arg(&out_path)
            .args(["--frames-policy", "newest"]),
    );
    assert!(e.contains("live input only"), "{e}");
}

/// A stereo recording's pose lines carry each step's covariance, the one of the `--json`
/// report; the first frame (no step of its own) has none.
#[test]
fn pose_lines_of_a_stereo_recording_carry_the_step_covariance() {
    let Some(seq) = shared_data("kitti/odometry/sequences/06") else {
        return;
    };
    let dir = tempfile::tempdir().unwrap();
    let json = dir.path().join("run.json");
    let out = run_ok(
        visnav()
            .args(["odometry", "--mode", "stereo", "--max-frames", "6"])
            .arg(&seq)
            .arg("-o")
            .arg(dir.path().join("poses.txt"))
            .arg("--json")
            .arg(&json)
            .args(["--poses-out", "-"]),
    );
    let lines = pose_lines(&out);
    assert_eq!(lines.len(), 6);
    let report: RunReport = serde_json::from_slice(&std::fs::read(&json).unwrap()).unwrap();
    assert!(lines[0].prev_from_cur_covariance.is_none());
    for (l, f) in lines.iter().zip(&report.per_frame).skip(1) {
        let c = l
            .prev_from_cur_covariance
            .expect("a stereo step has a covariance");
        assert_eq!(Some(c), f.prev_from_cur_covariance);
        assert!((0..6).all(|i| c[i][i] > 0.0 && c[i][i].is_finite()));
    }
}

#[test]
fn standard_input_is_read_to_its_end() {
    let _serial = serial();
    if !have_ffmpeg() {
        return;
    }
    let dir = tempfile::tempdir().unwrap();
    let d = dir.path();
    let clip = d.join("p.ts");
    test_pattern(&clip, 2.0);
    let cam = d.join("cam.yaml");
    camera_file(&cam, [150.0; 2], 79.5, 59.5, (160, 120));
    let out_path = d.join("poses.txt");
    let out = run_ok(
        visnav()
            .args(["odometry", "--mode", "mono", "--preset", "realtime", "-"])
            .arg("--camera")
            .arg(&cam)
            .arg("-o")
            .arg(&out_path)
            .arg("--json")
            .arg(out_path.with_extension("json"))
            .args(["--frames-policy", "all", "--poses-out", "-"])
            .stdin(std::fs::File::open(&clip).unwrap()),
    );
    let lines = pose_lines(&out);
    assert_eq!(lines.len(), 20);
    let report = RunReport::read(&out_path.with_extension("json")).unwrap();
    let live = report.live.as_ref().unwrap();
    assert!(!report.interrupted);
    assert!(
        live.end.as_deref().unwrap().contains("standard input"),
        "{live:?}"
    );
    assert!((lines[19].timestamp_s.unwrap() - 1.9).abs() < 1e-4);
}

/// A rendered monocular drive (exact ground truth; `visnav synth`, 40 frames of 480x144) streamed
/// live at 10 fps gives the poses of the run on the recorded stream, and they follow the ground
/// truth with the metric scale from the camera height, through the H.264 noise.
#[test]
fn a_udp_stream_of_a_rendered_drive_gives_the_file_runs_poses() {
    let _serial = serial();
    if !have_ffmpeg() {
        return;
    }
    let dir = tempfile::tempdir().unwrap();
    let d = dir.path();
    let seq = d.join("drive");
    synth_sequence(&seq, 40, 480, 144);
    let clip = h264_clip(d, &seq, "drive", (480, 144));
    // the renderer's camera, as its calib.txt holds it (P0: fx 0 cx 0 0 fy cy ...)
    let calib = std::fs::read_to_string(seq.join("calib.txt")).unwrap();
    let p0: Vec<f64> = calib.lines().next().unwrap()[3..]
        .split_whitespace()
        .map(|v| v.parse().unwrap())
        .collect();
    let camera = d.join("drive.yaml");
    camera_file(&camera, [p0[0], p0[5]], p0[2], p0[6], (480, 144));
    let flags = ["--preset", "realtime", "--camera-height", "1.65"];
    let file_out = d.join("file.txt");
    run_ok(
        visnav()
            .args(["-q", "odometry", "--mode", "mono"])
            .arg(&clip)
            .arg("--camera")
            .arg(&camera)
            .args(flags)
            .arg("-o")
            .arg(&file_out),
    );
    let port = free_port();
    let live_out = d.join("live.txt");
    let mut args = flags.to_vec();
    args.extend([
        "--frames-policy",
        "all",
        "--reconnect",
        "0",
        "--stream-timeout",
        "1",
    ]);
    let mut rx = start_live(port, &camera, &live_out, &args);
    wait_listening(port, &mut rx);
    send(&clip, port);
    let lines = pose_lines(&finished(rx));
    assert_eq!(lines.len(), 40);
    assert_eq!(kitti_poses(&live_out), kitti_poses(&file_out));
    // against the ground truth: the last pose within 10 % of the path (29 m; 1.28 m = 4.4 %
    // measured on 2026-12-02), the mono step covariance on the lines
    let gt = kitti_poses(&seq.join("poses.txt"));
    let est = kitti_poses(&live_out);
    let position = |p: &[f64; 12]| [p[3], p[7], p[11]];
    let path: f64 = gt
        .windows(2)
        .map(|w| {
            let (a, b) = (position(&w[0]), position(&w[1]));
            ((a[0] - b[0]).powi(2) + (a[1] - b[1]).powi(2) + (a[2] - b[2]).powi(2)).sqrt()
        })
        .sum();
    let (a, b) = (position(&gt[39]), position(&est[39]));
    let end_error = ((a[0] - b[0]).powi(2) + (a[1] - b[1]).powi(2) + (a[2] - b[2]).powi(2)).sqrt();
    eprintln!("rendered drive over UDP: end point {end_error:.3} m of a {path:.1} m path");
    assert!(
        end_error < 0.1 * path,
        "end point {end_error} m of {path} m"
    );
    let with_covariance = lines
        .iter()
        .filter(|l| l.prev_from_cur_covariance.is_some())
        .count();
    assert!(
        with_covariance >= 30,
        "{with_covariance} steps with a covariance"
    );
}
