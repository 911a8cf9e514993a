//! `umbrasweep bench` (placeholder until it lands).

/// Options of `umbrasweep bench`.
#[derive(clap::Args, Debug, Clone)]
pub struct BenchArgs {}

/// Runs `umbrasweep bench`.
pub fn run(_args: &BenchArgs) -> anyhow::Result<()> {
    anyhow::bail!("bench is not built yet")
}
