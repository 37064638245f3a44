//! g2o text format for 3-D pose graphs.
//!
//! Lines understood (tokens separated by white space, `#` starts a comment line):
//! * `VERTEX_SE3:QUAT id x y z qx qy qz qw` — the pose `world_from_vertex` (translation in metres,
//!   unit quaternion; a quaternion off unit norm by more than rounding is normalised);
//! * `EDGE_SE3:QUAT i j x y z qx qy qz qw I11 I12 .. I16 I22 .. I66` — the measurement `i_from_j`
//!   and the 21 upper-triangular entries of the information matrix, row-major, ordered
//!   (translation, rotation);
//! * `FIX id ...` — vertices held constant.
//!
//! Numbers are written with Rust's shortest round-trip formatting (`{:?}`), so writing, reading
//! and writing again gives identical bytes and identical `f64` values.

use std::collections::HashMap;
use std::fmt::Write as _;
use std::path::{Path, PathBuf};

use nalgebra::{Isometry3, Matrix6, Quaternion, Translation3, UnitQuaternion};
use visnav_core::Pose;

use crate::error::GraphError;
use crate::graph::{Edge, PoseGraph, Vertex};

/// Reads a g2o file. Information matrices that are not positive definite are projected to the
/// nearest positive-definite one ([`project_information`]) with a warning naming the edges (see
/// [`read_g2o_with_report`]).
///
/// # Errors
/// [`GraphError::Io`] when the file cannot be read, [`GraphError::Parse`] (with file and line)
/// for malformed or unsupported lines, [`GraphError::UnknownVertex`] for edges to undeclared ids.
pub fn read_g2o(path: &Path) -> Result<PoseGraph, GraphError> {
    let text = std::fs::read_to_string(path).map_err(|source| GraphError::Io {
        path: path.to_path_buf(),
        source,
    })?;
    parse_g2o(&text, path)
}

/// An edge whose information matrix the reader replaced ([`project_information`]).
#[derive(Debug, Clone, PartialEq)]
pub struct ProjectedEdge {
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
}

/// What the reader changed in a file.
#[derive(Debug, Clone, PartialEq, Default)]
pub struct G2oReport {
    /// Edges whose information matrix was not positive definite and was projected.
    pub projected: Vec<ProjectedEdge>,
}

