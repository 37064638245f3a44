//! The solver graph from and to the g2o format: the file format itself (parsing with file and
//! line errors, formatting with an exact round trip) is [`visnav_io::g2o`], which reads a plain
//! description ([`G2oGraph`]); this module builds the [`PoseGraph`] from it
//! ([`PoseGraph::from_g2o`]), replacing information matrices that are not positive definite by
//! SE-Sync's isotropic ones (a solver concern: the objective must not be indefinite), and back
//! ([`PoseGraph::to_g2o`]).

use std::path::{Path, PathBuf};

use nalgebra::Matrix6;
use visnav_io::g2o::{self as g2o_io, G2oEdge, G2oGraph, G2oVertex};

use crate::error::GraphError;
use crate::graph::{Edge, PoseGraph, Vertex};
use crate::numeric::{NumericProblem, numeric_problem};
use crate::sesync::{SeSyncWeights, isotropic_information, sesync_weights};

/// Reads a g2o file. An information matrix that is not positive definite is replaced by
/// SE-Sync's isotropic one ([`crate::sesync::isotropic_information`]) or, when its diagonal
/// blocks give no SE-Sync weights, projected to the nearest positive-definite matrix
/// ([`project_information`]); one warning names the edges (see [`read_g2o_with_report`]).
///
/// # Errors
/// [`GraphError::File`] when the file cannot be read or has a malformed or unsupported line, an
/// edge to an undeclared id (file and line named, [`visnav_io::g2o::read_g2o`]);
/// [`GraphError::Parse`] naming the line for an information matrix without a positive
/// eigenvalue, or an edge whose numbers cannot be optimised in `f64` (module
/// [`crate::numeric`]).
pub fn read_g2o(path: &Path) -> Result<PoseGraph, GraphError> {
    read_g2o_with_report(path).map(|(graph, _)| graph)
}

/// How the reader replaced an information matrix that is not positive definite.
#[derive(Debug, Clone, Copy, PartialEq)]
pub enum Replacement {
    /// SE-Sync's isotropic information `diag(τ I₃, 2κ I₃)` from the file's diagonal blocks
    /// (`τ = 3/tr(Ω_tt⁻¹)`, `κ = 3/(2 tr(Ω_rr⁻¹))`).
    Isotropic(SeSyncWeights),
    /// The nearest positive-definite matrix ([`project_information`]): the blocks gave no
    /// SE-Sync weights.
    Projected,
}

/// An edge whose information matrix the reader replaced.
#[derive(Debug, Clone, PartialEq)]
pub struct ReplacedEdge {
    /// 1-based line of the edge in the file.
    pub line: usize,
    /// Index of the edge in [`PoseGraph::edges`].
    pub edge: usize,
    /// Vertex id of the edge's first end.
    pub from_id: u64,
    /// Vertex id of the edge's second end.
    pub to_id: u64,
    /// Smallest eigenvalue of the matrix in the file.
    pub min_eigenvalue: f64,
    /// What replaced it.
    pub replacement: Replacement,
}

/// What the reader changed in a file.
#[derive(Debug, Clone, PartialEq, Default)]
pub struct G2oReport {
    /// Edges whose information matrix was not positive definite and was replaced, in file order.
    pub replaced: Vec<ReplacedEdge>,
    /// The 1-based line of each edge in the file (indexed like [`PoseGraph::edges`]).
    pub edge_lines: Vec<usize>,
}

impl G2oReport {
    /// The edges given SE-Sync's isotropic information.
    pub fn isotropic(&self) -> impl Iterator<Item = &ReplacedEdge> {
        self.replaced
            .iter()
            .filter(|r| matches!(r.replacement, Replacement::Isotropic(_)))
    }

    /// The edges whose information was projected.
    pub fn projected(&self) -> impl Iterator<Item = &ReplacedEdge> {
        self.replaced
            .iter()
            .filter(|r| r.replacement == Replacement::Projected)
    }
}

/// As [`read_g2o`], with the list of edges whose information matrix was replaced (the warning
/// is logged as well).
///
/// # Errors
/// As [`read_g2o`].
pub fn read_g2o_with_report(path: &Path) -> Result<(PoseGraph, G2oReport), GraphError> {
    PoseGraph::from_g2o(g2o_io::read_g2o(path)?, path)
}

