//! The numeric range a graph must lie in for the solver's `f64` arithmetic.
//!
//! The solver sums every edge's `Jᵀ Ω J` into the normal equations and `eᵀ Ω e` into the
//! objective. Two things make that fail in `f64`, and both are checked before a solve, so that
//! the message names the edge (and, for a file, its line) instead of a bare Cholesky failure or a
//! non-finite number:
//!
//! * **dynamic range**: an edge whose information (its largest eigenvalue `σ`) is below the
//!   machine precision `ε = 2.2e-16` times the median edge's adds nothing representable to the
//!   sums at the vertices it shares with ordinary edges — it cannot determine a pose, and a vertex
//!   it alone links is singular to working precision (information 1e-300 among edges of 100).
//!   Symmetrically, an edge above the median's `1/ε` times wipes out every ordinary edge at its
//!   vertices;
//! * **overflow**: an edge's terms grow as `σ (1 + |t|)²` (`t` its translation: the rotation
//!   columns of its Jacobian carry `[t]×`, its residual `t`), a vertex's as the largest `σ` times
//!   `(1 + |t_i|)²`; summed over the `m` edges they must stay below `f64::MAX` (a translation of
//!   1e308 m squares to infinity).

use nalgebra::Matrix6;

use crate::graph::PoseGraph;

/// What is out of range, and where.
#[derive(Debug, Clone, PartialEq)]
pub enum NumericProblem {
    /// An edge (index into [`PoseGraph::edges`]).
    Edge {
        /// Index of the edge.
        edge: usize,
        /// What is wrong.
        message: String,
    },
    /// A vertex's pose (index into [`PoseGraph::vertices`]).
    Vertex {
        /// Index of the vertex.
        vertex: usize,
        /// What is wrong.
        message: String,
    },
}

/// Largest eigenvalue of a symmetric information matrix (`NaN` when not finite).
fn largest_eigenvalue(information: &Matrix6<f64>) -> f64 {
    if !information.iter().all(|v| v.is_finite()) {
        return f64::NAN;
    }
    ((information + information.transpose()) * 0.5)
        .symmetric_eigenvalues()
        .max()
}

/// `|t|` in metres, or its largest component when the norm itself overflows.
fn describe_length(t: &nalgebra::Vector3<f64>) -> String {
    let norm = t.norm();
    if norm.is_finite() {
        format!("{norm:.3e} m")
    } else {
        format!("a component of {:.3e} m", t.amax())
    }
}

/// The first edge or vertex of `graph` outside the numeric range (module doc), edges first.
#[must_use]
pub fn numeric_problem(graph: &PoseGraph) -> Option<NumericProblem> {
    if graph.edges.is_empty() {
        return None;
    }
    let sigma: Vec<f64> = graph
        .edges
        .iter()
        .map(|e| largest_eigenvalue(&e.information))
        .collect();
    let mut sorted: Vec<f64> = sigma.iter().copied().filter(|s| s.is_finite()).collect();
    sorted.sort_by(f64::total_cmp);
    let median = sorted.get(sorted.len() / 2).copied().unwrap_or(f64::NAN);
    let largest = sorted.last().copied().unwrap_or(f64::NAN);
    let m = graph.edges.len() as f64;
    let eps = f64::EPSILON;
    for (k, (e, &s)) in graph.edges.iter().zip(&sigma).enumerate() {
        let message = if !s.is_finite() {
            Some("the information matrix has a non-finite eigenvalue".to_string())
        } else if s <= eps * median {
            Some(format!(
                "the information matrix is numerically zero: its largest eigenvalue {s:.3e} is \
                 {:.1e} times the median edge's ({median:.3e}), below f64's relative precision \
                 ({eps:.1e}): the edge cannot determine any pose",
                s / median
            ))
        } else if s * eps >= median {
            Some(format!(
                "the information matrix is numerically infinite: its largest eigenvalue {s:.3e} \
                 is {:.1e} times the median edge's ({median:.3e}), beyond f64's relative \
                 precision ({eps:.1e}): the other edges at its vertices would be lost in the sums",
                s / median
            ))
        } else {
            let t = e.from_from_to.translation.vector;
            let terms = s * (1.0 + t.norm()) * (1.0 + t.norm()) * m;
            (!(terms.is_finite() && terms < f64::MAX)).then(|| {
                format!(
                    "the translation ({}) with information up to {s:.3e} overflows f64: \
                     (1 + |t|)² × information × {m} edges exceeds {:.1e}",
                    describe_length(&t),
                    f64::MAX
                )
            })
        };
        if let Some(message) = message {
            return Some(NumericProblem::Edge { edge: k, message });
        }
    }
    for (k, v) in graph.vertices.iter().enumerate() {
        let t = v.world_from_vertex.translation.vector;
        let terms = largest * (1.0 + t.norm()) * (1.0 + t.norm()) * m;
        if !(terms.is_finite() && terms < f64::MAX) {
            return Some(NumericProblem::Vertex {
                vertex: k,
                message: format!(
                    "the position ({}) overflows f64 in the objective: (1 + |t|)² × the \
                     largest information ({largest:.3e}) × {m} edges exceeds {:.1e}",
                    describe_length(&t),
                    f64::MAX
                ),
            });
        }
    }
    None
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::synthetic::{LoopDriveConfig, loop_drive};
    use nalgebra::{Translation3, Vector3};

    #[test]
    fn ordinary_graphs_are_in_range_and_each_extreme_is_named() {
        let graph = loop_drive(&LoopDriveConfig::default()).graph;
        assert_eq!(numeric_problem(&graph), None);

        let mut tiny = graph.clone();
        tiny.edges[5].information *= 1e-300;
        match numeric_problem(&tiny) {
            Some(NumericProblem::Edge { edge: 5, message }) => {
                assert!(message.contains("numerically zero"), "{message}");
            }
            other => panic!("{other:?}"),
        }
        // 1e-12 of the others is small but representable: not an error
        let mut small = graph.clone();
        small.edges[5].information *= 1e-12;
        assert_eq!(numeric_problem(&small), None);

        let mut huge = graph.clone();
        huge.edges[7].information *= 1e300;
        assert!(matches!(
            numeric_problem(&huge),
            Some(NumericProblem::Edge { edge: 7, .. })
        ));

        let mut far = graph.clone();
        far.edges[9].from_from_to.translation = Translation3::from(Vector3::new(1e308, 0.0, 0.0));
        match numeric_problem(&far) {
            Some(NumericProblem::Edge { edge: 9, message }) => {
                assert!(message.contains("overflows"), "{message}");
            }
            other => panic!("{other:?}"),
        }
        // 1e100 m is absurd but computable: left to the solver (and its robust kernel)
        let mut absurd = graph.clone();
        absurd.edges[9].from_from_to.translation =
            Translation3::from(Vector3::new(1e100, 0.0, 0.0));
        assert_eq!(numeric_problem(&absurd), None);

        let mut vertex = graph;
        vertex.vertices[3].world_from_vertex.translation =
            Translation3::from(Vector3::new(0.0, -1e200, 0.0));
        assert!(matches!(
            numeric_problem(&vertex),
            Some(NumericProblem::Vertex { vertex: 3, .. })
        ));
    }
}
