//! A configuration file or inline table that sets one field of a section keeps the mode's
//! defaults for the others: the stereo tracker's `max_residual` (25, not the tracker type's 20),
//! the monocular flow's cost-slice uncertainty and copy fill (`FlowConfig::odometry`, not the
//! `visnav flow` defaults). Before, a partial section silently took its type's defaults.
#![allow(clippy::unwrap_used)] // fixtures

use visnav_flow::{FlowConfig, UncertaintyConfig};
use visnav_odometry::stereo::StereoConfig;
use visnav_pipeline::Mode;
use visnav_pipeline::job::{ConfigSource, RunSpec};

fn file(text: &str) -> (tempfile::TempDir, ConfigSource) {
    let dir = tempfile::tempdir().unwrap();
    let path = dir.path().join("config.toml");
    std::fs::write(&path, text).unwrap();
    (dir, ConfigSource::File(path))
}

#[test]
fn a_stereo_section_set_in_part_keeps_the_stereo_defaults() {
    let defaults = StereoConfig::default();
    assert!(
        (defaults.klt.max_residual - visnav_image::KltConfig::default().max_residual).abs() > 1.0,
        "the fixture needs a stereo default that differs from the tracker's own"
    );
    let mut spec = RunSpec::new("unused", Mode::Stereo);
    let (_dir, source) = file("[klt]\nwindow_radius = 6\n[corners]\nquality = 0.02\n");
    spec.config = Some(source);
    let c = spec.stereo_config().unwrap();
    assert_eq!(c.klt.window_radius, 6);
    assert_eq!(c.klt.max_residual, defaults.klt.max_residual);
    assert_eq!(c.klt.levels, defaults.klt.levels);
    assert!((c.corners.quality - 0.02).abs() < 1e-12);
    assert_eq!(c.corners.max_per_bucket, defaults.corners.max_per_bucket);
    assert_eq!(c.corners.bucket_cols, defaults.corners.bucket_cols);
    // the loop table beside it does not disturb the merge
    spec.loop_closure = true;
    let (_dir, source) =
        file("[klt]\nwindow_radius = 6\n[loop_closure]\nmin_pnp_inlier_fraction = 0.7\n");
    spec.config = Some(source);
    let c = spec.stereo_config().unwrap();
    assert_eq!(c.klt.max_residual, defaults.klt.max_residual);
}

#[test]
fn a_mono_flow_section_set_in_part_keeps_the_odometry_flow() {
    let odometry = FlowConfig::odometry();
    assert_ne!(odometry.uncertainty, UncertaintyConfig::default());
    let mut spec = RunSpec::new("unused", Mode::Mono);
    let (_dir, source) = file("[mono.flow.flow.refinement]\nfull_resolution_outer = 6\n");
    spec.config = Some(source);
    let c = spec.mono_config().unwrap();
    let flow = &c.mono.flow.flow;
    assert_eq!(flow.refinement.full_resolution_outer, 6);
    assert_eq!(
        flow.refinement.full_resolution_inner,
        odometry.refinement.full_resolution_inner
    );
    assert_eq!(flow.uncertainty, odometry.uncertainty);
    assert_eq!(flow.interpolation, odometry.interpolation);
    // the same as an inline table (the Python API's path)
    spec.config = Some(ConfigSource::Inline(serde_json::json!({
        "mono": {"flow": {"flow": {"refinement": {"full_resolution_outer": 6}}}}
    })));
    let c = spec.mono_config().unwrap();
    assert_eq!(c.mono.flow.flow.refinement.full_resolution_outer, 6);
    assert_eq!(c.mono.flow.flow.uncertainty, odometry.uncertainty);
}

/// The error with its sources, as the CLI prints it.
fn chain(e: &dyn std::error::Error) -> String {
    let mut out = e.to_string();
    let mut source = e.source();
    while let Some(s) = source {
        out += &format!(": {s}");
        source = s.source();
    }
    out
}

#[test]
fn unknown_and_mistyped_keys_still_name_their_line() {
    let mut spec = RunSpec::new("unused", Mode::Stereo);
    let (_dir, source) = file("max_depth_m = 60.0\n[klt]\nwindow_radiuss = 4\n");
    spec.config = Some(source);
    let e = chain(&spec.stereo_config().unwrap_err());
    assert!(e.contains("window_radiuss") && e.contains('3'), "{e}");
    let (_dir, source) = file("[klt]\nwindow_radius = \"x\"\n");
    spec.config = Some(source);
    let e = chain(&spec.stereo_config().unwrap_err());
    assert!(e.contains("invalid type") && e.contains('2'), "{e}");
}

