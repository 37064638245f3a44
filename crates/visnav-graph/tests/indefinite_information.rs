//! Edges whose information matrix is not positive definite (issue 21): the reader projects them
//! to the nearest positive-definite matrix and names them; the solver never optimises an
//! indefinite objective (a graph built in memory gets an error naming the edge instead of a
//! bare Cholesky failure) and never reports a negative χ².
#![allow(clippy::unwrap_used)]

use std::path::Path;

use visnav_graph::g2o::{is_positive_definite, project_information};
use visnav_graph::{
    GraphConfig, GraphError, Initialisation, RobustKernel, parse_g2o, parse_g2o_with_report, solve,
};

/// Rewrites the information of the edges on the given 1-based lines: the translation xy entry
/// becomes 5 times the diagonal (eigenvalues `d ± 5d`: indefinite).
fn make_indefinite(text: &str, lines: &[usize]) -> String {
    text.lines()
        .enumerate()
        .map(|(k, l)| {
            if !lines.contains(&(k + 1)) {
                return l.to_string();
            }
            let mut t: Vec<String> = l.split_whitespace().map(str::to_string).collect();
            assert_eq!(t[0], "EDGE_SE3:QUAT");
            // tokens: tag i j x y z qx qy qz qw I11 I12 ...
            let d: f64 = t[10].parse().unwrap();
            t[11] = format!("{}", 5.0 * d);
            t.join(" ")
        })
        .collect::<Vec<_>>()
        .join("\n")
}

fn edge_lines(text: &str) -> Vec<usize> {
    text.lines()
        .enumerate()
        .filter(|(_, l)| l.starts_with("EDGE_SE3:QUAT"))
        .map(|(k, _)| k + 1)
        .collect()
}

fn plain() -> GraphConfig {
    GraphConfig {
        robust: RobustKernel::None,
        initialisation: Initialisation::Chordal,
        ..GraphConfig::default()
    }
}

#[test]
fn indefinite_edges_are_projected_named_and_never_give_a_negative_chi2() {
    let Some(path) = visnav_core::testdata::shared_data("posegraph/smallGrid3D.g2o") else {
        eprintln!("VISNAV_DATA not set: skipped");
        return;
    };
    let text = std::fs::read_to_string(&path).unwrap();
    let clean = parse_g2o(&text, &path).unwrap();
    // the benchmark file itself is untouched
    let (_, report) = parse_g2o_with_report(&text, &path).unwrap();
    assert!(report.projected.is_empty());
    let lines = edge_lines(&text);
    let bad = [lines[3], lines[40], lines[200]];
    let corrupted = make_indefinite(&text, &bad);
    let (graph, report) = parse_g2o_with_report(&corrupted, Path::new("bad.g2o")).unwrap();
    // every indefinite edge is named with its line and vertex ids
    let named: Vec<usize> = report.projected.iter().map(|p| p.line).collect();
    assert_eq!(named, bad);
    for p in &report.projected {
        assert!(p.min_eigenvalue < 0.0);
        let e = &graph.edges[p.edge];
        assert_eq!(graph.vertices[e.from].id, p.from_id);
        assert!(is_positive_definite(&e.information));
        // the other entries' scale is kept: the projection is close to the file's matrix
        // where it was already positive
        assert!(e.information[(2, 2)] > 0.5 * clean.edges[p.edge].information[(2, 2)]);
    }
    // the untouched edges keep their exact matrices
    let projected: Vec<usize> = report.projected.iter().map(|p| p.edge).collect();
    for (k, (a, b)) in graph.edges.iter().zip(&clean.edges).enumerate() {
        if !projected.contains(&k) {
            assert_eq!(a.information, b.information);
        }
    }
    let solution = solve(&graph, &plain()).unwrap();
    assert!(solution.final_all_edges.chi2 >= 0.0);
    assert!(solution.final_inliers.chi2 >= 0.0);
    assert!(solution.initial.chi2 >= 0.0);
    eprintln!(
        "smallGrid3D with 3 indefinite edges: chi2 {:.4e} (clean {:.4e})",
        solution.final_all_edges.chi2,
        solve(&clean, &plain()).unwrap().final_all_edges.chi2
    );

    // the same matrices in a graph built in memory: an error naming the edge
    let mut raw = clean.clone();
    for &k in &projected {
        let mut m = raw.edges[k].information;
        m[(0, 1)] = 5.0 * m[(0, 0)];
        m[(1, 0)] = m[(0, 1)];
        raw.edges[k].information = m;
    }
    let err = solve(&raw, &plain()).unwrap_err();
    match &err {
        GraphError::IndefiniteInformation { edge, .. } => assert_eq!(*edge, projected[0]),
        other => panic!("{other}"),
    }
    assert!(
        err.to_string().contains("not positive definite") || err.to_string().contains("indefinite")
    );
}

#[test]
fn projection_raises_only_the_negative_eigenvalues() {
    let mut m = nalgebra::Matrix6::<f64>::from_diagonal(&nalgebra::Vector6::new(
        100.0, 100.0, 100.0, 400.0, 400.0, 400.0,
    ));
    m[(0, 1)] = 300.0;
    m[(1, 0)] = 300.0;
    assert!(!is_positive_definite(&m));
    let (p, min) = project_information(&m).unwrap();
    assert!((min + 200.0).abs() < 1e-9);
    assert!(is_positive_definite(&p));
    let eig = p.symmetric_eigenvalues();
    // eigenvalues of the xy block were 400 and -200: 400 stays, -200 goes to the floor
    let mut sorted: Vec<f64> = eig.iter().copied().collect();
    sorted.sort_by(f64::total_cmp);
    assert!((sorted[0] - 400.0 * visnav_graph::g2o::INFORMATION_EIGENVALUE_FLOOR).abs() < 1e-9);
    assert!(
        sorted[1..]
            .iter()
            .all(|l| (l - 100.0).abs() < 1e-9 || (l - 400.0).abs() < 1e-9)
    );
    // the untouched block is unchanged
    for r in 2..6 {
        assert!((p[(r, r)] - m[(r, r)]).abs() < 1e-9);
    }
    // nothing positive: no projection
    let negative = -nalgebra::Matrix6::<f64>::identity();
    assert!(project_information(&negative).is_none());
    let text = "VERTEX_SE3:QUAT 0 0 0 0 0 0 0 1\nVERTEX_SE3:QUAT 1 1 0 0 0 0 0 1\nEDGE_SE3:QUAT 0 1 1 0 0 0 0 0 1 -1 0 0 0 0 0 -1 0 0 0 0 -1 0 0 0 -1 0 0 -1 0 -1\n";
    let err = parse_g2o(text, Path::new("neg.g2o"))
        .unwrap_err()
        .to_string();
    assert!(err.starts_with("neg.g2o:3:"), "{err}");
}
