//! `umbrasweep bench`: argument parsing, progress lines on stderr, the tables on stdout and
//! the `--json` document. The measurements are [`umbrasweep::bench`] (the scene bench) and
//! [`umbrasweep::bench::foliage`] (the foliage study).

use serde::Serialize;
use std::path::{Path, PathBuf};
use umbrasweep::backend::gpu::GpuProjection;
use umbrasweep::bench::{self, BenchOptions, foliage};

/// Which backends `umbrasweep bench` runs.
#[derive(clap::ValueEnum, Clone, Copy, Debug, PartialEq, Eq)]
pub enum BenchBackend {
    /// The CPU backend only.
    Cpu,
    /// The GPU backend only (an error when no adapter exists).
    Gpu,
    /// The CPU backend, and the GPU backend when an adapter exists.
    All,
}

impl From<BenchBackend> for bench::BenchBackend {
    fn from(b: BenchBackend) -> Self {
        match b {
            BenchBackend::Cpu => bench::BenchBackend::Cpu,
            BenchBackend::Gpu => bench::BenchBackend::Gpu,
            BenchBackend::All => bench::BenchBackend::All,
        }
    }
}

/// Options of `umbrasweep bench`.
#[derive(clap::Args, Debug, Clone)]
#[command(after_help = "Examples:
  umbrasweep bench --quick
  umbrasweep bench --backend cpu --json bench.json
  umbrasweep bench --quick --scenes city,boxfield --cells 2 --rays 10000
  umbrasweep bench --foliage --json foliage.json
  umbrasweep bench --foliage --foliage-studies coarse,params --cells 1 --rays 2000
  umbrasweep bench --scenes city --cells 10 --hunt-rays 1000000 --confirm-rays 20000000
  umbrasweep bench --foliage --foliage-studies coarse --cells 1 --hunt-rays 20000000 --confirm-rays 80000000")]