/// Relative floor of the eigenvalues of a projected information matrix (times the largest).
pub const INFORMATION_EIGENVALUE_FLOOR: f64 = 1e-6;

/// Whether a symmetric information matrix is positive definite (its Cholesky factorisation
/// exists).
#[must_use]
pub fn is_positive_definite(information: &Matrix6<f64>) -> bool {
    information.iter().all(|v| v.is_finite()) && information.cholesky().is_some()
}

/// The nearest positive-definite matrix to a symmetric `information` (in the Frobenius norm,
/// up to the floor): its eigenvalues below `INFORMATION_EIGENVALUE_FLOOR` times the largest
/// are raised to that floor, the eigenvectors kept. `None` when no eigenvalue is positive
/// (nothing to keep). Also returns the smallest eigenvalue of the input. The reader uses it
/// only for matrices whose diagonal blocks give no SE-Sync weights: on a benchmark whose
/// indefinite matrices have large eigenvalues of both signs, the projection keeps the large
/// positive ones, an over-confident weight in directions the file never measured
/// (`docs/guide/posegraph.md`).
#[must_use]
pub fn project_information(information: &Matrix6<f64>) -> Option<(Matrix6<f64>, f64)> {
    let sym = (information + information.transpose()) * 0.5;
    let eig = sym.symmetric_eigen();
    let max = eig.eigenvalues.max();
    let min = eig.eigenvalues.min();
    if max.is_nan() || max <= 0.0 {
        return None;
    }
    let floor = max * INFORMATION_EIGENVALUE_FLOOR;
    let clamped = eig.eigenvalues.map(|l| l.max(floor));
    let q = &eig.eigenvectors;
    let projected = q * Matrix6::from_diagonal(&clamped) * q.transpose();
    // exactly symmetric
    Some(((projected + projected.transpose()) * 0.5, min))
}

/// Writes a g2o file (vertices, edges, then a `FIX` line for fixed vertices).
///
/// # Errors
/// [`GraphError::File`] when the file cannot be written.
pub fn write_g2o(path: &Path, graph: &PoseGraph) -> Result<(), GraphError> {
    Ok(g2o_io::write_g2o(path, &graph.to_g2o())?)
}

/// Parses g2o text; `path` only names the source in errors.
///
/// # Errors
/// As [`read_g2o`].
pub fn parse_g2o(text: &str, path: &Path) -> Result<PoseGraph, GraphError> {
    parse_g2o_with_report(text, path).map(|(graph, _)| graph)
}

/// As [`parse_g2o`], with the report of [`read_g2o_with_report`].
///
/// # Errors
/// As [`read_g2o`].
pub fn parse_g2o_with_report(
    text: &str,
    path: &Path,
) -> Result<(PoseGraph, G2oReport), GraphError> {
    PoseGraph::from_g2o(g2o_io::parse_g2o(text, path)?, path)
}

/// Every information matrix that is not positive definite is replaced (see [`read_g2o`]); one
/// warning names the file and the edges (line, vertex ids, smallest eigenvalue, the weights). A
/// matrix without a positive eigenvalue is an error naming its line.
fn replace_indefinite_information(
    graph: &mut PoseGraph,
    lines: &[usize],
    path: &Path,
) -> Result<G2oReport, GraphError> {
    let mut report = G2oReport::default();
    for (k, (edge, &line)) in graph.edges.iter_mut().zip(lines).enumerate() {
        if is_positive_definite(&edge.information) {
            continue;
        }
        let (from_id, to_id) = (graph.vertices[edge.from].id, graph.vertices[edge.to].id);
        let Some((projected, min_eigenvalue)) = project_information(&edge.information) else {
            return Err(GraphError::Parse {
                path: path.to_path_buf(),
                line,
                message: format!(
                    "EDGE_SE3:QUAT: edge {from_id} -> {to_id}: the information matrix has no positive eigenvalue"
                ),
            });
        };
        let replacement = match sesync_weights(&edge.information) {
            Some(weights) => {
                edge.information = isotropic_information(weights);
                Replacement::Isotropic(weights)
            }
            None => {
                edge.information = projected;
                Replacement::Projected
            }
        };
        report.replaced.push(ReplacedEdge {
            line,
            edge: k,
            from_id,
            to_id,
            min_eigenvalue,
            replacement,
        });
    }
    warn_replaced(&report, path);
    Ok(report)
}

