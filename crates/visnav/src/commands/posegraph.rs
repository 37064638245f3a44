//! `visnav posegraph`: optimise a g2o pose graph (SE(3)) and write the optimised graph.
//!
//! Reads `IN.g2o`, runs [`visnav_graph::solve`] (chordal initialisation, Levenberg–Marquardt,
//! pairwise-consistency preselection of loop closures unless `--robust gnc-gm` or `none`), writes `OUT.g2o` (same edges,
//! optimised vertices, full `f64` precision) and the effective configuration beside it as
//! `OUT.config.toml`, and reports the objective before and after in g2o's convention (`χ²`) and
//! GTSAM's (`½ χ²`) and SE-Sync's objective `f` at the solution, the iterations and the times —
//! as a table or, with `--json`, as JSON on stdout. Edges whose information matrix is not
//! positive definite get SE-Sync's isotropic weights (listed in the report with their lines).
//! With `--certify`, SE-Sync's dual certificate ([`visnav_graph::certify`]) says whether the
//! solution is in the basin of the global optimum of SE-Sync's problem: "globally optimal
//! (λ_min = …)" or "not certified (λ_min = …)".

use std::path::{Path, PathBuf};
use std::time::Instant;

use anyhow::Context as _;
use visnav_graph::g2o::{G2oReport, Replacement};
use visnav_graph::{Certificate, GraphConfig, Initialisation, Objective, RobustKernel, Verdict};

/// Robust treatment of loop closures (CLI names).
#[derive(Debug, Clone, Copy, PartialEq, Eq, clap::ValueEnum)]
pub enum RobustArg {
    /// Plain least squares.
    None,
    /// Graduated non-convexity with Geman–McClure on non-odometry edges, then rejection.
    GncGm,
    /// Pairwise-consistency preselection of loop closures, then a gated re-admission.
    Pairwise,
}

/// Where the optimiser starts (CLI names).
#[derive(Debug, Clone, Copy, PartialEq, Eq, clap::ValueEnum)]
pub enum InitArg {
    /// Chordal rotations, then linear positions.
    Chordal,
    /// The poses in the input file.
    Input,
}

/// Arguments of `visnav posegraph`.
#[derive(Debug, clap::Args)]
pub struct Args {
    /// Input pose graph (g2o: VERTEX_SE3:QUAT, EDGE_SE3:QUAT, FIX).
    pub input: PathBuf,
    /// Output pose graph with the optimised vertices.
    #[arg(long, short)]
    pub output: PathBuf,
    /// Print the report as JSON on stdout.
    #[arg(long)]
    pub json: bool,
    /// Robust treatment of loop closures [default: from --config, else pairwise].
    #[arg(long, value_enum)]
    pub robust: Option<RobustArg>,
    /// Initialisation [default: from --config, else chordal].
    #[arg(long, value_enum)]
    pub init: Option<InitArg>,
    /// Maximum Levenberg–Marquardt iterations [default: from --config, else 100].
    #[arg(long)]
    pub max_iterations: Option<usize>,
    /// A TOML file with a `GraphConfig` (fields as written to `OUT.config.toml`).
    #[arg(long)]
    pub config: Option<PathBuf>,
    /// Certify the solution with SE-Sync's dual certificate (Rosen et al. 2019, §4): refine it
    /// to a critical point of SE-Sync's objective and report "globally optimal (λ_min = …)" or
    /// "not certified (λ_min = …)".
    #[arg(long)]
    pub certify: bool,
}

/// Timings of the whole command, milliseconds.
#[derive(Debug, serde::Serialize)]
struct CommandTiming {
    read_ms: f64,
    initialisation_ms: f64,
    optimisation_ms: f64,
    solve_ms: f64,
    certify_ms: Option<f64>,
    write_ms: f64,
    total_ms: f64,
}

/// The report printed by the command.
#[derive(Debug, serde::Serialize)]
struct Report {
    input: PathBuf,
    output: PathBuf,
    vertices: usize,
    edges: usize,
    robust: RobustKernel,
    initialisation: Initialisation,
    objective_before: Objective,
    objective_after_initialisation: Objective,
    objective_after: Objective,
    objective_after_accepted_edges: Objective,
    /// SE-Sync's objective `f` at the solution over the accepted edges (comparable with the
    /// certified optima SE-Sync publishes).
    sesync_objective_after: Option<f64>,
    iterations: usize,
    converged: bool,
    rejected_edges: usize,
    /// File lines of the rejected edges.
    rejected_edge_lines: Vec<usize>,
    /// Edges whose information matrix was not positive definite, and what replaced it.
    information_replaced: Vec<ReplacedReport>,
    /// SE-Sync's certificate (`--certify`).
    certificate: Option<CertificateReport>,
    timing: CommandTiming,
}

