//! Scenario tests: the rendered images, depth and flow agree with each other and with the poses.
#![allow(clippy::unwrap_used)]

use nalgebra::{Point2, Point3, Translation3};
use visnav_core::{PinholeCamera, Pose, StereoCamera};
use visnav_synth::{
    FlowGt, KITTI_BASELINE_M, Scene, View, drive_trajectory, flow_between, kitti_like_camera,
    render_stereo, render_view, warp_by_flow,
};

fn small_cam() -> PinholeCamera {
    kitti_like_camera(320, 96)
}

/// Mean absolute difference between `image_a` and `image_b` warped by the flow, over valid
/// pixels away from the border; and the number of pixels compared.
fn warp_error(a: &View, b: &View, gt: &FlowGt) -> (f64, usize) {
    let warped = warp_by_flow(&b.image, &gt.flow);
    let w = a.image.width();
    let h = a.image.height();
    let mut sum = 0.0;
    let mut count = 0;
    for y in 2..h - 2 {
        for x in 2..w - 2 {
            let i = y * w + x;
            if let (true, Some(v)) = (gt.valid[i], warped[i]) {
                sum += f64::from((v - a.image.get(x, y)).abs());
                count += 1;
            }
        }
    }
    (sum / count.max(1) as f64, count)
}

#[test]
fn warping_by_ground_truth_flow_reproduces_the_frame() {
    let poses = drive_trajectory(60, 11);
    let scene = Scene::along(&poses, 11).unwrap();
    let cam = small_cam();
    // cruise, turn, standstill, rotation on the spot, late cruise
    for i in [3usize, 14, 27, 39, 55] {
        let a = render_view(&scene, &cam, &poses[i]);
        let b = render_view(&scene, &cam, &poses[i + 1]);
        let gt = flow_between(&scene, &cam, &poses[i], &a, &poses[i + 1], &b);
        let (mae, n) = warp_error(&a, &b, &gt);
        eprintln!(
            "frame {i}: warp MAE {mae:.3} gray levels over {n} px, valid {:.3}",
            gt.valid_fraction()
        );
        assert!(n > 320 * 96 / 2, "too few valid pixels: {n}");
        assert!(mae < 2.0, "frame {i}: MAE {mae}");
    }
}

#[test]
fn flow_is_consistent_forward_and_backward() {
    let poses = drive_trajectory(20, 5);
    let scene = Scene::along(&poses, 5).unwrap();
    let cam = small_cam();
    let a = render_view(&scene, &cam, &poses[4]);
    let b = render_view(&scene, &cam, &poses[5]);
    let fwd = flow_between(&scene, &cam, &poses[4], &a, &poses[5], &b);
    let bwd = flow_between(&scene, &cam, &poses[5], &b, &poses[4], &a);
    // at 10 m/s a tenth of the near road leaves the bottom of the image
    assert!(fwd.valid_fraction() > 0.65, "{}", fwd.valid_fraction());
    let w = cam.width as usize;
    let mut worst = 0.0f64;
    let mut checked = 0;
    for y in 0..cam.height as usize {
        for x in 0..w {
            if !fwd.valid[y * w + x] {
                continue;
            }
            let (u, v) = fwd.flow.get(x, y);
            let tx = x as f64 + f64::from(u);
            let ty = y as f64 + f64::from(v);
            // nearest target pixel: the backward flow there returns within a pixel-ish of (x, y)
            // after accounting for the sub-pixel offset to the target
            let (rx, ry) = (tx.round() as usize, ty.round() as usize);
            if !bwd.valid[ry * w + rx] {
                continue;
            }
            let (bu, bv) = bwd.flow.get(rx, ry);
            let back_x = rx as f64 + f64::from(bu);
            let back_y = ry as f64 + f64::from(bv);
            // the round trip error is bounded by the rounding offset times the flow gradient
            let err = ((back_x - x as f64) - (rx as f64 - tx))
                .hypot((back_y - y as f64) - (ry as f64 - ty));
            worst = worst.max(err);
            checked += 1;
        }
    }
    assert!(checked > 10_000, "{checked}");
    assert!(worst < 0.6, "worst round trip {worst} px");
}

