//! `umbrasweep merge OUT SHARD…`: joins the shard files of one `bake --shard I/N` run into the
//! PVS one bake of all cells writes (`.json` or `.pvs`), refusing shards of different bakes
//! and naming missing or duplicated ones.

use anyhow::{Context, bail};
use std::path::PathBuf;
use umbrasweep::bake::{self, SHARD_FORMAT, ShardFile};

#[derive(clap::Args, Debug)]
#[command(
    after_help = "Examples:\n  umbrasweep bake city.obj --cells cells.json --shard 0/2 -o part0.json\n  umbrasweep bake city.obj --cells cells.json --shard 1/2 -o part1.json\n  umbrasweep merge city.pvs part0.json part1.json"
)]
pub struct MergeArgs {
    /// The merged PVS: .json (the document) or .pvs (the binary file).
    pub output: PathBuf,
    /// The shard files (`bake --shard I/N -o SHARD.json` or `SHARD.pvs`), every shard of one
    /// bake once, in any order.
    #[arg(required = true)]
    pub shards: Vec<PathBuf>,
    /// No summary.
    #[arg(short, long)]
    pub quiet: bool,
}

/// Reads one shard file, with errors that say what the file is instead.
fn read_shard(path: &PathBuf) -> anyhow::Result<ShardFile> {
    let bytes = std::fs::read(path).with_context(|| format!("{}: cannot read", path.display()))?;
    if bytes.starts_with(&umbrasweep::pvs::format::MAGIC) {
        let db = umbrasweep::pvs::PvsDatabase::from_bytes(&bytes)
            .map_err(|e| anyhow::anyhow!("{}: {}", path.display(), e.kind))?;
        let Some(json) = db.shard() else {
            bail!(
                "{}: a whole .pvs file, not a shard (bake with --shard I/N to write shards)",
                path.display()
            );
        };
        let mut file: ShardFile = serde_json::from_str(json)
            .with_context(|| format!("{}: a damaged shard description", path.display()))?;
        let doc = db.to_document();
        file.document.cells = doc.cells;
        file.document.objects = doc.objects;
        return Ok(file);
    }
    let value: serde_json::Value = serde_json::from_slice(&bytes)
        .with_context(|| format!("{}: not a shard file (not JSON)", path.display()))?;
    match value.get("format").and_then(|f| f.as_str()) {
        Some(SHARD_FORMAT) => {}
        Some("umbrasweep-pvs") => bail!(
            "{}: a whole PVS document, not a shard (bake with --shard I/N to write shards)",
            path.display()
        ),
        other => bail!(
            "{}: not a shard file (format {:?}, expected {SHARD_FORMAT:?})",
            path.display(),
            other.unwrap_or("missing")
        ),
    }
    serde_json::from_value(value)
        .with_context(|| format!("{}: a damaged shard file", path.display()))
}

pub fn run(a: &MergeArgs) -> anyhow::Result<()> {
    let t = std::time::Instant::now();
    let binary = crate::cli_bake::output_is_binary(&a.output)?;
    let mut shards = Vec::with_capacity(a.shards.len());
    for p in &a.shards {
        shards.push((p.clone(), read_shard(p)?));
    }
    let doc = bake::merge(&shards)?;
    crate::cli_bake::write_document(&a.output, &doc, binary)
        .with_context(|| "writing the merged PVS")?;
    if !a.quiet {
        eprintln!(
            "merged      {} shards, {} cells in {:.2} s",
            shards.len(),
            doc.cells.len(),
            t.elapsed().as_secs_f64()
        );
        eprintln!("wrote       {}", a.output.display());
    }
    Ok(())
}
