//! Typed configuration of a run: the monocular file (`[mono]`, `[mono.flow]`, `[loop_closure]`)
//! or the stereo one (`StereoConfig` fields), with the papers' defaults; the same TOML keys from
//! the CLI's `--config`, Python and library users.

use serde::{Deserialize, Serialize};
use visnav_loop::LoopConfig;
use visnav_odometry::mono::MonoConfig;
use visnav_odometry::stereo::StereoConfig;

use crate::PipelineError;

/// Which odometry.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Serialize, Deserialize)]
#[serde(rename_all = "snake_case")]
pub enum Mode {
    /// Stereo RotROCC.
    Stereo,
    /// Monocular VO from dense flow with uncertainty.
    Mono,
}

impl Mode {
    /// `"mono"` or `"stereo"`.
    #[must_use]
    pub fn name(self) -> &'static str {
        match self {
            Self::Mono => "mono",
            Self::Stereo => "stereo",
        }
    }
}

/// A named set of defaults under a run's configuration file (`--preset`).
#[derive(Debug, Clone, Copy, Default, PartialEq, Eq, Serialize, Deserialize)]
#[serde(rename_all = "kebab-case")]
pub enum Preset {
    /// The papers' pipelines (the default): the monocular odometry on the paper's dense flow.
    #[default]
    Paper,
    /// Real time on a laptop CPU: the monocular odometry on the fast flow
    /// ([`MonoRunConfig::realtime`]). Stereo runs are real time with the paper's settings, so the
    /// preset leaves them as they are.
    Realtime,
}

impl Preset {
    /// `"paper"` or `"realtime"`.
    #[must_use]
    pub fn name(self) -> &'static str {
        match self {
            Self::Paper => "paper",
            Self::Realtime => "realtime",
        }
    }
}

/// The monocular configuration: a `[mono]` table (with the flow in `[mono.flow]`) and a
/// `[loop_closure]` table; missing fields take the defaults.
#[derive(Debug, Clone, Default, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields, default)]
pub struct MonoRunConfig {
    /// The monocular odometry and its flow (paper defaults, see `MonoConfig`).
    pub mono: MonoConfig,
    /// Loop closure (see `LoopConfig`; used when loop closure is enabled).
    pub loop_closure: LoopConfig,
}

impl MonoRunConfig {
    /// The real-time preset ([`MonoConfig::realtime`]; loop closure as in the paper preset).
    #[must_use]
    pub fn realtime() -> Self {
        Self {
            mono: MonoConfig::realtime(),
            ..Self::default()
        }
    }

    /// The defaults of `preset`.
    #[must_use]
    pub fn of_preset(preset: Preset) -> Self {
        match preset {
            Preset::Paper => Self::default(),
            Preset::Realtime => Self::realtime(),
        }
    }

    /// The loop-closure stage for `camera`: `loop_closure` configures it, `mono` the closures'
    /// relative pose (PnP) and `mono.flow` their flow.
    ///
    /// # Errors
    /// [`visnav_loop::LoopError`] for an invalid configuration.
    pub fn loop_closer(
        &self,
        camera: visnav_core::PinholeCamera,
    ) -> Result<visnav_loop::LoopCloser, visnav_loop::LoopError> {
        visnav_loop::LoopCloser::new(
            camera,
            self.loop_closure.clone(),
            self.mono.clone(),
            self.mono.flow.flow.clone(),
        )
    }

    /// Checks both tables.
    ///
    /// # Errors
    /// [`PipelineError`] naming the bad field.
    pub fn validate(&self) -> Result<(), PipelineError> {
        self.mono.validate()?;
        self.loop_closure.validate()?;
        Ok(())
    }
}

/// The configuration of a stereo run with loop closure: the `StereoConfig` fields and a
/// `[loop_closure]` table (what a stereo `--config` file with loop closure holds).
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct StereoLoopConfig {
    /// The stereo odometry.
    #[serde(flatten)]
    pub stereo: StereoConfig,
    /// The loop closure (over `LoopConfig::stereo`).
    pub loop_closure: LoopConfig,
}

/// The configuration of a run, by mode (what the run report records).
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(untagged)]
pub enum RunConfig {
    /// Monocular.
    Mono(Box<MonoRunConfig>),
    /// Stereo.
    Stereo(Box<StereoConfig>),
    /// Stereo with loop closure.
    StereoLoop(Box<StereoLoopConfig>),
}

impl RunConfig {
    /// The configuration as TOML (what `--config` reads back).
    ///
    /// # Errors
    /// A message when serialisation fails.
    pub fn to_toml(&self) -> Result<String, String> {
        match self {
            Self::Mono(c) => toml_string(c.as_ref()),
            Self::Stereo(c) => toml_string(c.as_ref()),
            Self::StereoLoop(c) => toml_string(c.as_ref()),
        }
    }
}

fn toml_string<T: Serialize>(value: &T) -> Result<String, String> {
    toml::to_string_pretty(value).map_err(|e| e.to_string())
}

/// The first number of a configuration table that is not finite, with its dotted key
/// (`flow.uncertainty.extra_variance_weight`), in key order; `None` when all are finite.
#[must_use]
pub(crate) fn first_non_finite(table: &toml::Table) -> Option<(String, f64)> {
    fn walk(value: &toml::Value, key: &str) -> Option<(String, f64)> {
        match value {
            toml::Value::Float(f) if !f.is_finite() => Some((key.to_owned(), *f)),
            toml::Value::Table(t) => t.iter().find_map(|(k, v)| {
                let key = if key.is_empty() {
                    k.clone()
                } else {
                    format!("{key}.{k}")
                };
                walk(v, &key)
            }),
            toml::Value::Array(a) => a
                .iter()
                .enumerate()
                .find_map(|(i, v)| walk(v, &format!("{key}[{i}]"))),
            _ => None,
        }
    }
    table.iter().find_map(|(k, v)| walk(v, k))
}