/// One warning per kind of replacement, naming the first ten edges.
fn warn_replaced(report: &G2oReport, path: &Path) {
    let describe = |r: &ReplacedEdge| match r.replacement {
        Replacement::Isotropic(w) => format!(
            "line {} ({} -> {}, smallest eigenvalue {:.3e}, tau {:.4e}, kappa {:.4e})",
            r.line, r.from_id, r.to_id, r.min_eigenvalue, w.tau, w.kappa
        ),
        Replacement::Projected => format!(
            "line {} ({} -> {}, smallest eigenvalue {:.3e})",
            r.line, r.from_id, r.to_id, r.min_eigenvalue
        ),
    };
    let groups: [(Vec<&ReplacedEdge>, &str); 2] = [
        (
            report.isotropic().collect(),
            "replaced by SE-Sync's isotropic weights (tau = 3/tr(inverse translation block), kappa = 3/(2 tr(inverse rotation block)))",
        ),
        (
            report.projected().collect(),
            "projected to the nearest positive-definite matrix (its diagonal blocks give no SE-Sync weights)",
        ),
    ];
    for (edges, what) in groups {
        if edges.is_empty() {
            continue;
        }
        let shown: Vec<String> = edges.iter().take(10).map(|r| describe(r)).collect();
        let more = edges.len().saturating_sub(shown.len());
        log::warn!(
            "{}: {} edge(s) with an information matrix that is not positive definite, {what}: {}{}",
            path.display(),
            edges.len(),
            shown.join(", "),
            if more > 0 {
                format!(" and {more} more")
            } else {
                String::new()
            }
        );
    }
}

/// The g2o text of a graph.
#[must_use]
pub fn format_g2o(graph: &PoseGraph) -> String {
    g2o_io::format_g2o(&graph.to_g2o())
}

impl PoseGraph {
    /// The solver graph of a g2o description ([`visnav_io::g2o::read_g2o`]): every information
    /// matrix that is not positive definite is replaced (see [`read_g2o`]); `path` names the
    /// source in the warning and errors.
    ///
    /// # Errors
    /// [`GraphError::Parse`] naming the edge's line when an information matrix has no positive
    /// eigenvalue, and the line of the first edge or vertex outside the numeric range of the
    /// solver ([`crate::numeric`]: information numerically zero or infinite next to the other
    /// edges', a translation or position whose squares overflow).
    pub fn from_g2o(description: G2oGraph, path: &Path) -> Result<(Self, G2oReport), GraphError> {
        let lines: Vec<usize> = description.edges.iter().map(|e| e.line).collect();
        let vertex_lines: Vec<usize> = description.vertices.iter().map(|v| v.line).collect();
        let mut graph = Self {
            vertices: description
                .vertices
                .into_iter()
                .map(|v| Vertex {
                    id: v.id,
                    world_from_vertex: v.world_from_vertex,
                    fixed: v.fixed,
                })
                .collect(),
            edges: description
                .edges
                .into_iter()
                .map(|e| Edge {
                    from: e.from,
                    to: e.to,
                    from_from_to: e.from_from_to,
                    information: e.information,
                })
                .collect(),
        };
        let mut report = replace_indefinite_information(&mut graph, &lines, path)?;
        if let Some(problem) = numeric_problem(&graph) {
            let (line, what, message) = match problem {
                NumericProblem::Edge { edge, message } => {
                    let e = &graph.edges[edge];
                    (
                        lines[edge],
                        format!(
                            "EDGE_SE3:QUAT: edge {} -> {}",
                            graph.vertices[e.from].id, graph.vertices[e.to].id
                        ),
                        message,
                    )
                }
                NumericProblem::Vertex { vertex, message } => (
                    vertex_lines[vertex],
                    format!("VERTEX_SE3:QUAT: vertex id {}", graph.vertices[vertex].id),
                    message,
                ),
            };
            return Err(GraphError::Parse {
                path: path.to_path_buf(),
                line,
                message: format!("{what}: {message}"),
            });
        }
        report.edge_lines = lines;
        Ok((graph, report))
    }

