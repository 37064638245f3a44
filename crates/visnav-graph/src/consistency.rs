//! Pairwise consistency of loop closures: the preselection step of the robust solver.
//!
//! This is the pairwise consistency test of PCM (Mangelson, Dominic, Eustice and Vasudevan,
//! "Pairwise Consistent Measurement Set Maximization for Robust Multi-robot Map Merging", ICRA
//! 2018, eq. 5–6), restricted to pairs of closures whose ends are linked by *short* odometry
//! chains, with "consistent with at least one other closure" in place of the maximum clique.
//!
//! Two loop closures `Z_ab` (vertex ids `a < b`) and `Z_a'b'` with `|a − a'| ≤ w` and
//! `|b − b'| ≤ w` close the cycle
//!
//! `E = Z_ab⁻¹ · O(a → a') · Z_a'b' · O(b' → b)`,
//!
//! where `O(p → q)` composes the odometry edges between consecutive ids. For two genuine closures
//! `E ≈ I`. First-order propagation of every factor's covariance `Σ_k = Ω_k⁻¹` (perturbations on
//! the right, `F_k Exp(δ_k)`) gives `Σ_E = Σ_k Ad(S_k⁻¹) Σ_k Ad(S_k⁻¹)ᵀ` with `S_k` the product
//! of the factors after `k`; the pair is consistent when `Log(E)ᵀ Σ_E⁻¹ Log(E) ≤` the `χ²₆`
//! gate. A closure is *supported* when it is consistent with at least one other closure.
//!
//! Why this works against perceptual aliasing: genuine closures come in runs (a revisited place
//! is seen from several consecutive poses) whose members confirm each other through a few
//! odometry steps, whereas a wrong closure between random poses almost never has another closure
//! near both of its ends, and when it has, the cycle does not close. The short chains keep the
//! test sharp (a long odometry chain's covariance would let anything pass) and cheap: each
//! closure looks only at closures within the window and stops at its first consistent partner,
//! so the cost is linear in the number of closures.

use std::collections::HashMap;

use nalgebra::Matrix6;
use visnav_core::Pose;
use visnav_core::se3::se3_log;

use crate::graph::PoseGraph;
use crate::lie::adjoint;

/// One factor of a cycle: a relative pose and the covariance of its right perturbation.
type Factor = (Pose, Matrix6<f64>);

/// A loop closure oriented from the smaller to the larger vertex id.
#[derive(Debug, Clone, Copy)]
struct Closure {
    /// Index of the edge in the graph.
    edge: usize,
    /// Smaller vertex id.
    id_a: u64,
    /// Larger vertex id.
    id_b: u64,
    /// `a_from_b` and its covariance.
    factor: Factor,
}

/// The covariance `Σ = Ω⁻¹`; `None` when `Ω` is not positive definite.
fn covariance(information: &Matrix6<f64>) -> Option<Matrix6<f64>> {
    information.cholesky().map(|c| c.inverse())
}

/// The factor of `Z⁻¹` given that of `Z`: `(Z Exp(δ))⁻¹ = Z⁻¹ Exp(−Ad(Z) δ)`.
fn inverse_factor((z, sigma): &Factor) -> Factor {
    let ad = adjoint(z);
    (z.inverse(), ad * sigma * ad.transpose())
}

/// Odometry between consecutive ids: `step[id] = (id_from_id+1, covariance)`.
struct Odometry {
    steps: HashMap<u64, Factor>,
}

impl Odometry {
    fn new(graph: &PoseGraph) -> Self {
        let mut steps = HashMap::new();
        for e in &graph.edges {
            if !graph.is_odometry(e) {
                continue;
            }
            let Some(sigma) = covariance(&e.information) else {
                continue;
            };
            let (id_from, id_to) = (graph.vertices[e.from].id, graph.vertices[e.to].id);
            let factor = (e.from_from_to, sigma);
            let (key, forward) = if id_to > id_from {
                (id_from, factor)
            } else {
                (id_to, inverse_factor(&factor))
            };
            steps.entry(key).or_insert(forward);
        }
        Self { steps }
    }

