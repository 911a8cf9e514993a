//! `umbrasweep report`: argument parsing and reading the scene and the PVS document. The page
//! is made and written by [`umbrasweep::inspect::report`].

use std::path::PathBuf;
use umbrasweep::inspect::report::{self, ReportOptions};

/// Options of `umbrasweep report`.
#[derive(clap::Args, Debug, Clone)]
#[command(
    after_help = "Examples:\n  umbrasweep report data/demo_city.obj demo.json -o report/\n  umbrasweep report data/demo_city.obj demo.json -o report/ --cell 5"
)]
pub struct ReportArgs {
    /// The scene the PVS was baked from (.obj, .gltf, .glb).
    pub scene: PathBuf,
    /// The PVS (.json or .pvs) written by `umbrasweep bake`.
    pub pvs: PathBuf,
    /// Output folder (created when missing); the page is DIR/index.html.
    #[arg(short, long, value_name = "DIR")]
    pub output: PathBuf,
    /// The cell whose PVS colours the picture and whose planes are previewed.
    #[arg(long, default_value_t = 0)]
    pub cell: usize,
    /// Do not re-bake the chosen cell for the plane previews.
    #[arg(long)]
    pub no_previews: bool,
}

/// Runs `umbrasweep report`: reads the scene and the PVS, writes `OUTPUT/index.html`.
///
/// # Errors
/// Unreadable or mismatching scene and PVS, a cell index out of range, invalid recorded
/// settings, or I/O errors writing the page (nothing is written then).
pub fn run(args: &ReportArgs) -> anyhow::Result<()> {
    let doc = umbrasweep::pvs::json::read_any(&args.pvs).map_err(anyhow::Error::msg)?;
    let scene = umbrasweep::scene::load_with(
        &args.scene,
        &umbrasweep::scene::LoadOptions {
            alpha_missing: doc.settings.bake.alpha_missing,
        },
    )?;
    let scene = umbrasweep::scene::split::as_baked(scene, doc.split.as_ref()).map_err(|e| {
        anyhow::anyhow!(
            "{} against {}: {e}",
            args.pvs.display(),
            args.scene.display()
        )
    })?;
    let opts = ReportOptions {
        scene_file: args.scene.clone(),
        pvs_file: args.pvs.clone(),
        cell: args.cell,
        no_previews: args.no_previews,
    };
    let html = report::render(&scene, &doc, &opts)?;
    report::write_page(&args.output, &html)?;
    Ok(())
}