pub struct BenchArgs {
    /// A small version that runs in a few minutes: 10 cells per scene, 3 on the GPU, a forest
    /// of 300 trees and 6 model trees.
    #[arg(long)]
    pub quick: bool,
    /// Cells per scene (default 50, 10 with --quick or --foliage).
    #[arg(long, value_name = "N")]
    pub cells: Option<usize>,
    /// Cells per scene on the GPU backend, the first of the CPU's (default 10, 3 with
    /// --quick: software rasterisers such as lavapipe are slow).
    #[arg(long, value_name = "N")]
    pub gpu_cells: Option<usize>,
    /// Validation rays per cell (default 1,000,000; 200,000 with --foliage).
    #[arg(long, value_name = "N")]
    pub rays: Option<u64>,
    /// Seed of the generated scenes, of the free-space cells and of the validation rays.
    #[arg(long, default_value_t = 1)]
    pub seed: u64,
    /// Backends to run.
    #[arg(long, value_enum, default_value_t = BenchBackend::All)]
    pub backend: BenchBackend,
    /// How the GPU backend makes occluders' Projections: `clipped` (views intersected on the
    /// CPU) or `counting` (views projected, hulled and counted per fragment on the GPU; needs
    /// SHADER_F64). Default: the backend's choice, as `bake --gpu-projection`.
    #[arg(long, value_name = "clipped|counting")]
    pub gpu_projection: Option<GpuProjection>,
    /// Run ray space factorization's charts on the GPU backend's device (needs SHADER_F64)
    /// instead of the CPU: the same charts, slower on every device measured so far.
    #[arg(long)]
    pub rsf_on_gpu: bool,
    /// Read the GPU backend's Depth Maps back (separate planes' and the occlusion sweep's)
    /// and test occludees on the CPU instead of on the device (the default): the same PVS,
    /// to compare the two.
    #[arg(long)]
    pub tests_on_cpu: bool,
    /// Read only the occlusion sweep's Depth Maps back instead of keeping them on the device
    /// (the default): the same PVS, to compare the two.
    #[arg(long)]
    pub sweep_maps_on_cpu: bool,
    /// Send each occludee box with its test instead of keeping the bake's boxes on the device
    /// (the default), as `bake --boxes-inline`: the same PVS, to compare the two.
    #[arg(long)]
    pub boxes_inline: bool,
    /// Send counted occluders' points with their planes instead of keeping the scene's
    /// occluder parts on the device (the default), as `bake --occluders-inline`: the same
    /// PVS, to compare the two.
    #[arg(long)]
    pub occluders_inline: bool,
    /// Pixels per occludee test asked of the GPU backend's device, as `bake
    /// --pixels-per-device-test` (default 64).
    #[arg(long, value_name = "N", value_parser = clap::value_parser!(u32).range(1..))]
    pub pixels_per_device_test: Option<u32>,
    /// Device memory the shrunk-occluder sampler's GPU samplers may take together (e.g. 16G;
    /// default 4G), as `bake --gpu-sampler-memory`.
    #[arg(long, value_name = "SIZE", value_parser = crate::cli_bake::parse_size)]
    pub gpu_sampler_memory: Option<u64>,
    /// The shared scene folder (default: ../shared/scenes when it exists).
    #[arg(long, value_name = "DIR")]
    pub shared: Option<PathBuf>,
    /// Only these scenes (comma-separated): city, forest, boxfield, munich, etoile, zdm2,
    /// poinciana.
    #[arg(long, value_name = "LIST", value_delimiter = ',')]
    pub scenes: Option<Vec<String>>,
    /// Force ray space factorization on in the scene table's bakes (default: chosen per scene,
    /// as `bake` does).
    #[arg(long, conflicts_with = "no_rsf")]
    pub rsf: bool,
    /// Never run ray space factorization in the scene table's bakes (to measure what it adds).
    #[arg(long)]
    pub no_rsf: bool,
    /// Also write the rows as JSON to this file.
    #[arg(long, value_name = "OUT.json")]
    pub json: Option<PathBuf>,
    /// Also write every bake's PVS document to DIR/SCENE-BACKEND.json (created if needed), to
    /// compare two builds cell for cell (`cargo run --example pvs_diff -- A.json B.json`).
    #[arg(long, value_name = "DIR")]
    pub pvs_out: Option<PathBuf>,
    /// Run the foliage study instead of the scene table: forests baked with and without the
    /// sweep, with sub-cells and with other sweep settings, one table per study (on the CPU
    /// backend unless --backend gpu; see docs/bench.md).
    #[arg(long, conflicts_with_all = ["quick", "gpu_cells", "scenes"])]
    pub foliage: bool,
    /// Only these foliage studies (comma-separated): coarse, ellipsoid, fine, params, paper, jacaranda,
    /// palm, birch, beech (the last three: textured trees with alpha-tested cards).
    #[arg(long, value_name = "LIST", value_delimiter = ',', requires = "foliage")]
    pub foliage_studies: Option<Vec<String>>,
    /// Cells baked by the fine forest's sub-cell variants and by the sampler rows (spread over
    /// their forest's --cells).
    #[arg(
        long,
        value_name = "N",
        default_value_t = foliage::DEFAULT_SUBCELL_CELLS,
        requires = "foliage"
    )]
    pub foliage_subcell_cells: usize,
    /// Cells of the paper's forest (7,750 trees, 7.8 M triangles).
    #[arg(
        long,
        value_name = "N",
        default_value_t = foliage::DEFAULT_PAPER_CELLS,
        requires = "foliage"
    )]
    pub foliage_paper_cells: usize,
    /// Jacaranda trees in the jacaranda study (55 k triangles each; gen's coarse 1,500
    /// would make 82 M triangles).
    #[arg(
        long,
        value_name = "N",
        default_value_t = foliage::DEFAULT_MODEL_TREES,
        requires = "foliage"
    )]
    pub foliage_model_trees: u32,
    /// Tests only: trees of every procedural foliage forest (instead of 1,500 and 7,750).
    #[arg(long, value_name = "N", hide = true, requires = "foliage")]
    pub foliage_trees: Option<u32>,
    /// Sample points per cell of the sampler rows (their `--sampling-budget`). The fine
    /// forest's finest level needs tens of thousands: raise it with
    /// --foliage-sampling-max-eps for a row that can cull (hours per cell on two cores).
    #[arg(
        long,
        value_name = "POINTS",
        default_value_t = foliage::SAMPLING_BENCH_POINTS,
        requires = "foliage"
    )]
    pub foliage_sampling_budget: u64,
    /// The sampler rows' --sampling-max-eps E: levels coarser than E are split without being
    /// sampled (e.g. 0.05 on the fine forest, whose coarser levels hide nothing).
    #[arg(long, value_name = "E", requires = "foliage")]
    pub foliage_sampling_max_eps: Option<f64>,
    /// Turn the sampler rows' tuck pass on (their --sampling-tuck): leaf edges that nearer
    /// leaves cover are drawn unshrunk.
    #[arg(long, requires = "foliage")]
    pub foliage_sampling_tuck: bool,
    /// The sampler rows' finest ε (their --sampling-eps E; default: the bake's, from the
    /// leaves' size). With --foliage-sampling-levels, the cost curve's range: e.g.
    /// `--foliage-sampling-eps 0.022 --foliage-sampling-levels 4` on the coarse forest samples
    /// ε 0.35 down to 0.022.
    #[arg(long, value_name = "E", requires = "foliage")]
    pub foliage_sampling_eps: Option<f64>,
    /// The sampler rows' refinement levels (their --sampling-levels N): the coarsest level's ε
    /// is 2^N × the finest.
    #[arg(long, value_name = "N", requires = "foliage")]
    pub foliage_sampling_levels: Option<u32>,
    /// Also hunt every row's PVS as `validate --hunt --rays N` does (N rays per cell at its
    /// culled objects); hunted objects, rays per object and false culls follow the table (each
    /// study's with --foliage), and a false cull found counts in the exit code.
    #[arg(long, value_name = "N")]
    pub hunt_rays: Option<u64>,
    /// Also measure every row's PVS as `validate --confirm-rays N` does (N more rays per cell
    /// at the PVS objects the validation's sample missed): |VS+| and PVS/VS+ follow the table.
    #[arg(long, value_name = "N")]
    pub confirm_rays: Option<u64>,
    /// Save the foliage study's sampler cells' progress in DIR (created if needed; files
    /// STUDY-ROW.sampler-*, kept when a cell finishes). Running the same command again with
    /// the same DIR replays what they recorded: a killed bench redoes no finished sampler cell
    /// and resumes the one it was in, and each row's times include the earlier runs'. Files
    /// whose options or scene differ are ignored; delete DIR to start afresh.
    #[arg(long, value_name = "DIR", requires = "foliage")]
    pub checkpoint_dir: Option<PathBuf>,
    /// Seconds at least between two saves of a cell's checkpoint (with --checkpoint-dir).
    #[arg(
        long,
        value_name = "SECS",
        default_value_t = 60.0,
        requires = "checkpoint_dir"
    )]
    pub checkpoint_every: f64,
}

