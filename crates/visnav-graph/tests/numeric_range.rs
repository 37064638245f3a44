//! Issue 53, item 6: a pose graph that fails numerically names the edge (or vertex) and its line,
//! as every other g2o error does. Before, information 1e-300 stopped the solve at "sparse
//! Cholesky of the position normal equations failed: NonPositivePivot { index: 22 }", a
//! translation of 1e308 at "… failed: non-finite solution", information 1e300 at
//! "NonPositivePivot { index: 16 }", and a vertex at 1e308 m gave an objective of `inf` with exit
//! 0 (`--init input`).
#![allow(clippy::unwrap_used)]

use std::path::Path;

use visnav_graph::synthetic::{LoopDriveConfig, loop_drive};
use visnav_graph::{GraphConfig, GraphError, format_g2o, parse_g2o, solve};

/// The g2o text of a small loop drive (vertices on lines 1..=200, edges after).
fn text() -> String {
    format_g2o(&loop_drive(&LoopDriveConfig::default()).graph)
}

/// `text` with token `token` (0-based, the tag is token 0) of 1-based line `line` replaced.
fn edit(text: &str, line: usize, tokens: &[(usize, &str)]) -> String {
    text.lines()
        .enumerate()
        .map(|(k, l)| {
            if k + 1 != line {
                return l.to_string();
            }
            let mut t: Vec<&str> = l.split_whitespace().collect();
            for &(i, v) in tokens {
                t[i] = v;
            }
            t.join(" ")
        })
        .collect::<Vec<_>>()
        .join("\n")
}

fn error_of(text: &str) -> String {
    let err = parse_g2o(text, Path::new("g.g2o")).unwrap_err();
    assert!(matches!(err, GraphError::Parse { .. }), "{err:?}");
    err.to_string()
}

/// The 21 information entries of an edge line are tokens 10..=30; the diagonal ones are
/// 10, 16, 21, 25, 28, 30.
const DIAGONAL: [usize; 6] = [10, 16, 21, 25, 28, 30];

#[test]
fn information_1e_300_names_the_edge_and_its_line() {
    let base = text();
    // line 201 is the first edge, 0 -> 1 (the only edge of the fixed vertex 0 but one closure)
    let tokens: Vec<(usize, &str)> = DIAGONAL.iter().map(|&i| (i, "1e-300")).collect();
    let err = error_of(&edit(&base, 201, &tokens));
    assert!(
        err.starts_with("g.g2o:201: EDGE_SE3:QUAT: edge 0 -> 1:"),
        "{err}"
    );
    assert!(err.contains("numerically zero"), "{err}");
    // an odometry edge in the middle
    let err = error_of(&edit(&base, 260, &tokens));
    assert!(
        err.starts_with("g.g2o:260: EDGE_SE3:QUAT: edge 59 -> 60:"),
        "{err}"
    );
}

#[test]
fn information_1e300_names_the_edge_and_its_line() {
    let tokens: Vec<(usize, &str)> = DIAGONAL.iter().map(|&i| (i, "1e300")).collect();
    let err = error_of(&edit(&text(), 230, &tokens));
    assert!(
        err.starts_with("g.g2o:230: EDGE_SE3:QUAT: edge 29 -> 30:"),
        "{err}"
    );
    assert!(err.contains("numerically infinite"), "{err}");
}

#[test]
fn translation_1e308_names_the_edge_and_its_line() {
    let err = error_of(&edit(&text(), 212, &[(3, "1e308")]));
    assert!(
        err.starts_with("g.g2o:212: EDGE_SE3:QUAT: edge 11 -> 12:"),
        "{err}"
    );
    assert!(err.contains("overflows"), "{err}");
}

#[test]
fn a_vertex_at_1e308_m_names_the_vertex_and_its_line() {
    let err = error_of(&edit(&text(), 8, &[(2, "1e308")]));
    assert!(
        err.starts_with("g.g2o:8: VERTEX_SE3:QUAT: vertex id 7:"),
        "{err}"
    );
    assert!(err.contains("overflows"), "{err}");
}

#[test]
fn extreme_but_computable_values_still_solve() {
    // a thousand times less information on one edge, a 1e6 m odometry claim: odd, not a
    // numeric failure (the robust solver sees an inconsistent graph)
    let base = text();
    let tokens: Vec<(usize, &str)> = DIAGONAL.iter().map(|&i| (i, "0.4")).collect();
    let graph = parse_g2o(&edit(&base, 230, &tokens), Path::new("g.g2o")).unwrap();
    assert!(solve(&graph, &GraphConfig::default()).is_ok());
    let graph = parse_g2o(&edit(&base, 212, &[(3, "1e6")]), Path::new("g.g2o")).unwrap();
    let sol = solve(&graph, &GraphConfig::default()).unwrap();
    assert!(sol.final_all_edges.chi2.is_finite());
}

#[test]
fn a_graph_built_in_memory_gets_the_edge_named_by_the_solver() {
    let mut graph = loop_drive(&LoopDriveConfig::default()).graph;
    graph.edges[40].information *= 1e-300;
    let err = solve(&graph, &GraphConfig::default()).unwrap_err();
    match &err {
        GraphError::NumericRange { what, message } => {
            assert_eq!(what, "edge 40 (40 -> 41)");
            assert!(message.contains("numerically zero"), "{message}");
        }
        other => panic!("{other:?}"),
    }
}
