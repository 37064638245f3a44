//! ROS 2 bags (MCAP) built here with the `mcap` crate's writer: a stereo sequence with
//! `CameraInfo` opens with the right camera, pairing and frame order; and the reader survives
//! mutated files (byte flips, truncation, inserted bytes: `VISNAV_FUZZ_CASES` cases, default
//! 48) with a clear error or a result, never a panic. The bags written by the independent
//! Python `rosbags` package from the real KITTI and EuRoC clips are tested in
//! `python/tests/test_rosbag.py`.

#![allow(clippy::unwrap_used)] // test helpers build fixed, known-good bags

use std::collections::BTreeMap;
use std::io::Cursor;
use std::path::Path;

use proptest::prelude::*;
use proptest::test_runner::{Config, TestRunner};
use visnav_io::bag::cdr::CdrWriter;
use visnav_io::bag::{BagOptions, msgs, open_bag_sequence};
use visnav_io::{FrameSource, SequenceLayout};

const W: u32 = 16;
const H: u32 = 8;

fn header(w: &mut CdrWriter, stamp_ns: i64, frame: &str) {
    w.i32(i32::try_from(stamp_ns / 1_000_000_000).unwrap());
    w.u32(u32::try_from(stamp_ns % 1_000_000_000).unwrap());
    w.string(frame);
}

fn image(stamp_ns: i64, value: u8) -> Vec<u8> {
    let mut w = CdrWriter::new();
    header(&mut w, stamp_ns, "cam");
    w.u32(H);
    w.u32(W);
    w.string("mono8");
    w.u8(0);
    w.u32(W);
    let px: Vec<u8> = (0..W * H).map(|i| value.wrapping_add(i as u8)).collect();
    w.bytes(&px);
    w.finish()
}

/// A rectified camera: `P = [f 0 c tx; 0 f c 0; 0 0 1 0]`.
fn camera_info(stamp_ns: i64, tx: f64) -> Vec<u8> {
    let mut w = CdrWriter::new();
    header(&mut w, stamp_ns, "cam");
    w.u32(H);
    w.u32(W);
    w.string("plumb_bob");
    w.f64_seq(&[0.0; 5]);
    for v in [20.0, 0.0, 8.0, 0.0, 20.0, 4.0, 0.0, 0.0, 1.0] {
        w.f64(v);
    }
    for v in [1.0, 0.0, 0.0, 0.0, 1.0, 0.0, 0.0, 0.0, 1.0] {
        w.f64(v);
    }
    for v in [20.0, 0.0, 8.0, tx, 0.0, 20.0, 4.0, 0.0, 0.0, 0.0, 1.0, 0.0] {
        w.f64(v);
    }
    for _ in 0..6 {
        w.u32(0);
    }
    w.u8(0);
    w.finish()
}

/// A stereo bag of `n` frames at 10 Hz; the right image of frame `drop` is missing and the
/// messages are written out of stamp order (right before left, frames 1 and 2 swapped).
fn stereo_bag(n: i64, drop: i64, compression: Option<mcap::Compression>) -> Vec<u8> {
    let mut w = mcap::WriteOptions::new()
        .compression(compression)
        .chunk_size(Some(700))
        .create(Cursor::new(Vec::new()))
        .unwrap();
    let empty = BTreeMap::new();
    let img = w.add_schema(msgs::IMAGE, "ros2msg", b"").unwrap();
    let info = w.add_schema(msgs::CAMERA_INFO, "ros2msg", b"").unwrap();
    let ch = |w: &mut mcap::Writer<_>, s, t| w.add_channel(s, t, "cdr", &empty).unwrap();
    let left = ch(&mut w, img, "/left/image_raw");
    let right = ch(&mut w, img, "/right/image_raw");
    let left_info = ch(&mut w, info, "/left/camera_info");
    let right_info = ch(&mut w, info, "/right/camera_info");
    let order: Vec<i64> = (0..n)
        .map(|i| match i {
            1 => 2,
            2 => 1,
            i => i,
        })
        .collect();
    for (seq, &i) in order.iter().enumerate() {
        let t = 1_000_000_000 + i * 100_000_000;
        let mut put = |channel_id, data: Vec<u8>| {
            let h = mcap::records::MessageHeader {
                channel_id,
                sequence: u32::try_from(seq).unwrap(),
                log_time: u64::try_from(t).unwrap(),
                publish_time: u64::try_from(t).unwrap(),
            };
            w.write_to_known_channel(&h, &data).unwrap();
        };
        if i != drop {
            // a right stamp 2 ms after the left one: within the default tolerance (10 ms)
            put(right, image(t + 2_000_000, 100 + i as u8));
        }
        put(left, image(t, i as u8));
        put(left_info, camera_info(t, 0.0));
        put(right_info, camera_info(t, -10.0));
    }
    w.finish().unwrap();
    w.into_inner().into_inner()
}