/// Prints a progress line on stderr.
fn progress(line: &str) {
    eprintln!("{line}");
}

impl From<&BenchArgs> for BenchOptions {
    fn from(a: &BenchArgs) -> Self {
        BenchOptions {
            quick: a.quick,
            cells: a.cells,
            gpu_cells: a.gpu_cells,
            rays: a.rays,
            seed: a.seed,
            backend: a.backend.into(),
            gpu_projection: a.gpu_projection,
            rsf_on_gpu: a.rsf_on_gpu,
            tests_on_cpu: a.tests_on_cpu,
            sweep_maps_on_cpu: a.sweep_maps_on_cpu,
            boxes_inline: a.boxes_inline,
            occluders_inline: a.occluders_inline,
            pixels_per_device_test: a.pixels_per_device_test.map(|n| n as usize),
            gpu_sampler_memory: a.gpu_sampler_memory,
            shared: a.shared.clone(),
            scenes: a.scenes.clone(),
            pvs_out: a.pvs_out.clone(),
            rsf: if a.rsf {
                umbrasweep::settings::SweepChoice::On
            } else if a.no_rsf {
                umbrasweep::settings::SweepChoice::Off
            } else {
                umbrasweep::settings::SweepChoice::Auto
            },
            foliage_studies: a.foliage_studies.clone(),
            foliage_subcell_cells: a.foliage_subcell_cells,
            foliage_paper_cells: a.foliage_paper_cells,
            foliage_model_trees: a.foliage_model_trees,
            foliage_trees: a.foliage_trees,
            foliage_sampling_budget: a.foliage_sampling_budget,
            foliage_sampling_max_eps: a.foliage_sampling_max_eps,
            foliage_sampling_tuck: a.foliage_sampling_tuck,
            foliage_sampling_eps: a.foliage_sampling_eps,
            foliage_sampling_levels: a.foliage_sampling_levels,
            hunt_rays: a.hunt_rays,
            confirm_rays: a.confirm_rays,
            checkpoint_dir: a.checkpoint_dir.clone(),
            checkpoint_seconds: a.checkpoint_every,
            progress: Some(progress),
        }
    }
}