    /// Appends the factors of `O(p → q)` to `out`; `false` when a step is missing.
    fn chain(&self, p: u64, q: u64, out: &mut Vec<Factor>) -> bool {
        if q >= p {
            for id in p..q {
                match self.steps.get(&id) {
                    Some(f) => out.push(*f),
                    None => return false,
                }
            }
        } else {
            for id in (q..p).rev() {
                match self.steps.get(&id) {
                    Some(f) => out.push(inverse_factor(f)),
                    None => return false,
                }
            }
        }
        true
    }
}

/// The composed pose and the first-order covariance of the product `F_0 F_1 ⋯ F_n`:
/// `Σ = Σ_k Ad(S_k⁻¹) Σ_k Ad(S_k⁻¹)ᵀ`, `S_k = F_{k+1} ⋯ F_n`.
fn compose(factors: &[Factor]) -> Factor {
    let mut suffix = Pose::identity();
    let mut sigma = Matrix6::zeros();
    for (pose, sigma_k) in factors.iter().rev() {
        let ad = adjoint(&suffix.inverse());
        sigma += ad * sigma_k * ad.transpose();
        suffix = pose * suffix;
    }
    (suffix, sigma)
}

/// `χ²` of the cycle through closures `c` and `d`; `None` when an odometry step is missing or the
/// covariance is singular.
fn cycle_chi2(odometry: &Odometry, c: &Closure, d: &Closure, buf: &mut Vec<Factor>) -> Option<f64> {
    buf.clear();
    buf.push(inverse_factor(&c.factor));
    if !odometry.chain(c.id_a, d.id_a, buf) {
        return None;
    }
    buf.push(d.factor);
    if !odometry.chain(d.id_b, c.id_b, buf) {
        return None;
    }
    let (cycle, sigma) = compose(buf);
    let e = se3_log(&cycle);
    let info = sigma.cholesky()?;
    Some(e.dot(&info.solve(&e)))
}

/// Which loop closures are confirmed by another one.
#[derive(Debug, Clone, PartialEq, Eq)]
pub struct ClosureSupport {
    /// Per edge: `true` for a loop closure consistent with enough other closures within the
    /// window (odometry edges are `false`).
    pub supported: Vec<bool>,
    /// Number of loop closures (non-odometry edges between distinct vertices).
    pub closures: usize,
    /// Number of cycles tested.
    pub pairs_tested: usize,
    /// Per edge: the edges of the consistent partners found (empty for odometry edges).
    pub partners: Vec<Vec<usize>>,
}

impl ClosureSupport {
    /// Number of supported closures.
    #[must_use]
    pub fn n_supported(&self) -> usize {
        self.supported.iter().filter(|s| **s).count()
    }
}

/// Tests loop closures pairwise (see the module doc): a closure is supported when at least
/// `min_partners` other closures whose ends are within `window` ids of its own close a cycle
/// with it with `χ² ≤ gate_chi2`. Each closure stops testing once it has its partners, so the
/// last closure of a run may be left untested by predecessors that stopped (its support is a
/// lower bound; [`closure_confirmation`] tests every needed pair).
#[must_use]
pub fn closure_support(
    graph: &PoseGraph,
    window: u64,
    gate_chi2: f64,
    min_partners: usize,
) -> ClosureSupport {
    support(graph, window, gate_chi2, min_partners, false)
}

/// As [`closure_support`], but a pair is skipped only when both closures already have their
/// partners: every closure that can be supported is (the solver's final gate uses it; issue 53:
/// in a run of closures at consecutive poses, every third closure stopped testing at once and
/// the run's last closure was left with no partner tested).
#[must_use]
pub fn closure_confirmation(
    graph: &PoseGraph,
    window: u64,
    gate_chi2: f64,
    min_partners: usize,
) -> ClosureSupport {
    support(graph, window, gate_chi2, min_partners, true)
}

