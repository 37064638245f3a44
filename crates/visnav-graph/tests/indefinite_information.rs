//! Edges whose information matrix is not positive definite (issues 21 and 53): the reader replaces
//! them by SE-Sync's isotropic information (issue 53, item 8; the projection to the nearest
//! positive-definite matrix of issue 21 only when the blocks give no SE-Sync weights) and names
//! them; the solver never optimises an indefinite objective (a graph built in memory gets an error
//! naming the edge instead of a bare Cholesky failure) and never reports a negative χ². On a
//! rendered graph whose matrices are indefinite as the benchmark's are, the solution is SE-Sync's
//! certified optimum; the projection ended 1.5x above it.
#![allow(clippy::unwrap_used)]

use std::path::Path;

use visnav_graph::g2o::{Replacement, is_positive_definite, project_information};
use visnav_graph::synthetic::{
    LoopDriveConfig, ate_and_extent, loop_drive, make_information_indefinite,
};
use visnav_graph::{
    CertifyConfig, GraphConfig, GraphError, Initialisation, RobustKernel, Verdict, certify,
    format_g2o, parse_g2o, parse_g2o_with_report, sesync_weights, solve,
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
fn indefinite_edges_get_isotropic_weights_named_and_never_give_a_negative_chi2() {
    let Some(path) = visnav_core::testdata::shared_data("posegraph/smallGrid3D.g2o") else {
        eprintln!("VISNAV_DATA not set: skipped");
        return;
    };
    let text = std::fs::read_to_string(&path).unwrap();
    let clean = parse_g2o(&text, &path).unwrap();
    // the benchmark file itself is untouched
    let (_, report) = parse_g2o_with_report(&text, &path).unwrap();
    assert!(report.replaced.is_empty());
    let lines = edge_lines(&text);
    let bad = [lines[3], lines[40], lines[200]];
    let corrupted = make_indefinite(&text, &bad);
    let (graph, report) = parse_g2o_with_report(&corrupted, Path::new("bad.g2o")).unwrap();
    // every indefinite edge is named with its line and vertex ids
    let named: Vec<usize> = report.replaced.iter().map(|p| p.line).collect();
    assert_eq!(named, bad);
    assert_eq!(report.edge_lines.len(), graph.edges.len());
    for p in &report.replaced {
        assert!(p.min_eigenvalue < 0.0);
        let e = &graph.edges[p.edge];
        assert_eq!(graph.vertices[e.from].id, p.from_id);
        assert_eq!(report.edge_lines[p.edge], p.line);
        assert!(is_positive_definite(&e.information));
        // SE-Sync's weights of the file's blocks: translation [[d, 5d, 0], [5d, d, 0], [0, 0, d]]
        // with d = 100 has tr(inverse) = 11/(12 d), so τ = 36 d / 11; rotation 25 I gives κ = 12.5
        let Replacement::Isotropic(w) = p.replacement else {
            panic!("{:?}", p.replacement)
        };
        assert!((w.tau - 3600.0 / 11.0).abs() < 1e-9, "{}", w.tau);
        assert!((w.kappa - 12.5).abs() < 1e-9, "{}", w.kappa);
        assert_eq!(e.information[(0, 0)], w.tau);
        assert_eq!(e.information[(3, 3)], 2.0 * w.kappa);
        assert_eq!(e.information[(0, 1)], 0.0);
    }
    // the untouched edges keep their exact matrices
    let projected: Vec<usize> = report.replaced.iter().map(|p| p.edge).collect();
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
        "smallGrid3D with 3 indefinite edges (isotropic weights): chi2 {:.4e} (clean {:.4e})",
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

/// Issue 53, item 8: a rendered loop drive (3 laps of 300 poses, a closure at every pose of
/// the later laps, 1,499 edges) whose information matrices are made indefinite on 30 % of the
/// edges, as the benchmark's are (`make_information_indefinite`: the cross block of a noisy
/// estimate, the diagonal blocks those of the true noise). Read from g2o text as a user would:
/// every such edge is named, gets SE-Sync's isotropic weights, nothing is rejected, and the
/// solution's SE-Sync objective equals the certified optimum, which is below the objective at
/// the ground truth (the optimum fits the noise). The projection of issue 21 on the same file
/// ended 1.5x above the optimum, 40 % farther from the truth.
#[test]
fn a_rendered_graph_with_indefinite_matrices_reaches_the_certified_optimum() {
    let synth = loop_drive(&LoopDriveConfig {
        laps: 3,
        poses_per_lap: 300,
        closure_every: 1,
        ..LoopDriveConfig::default()
    });
    let mut graph = synth.graph.clone();
    let changed = make_information_indefinite(&mut graph, 0.3, 1);
    assert_eq!(changed.len(), 450);
    assert!(
        changed
            .iter()
            .all(|&k| !is_positive_definite(&graph.edges[k].information))
    );
    let text = format_g2o(&graph);
    let (read, report) = parse_g2o_with_report(&text, Path::new("rendered.g2o")).unwrap();
    let named: Vec<usize> = report.replaced.iter().map(|r| r.edge).collect();
    assert_eq!(named, changed);
    assert!(
        report
            .replaced
            .iter()
            .all(|r| matches!(r.replacement, Replacement::Isotropic(_)))
    );
    let sol = solve(&read, &GraphConfig::default()).unwrap();
    assert!(sol.rejected_edges.is_empty(), "{:?}", sol.rejected_edges);
    let all = vec![true; read.edges.len()];
    let cert = certify(&read, &sol.poses, &all, &CertifyConfig::default()).unwrap();
    assert_eq!(cert.verdict, Verdict::GloballyOptimal, "{cert:?}");
    let at_truth = read.sesync_objective(&synth.ground_truth, None).unwrap();
    let (ate, extent) = ate_and_extent(&sol.poses, &synth.ground_truth);

    // the old treatment: every indefinite matrix projected to the nearest positive-definite one
    let mut projected = graph.clone();
    for &k in &changed {
        projected.edges[k].information =
            project_information(&graph.edges[k].information).unwrap().0;
    }
    let old = solve(&projected, &GraphConfig::default()).unwrap();
    let old_f = read.sesync_objective(&old.poses, None).unwrap();
    let (old_ate, _) = ate_and_extent(&old.poses, &synth.ground_truth);
    eprintln!(
        "rendered, {} of {} edges indefinite: f(solution) {:.4}, certified optimum {:.4} \
         (lambda_min {:.2e}), f(truth) {at_truth:.4}, ATE {ate:.4} m of {extent:.1} m; \
         projection: f {old_f:.4} = {:.3}x the optimum, ATE {old_ate:.4} m, {} rejected",
        changed.len(),
        read.edges.len(),
        cert.objective_at_input,
        cert.objective,
        cert.lambda_min,
        old_f / cert.objective,
        old.rejected_edges.len()
    );
    // the solution is the certified optimum (the blocks are the true information, so the
    // isotropic weights are exact here)
    assert!((cert.objective_at_input - cert.objective).abs() <= 1e-6 * cert.objective);
    assert!(cert.objective < at_truth);
    assert!(
        old_f > 1.3 * cert.objective,
        "{old_f} vs {}",
        cert.objective
    );
    assert!(old_ate > 1.2 * ate, "{old_ate} vs {ate}");
    // the weights are SE-Sync's of the file's blocks
    for r in &report.replaced {
        let w = sesync_weights(&graph.edges[r.edge].information).unwrap();
        assert_eq!(r.replacement, Replacement::Isotropic(w));
    }
}