/// One edge whose information matrix the reader replaced.
#[derive(Debug, serde::Serialize)]
struct ReplacedReport {
    line: usize,
    from_id: u64,
    to_id: u64,
    min_eigenvalue: f64,
    /// `isotropic` (SE-Sync's weights) or `projected`.
    replacement: &'static str,
    tau: Option<f64>,
    kappa: Option<f64>,
}

/// The certificate in the report.
#[derive(Debug, serde::Serialize)]
struct CertificateReport {
    /// `globally-optimal` or `not-certified`.
    verdict: Verdict,
    /// The smallest eigenvalue of the certificate matrix (estimate, never below the true one).
    lambda_min: f64,
    /// `ε` of the test `λ_min ≥ −ε`.
    tolerance: f64,
    /// SE-Sync's objective at the refined critical point (the certified optimum when globally
    /// optimal).
    objective: f64,
    /// SE-Sync's objective at the solution written to the output.
    objective_at_solution: f64,
    /// `Σ tr Λ_i`, a lower bound of every feasible objective when certified.
    dual_bound: f64,
    refinement_iterations: usize,
    refinement_converged: bool,
    edges: usize,
}

impl From<&Certificate> for CertificateReport {
    fn from(c: &Certificate) -> Self {
        Self {
            verdict: c.verdict,
            lambda_min: c.lambda_min,
            tolerance: c.tolerance,
            objective: c.objective,
            objective_at_solution: c.objective_at_input,
            dual_bound: c.dual_bound,
            refinement_iterations: c.refinement_iterations,
            refinement_converged: c.refinement_converged,
            edges: c.edges,
        }
    }
}

fn replaced_reports(report: &G2oReport) -> Vec<ReplacedReport> {
    report
        .replaced
        .iter()
        .map(|r| {
            let (replacement, tau, kappa) = match r.replacement {
                Replacement::Isotropic(w) => ("isotropic", Some(w.tau), Some(w.kappa)),
                Replacement::Projected => ("projected", None, None),
            };
            ReplacedReport {
                line: r.line,
                from_id: r.from_id,
                to_id: r.to_id,
                min_eigenvalue: r.min_eigenvalue,
                replacement,
                tau,
                kappa,
            }
        })
        .collect()
}

fn load_config(args: &Args) -> anyhow::Result<GraphConfig> {
    let mut config = match &args.config {
        Some(path) => {
            let text = visnav_io::text::read_text(path)
                .with_context(|| format!("reading {}", path.display()))?;
            toml::from_str(&text).with_context(|| format!("parsing {}", path.display()))?
        }
        None => GraphConfig::default(),
    };
    if let Some(r) = args.robust {
        config.robust = match r {
            RobustArg::None => RobustKernel::None,
            RobustArg::GncGm => RobustKernel::GncGemanMcClure,
            RobustArg::Pairwise => RobustKernel::PairwiseConsistency,
        };
    }
    if let Some(i) = args.init {
        config.initialisation = match i {
            InitArg::Chordal => Initialisation::Chordal,
            InitArg::Input => Initialisation::Input,
        };
    }
    if let Some(n) = args.max_iterations {
        config.max_iterations = n;
    }
    config.validate()?;
    Ok(config)
}

fn config_path(output: &Path) -> PathBuf {
    output.with_extension("config.toml")
}

fn ms_since(t: Instant) -> f64 {
    t.elapsed().as_secs_f64() * 1e3
}