/// Runs `umbrasweep bench` (or, with `--foliage`, the foliage study): progress on stderr,
/// the table(s) on stdout, `--json` if asked.
///
/// # Errors
/// See [`bench::collect`] and [`foliage::collect`]; or a `--json` file that cannot be
/// written.
pub fn run(args: &BenchArgs) -> anyhow::Result<()> {
    let opts = BenchOptions::from(args);
    if args.foliage {
        let bench = foliage::collect(&opts)?;
        let false_culls = bench
            .rows
            .iter()
            .map(|r| r.row.false_culls + harder_false_culls(&r.row))
            .sum();
        return report(&bench.tables(), false_culls, &bench, args.json.as_deref());
    }
    let bench = bench::collect(&opts)?;
    let false_culls = bench
        .rows
        .iter()
        .map(|r| r.false_culls + harder_false_culls(r))
        .sum();
    report(&bench.table(), false_culls, &bench, args.json.as_deref())
}

/// The false culls a row's harder checks found (`--hunt-rays`, `--confirm-rays`).
fn harder_false_culls(r: &bench::BenchRow) -> usize {
    r.hunt.as_ref().map_or(0, |h| h.false_culls) + r.confirm.as_ref().map_or(0, |c| c.false_culls)
}

/// Prints a bench's tables, warns about false culls, and writes `--json` if asked.
fn report(
    tables: &str,
    false_culls: usize,
    doc: &impl Serialize,
    json: Option<&Path>,
) -> anyhow::Result<()> {
    print!("{tables}");
    if false_culls > 0 {
        eprintln!("bench: {false_culls} FALSE CULLS (see above): the PVS is not conservative");
    }
    if let Some(path) = json {
        let bytes = serde_json::to_vec_pretty(doc)?;
        umbrasweep::util::write_atomic(path, &bytes).map_err(anyhow::Error::msg)?;
    }
    Ok(())
}

#[cfg(test)]
mod tests {
    use super::*;
    use clap::Parser;

    #[derive(Parser)]
    struct Cli {
        #[command(flatten)]
        args: BenchArgs,
    }

    #[test]
    fn flags_map_to_the_library_options() {
        let cli = Cli::parse_from([
            "bench",
            "--quick",
            "--scenes",
            "boxfield,city",
            "--cells",
            "1",
            "--rays",
            "1000",
            "--backend",
            "cpu",
        ]);
        let o = BenchOptions::from(&cli.args);
        assert!(o.quick);
        assert_eq!(o.scenes, Some(vec!["boxfield".into(), "city".into()]));
        assert_eq!((o.cells, o.rays, o.seed), (Some(1), Some(1000), 1));
        assert_eq!(o.backend, bench::BenchBackend::Cpu);
        // The defaults of the flags are the library's.
        let d = BenchOptions::default();
        let o = BenchOptions::from(&Cli::parse_from(["bench"]).args);
        assert_eq!(
            (o.seed, o.backend, o.cells, o.rays, o.gpu_cells),
            (d.seed, d.backend, d.cells, d.rays, d.gpu_cells)
        );
        assert_eq!(
            (
                o.foliage_subcell_cells,
                o.foliage_paper_cells,
                o.foliage_model_trees
            ),
            (
                d.foliage_subcell_cells,
                d.foliage_paper_cells,
                d.foliage_model_trees
            )
        );
    }

    #[test]
    fn foliage_flags_need_foliage_and_exclude_the_scene_bench() {
        assert!(Cli::try_parse_from(["bench", "--foliage", "--quick"]).is_err());
        assert!(Cli::try_parse_from(["bench", "--foliage-studies", "coarse"]).is_err());
        let cli = Cli::parse_from(["bench", "--foliage", "--foliage-studies", "moon"]);
        let err = foliage::collect(&BenchOptions::from(&cli.args))
            .unwrap_err()
            .to_string();
        assert!(err.contains("moon"), "{err}");
    }
}