#[test]
fn a_stereo_bag_opens_in_stamp_order_with_its_camera_and_pairs() {
    let dir = tempfile::tempdir().unwrap();
    let path = dir.path().join("s.mcap");
    for compression in [None, Some(mcap::Compression::Lz4)] {
        std::fs::write(&path, stereo_bag(6, 3, compression)).unwrap();
        let seq = open_bag_sequence(
            &path,
            &BagOptions {
                topic: Some("/left/image_raw".into()),
                right_topic: Some("/right/image_raw".into()),
                ..BagOptions::default()
            },
        )
        .unwrap();
        assert_eq!(seq.load_right(5).unwrap().data()[0], 105.0);
    }
    std::fs::write(&path, stereo_bag(6, 3, Some(mcap::Compression::Zstd))).unwrap();
    let options = BagOptions {
        topic: Some("/left/image_raw".into()),
        right_topic: Some("/right/image_raw".into()),
        ..BagOptions::default()
    };
    let seq = open_bag_sequence(&path, &options).unwrap();
    assert_eq!(seq.layout, SequenceLayout::RosBag);
    assert_eq!(seq.len(), 6);
    assert!(seq.has_stereo());
    assert_eq!(
        (seq.camera.fx, seq.camera.cx, seq.camera.cy),
        (20.0, 8.0, 4.0)
    );
    assert_eq!(seq.baseline_m, Some(0.5));
    assert!((seq.timestamps[2] - 1.2).abs() < 1e-12);
    for i in 0..6 {
        // frames in stamp order although written out of order
        let left = seq.load_left(i).unwrap();
        assert_eq!(left.data()[0], i as f32);
        let right = seq.load_right(i);
        if i == 3 {
            assert!(right.unwrap_err().to_string().contains("/right/image_raw"));
        } else {
            assert_eq!(right.unwrap().data()[0], 100.0 + i as f32);
        }
    }
    // the source reports the missing right image as this frame's error
    assert!(seq.item(3, true).frame.is_err());
    // the only-topic rule: two image topics need --topic
    let e = open_bag_sequence(&path, &BagOptions::default())
        .unwrap_err()
        .to_string();
    assert!(
        e.contains("--topic") && e.contains("/left/image_raw"),
        "{e}"
    );
    // the directory of a rosbag2 bag opens the same way as its file
    let bag_dir = dir.path().join("rosbag2");
    std::fs::create_dir(&bag_dir).unwrap();
    std::fs::copy(&path, bag_dir.join("rosbag2_0.mcap")).unwrap();
    std::fs::write(
        bag_dir.join("metadata.yaml"),
        "rosbag2_bagfile_information: {}\n",
    )
    .unwrap();
    assert_eq!(open_bag_sequence(&bag_dir, &options).unwrap().len(), 6);
}

fn cases() -> u32 {
    std::env::var("VISNAV_FUZZ_CASES")
        .ok()
        .and_then(|v| v.parse().ok())
        .unwrap_or(48)
}

/// Opens a mutated bag and reads every frame: an error must name the file.
fn read_all(path: &Path) -> Result<usize, String> {
    let options = BagOptions {
        topic: Some("/left/image_raw".into()),
        right_topic: Some("/right/image_raw".into()),
        ..BagOptions::default()
    };
    let seq = open_bag_sequence(path, &options).map_err(|e| e.to_string())?;
    let mut ok = 0;
    for i in 0..seq.len() {
        if seq.item(i, true).frame.is_ok() {
            ok += 1;
        }
    }
    Ok(ok)
}

#[test]
fn mutated_bags_give_errors_never_panics() {
    let seed = stereo_bag(5, 99, Some(mcap::Compression::Zstd));
    let dir = tempfile::tempdir().unwrap();
    let path = dir.path().join("fuzz.mcap");
    let mut runner = TestRunner::new(Config {
        cases: cases(),
        failure_persistence: None,
        ..Config::default()
    });
    let strategy = prop_oneof![
        (any::<usize>(), 1..=255u8).prop_map(|(i, m)| (0u8, i, m)),
        any::<usize>().prop_map(|i| (1u8, i, 0)),
        (any::<usize>(), any::<u8>()).prop_map(|(i, b)| (2u8, i, b)),
    ];
    let result = runner.run(&proptest::collection::vec(strategy, 1..4), |muts| {
        let mut bytes = seed.clone();
        for (kind, i, b) in muts {
            let len = bytes.len();
            match kind {
                0 if len > 0 => bytes[i % len] ^= b,
                1 => bytes.truncate(i % (len + 1)),
                _ => bytes.insert(i % (len + 1), b),
            }
        }
        std::fs::write(&path, &bytes).unwrap();
        if let Err(e) = read_all(&path) {
            prop_assert!(
                e.contains("fuzz.mcap"),
                "the error does not name the file: {e}"
            );
        }
        Ok(())
    });
    if let Err(e) = result {
        panic!("{e}");
    }
}
