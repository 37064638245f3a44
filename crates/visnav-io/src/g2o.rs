//! The g2o text format of 3-D pose graphs, read into and written from a plain typed description
//! ([`G2oGraph`]); `visnav-graph` builds its solver graph from it.
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
//! and writing again gives identical bytes and identical `f64` values. Every error names the file
//! and the 1-based line.

use std::collections::HashMap;
use std::fmt::Write as _;
use std::path::Path;

use nalgebra::{Isometry3, Matrix6, Quaternion, Translation3, UnitQuaternion};
use visnav_core::Pose;

use crate::error::{IoError, Result};

/// A `VERTEX_SE3:QUAT` line.
#[derive(Debug, Clone, PartialEq)]
pub struct G2oVertex {
    /// 1-based line of the vertex in its file (0 for a graph built in memory).
    pub line: usize,
    /// The vertex id of the file (ids need not be contiguous).
    pub id: u64,
    /// The pose, `world_from_vertex`.
    pub world_from_vertex: Pose,
    /// Named by a `FIX` line.
    pub fixed: bool,
}

/// An `EDGE_SE3:QUAT` line, its ends resolved to vertex indices.
#[derive(Debug, Clone, PartialEq)]
pub struct G2oEdge {
    /// 1-based line of the edge in its file (0 for a graph built in memory).
    pub line: usize,
    /// Index (into [`G2oGraph::vertices`]) of the first end `i`.
    pub from: usize,
    /// Index of the second end `j`.
    pub to: usize,
    /// The measurement `Z_ij = i_from_j`.
    pub from_from_to: Pose,
    /// Information matrix as in the file (symmetric, not checked for definiteness), ordered
    /// (translation, rotation).
    pub information: Matrix6<f64>,
}

/// A g2o file: vertices and edges in file order.
#[derive(Debug, Clone, PartialEq, Default)]
pub struct G2oGraph {
    /// The vertices in file order.
    pub vertices: Vec<G2oVertex>,
    /// The edges in file order.
    pub edges: Vec<G2oEdge>,
}

/// Reads a g2o file (through [`crate::text::read_text`]).
///
/// # Errors
/// [`IoError::NotFound`] / [`IoError::Io`] when the file cannot be read, [`IoError::Parse`] (with
/// file and line) for malformed or unsupported lines, duplicate vertex ids and edges or `FIX`
/// lines naming undeclared vertex ids.
pub fn read_g2o(path: &Path) -> Result<G2oGraph> {
    let text = crate::text::read_text(path)?;
    parse_g2o(&text, path)
}

/// Parses g2o text; `path` only names the source in errors. Two stages: every line is parsed on
/// its own (`Records::scan`), then the vertex ids of edges and `FIX` lines are resolved
/// (`Records::link`; edges may name vertices declared later).
///
/// # Errors
/// As [`read_g2o`].
pub fn parse_g2o(text: &str, path: &Path) -> Result<G2oGraph> {
    Records::scan(text, path)?.link(path)
}

/// Writes a g2o file atomically (vertices, edges, then a `FIX` line for fixed vertices).
///
/// # Errors
/// [`IoError::Io`] when the file cannot be written.
pub fn write_g2o(path: &Path, graph: &G2oGraph) -> Result<()> {
    crate::atomic::write_atomic(path, format_g2o(graph).as_bytes())
}

fn parse_error(path: &Path, line: usize, message: impl Into<String>) -> IoError {
    IoError::Parse {
        path: path.to_path_buf(),
        line,
        message: message.into(),
    }
}

