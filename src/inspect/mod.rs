//! Inspection: what a bake saw, for people tuning it.
//!
//! - [`dump_plane`] writes one rendered plane of one cell as an OpenEXR file ([`exr_dump`]:
//!   channels `depth` and `mask`, the Hierarchical Depth Map's levels as further layers,
//!   the plane's frame as header attributes) and as 8-bit PNG previews ([`preview`]: a fixed
//!   colour ramp for Depth, white/black for the mask, a `legend.png` beside them).
//! - [`report::render`] makes the self-contained static HTML page of `umbrasweep report`
//!   ([`report`]): a top-down picture of the scene, a per-cell table and the plane previews of
//!   one cell; [`report::write_page`] writes it as `DIR/index.html`.
//!
//! File names, channels and colours are documented in `docs/inspect.md`.

pub mod exr_dump;
pub mod preview;
pub mod report;

use crate::hdm::Hdm;
use crate::plane::{DepthMap, PlaneJob};
use std::path::{Path, PathBuf};

pub use report::{ReportError, ReportOptions};

/// Where `bake --dump-exr/--dump-png` write, and which cells.
#[derive(Clone, Debug, Default)]
pub struct DumpOptions {
    /// Folder of the OpenEXR dumps (created when missing); none when `None`.
    pub exr: Option<PathBuf>,
    /// Folder of the PNG previews (created when missing); none when `None`.
    pub png: Option<PathBuf>,
    /// Only these cell indices (all when `None`).
    pub cells: Option<Vec<usize>>,
}

/// The file name stem of one plane's dumps: `cell0003_plane07_x+` (cell index, plane index
/// within the cell in rendering order, the plane's axis and side).
pub fn file_stem(cell: usize, plane: usize, job: &PlaneJob) -> String {
    let axis = ["x", "y", "z"][job.frame.axis.min(2)];
    let side = if job.frame.positive { '+' } else { '-' };
    format!("cell{cell:04}_plane{plane:02}_{axis}{side}")
}

/// Creates `dir` (and its parents) when missing.
fn ensure_dir(dir: &Path) -> Result<(), String> {
    std::fs::create_dir_all(dir).map_err(|e| format!("{}: cannot create: {e}", dir.display()))
}

/// Writes ray space factorization's charts of one cell as `cell<NNNN>_rsf.exr` into
/// `opts.exr` (nothing without it; layout in [`exr_dump::encode_charts`]), atomically.
///
/// # Errors
/// I/O or encoding errors, naming the file.
pub fn dump_charts(
    opts: &DumpOptions,
    cell: usize,
    bounds: &crate::geom::Aabb,
    charts: &crate::rsf::RayCharts,
) -> Result<(), String> {
    let Some(dir) = &opts.exr else {
        return Ok(());
    };
    ensure_dir(dir)?;
    let path = dir.join(format!("cell{cell:04}_rsf.exr"));
    let bytes = exr_dump::encode_charts(cell, bounds, charts)
        .map_err(|e| format!("{}: {e}", path.display()))?;
    crate::util::write_atomic(&path, &bytes).map_err(|e| e.to_string())
}

/// Writes the dumps of one plane of one cell: `<stem>.exr` into `opts.exr`, and
/// `<stem>_depth.png`, `<stem>_mask.png`, `<stem>_hdm.png` and `legend.png` into `opts.png`
/// (see [`file_stem`]; folders are created when missing). Every file is written atomically
/// (temporary file, then rename), and nothing is shared between calls, so planes may be
/// dumped from several threads at once. `opts.cells` is not checked here: the caller selects
/// the cells.
///
/// # Errors
/// I/O or encoding errors, naming the file.
pub fn dump_plane(
    opts: &DumpOptions,
    cell: usize,
    plane: usize,
    job: &PlaneJob,
    map: &DepthMap,
    hdm: &Hdm,
) -> Result<(), String> {
    let stem = file_stem(cell, plane, job);
    if let Some(dir) = &opts.exr {
        ensure_dir(dir)?;
        let path = dir.join(format!("{stem}.exr"));
        let bytes = exr_dump::encode(cell, plane, job, map, hdm)
            .map_err(|e| format!("{}: {e}", path.display()))?;
        crate::util::write_atomic(&path, &bytes).map_err(|e| e.to_string())?;
    }
    if let Some(dir) = &opts.png {
        ensure_dir(dir)?;
        let d = preview::plane_distance(&job.frame);
        let files = [
            ("depth", preview::depth_image(map, d)),
            ("mask", preview::mask_image(map)),
            ("hdm", preview::hdm_image(hdm, d)),
        ];
        for (what, img) in files {
            let path = dir.join(format!("{stem}_{what}.png"));
            let bytes =
                preview::encode_png(&img).map_err(|e| format!("{}: {e}", path.display()))?;
            crate::util::write_atomic(&path, &bytes).map_err(|e| e.to_string())?;
        }
        // Identical content from every call: a concurrent duplicate write is harmless.
        let legend = dir.join("legend.png");
        if !legend.is_file() {
            let bytes = preview::encode_png(&preview::legend_image())
                .map_err(|e| format!("{}: {e}", legend.display()))?;
            crate::util::write_atomic(&legend, &bytes).map_err(|e| e.to_string())?;
        }
    }
    Ok(())
}