/// As [`read_g2o`], with the list of edges whose information matrix was projected (the warning
/// is logged as well).
///
/// # Errors
/// As [`read_g2o`].
pub fn read_g2o_with_report(path: &Path) -> Result<(PoseGraph, G2oReport), GraphError> {
    let text = std::fs::read_to_string(path).map_err(|source| GraphError::Io {
        path: path.to_path_buf(),
        source,
    })?;
    parse_g2o_with_report(&text, path)
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
/// are raised to that floor, the eigenvectors kept — what GTSAM users and SE-Sync's loaders do
/// with such files instead of optimising an indefinite objective. `None` when no eigenvalue is
/// positive (nothing to keep). Also returns the smallest eigenvalue of the input.
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
/// [`GraphError::Io`] when the file cannot be written.
pub fn write_g2o(path: &Path, graph: &PoseGraph) -> Result<(), GraphError> {
    std::fs::write(path, format_g2o(graph)).map_err(|source| GraphError::Io {
        path: path.to_path_buf(),
        source,
    })
}

fn parse_error(path: &Path, line: usize, message: impl Into<String>) -> GraphError {
    GraphError::Parse {
        path: path.to_path_buf(),
        line,
        message: message.into(),
    }
}

fn parse_numbers(
    tokens: &[&str],
    path: &Path,
    line: usize,
    tag: &str,
) -> Result<Vec<f64>, GraphError> {
    tokens
        .iter()
        .map(|t| {
            t.parse::<f64>()
                .ok()
                .filter(|v| v.is_finite())
                .ok_or_else(|| {
                    parse_error(path, line, format!("{tag}: `{t}` is not a finite number"))
                })
        })
        .collect()
}

fn parse_id(token: &str, path: &Path, line: usize, tag: &str) -> Result<u64, GraphError> {
    token
        .parse::<u64>()
        .map_err(|_| parse_error(path, line, format!("{tag}: `{token}` is not a vertex id")))
}

/// The pose of `x y z qx qy qz qw`.
fn pose_from_values(v: &[f64], path: &Path, line: usize) -> Result<Pose, GraphError> {
    let q = Quaternion::new(v[6], v[3], v[4], v[5]);
    let norm = q.norm();
    if norm.is_nan() || norm <= 1e-12 {
        return Err(parse_error(path, line, "quaternion has zero norm"));
    }
    // Keep exact values when already unit up to rounding so that files round-trip bit for bit.
    let rotation = if (norm - 1.0).abs() <= 4.0 * f64::EPSILON {
        UnitQuaternion::new_unchecked(q)
    } else {
        UnitQuaternion::from_quaternion(q)
    };
    Ok(Isometry3::from_parts(
        Translation3::new(v[0], v[1], v[2]),
        rotation,
    ))
}

/// An `EDGE_SE3:QUAT` line before its vertex ids are resolved (the vertices may come later).
#[derive(Debug, Clone)]
struct EdgeRecord {
    /// 1-based line number (for errors).
    line: usize,
    /// Vertex id of the edge's first end.
    from_id: u64,
    /// Vertex id of the edge's second end.
    to_id: u64,
    /// The measurement `from_from_to`.
    from_from_to: Pose,
    /// The information matrix, symmetric, ordered (translation, rotation).
    information: Matrix6<f64>,
}

/// A vertex id named by a `FIX` line.
#[derive(Debug, Clone, Copy)]
struct FixRecord {
    /// 1-based line number (for errors).
    line: usize,
    /// The fixed vertex id.
    id: u64,
}

/// Stage 1 of the reader, the scan: every line parsed on its own, ids not yet resolved.
#[derive(Debug, Default)]
struct Records {
    /// Vertices in file order (`fixed` still false).
    vertices: Vec<Vertex>,
    /// Index in `vertices` of each vertex id.
    index_of: HashMap<u64, usize>,
    /// Edges in file order.
    edges: Vec<EdgeRecord>,
    /// `FIX` ids in file order.
    fixed: Vec<FixRecord>,
}

/// `VERTEX_SE3:QUAT id x y z qx qy qz qw`.
fn parse_vertex(rest: &[&str], path: &Path, line: usize, tag: &str) -> Result<Vertex, GraphError> {
    if rest.len() != 8 {
        return Err(parse_error(
            path,
            line,
            format!(
                "{tag}: expected 8 fields (id x y z qx qy qz qw), got {}",
                rest.len()
            ),
        ));
    }
    let id = parse_id(rest[0], path, line, tag)?;
    let v = parse_numbers(&rest[1..], path, line, tag)?;
    let pose = pose_from_values(&v, path, line)?;
    Ok(Vertex {
        id,
        world_from_vertex: pose,
        fixed: false,
    })
}

/// `EDGE_SE3:QUAT i j x y z qx qy qz qw` + the 21 upper-triangular information entries.
fn parse_edge(
    rest: &[&str],
    path: &Path,
    line: usize,
    tag: &str,
) -> Result<EdgeRecord, GraphError> {
    if rest.len() != 30 {
        return Err(parse_error(
            path,
            line,
            format!(
                "{tag}: expected 30 fields (i j x y z qx qy qz qw + 21 information \
                 entries), got {}",
                rest.len()
            ),
        ));
    }
    let i = parse_id(rest[0], path, line, tag)?;
    let j = parse_id(rest[1], path, line, tag)?;
    let v = parse_numbers(&rest[2..], path, line, tag)?;
    let pose = pose_from_values(&v[..7], path, line)?;
    let mut info = Matrix6::zeros();
    let mut n = 7;
    for r in 0..6 {
        for c in r..6 {
            info[(r, c)] = v[n];
            info[(c, r)] = v[n];
            n += 1;
        }
    }
    if i == j {
        return Err(parse_error(
            path,
            line,
            format!("{tag}: edge from vertex {i} to itself"),
        ));
    }
    Ok(EdgeRecord {
        line,
        from_id: i,
        to_id: j,
        from_from_to: pose,
        information: info,
    })
}

impl Records {
    /// Stage 1: parses every line of `text` (comments and blank lines skipped).
    fn scan(text: &str, path: &Path) -> Result<Self, GraphError> {
        let mut records = Self::default();
        for (k, raw) in text.lines().enumerate() {
            let line = k + 1;
            let tokens: Vec<&str> = raw.split_whitespace().collect();
            let Some((&tag, rest)) = tokens.split_first() else {
                continue;
            };
            if tag.starts_with('#') {
                continue;
            }
            records.push_line(tag, rest, path, line)?;
        }
        Ok(records)
    }

    /// One non-comment line.
    fn push_line(
        &mut self,
        tag: &str,
        rest: &[&str],
        path: &Path,
        line: usize,
    ) -> Result<(), GraphError> {
        match tag {
            "VERTEX_SE3:QUAT" => {
                let vertex = parse_vertex(rest, path, line, tag)?;
                let id = vertex.id;
                if self.index_of.insert(id, self.vertices.len()).is_some() {
                    return Err(parse_error(
                        path,
                        line,
                        format!("{tag}: duplicate vertex id {id}"),
                    ));
                }
                self.vertices.push(vertex);
            }
            "EDGE_SE3:QUAT" => self.edges.push(parse_edge(rest, path, line, tag)?),
            "FIX" => {
                if rest.is_empty() {
                    return Err(parse_error(
                        path,
                        line,
                        "FIX: expected at least one vertex id",
                    ));
                }
                for t in rest {
                    let id = parse_id(t, path, line, tag)?;
                    self.fixed.push(FixRecord { line, id });
                }
            }
            other => {
                return Err(parse_error(
                    path,
                    line,
                    format!(
                        "unsupported tag `{other}` (expected VERTEX_SE3:QUAT, EDGE_SE3:QUAT or FIX)"
                    ),
                ));
            }
        }
        Ok(())
    }

    /// Stage 2, the link: edge and `FIX` ids resolved to vertex indices.
    fn link(self, path: &Path) -> Result<PoseGraph, GraphError> {
        let Self {
            vertices,
            index_of,
            edges,
            fixed,
        } = self;
        let lookup = |line: usize, id: u64| {
            index_of
                .get(&id)
                .copied()
                .ok_or_else(|| GraphError::UnknownVertex {
                    path: path.to_path_buf(),
                    line,
                    id,
                })
        };
        let mut graph = PoseGraph {
            vertices,
            ..PoseGraph::default()
        };
        for e in edges {
            let from = lookup(e.line, e.from_id)?;
            let to = lookup(e.line, e.to_id)?;
            graph.edges.push(Edge {
                from,
                to,
                from_from_to: e.from_from_to,
                information: e.information,
            });
        }
        for f in fixed {
            let k = lookup(f.line, f.id)?;
            graph.vertices[k].fixed = true;
        }
        Ok(graph)
    }
}

/// Parses g2o text; `path` only names the source in errors.
///
/// Two stages: `Records::scan` parses each line, `Records::link` resolves the vertex ids
/// (edges may name vertices declared later).
///
/// # Errors
/// As [`read_g2o`].
pub fn parse_g2o(text: &str, path: &Path) -> Result<PoseGraph, GraphError> {
    parse_g2o_with_report(text, path).map(|(graph, _)| graph)
}

/// As [`parse_g2o`], with the report of [`read_g2o_with_report`]. Three stages:
/// `Records::scan`, `Records::link` and `make_information_positive_definite`.
///
/// # Errors
/// As [`read_g2o`].
pub fn parse_g2o_with_report(
    text: &str,
    path: &Path,
) -> Result<(PoseGraph, G2oReport), GraphError> {
    let records = Records::scan(text, path)?;
    let lines: Vec<usize> = records.edges.iter().map(|e| e.line).collect();
    let mut graph = records.link(path)?;
    let report = make_information_positive_definite(&mut graph, &lines, path)?;
    Ok((graph, report))
}

/// Stage 3 of the reader: every information matrix that is not positive definite is replaced by
/// the nearest positive-definite one ([`project_information`]); one warning names the file and
/// the edges (line, vertex ids, smallest eigenvalue). A matrix without a positive eigenvalue is
/// an error naming its line.
fn make_information_positive_definite(
    graph: &mut PoseGraph,
    lines: &[usize],
    path: &Path,
) -> Result<G2oReport, GraphError> {
    let mut report = G2oReport::default();
    for (k, (edge, &line)) in graph.edges.iter_mut().zip(lines).enumerate() {
        if is_positive_definite(&edge.information) {
            continue;
        }
        let Some((projected, min_eigenvalue)) = project_information(&edge.information) else {
            return Err(parse_error(
                path,
                line,
                "EDGE_SE3:QUAT: the information matrix has no positive eigenvalue",
            ));
        };
        edge.information = projected;
        report.projected.push(ProjectedEdge {
            line,
            edge: k,
            from_id: graph.vertices[edge.from].id,
            to_id: graph.vertices[edge.to].id,
            min_eigenvalue,
        });
    }
    if !report.projected.is_empty() {
        let shown: Vec<String> = report
            .projected
            .iter()
            .take(10)
            .map(|p| {
                format!(
                    "line {} ({} -> {}, smallest eigenvalue {:.3e})",
                    p.line, p.from_id, p.to_id, p.min_eigenvalue
                )
            })
            .collect();
        let more = report.projected.len().saturating_sub(shown.len());
        log::warn!(
            "{}: {} edge(s) with an information matrix that is not positive definite, projected to the nearest positive-definite matrix: {}{}",
            path.display(),
            report.projected.len(),
            shown.join(", "),
            if more > 0 {
                format!(" and {more} more")
            } else {
                String::new()
            }
        );
    }
    Ok(report)
}

fn push_pose(out: &mut String, pose: &Pose) {
    let t = &pose.translation.vector;
    let q = pose.rotation.quaternion();
    let _ = write!(
        out,
        " {:?} {:?} {:?} {:?} {:?} {:?} {:?}",
        t.x, t.y, t.z, q.i, q.j, q.k, q.w
    );
}

/// The g2o text of a graph.
#[must_use]
pub fn format_g2o(graph: &PoseGraph) -> String {
    let mut out = String::with_capacity(64 * graph.vertices.len() + 256 * graph.edges.len());
    for v in &graph.vertices {
        let _ = write!(out, "VERTEX_SE3:QUAT {}", v.id);
        push_pose(&mut out, &v.world_from_vertex);
        out.push('\n');
    }
    for e in &graph.edges {
        let _ = write!(
            out,
            "EDGE_SE3:QUAT {} {}",
            graph.vertices[e.from].id, graph.vertices[e.to].id
        );
        push_pose(&mut out, &e.from_from_to);
        for r in 0..6 {
            for c in r..6 {
                let _ = write!(out, " {:?}", e.information[(r, c)]);
            }
        }
        out.push('\n');
    }
    let fixed: Vec<String> = graph
        .vertices
        .iter()
        .filter(|v| v.fixed)
        .map(|v| v.id.to_string())
        .collect();
    if !fixed.is_empty() {
        let _ = writeln!(out, "FIX {}", fixed.join(" "));
    }
    out
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
            matches!(err, GraphError::UnknownVertex { line: 2, id: 7, .. }),
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