fn parse_numbers(tokens: &[&str], path: &Path, line: usize, tag: &str) -> Result<Vec<f64>> {
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

fn parse_id(token: &str, path: &Path, line: usize, tag: &str) -> Result<u64> {
    token
        .parse::<u64>()
        .map_err(|_| parse_error(path, line, format!("{tag}: `{token}` is not a vertex id")))
}

/// The pose of `x y z qx qy qz qw`.
fn pose_from_values(v: &[f64], path: &Path, line: usize) -> Result<Pose> {
    let q = Quaternion::new(v[6], v[3], v[4], v[5]);
    let norm = q.norm();
    if !norm.is_finite() || norm <= 1e-12 {
        return Err(parse_error(
            path,
            line,
            "quaternion has zero or non-finite norm",
        ));
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
    line: usize,
    from_id: u64,
    to_id: u64,
    from_from_to: Pose,
    information: Matrix6<f64>,
}

/// Stage 1 of the reader, the scan: every line parsed on its own, ids not yet resolved.
#[derive(Debug, Default)]
struct Records {
    /// Vertices in file order (`fixed` still false).
    vertices: Vec<G2oVertex>,
    /// Index in `vertices` of each vertex id.
    index_of: HashMap<u64, usize>,
    /// Edges in file order.
    edges: Vec<EdgeRecord>,
    /// `FIX` ids in file order, with their lines.
    fixed: Vec<(usize, u64)>,
}

/// `VERTEX_SE3:QUAT id x y z qx qy qz qw`.
fn parse_vertex(rest: &[&str], path: &Path, line: usize, tag: &str) -> Result<G2oVertex> {
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
    Ok(G2oVertex {
        line,
        id,
        world_from_vertex: pose_from_values(&v, path, line)?,
        fixed: false,
    })
}

/// `EDGE_SE3:QUAT i j x y z qx qy qz qw` + the 21 upper-triangular information entries.
fn parse_edge(rest: &[&str], path: &Path, line: usize, tag: &str) -> Result<EdgeRecord> {
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
    fn scan(text: &str, path: &Path) -> Result<Self> {
        let mut records = Self::default();
        for (k, raw) in text.lines().enumerate() {
            let tokens: Vec<&str> = raw.split_whitespace().collect();
            let Some((&tag, rest)) = tokens.split_first() else {
                continue;
            };
            if tag.starts_with('#') {
                continue;
            }
            records.push_line(tag, rest, path, k + 1)?;
        }
        Ok(records)
    }

    /// One non-comment line.
    fn push_line(&mut self, tag: &str, rest: &[&str], path: &Path, line: usize) -> Result<()> {
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
                    self.fixed.push((line, parse_id(t, path, line, tag)?));
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
    fn link(self, path: &Path) -> Result<G2oGraph> {
        let Self {
            vertices,
            index_of,
            edges,
            fixed,
        } = self;
        let lookup = |line: usize, id: u64| {
            index_of.get(&id).copied().ok_or_else(|| {
                parse_error(
                    path,
                    line,
                    format!(
                        "refers to unknown vertex id {id} (no VERTEX_SE3:QUAT line declares it)"
                    ),
                )
            })
        };
        let mut graph = G2oGraph {
            vertices,
            edges: Vec::with_capacity(edges.len()),
        };
        for e in edges {
            let from = lookup(e.line, e.from_id)?;
            let to = lookup(e.line, e.to_id)?;
            graph.edges.push(G2oEdge {
                line: e.line,
                from,
                to,
                from_from_to: e.from_from_to,
                information: e.information,
            });
        }
        for (line, id) in fixed {
            let k = lookup(line, id)?;
            graph.vertices[k].fixed = true;
        }
        Ok(graph)
    }
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

/// The g2o text of a graph (edge lines in `edges` order; [`G2oEdge::line`] is not used).
#[must_use]
pub fn format_g2o(graph: &G2oGraph) -> String {
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
        let g = parse_g2o(SMALL, Path::new("<memory>")).unwrap();
        assert_eq!(g.vertices.len(), 2);
        assert_eq!(g.edges.len(), 1);
        assert_eq!(g.edges[0].line, 4);
        assert!(g.vertices[0].fixed && !g.vertices[1].fixed);
        assert_eq!(g.edges[0].information[(3, 3)], 400.0);
        assert_eq!(g.edges[0].information[(0, 0)], 100.0);
        let text = format_g2o(&g);
        let back = parse_g2o(&text, Path::new("<memory>")).unwrap();
        assert_eq!(format_g2o(&back), text);
        let content = |g: &G2oGraph| -> Vec<(u64, Pose, bool)> {
            g.vertices
                .iter()
                .map(|v| (v.id, v.world_from_vertex, v.fixed))
                .collect()
        };
        assert_eq!(content(&back), content(&g));
        // lines are those of each text: after the comment in SMALL, from the top in the output
        assert_eq!((g.vertices[0].line, back.vertices[0].line), (2, 1));
    }

    #[test]
    fn errors_name_file_and_line() {
        let err = |text: &str| parse_g2o(text, Path::new("g.g2o")).unwrap_err().to_string();
        let bad = err("VERTEX_SE3:QUAT 0 0 0 0 0 0 0 1\nVERTEX_SE3:QUAT 1 0 0 0 0 0 x 1\n");
        assert!(bad.starts_with("g.g2o:2:") && bad.contains("`x`"), "{bad}");
        let short = err("EDGE_SE3:QUAT 0 1 0 0 0\n");
        assert!(
            short.starts_with("g.g2o:1:") && short.contains("expected 30 fields"),
            "{short}"
        );
        let unknown = err(
            "VERTEX_SE3:QUAT 0 0 0 0 0 0 0 1\nEDGE_SE3:QUAT 0 7 0 0 0 0 0 0 1 1 0 0 0 0 0 1 0 0 0 0 1 0 0 0 1 0 0 1 0 1\n",
        );
        assert!(
            unknown.starts_with("g.g2o:2:") && unknown.contains("unknown vertex id 7"),
            "{unknown}"
        );
        let fix = err("VERTEX_SE3:QUAT 0 0 0 0 0 0 0 1\n\nFIX 3\n");
        assert!(fix.starts_with("g.g2o:3:") && fix.contains("id 3"), "{fix}");
        assert!(err("VERTEX_SE2 0 0 0 0\n").contains("unsupported tag"));
        let dup = err("VERTEX_SE3:QUAT 0 0 0 0 0 0 0 1\nVERTEX_SE3:QUAT 0 0 0 0 0 0 0 1\n");
        assert!(
            dup.starts_with("g.g2o:2:") && dup.contains("duplicate"),
            "{dup}"
        );
        assert!(err("VERTEX_SE3:QUAT 0 0 0 0 0 0 0 0\n").contains("quaternion"));
        let huge = err("VERTEX_SE3:QUAT 0 0 0 0 1e308 1e308 0 1\n");
        assert!(huge.contains("quaternion"), "{huge}");
    }
}
