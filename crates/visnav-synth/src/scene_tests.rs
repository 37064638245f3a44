//! Tests of the scene layout (moved out of `scene.rs` to keep it under the size limit).

use super::shade::pulse_box;
use super::*;

mod tests {
    use super::*;

    #[test]
    fn city_has_objects_clear_of_the_road() {
        let scene = Scene::city(1);
        assert!(scene.object_count() > 50, "{}", scene.object_count());
        for o in &scene.objects {
            assert!(footprint_distance(o, 0.0, 10.0) > 4.0);
        }
        // a ray straight ahead along the road at camera height hits something far or nothing
        let hit = scene.trace(&Vector3::zeros(), &Vector3::new(0.0, 0.0, 1.0));
        assert!(hit.is_none_or(|h| h.t > 50.0));
        // a ray down hits the ground at 1.65 m
        let hit = scene.trace(&Vector3::zeros(), &Vector3::new(0.0, 1.0, 0.0));
        assert!((hit.map(|h| h.t).unwrap_or(0.0) - 1.65).abs() < 1e-12);
        // a ray to the side hits a facade between the set-back limits
        let hit = scene.trace(&Vector3::new(0.0, 0.0, 100.0), &Vector3::new(1.0, 0.0, 0.0));
        if let Some(h) = hit {
            assert!(h.t > 4.0, "{}", h.t);
        }
    }

    #[test]
    fn ground_follows_a_sloped_path() {
        // uphill along +z (y down: y decreases), with a bump of 0.2 m in the middle
        let path: Vec<Pose> = (0..50)
            .map(|i| {
                let z = f64::from(i);
                let bump = if i == 25 { 0.2 } else { 0.0 };
                Isometry3::translation(0.0, -0.05 * z + bump, z)
            })
            .collect();
        let scene = Scene::along(&path, 0).unwrap();
        for p in &path {
            let t = p.translation.vector;
            let clearance = scene.ground.y_at(t.x, t.z) - t.y;
            assert!(clearance >= 1.65 - 1e-9, "{clearance}");
            assert!(clearance < 1.65 + 0.25, "{clearance}");
        }
        // a ray straight down from a camera hits the ground at its clearance
        let t = path[10].translation.vector;
        let hit = scene.trace(&t, &Vector3::new(0.0, 1.0, 0.0)).unwrap();
        assert!((hit.t - (scene.ground.y_at(t.x, t.z) - t.y)).abs() < 1e-9);
        assert!((scene.ground.normal_up().y + 1.0).abs() < 2e-3);
    }

    #[test]
    fn a_huge_path_keeps_the_grid_small() {
        let path = [Pose::identity(), Isometry3::translation(1e5, 0.0, 1e5)];
        let scene = Scene::along(&path, 0).unwrap();
        assert!(scene.object_grid.nx * scene.object_grid.nz <= 1_100_000);
        let hit = scene.trace(&Vector3::zeros(), &Vector3::new(0.0, 1.0, 0.0));
        assert!((hit.map(|h| h.t).unwrap_or(0.0) - 1.65).abs() < 1e-9);
    }

    #[test]
    fn pulse_box_is_the_filtered_pulse() {
        // tiny footprint: the pulse itself
        assert!((pulse_box(0.5, 2.0, 1.0, 1e-6) - 1.0).abs() < 1e-6);
        assert!(pulse_box(1.5, 2.0, 1.0, 1e-6).abs() < 1e-6);
        // footprint over many periods: the duty cycle
        assert!((pulse_box(0.3, 2.0, 0.5, 200.0) - 0.25).abs() < 1e-3);
    }

    #[test]
    fn config_validation() {
        assert!(SceneConfig::default().validate().is_ok());
        let bad = SceneConfig {
            setback_min_m: 2.0,
            ..SceneConfig::default()
        };
        assert!(bad.validate().is_err());
        assert!(matches!(
            Scene::along(&[], 0),
            Err(SynthError::EmptyTrajectory)
        ));
    }
}

mod far_pose_tests {
    use super::*;
    use nalgebra::{Translation3, UnitQuaternion};

    /// A pose 1e308 m (or 1e7 m) away made `place_objects` loop for ever (for 9 s and 0.8 GB):
    /// it is an error naming the pose (issue 21).
    #[test]
    fn a_pose_far_away_is_an_error_not_a_hang() {
        for far in [1e7, 1e308, -1.7e308] {
            let poses: Vec<Pose> = [0.0, 1.0, far, 3.0]
                .iter()
                .map(|&z| {
                    Pose::from_parts(Translation3::new(0.0, 0.0, z), UnitQuaternion::identity())
                })
                .collect();
            let t = std::time::Instant::now();
            let e = Scene::along(&poses, 1).unwrap_err();
            assert!(
                matches!(e, SynthError::TrajectoryTooLong { index: 2, .. }),
                "{far}: {e}"
            );
            assert!(t.elapsed().as_secs_f64() < 5.0);
        }
        // a long but real drive still lays out
        let poses: Vec<Pose> = (0..50)
            .map(|i| {
                Pose::from_parts(
                    Translation3::new(0.0, 0.0, 10.0 * f64::from(i)),
                    UnitQuaternion::identity(),
                )
            })
            .collect();
        assert!(Scene::along(&poses, 1).unwrap().object_count() > 0);
    }
}