/// [`closure_support`] (`exhaustive` false) and [`closure_confirmation`] (true).
fn support(
    graph: &PoseGraph,
    window: u64,
    gate_chi2: f64,
    min_partners: usize,
    exhaustive: bool,
) -> ClosureSupport {
    let odometry = Odometry::new(graph);
    let mut closures: Vec<Closure> = graph
        .edges
        .iter()
        .enumerate()
        .filter(|(_, e)| e.from != e.to && !graph.is_odometry(e))
        .filter_map(|(k, e)| {
            let sigma = covariance(&e.information)?;
            let (id_from, id_to) = (graph.vertices[e.from].id, graph.vertices[e.to].id);
            let factor = (e.from_from_to, sigma);
            Some(if id_from < id_to {
                Closure {
                    edge: k,
                    id_a: id_from,
                    id_b: id_to,
                    factor,
                }
            } else {
                Closure {
                    edge: k,
                    id_a: id_to,
                    id_b: id_from,
                    factor: inverse_factor(&factor),
                }
            })
        })
        .collect();
    closures.sort_by_key(|c| (c.id_a, c.id_b, c.edge));
    let min_partners = min_partners.max(1);
    // Consistent partners found so far; each pair is tested at most once (the later closure
    // of the pair in sorted order is only tested by the earlier one).
    let mut partners = vec![0_usize; closures.len()];
    let mut pairs_tested = 0;
    let mut partner_edges = vec![Vec::new(); graph.edges.len()];
    let mut buf = Vec::new();
    for ci in 0..closures.len() {
        let c = closures[ci];
        for di in ci + 1..closures.len() {
            if !exhaustive && partners[ci] >= min_partners {
                break;
            }
            let d = closures[di];
            if d.id_a > c.id_a + window {
                break;
            }
            if d.id_b.abs_diff(c.id_b) > window
                || (exhaustive && partners[ci] >= min_partners && partners[di] >= min_partners)
            {
                continue;
            }
            pairs_tested += 1;
            if cycle_chi2(&odometry, &c, &d, &mut buf).is_some_and(|chi2| chi2 <= gate_chi2) {
                partners[ci] += 1;
                partners[di] += 1;
                partner_edges[c.edge].push(d.edge);
                partner_edges[d.edge].push(c.edge);
            }
        }
    }
    let mut supported = vec![false; graph.edges.len()];
    for (c, p) in closures.iter().zip(&partners) {
        supported[c.edge] = *p >= min_partners;
    }
    ClosureSupport {
        supported,
        closures: closures.len(),
        pairs_tested,
        partners: partner_edges,
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::synthetic::{LoopDriveConfig, add_wrong_loop_closures, loop_drive};
    use nalgebra::Vector6;
    use visnav_core::se3::se3_exp;

    #[test]
    fn composed_covariance_matches_sampling_to_first_order() {
        // Compose three noisy factors; the covariance of Log(Ẑ⁻¹ Z) over many samples matches
        // the propagated one.
        use rand::{Rng, SeedableRng};
        let poses = [
            se3_exp(&Vector6::new(1.0, 0.2, -0.3, 0.1, 0.4, -0.2)),
            se3_exp(&Vector6::new(-0.5, 2.0, 0.1, -0.3, 0.0, 0.5)),
            se3_exp(&Vector6::new(0.3, -0.1, 1.5, 0.2, -0.6, 0.1)),
        ];
        let sigma_k = Matrix6::from_diagonal(&Vector6::new(4e-6, 1e-6, 9e-6, 1e-6, 4e-6, 2e-6));
        let factors: Vec<Factor> = poses.iter().map(|p| (*p, sigma_k)).collect();
        let (mean, sigma) = compose(&factors);
        let mut rng = rand_chacha::ChaCha8Rng::seed_from_u64(3);
        let chol = sigma_k.cholesky().unwrap().l();
        let n = 20_000;
        let mut empirical = Matrix6::zeros();
        for _ in 0..n {
            let mut p = Pose::identity();
            for pose in &poses {
                let z = Vector6::from_fn(|_, _| {
                    // Irwin–Hall approximation of a standard normal (sum of 12 uniforms − 6).
                    (0..12).map(|_| rng.random::<f64>()).sum::<f64>() - 6.0
                });
                p = p * pose * se3_exp(&(chol * z));
            }
            let e = se3_log(&(mean.inverse() * p));
            empirical += e * e.transpose() / f64::from(n);
        }
        let rel = (empirical - sigma).norm() / sigma.norm();
        assert!(rel < 0.05, "relative covariance error {rel}");
    }

    #[test]
    fn genuine_closures_are_supported_and_wrong_ones_are_not() {
        let synth = loop_drive(&LoopDriveConfig::default());
        let mut graph = synth.graph.clone();
        let genuine: Vec<usize> = (0..graph.edges.len())
            .filter(|&k| !graph.is_odometry(&graph.edges[k]))
            .collect();
        let wrong = add_wrong_loop_closures(&mut graph, 0.3, 20.0, 5);
        let support = closure_support(&graph, 10, 27.86, 1);
        assert_eq!(support.closures, genuine.len() + wrong.len());
        let genuine_ok = genuine.iter().filter(|&&k| support.supported[k]).count();
        let wrong_ok = wrong.iter().filter(|&&k| support.supported[k]).count();
        assert!(
            genuine_ok * 100 >= genuine.len() * 95,
            "{genuine_ok} of {} genuine supported",
            genuine.len()
        );
        assert!(wrong_ok <= 1, "{wrong_ok} wrong closures supported");
        // Odometry edges are never marked.
        assert!(
            graph
                .edges
                .iter()
                .zip(&support.supported)
                .all(|(e, s)| !(*s && graph.is_odometry(e)))
        );
    }

    /// Regression (issue 53): closures at every pose of the second lap; the early stop left the
    /// run's last closure (99 -> 199) without a tested partner, the exhaustive test confirms it.
    #[test]
    fn the_last_closure_of_a_run_is_confirmed() {
        let synth = loop_drive(&LoopDriveConfig {
            closure_every: 1,
            ..LoopDriveConfig::default()
        });
        let graph = &synth.graph;
        let last = graph.edges.len() - 1;
        assert!(!graph.is_odometry(&graph.edges[last]));
        assert!(!closure_support(graph, 10, 27.86, 2).supported[last]);
        let confirmed = closure_confirmation(graph, 10, 27.86, 2);
        assert!(confirmed.supported[last]);
        assert_eq!(confirmed.n_supported(), confirmed.closures);
        // its partners are two closures of the same run within the window
        let partners = &confirmed.partners[last];
        assert_eq!(partners.len(), 2);
        assert!(
            partners.iter().all(|&p| p < last && p + 10 >= last),
            "{partners:?}"
        );
    }

    #[test]
    fn an_isolated_closure_has_no_support() {
        let synth = loop_drive(&LoopDriveConfig {
            closure_every: 1000,
            ..LoopDriveConfig::default()
        });
        let support = closure_support(&synth.graph, 10, 27.86, 1);
        assert_eq!(support.closures, 1);
        assert_eq!(support.n_supported(), 0);
        assert_eq!(support.pairs_tested, 0);
    }

    #[test]
    fn a_perturbed_partner_is_inconsistent() {
        // Two genuine closures one step apart are consistent; moving one by 2 m breaks the cycle.
        let synth = loop_drive(&LoopDriveConfig {
            closure_every: 50,
            ..LoopDriveConfig::default()
        });
        let mut graph = synth.graph.clone();
        let first = graph
            .edges
            .iter()
            .position(|e| !graph.is_odometry(e))
            .unwrap();
        let mut twin = graph.edges[first].clone();
        twin.to += 1;
        twin.from_from_to = synth.ground_truth[twin.from].inverse() * synth.ground_truth[twin.to];
        graph.edges.push(twin.clone());
        let support = closure_support(&graph, 10, 27.86, 1);
        assert!(support.supported[first]);
        assert!(support.supported[graph.edges.len() - 1]);
        let last = graph.edges.len() - 1;
        graph.edges[last].from_from_to =
            twin.from_from_to * se3_exp(&Vector6::new(2.0, 0.0, 0.0, 0.0, 0.0, 0.0));
        let support = closure_support(&graph, 10, 27.86, 1);
        assert!(!support.supported[first]);
        assert!(!support.supported[last]);
    }
}
