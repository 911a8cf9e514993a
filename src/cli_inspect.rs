//! `umbrasweep inspect FILE.pvs` (placeholder until it lands).

/// Options of `umbrasweep inspect`.
#[derive(clap::Args, Debug, Clone)]
pub struct InspectArgs {}

/// Runs `umbrasweep inspect`.
pub fn run(_a: &InspectArgs) -> anyhow::Result<()> {
    anyhow::bail!("inspect is not built yet")
}