/// Runs the subcommand.
///
/// # Errors
/// When the input cannot be read or parsed, the configuration is invalid, the graph is
/// disconnected or singular, or an output cannot be written.
pub fn run(args: &Args, ctx: &super::Context) -> anyhow::Result<()> {
    let start = Instant::now();
    let config = load_config(args)?;
    let (mut graph, read_report) = visnav_graph::read_g2o_with_report(&args.input)?;
    let read_ms = ms_since(start);
    let solution = visnav_graph::solve(&graph, &config)?;
    let keep: Vec<bool> = (0..graph.edges.len())
        .map(|k| solution.rejected_edges.binary_search(&k).is_err())
        .collect();
    let certificate = if args.certify {
        let t = Instant::now();
        let c = visnav_graph::certify(&graph, &solution.poses, &keep, &config.certify)?;
        Some((c, ms_since(t)))
    } else {
        None
    };
    let t_write = Instant::now();
    graph.set_poses(&solution.poses);
    visnav_graph::write_g2o(&args.output, &graph)?;
    let cfg_path = config_path(&args.output);
    visnav_io::atomic::write_atomic(&cfg_path, toml::to_string_pretty(&config)?.as_bytes())
        .with_context(|| format!("writing {}", cfg_path.display()))?;
    let write_ms = ms_since(t_write);
    let report = Report {
        input: args.input.clone(),
        output: args.output.clone(),
        vertices: graph.vertices.len(),
        edges: graph.edges.len(),
        robust: config.robust,
        initialisation: config.initialisation,
        objective_before: solution.initial,
        objective_after_initialisation: solution.after_initialisation,
        objective_after: solution.final_all_edges,
        objective_after_accepted_edges: solution.final_inliers,
        sesync_objective_after: graph.sesync_objective(&solution.poses, Some(&keep)),
        iterations: solution.iterations,
        converged: solution.converged,
        rejected_edges: solution.rejected_edges.len(),
        rejected_edge_lines: solution
            .rejected_edges
            .iter()
            .filter_map(|&k| read_report.edge_lines.get(k).copied())
            .collect(),
        information_replaced: replaced_reports(&read_report),
        certificate: certificate.as_ref().map(|(c, _)| c.into()),
        timing: CommandTiming {
            read_ms,
            initialisation_ms: solution.timing.initialisation_ms,
            optimisation_ms: solution.timing.optimisation_ms,
            solve_ms: solution.timing.total_ms,
            certify_ms: certificate.as_ref().map(|(_, ms)| *ms),
            write_ms,
            total_ms: ms_since(start),
        },
    };
    if args.json {
        println!("{}", serde_json::to_string_pretty(&report)?);
    } else if !ctx.quiet {
        print_table(&report);
    }
    Ok(())
}

/// The certificate's line of the table.
fn certificate_line(c: &CertificateReport) -> String {
    let verdict = match c.verdict {
        Verdict::GloballyOptimal => format!(
            "globally optimal (λ_min = {:.3e} ≥ −{:.1e})",
            c.lambda_min, c.tolerance
        ),
        Verdict::NotCertified => format!(
            "not certified (λ_min = {:.3e} < −{:.1e})",
            c.lambda_min, c.tolerance
        ),
    };
    let refined = if c.refinement_converged {
        String::new()
    } else {
        format!(
            "; the refinement stopped after {} iterations before a critical point",
            c.refinement_iterations
        )
    };
    format!(
        "certificate: {verdict}: SE-Sync objective {:.6} at the critical point it refines to, \
         {:.6} at this solution ({:+.2} %), dual bound {:.6}{refined}",
        c.objective,
        c.objective_at_solution,
        100.0 * (c.objective_at_solution / c.objective - 1.0),
        c.dual_bound
    )
}

fn print_table(r: &Report) {
    println!(
        "{}: {} vertices, {} edges (robust {:?}, init {:?})",
        r.input.display(),
        r.vertices,
        r.edges,
        r.robust,
        r.initialisation
    );
    println!(
        "{:<28} {:>18} {:>18}",
        "objective", "chi2 (sum)", "GTSAM (1/2 sum)"
    );
    for (name, o) in [
        ("before", &r.objective_before),
        ("after initialisation", &r.objective_after_initialisation),
        ("after", &r.objective_after),
        ("after (accepted edges)", &r.objective_after_accepted_edges),
    ] {
        println!("{name:<28} {:>18.6} {:>18.6}", o.chi2, o.gtsam_error);
    }
    if let Some(f) = r.sesync_objective_after {
        println!("{:<28} {f:>18.6}", "SE-Sync objective f after");
    }
    if !r.information_replaced.is_empty() {
        let isotropic = r
            .information_replaced
            .iter()
            .filter(|e| e.replacement == "isotropic")
            .count();
        println!(
            "{} edges with an information matrix not positive definite: {isotropic} given SE-Sync's isotropic weights, {} projected",
            r.information_replaced.len(),
            r.information_replaced.len() - isotropic
        );
    }
    if let Some(c) = &r.certificate {
        println!("{}", certificate_line(c));
    }
    println!(
        "{} iterations{}, {} edges rejected, solve {:.1} ms (init {:.1} ms, LM {:.1} ms), total {:.1} ms",
        r.iterations,
        if r.converged { "" } else { " (not converged)" },
        r.rejected_edges,
        r.timing.solve_ms,
        r.timing.initialisation_ms,
        r.timing.optimisation_ms,
        r.timing.total_ms
    );
    println!("wrote {}", r.output.display());
}
