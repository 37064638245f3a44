//! `visnav eval` (being built).

/// Arguments of `visnav eval`.
#[derive(Debug, clap::Args)]
pub struct Args {}

/// Runs the subcommand.
///
/// # Errors
/// Always, until the subcommand is built.
pub fn run(_args: &Args, _ctx: &super::Context) -> anyhow::Result<()> {
    anyhow::bail!("`visnav eval` is not built yet")
}
