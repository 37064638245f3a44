//! `visnav posegraph`: optimise a g2o pose graph (SE(3)) and write the optimised graph.
//!
//! Reads `IN.g2o`, runs [`visnav_graph::solve`] (chordal initialisation, Levenberg–Marquardt,
//! pairwise-consistency preselection of loop closures unless `--robust gnc-gm` or `none`), writes `OUT.g2o` (same edges,
//! optimised vertices, full `f64` precision) and the effective configuration beside it as
//! `OUT.config.toml`, and reports the objective before and after in g2o's convention (`χ²`) and
//! GTSAM's (`½ χ²`), the iterations and the times — as a table or, with `--json`, as JSON on
//! stdout.

use std::path::{Path, PathBuf};
use std::time::Instant;

use anyhow::Context as _;
use visnav_graph::{GraphConfig, Initialisation, Objective, RobustKernel};

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
}

/// Timings of the whole command, milliseconds.
#[derive(Debug, serde::Serialize)]
struct CommandTiming {
    read_ms: f64,
    initialisation_ms: f64,
    optimisation_ms: f64,
    solve_ms: f64,
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
    iterations: usize,
    converged: bool,
    rejected_edges: usize,
    timing: CommandTiming,
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
    let mut graph = visnav_graph::read_g2o(&args.input)?;
    let read_ms = ms_since(start);
    let solution = visnav_graph::solve(&graph, &config)?;
    let t_write = Instant::now();
    graph.set_poses(&solution.poses);
    visnav_graph::write_g2o(&args.output, &graph)?;
    let cfg_path = config_path(&args.output);
    std::fs::write(&cfg_path, toml::to_string_pretty(&config)?)
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
        iterations: solution.iterations,
        converged: solution.converged,
        rejected_edges: solution.rejected_edges.len(),
        timing: CommandTiming {
            read_ms,
            initialisation_ms: solution.timing.initialisation_ms,
            optimisation_ms: solution.timing.optimisation_ms,
            solve_ms: solution.timing.total_ms,
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