#[test]
fn depth_and_flow_agree_with_the_poses() {
    let scene = Scene::city(2);
    let cam = small_cam();
    let a_pose = Pose::identity();
    let b_pose = Pose::from_parts(
        Translation3::new(0.1, -0.02, 1.0),
        nalgebra::UnitQuaternion::from_euler_angles(0.01, 0.03, -0.005),
    );
    let a = render_view(&scene, &cam, &a_pose);
    let b = render_view(&scene, &cam, &b_pose);
    let gt = flow_between(&scene, &cam, &a_pose, &a, &b_pose, &b);
    let w = cam.width as usize;
    // the road straight below the camera is the plane y = 1.65: z = fy * 1.65 / (v - cy)
    for y in (cam.cy.ceil() as usize + 8)..cam.height as usize {
        let x = cam.cx.round() as usize;
        let z = f64::from(a.depth_at(x, y));
        let expected = cam.fy * 1.65 / (y as f64 - cam.cy);
        assert!(
            (z - expected).abs() < 1e-4 * expected,
            "row {y}: {z} vs {expected}"
        );
    }
    // every valid pixel: the 3-D point from depth a, moved by the relative pose, lands at the
    // flow target with the depth that view b rendered there
    let b_from_a = b_pose.inverse() * a_pose;
    let mut checked = 0;
    for y in 0..cam.height as usize {
        for x in 0..w {
            let i = y * w + x;
            let z = f64::from(a.depth_m[i]);
            if !gt.valid[i] || !z.is_finite() {
                continue;
            }
            let p_in_b = b_from_a * cam.unproject(&Point2::new(x as f64, y as f64), z);
            let target = cam.project(&p_in_b).unwrap();
            let (u, v) = gt.flow.get(x, y);
            assert!((target.x - x as f64 - f64::from(u)).abs() < 1e-3);
            assert!((target.y - y as f64 - f64::from(v)).abs() < 1e-3);
            if p_in_b.z < 30.0 {
                // view b rendered the same surface there: nearest-pixel depth differs by at
                // most the depth gradient over half a pixel
                let (tx, ty) = (target.x.round() as usize, target.y.round() as usize);
                let z_b = f64::from(b.depth_at(tx, ty));
                assert!(
                    (z_b - p_in_b.z).abs() < 0.1 * p_in_b.z,
                    "{z_b} vs {}",
                    p_in_b.z
                );
            }
            checked += 1;
        }
    }
    assert!(checked > 320 * 96 / 2, "{checked}");
}

#[test]
fn right_image_at_disparity_matches_left() {
    let poses = drive_trajectory(10, 3);
    let scene = Scene::along(&poses, 3).unwrap();
    let rig = StereoCamera::new(small_cam(), KITTI_BASELINE_M).unwrap();
    let (left, right) = render_stereo(&scene, &rig, &poses[5]);
    let w = rig.left.width as usize;
    let mut sum = 0.0;
    let mut n = 0;
    for y in 2..rig.left.height as usize - 2 {
        for x in 2..w - 2 {
            let z = f64::from(left.depth_at(x, y));
            let d = if z.is_finite() {
                rig.left.fx * rig.baseline_m / z
            } else {
                0.0
            };
            let xr = x as f64 - d;
            // visible in the right image: its depth there agrees
            let Some(zr) = right
                .image
                .bilinear(xr, y as f64)
                .and(Some(right.depth_at(xr.round().max(0.0) as usize, y)))
            else {
                continue;
            };
            if z.is_finite() && (f64::from(zr) - z).abs() > 0.01 * z {
                continue;
            }
            if !z.is_finite() && zr.is_finite() {
                continue;
            }
            sum += f64::from(
                (right.image.bilinear(xr, y as f64).unwrap() - left.image.get(x, y)).abs(),
            );
            n += 1;
        }
    }
    let mae = sum / n as f64;
    eprintln!("stereo: MAE {mae:.3} over {n} px");
    assert!(n > 320 * 96 / 2);
    assert!(mae < 2.5, "{mae}");
    // the flow from the left to the right camera is the disparity, purely horizontal
    let right_pose = poses[5] * Translation3::new(KITTI_BASELINE_M, 0.0, 0.0);
    let gt = flow_between(&scene, &rig.left, &poses[5], &left, &right_pose, &right);
    for i in (0..w * rig.left.height as usize).step_by(37) {
        let z = f64::from(left.depth_m[i]);
        let (u, v) = gt.flow.get(i % w, i / w);
        let d = if z.is_finite() {
            rig.left.fx * rig.baseline_m / z
        } else {
            0.0
        };
        assert!(
            (f64::from(u) + d).abs() < 1e-3 && v.abs() < 1e-4,
            "{u} {v} vs {d}"
        );
    }
}

