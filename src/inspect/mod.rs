//! Inspection: EXR dumps, PNG previews, the HTML report (placeholder until it lands).

use crate::backend::{DepthMap, PlaneJob};
use crate::hdm::Hdm;
use std::path::PathBuf;

/// Where `bake --dump-exr/--dump-png` write, and which cells.
#[derive(Clone, Debug, Default)]
pub struct DumpOptions {
    pub exr: Option<PathBuf>,
    pub png: Option<PathBuf>,
    /// Only these cell indices (all when `None`).
    pub cells: Option<Vec<usize>>,
}

/// Writes the dumps of one plane of one cell.
///
/// # Errors
/// I/O errors, naming the file.
pub fn dump_plane(
    _opts: &DumpOptions,
    _cell: usize,
    _plane: usize,
    _job: &PlaneJob,
    _map: &DepthMap,
    _hdm: &Hdm,
) -> Result<(), String> {
    Err("dumps are not built yet".into())
}

/// Options of `umbrasweep report`.
#[derive(clap::Args, Debug, Clone)]
pub struct ReportArgs {}

/// Runs `umbrasweep report`.
pub fn run_report(_args: &ReportArgs) -> anyhow::Result<()> {
    anyhow::bail!("report is not built yet")
}