/// Issue 53's fuzz campaign: a value out of range in a configuration file said "invalid stereo
/// configuration: …" without naming the file; now the file is named. A value out of range that
/// comes from an option (not the file) does not blame the file.
#[test]
fn a_value_out_of_range_names_the_configuration_file() {
    let mut spec = RunSpec::new("unused", Mode::Stereo);
    let (_dir, source) = file("[corners]\nbucket_cols = 0\n");
    spec.config = Some(source);
    let e = chain(&spec.stereo_config().unwrap_err());
    assert!(
        e.contains("invalid stereo configuration in ") && e.contains("config.toml"),
        "{e}"
    );
    assert!(e.contains("bucket_cols"), "{e}");
    let mut spec = RunSpec::new("unused", Mode::Mono);
    let (_dir, source) = file("[mono]\nmax_depth_m = 80.0\n");
    spec.config = Some(source);
    spec.camera_height = Some(-1.0);
    let e = chain(&spec.mono_config().unwrap_err());
    assert!(e.contains("invalid mono configuration"), "{e}");
    assert!(!e.contains("config.toml"), "the file is not to blame: {e}");
}

/// Issue 53's fuzz campaign: `extra_variance_weight = 1e308` (a 32-bit field) was read as
/// infinity in silence; now a number that is not finite once read is an error naming the key,
/// the file and its line (also inline and in the loop closure's table).
#[test]
fn a_number_too_large_for_its_field_is_an_error_naming_key_and_line() {
    let mut spec = RunSpec::new("unused", Mode::Mono);
    let (_dir, source) = file(
        "[mono]\nmax_depth_m = 80.0\n[mono.flow.flow.uncertainty]\nextra_variance_weight = 1e308\n",
    );
    spec.config = Some(source);
    let e = chain(&spec.mono_config().unwrap_err());
    assert!(
        e.contains("config.toml:4: mono.flow.flow.uncertainty.extra_variance_weight = inf"),
        "{e}"
    );
    assert!(e.contains("not a finite number"), "{e}");
    spec.config = Some(ConfigSource::Inline(serde_json::json!({
        "mono": {"flow": {"flow": {"uncertainty": {"extra_variance_weight": 1e308}}}}
    })));
    let e = chain(&spec.mono_config().unwrap_err());
    assert!(
        e.contains("the inline mono config") && e.contains("= inf"),
        "{e}"
    );
    // a finite value is read as written
    let (_dir, source) = file("[mono.flow.flow.uncertainty]\nextra_variance_weight = 1e30\n");
    spec.config = Some(source);
    let c = spec.mono_config().unwrap();
    assert_eq!(c.mono.flow.flow.uncertainty.extra_variance_weight, 1e30);
}

/// Every preset survives its round trip through a configuration file: a file that sets one
/// unrelated field gives the preset with that field changed, and the configuration a run
/// writes beside its poses (`poses.config.toml`) reads back as the run's. Before, the real-time
/// preset's `finest_variational_outer = None` was dropped by TOML and came back as the fast
/// flow type's default (0): `--preset realtime --config FILE` ran another flow than
/// `--preset realtime`.
#[test]
fn every_preset_survives_a_configuration_file() {
    use visnav_pipeline::{MonoRunConfig, Preset};
    for preset in [Preset::Paper, Preset::Realtime] {
        let want = MonoRunConfig::of_preset(preset);
        let written = toml::to_string(&want).unwrap();
        let back: MonoRunConfig = toml::from_str(&written).unwrap();
        assert_eq!(back, want, "{}: the written configuration", preset.name());
        let mut spec = RunSpec::new("unused", Mode::Mono);
        spec.preset = preset;
        let (_dir, source) = file("[mono.covariance]\ninflation = 2.0\n");
        spec.config = Some(source);
        let mut got = spec.mono_config().unwrap();
        assert!((got.mono.covariance.inflation - 2.0).abs() < 1e-12);
        got.mono.covariance.inflation = want.mono.covariance.inflation;
        assert_eq!(got, want, "{}: a file over the preset", preset.name());
    }
    let stereo = StereoConfig::default();
    let back: StereoConfig = toml::from_str(&toml::to_string(&stereo).unwrap()).unwrap();
    assert_eq!(back, stereo);
}
