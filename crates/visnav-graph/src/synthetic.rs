//! Seeded synthetic pose graphs with exact ground truth, and wrong loop closures for robustness
//! tests and benchmarks.

use nalgebra::{Isometry3, Matrix6, Translation3, UnitQuaternion, Vector3, Vector6};
use rand::{Rng, SeedableRng};
use rand_chacha::ChaCha8Rng;
use visnav_core::Pose;
use visnav_core::se3::se3_exp;

use crate::graph::{Edge, PoseGraph, Vertex};

/// A drive around a closed loop, several laps, with odometry between consecutive poses and loop
/// closures between the same place on consecutive laps.
#[derive(Debug, Clone, PartialEq, serde::Serialize, serde::Deserialize)]
#[serde(deny_unknown_fields, default)]
pub struct LoopDriveConfig {
    /// Number of laps. Default 2.
    pub laps: usize,
    /// Poses per lap. Default 100.
    pub poses_per_lap: usize,
    /// Radius of the loop, metres. Default 20.
    pub radius_m: f64,
    /// Standard deviation of the measurement noise on each translation axis, metres. Default 0.05.
    pub translation_sigma_m: f64,
    /// Standard deviation of the measurement noise on each rotation axis, radians. Default 0.003.
    pub rotation_sigma_rad: f64,
    /// A loop closure every this many poses of the second and later laps. Default 2.
    pub closure_every: usize,
    /// Seed of the noise. Default 7.
    pub seed: u64,
}

impl Default for LoopDriveConfig {
    fn default() -> Self {
        Self {
            laps: 2,
            poses_per_lap: 100,
            radius_m: 20.0,
            translation_sigma_m: 0.05,
            rotation_sigma_rad: 0.003,
            closure_every: 2,
            seed: 7,
        }
    }
}

/// A synthetic graph (vertices initialised by composing the noisy odometry) and its ground truth.
#[derive(Debug, Clone, PartialEq)]
pub struct SyntheticGraph {
    /// The graph; vertex 0 is fixed at its true pose.
    pub graph: PoseGraph,
    /// True `world_from_vertex` of each vertex.
    pub ground_truth: Vec<Pose>,
}

/// A standard normal sample (Box–Muller).
fn normal(rng: &mut ChaCha8Rng) -> f64 {
    let u1: f64 = rng.random::<f64>().max(1e-300);
    let u2: f64 = rng.random();
    (-2.0 * u1.ln()).sqrt() * (std::f64::consts::TAU * u2).cos()
}

fn noise(rng: &mut ChaCha8Rng, sigma_t: f64, sigma_r: f64) -> Pose {
    let xi = Vector6::new(
        sigma_t * normal(rng),
        sigma_t * normal(rng),
        sigma_t * normal(rng),
        sigma_r * normal(rng),
        sigma_r * normal(rng),
        sigma_r * normal(rng),
    );
    se3_exp(&xi)
}

/// Builds the loop drive of `config`.
#[must_use]
pub fn loop_drive(config: &LoopDriveConfig) -> SyntheticGraph {
    let mut rng = ChaCha8Rng::seed_from_u64(config.seed);
    let per_lap = config.poses_per_lap.max(3);
    let n = per_lap * config.laps.max(1);
    let ground_truth: Vec<Pose> = (0..n)
        .map(|k| {
            let phi = std::f64::consts::TAU * (k % per_lap) as f64 / per_lap as f64;
            let t = Vector3::new(
                config.radius_m * phi.cos(),
                config.radius_m * phi.sin(),
                0.5 * (3.0 * phi).sin(),
            );
            Isometry3::from_parts(
                Translation3::from(t),
                UnitQuaternion::from_scaled_axis(
                    Vector3::z() * (phi + std::f64::consts::FRAC_PI_2),
                ),
            )
        })
        .collect();
    let (st, sr) = (config.translation_sigma_m, config.rotation_sigma_rad);
    let mut info = Matrix6::zeros();
    for k in 0..3 {
        info[(k, k)] = 1.0 / (st * st).max(1e-12);
        info[(k + 3, k + 3)] = 1.0 / (sr * sr).max(1e-12);
    }
    let mut edges = Vec::new();
    let measure = |rng: &mut ChaCha8Rng, i: usize, j: usize| Edge {
        from: i,
        to: j,
        from_from_to: ground_truth[i].inverse() * ground_truth[j] * noise(rng, st, sr),
        information: info,
    };
    for k in 0..n - 1 {
        edges.push(measure(&mut rng, k, k + 1));
    }
    for k in (per_lap..n).step_by(config.closure_every.max(1)) {
        edges.push(measure(&mut rng, k - per_lap, k));
    }
    // Initial guess: compose the odometry from the true first pose.
    let mut vertices = Vec::with_capacity(n);
    let mut pose = ground_truth[0];
    for k in 0..n {
        if k > 0 {
            pose *= edges[k - 1].from_from_to;
        }
        vertices.push(Vertex {
            id: k as u64,
            world_from_vertex: pose,
            fixed: k == 0,
        });
    }
    SyntheticGraph {
        graph: PoseGraph { vertices, edges },
        ground_truth,
    }
}