    /// The g2o description of this graph (edge lines numbered as [`format_g2o`] writes them).
    #[must_use]
    pub fn to_g2o(&self) -> G2oGraph {
        let first_edge_line = self.vertices.len() + 1;
        G2oGraph {
            vertices: self
                .vertices
                .iter()
                .enumerate()
                .map(|(k, v)| G2oVertex {
                    line: k + 1,
                    id: v.id,
                    world_from_vertex: v.world_from_vertex,
                    fixed: v.fixed,
                })
                .collect(),
            edges: self
                .edges
                .iter()
                .enumerate()
                .map(|(k, e)| G2oEdge {
                    line: first_edge_line + k,
                    from: e.from,
                    to: e.to,
                    from_from_to: e.from_from_to,
                    information: e.information,
                })
                .collect(),
        }
    }
}

/// A path naming in-memory text in errors.
#[must_use]
pub fn memory_path() -> PathBuf {
    PathBuf::from("<memory>")
}

#[cfg(test)]
mod tests {
    use super::*;

    const SMALL: &str = "\
# a comment
VERTEX_SE3:QUAT 0 0 0 0 0 0 0 1
VERTEX_SE3:QUAT 1 1.5 0.25 -0.125 0 0 0.0998334 0.995004
EDGE_SE3:QUAT 0 1 1.5 0.25 -0.125 0 0 0.0998334 0.995004 100 0 0 0 0 0 100 0 0 0 0 100 0 0 0 400 0 0 400 0 400
FIX 0
";

    #[test]
    fn parses_and_round_trips_exactly() {
        let g = parse_g2o(SMALL, &memory_path()).unwrap();
        assert_eq!(g.vertices.len(), 2);
        assert_eq!(g.edges.len(), 1);
        assert!(g.vertices[0].fixed && !g.vertices[1].fixed);
        assert_eq!(g.edges[0].information[(3, 3)], 400.0);
        assert_eq!(g.edges[0].information[(0, 0)], 100.0);
        let text = format_g2o(&g);
        let back = parse_g2o(&text, &memory_path()).unwrap();
        assert_eq!(back, g);
        assert_eq!(format_g2o(&back), text);
        // the description's edge lines are those of the written text
        assert_eq!(g.to_g2o().edges[0].line, 3);
    }

    #[test]
    fn errors_name_file_and_line() {
        let bad = "VERTEX_SE3:QUAT 0 0 0 0 0 0 0 1\nVERTEX_SE3:QUAT 1 0 0 0 0 0 x 1\n";
        let err = parse_g2o(bad, Path::new("g.g2o")).unwrap_err().to_string();
        assert!(err.starts_with("g.g2o:2:"), "{err}");
        assert!(err.contains("`x`"), "{err}");

        let short = "EDGE_SE3:QUAT 0 1 0 0 0\n";
        let err = parse_g2o(short, Path::new("g.g2o"))
            .unwrap_err()
            .to_string();
        assert!(
            err.contains("g.g2o:1:") && err.contains("expected 30 fields"),
            "{err}"
        );

        let unknown = "VERTEX_SE3:QUAT 0 0 0 0 0 0 0 1\nEDGE_SE3:QUAT 0 7 0 0 0 0 0 0 1 1 0 0 0 0 0 1 0 0 0 0 1 0 0 0 1 0 0 1 0 1\n";
        let err = parse_g2o(unknown, Path::new("g.g2o")).unwrap_err();
        assert!(
            matches!(
                &err,
                GraphError::File(visnav_io::IoError::Parse { line: 2, .. })
            ) && err.to_string().contains("unknown vertex id 7"),
            "{err}"
        );

        let tag = "VERTEX_SE2 0 0 0 0\n";
        let err = parse_g2o(tag, Path::new("g.g2o")).unwrap_err().to_string();
        assert!(err.contains("unsupported tag"), "{err}");

        let dup = "VERTEX_SE3:QUAT 0 0 0 0 0 0 0 1\nVERTEX_SE3:QUAT 0 0 0 0 0 0 0 1\n";
        assert!(parse_g2o(dup, Path::new("g")).is_err());
        let zero_q = "VERTEX_SE3:QUAT 0 0 0 0 0 0 0 0\n";
        assert!(parse_g2o(zero_q, Path::new("g")).is_err());
    }
}