#[test]
fn deterministic_for_a_seed_and_different_for_another() {
    let cam = kitti_like_camera(160, 48);
    let pose = Pose::translation(0.0, 0.0, 5.0);
    let a = render_view(&Scene::city(4), &cam, &pose);
    let b = render_view(&Scene::city(4), &cam, &pose);
    let c = render_view(&Scene::city(5), &cam, &pose);
    assert_eq!(a, b);
    let diff = a
        .image
        .data()
        .iter()
        .zip(c.image.data())
        .filter(|(p, q)| (*p - *q).abs() > 1.0)
        .count();
    assert!(diff > 160 * 48 / 4, "{diff}");
}

#[test]
fn images_look_like_kitti() {
    let cam = kitti_like_camera(320, 96);
    let view = render_view(&Scene::city(1), &cam, &Pose::identity());
    let data = view.image.data();
    let n = data.len() as f32;
    let mean = data.iter().sum::<f32>() / n;
    let std = (data.iter().map(|v| (v - mean).powi(2)).sum::<f32>() / n).sqrt();
    let saturated = data.iter().filter(|v| **v <= 1.0 || **v >= 254.0).count();
    eprintln!("mean {mean:.1}, std {std:.1}");
    assert!((60.0..160.0).contains(&mean), "mean {mean}");
    assert!((20.0..80.0).contains(&std), "std {std}");
    assert_eq!(saturated, 0);
    // texture everywhere: the mean gradient magnitude on the road is not negligible
    let w = cam.width as usize;
    let mut grad = 0.0f32;
    let mut count = 0;
    for y in 70..94 {
        for x in 100..220 {
            grad += (view.image.get(x + 1, y) - view.image.get(x, y)).abs()
                + (view.image.get(x, y + 1) - view.image.get(x, y)).abs();
            count += 1;
        }
    }
    let _ = w;
    let mean_grad = grad / count as f32;
    eprintln!("road mean gradient {mean_grad:.2}");
    assert!(mean_grad > 0.5, "{mean_grad}");
    // sky has infinite depth, the road finite
    assert!(view.depth_m[0].is_infinite() || view.depth_m[0] > 0.0);
    assert!(view.depth_at(160, 95).is_finite());
    let p = cam.unproject(&Point2::new(160.0, 95.0), f64::from(view.depth_at(160, 95)));
    assert!((p.y - 1.65).abs() < 1e-3, "{p:?}");
    let _ = Point3::<f64>::origin();
}

#[test]
fn standstill_frames_are_identical_with_zero_flow() {
    let poses = drive_trajectory(60, 11);
    let i = (0..59)
        .find(|&i| poses[i] == poses[i + 1])
        .expect("the drive stands still for a few frames");
    let scene = Scene::along(&poses, 11).unwrap();
    let cam = kitti_like_camera(160, 48);
    let a = render_view(&scene, &cam, &poses[i]);
    let b = render_view(&scene, &cam, &poses[i + 1]);
    assert_eq!(a, b);
    let gt = flow_between(&scene, &cam, &poses[i], &a, &poses[i + 1], &b);
    assert!(gt.flow.uv.iter().all(|v| v.abs() < 1e-4));
    assert!(gt.valid_fraction() > 0.97, "{}", gt.valid_fraction());
}