/// Appends `round(fraction × edges)` wrong loop closures between random non-consecutive vertices
/// (seeded): half claim an arbitrary relative pose (translation uniform in ±`spread_m` per axis,
/// rotation of a uniform random angle in `[0, π)` about a random axis), half claim "same place"
/// (identity up to small noise), as perceptual aliasing does. Each copies the information matrix
/// of an existing loop closure (of the first edge when there is none). Returns the indices of the
/// added edges.
pub fn add_wrong_loop_closures(
    graph: &mut PoseGraph,
    fraction: f64,
    spread_m: f64,
    seed: u64,
) -> Vec<usize> {
    let mut rng = ChaCha8Rng::seed_from_u64(seed);
    let n_vertices = graph.vertices.len();
    if n_vertices < 3 || graph.edges.is_empty() {
        return Vec::new();
    }
    let closures: Vec<usize> = (0..graph.edges.len())
        .filter(|&k| !graph.is_odometry(&graph.edges[k]))
        .collect();
    let count = (fraction * graph.edges.len() as f64).round() as usize;
    let mut added = Vec::with_capacity(count);
    while added.len() < count {
        let i = rng.random_range(0..n_vertices);
        let j = rng.random_range(0..n_vertices);
        if graph.vertices[i].id.abs_diff(graph.vertices[j].id) <= 1 {
            continue;
        }
        let measured = if rng.random::<bool>() {
            let axis = Vector3::new(normal(&mut rng), normal(&mut rng), normal(&mut rng));
            let angle = rng.random_range(0.0..std::f64::consts::PI);
            let axis = axis.try_normalize(1e-12).unwrap_or_else(Vector3::z);
            Isometry3::from_parts(
                Translation3::new(
                    rng.random_range(-spread_m..spread_m),
                    rng.random_range(-spread_m..spread_m),
                    rng.random_range(-spread_m..spread_m),
                ),
                UnitQuaternion::from_scaled_axis(axis * angle),
            )
        } else {
            noise(&mut rng, 0.05, 0.01)
        };
        let information = if closures.is_empty() {
            graph.edges[0].information
        } else {
            graph.edges[closures[rng.random_range(0..closures.len())]].information
        };
        added.push(graph.edges.len());
        graph.edges.push(Edge {
            from: i,
            to: j,
            from_from_to: measured,
            information,
        });
    }
    added
}

/// Makes the information matrices of `round(fraction × edges)` randomly chosen edges
/// indefinite (seeded), as a front end's that estimated the translation–rotation cross block
/// with noise: the diagonal blocks `Ω_tt`, `Ω_rr` are kept and the cross block becomes
/// `C = ρ (Ω_tt)^{1/2} G (Ω_rr)^{1/2}` with `G` a random matrix of unit spectral norm and `ρ`
/// uniform in `[1.2, 3]`; since `‖Ω_tt^{-1/2} C Ω_rr^{-1/2}‖ = ρ > 1` the matrix has a negative
/// eigenvalue, while its blocks (and so SE-Sync's weights) are those of the true noise. Returns
/// the indices of the changed edges, ascending.
pub fn make_information_indefinite(graph: &mut PoseGraph, fraction: f64, seed: u64) -> Vec<usize> {
    let mut rng = ChaCha8Rng::seed_from_u64(seed);
    let m = graph.edges.len();
    let count = ((fraction * m as f64).round() as usize).min(m);
    let mut order: Vec<usize> = (0..m).collect();
    // partial Fisher–Yates: the first `count` entries are a uniform sample
    for k in 0..count {
        let pick = rng.random_range(k..m);
        order.swap(k, pick);
    }
    let mut chosen: Vec<usize> = order[..count].to_vec();
    chosen.sort_unstable();
    for &k in &chosen {
        let info = &mut graph.edges[k].information;
        let sqrt_block = |b: nalgebra::Matrix3<f64>| {
            let eig = b.symmetric_eigen();
            eig.eigenvectors
                * nalgebra::Matrix3::from_diagonal(&eig.eigenvalues.map(|l| l.max(0.0).sqrt()))
                * eig.eigenvectors.transpose()
        };
        let a = sqrt_block(info.fixed_view::<3, 3>(0, 0).into_owned());
        let b = sqrt_block(info.fixed_view::<3, 3>(3, 3).into_owned());
        let g = nalgebra::Matrix3::from_fn(|_, _| normal(&mut rng));
        let norm = g.singular_values().max().max(f64::MIN_POSITIVE);
        let rho = rng.random_range(1.2..3.0);
        let c = a * g * b * (rho / norm);
        info.fixed_view_mut::<3, 3>(0, 3).copy_from(&c);
        info.fixed_view_mut::<3, 3>(3, 0).copy_from(&c.transpose());
    }
    chosen
}

/// Absolute trajectory error (RMS of position differences, metres) between two pose lists in
/// the same frame (no alignment: both graphs hold the same fixed vertex), and the extent of the
/// reference (diagonal of the bounding box of its positions, metres).
#[must_use]
pub fn ate_and_extent(estimate: &[Pose], reference: &[Pose]) -> (f64, f64) {
    let n = estimate.len().min(reference.len());
    if n == 0 {
        return (0.0, 0.0);
    }
    let sum: f64 = estimate
        .iter()
        .zip(reference)
        .map(|(a, b)| (a.translation.vector - b.translation.vector).norm_squared())
        .sum();
    let mut lo = Vector3::repeat(f64::INFINITY);
    let mut hi = Vector3::repeat(f64::NEG_INFINITY);
    for p in &reference[..n] {
        lo = lo.inf(&p.translation.vector);
        hi = hi.sup(&p.translation.vector);
    }
    ((sum / n as f64).sqrt(), (hi - lo).norm())
}
