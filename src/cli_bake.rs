//! `umbrasweep bake`: argument parsing, backend choice, progress bar, summary and the atomic
//! write of the PVS document.

use anyhow::{Context, bail};
use clap::ValueEnum;
use glam::DVec3;
use std::io::IsTerminal;
use std::path::PathBuf;
use umbrasweep::backend::RasterBackend;
use umbrasweep::backend::cpu::CpuBackend;
use umbrasweep::backend::gpu::GpuProjection;
use umbrasweep::bake::{self, BakeSettings, SweepChoice};
use umbrasweep::geom::Aabb;
use umbrasweep::project::planes::{Spacing, SweepSettings};
use umbrasweep::settings::{SamplingFusion, UpAxis};
use umbrasweep::{cells, scene};

/// Where each direction's planes go.
#[derive(Clone, Copy, Debug, PartialEq, Eq, ValueEnum)]
pub enum PlacementChoice {
    /// Geometric spacing from the nearest to the far occluders (measured best).
    Geometric,
    /// Weighted quantiles of the occluders' distances.
    Quantile,
}

/// How the sampler's render of a face rectangle fuses the leaves (`--sampling-fusion`).
#[derive(Clone, Copy, Debug, PartialEq, Eq, ValueEnum)]
pub enum FusionChoice {
    /// Every leaf shrunk for the whole rectangle's parallax.
    Shrink,
    /// The per-rectangle occlusion sweep (CPU only).
    Sweep,
}

/// How sweep planes are spaced.
#[derive(Clone, Copy, Debug, PartialEq, Eq, ValueEnum)]
pub enum SpacingChoice {
    /// Geometric spacing between the nearest and far occluders (measured best).
    Geometric,
    /// The paper's rule: each step makes the kernel K pixels wide.
    Kernel,
}

/// How alpha-tested cards occlude.
#[derive(Clone, Copy, Debug, PartialEq, Eq, ValueEnum)]
pub enum CardChoice {
    /// The parts of each card that are opaque at every trusted mip level (conservative).
    Coverage,
    /// Cards never occlude.
    Ignore,
}

/// What import does with an alpha-tested material's missing or undecodable image.
#[derive(Clone, Copy, Debug, PartialEq, Eq, ValueEnum)]
pub enum MissingChoice {
    /// Refuse the scene, naming the file and the image.
    Error,
    /// Keep those cards as non-occluders, with a warning.
    Transparent,
}

/// The scene's up axis.
#[derive(Clone, Copy, Debug, PartialEq, Eq, ValueEnum)]
pub enum UpChoice {
    /// y is up (glTF, most OBJ exports).
    Y,
    /// z is up.
    Z,
}

/// Which raster backend runs.
#[derive(Clone, Copy, Debug, PartialEq, Eq, ValueEnum)]
pub enum BackendChoice {
    /// The GPU when a hardware adapter exists, else the CPU.
    Auto,
    /// wgpu; fails (exit 2) when no adapter exists.
    Gpu,
    /// Pure Rust with rayon.
    Cpu,
}

#[derive(clap::Args, Debug)]
#[command(
    after_help = "Examples:\n  umbrasweep bake data/demo_city.obj --cells data/demo_city_cells.json -o demo.json\n  umbrasweep bake city.obj --grid-box 0,1,0,100,3,100 --grid-size 20,1,20 -o city.json --backend cpu\n  umbrasweep bake city.obj --cells cells.json -o city.pvs --resume      (after an interruption)\n  umbrasweep bake city.obj --cells cells.json -o s0.json --shard 0/4    (then umbrasweep merge)\n  umbrasweep bake level.obj --cells auto --cell-size 64 --band 32 --headroom 24 --one-sided --split-objects 64 -o level.pvs\n  umbrasweep bake city.glb --cells cells.json --max-pvs-triangles 25000 -o city.pvs   (halves cells over budget)"
)]
pub struct BakeArgs {
    /// The scene: .obj, .gltf or .glb.
    pub scene: PathBuf,
    /// View cells: {"cells": [{"min": [x,y,z], "max": [x,y,z]}, …]} in scene units, or `auto`:
    /// found from the scene above its walkable surfaces (the rule of `umbrasweep cells`, with
    /// the options under "Automatic cells").
    #[arg(long, value_name = "FILE|auto", conflicts_with_all = ["grid_box", "grid_size"], required_unless_present = "grid_box")]
    pub cells: Option<PathBuf>,
    /// The options of `--cells auto`.
    #[command(flatten)]
    pub auto_cells: Box<crate::cli_cells::AutoCellArgs>,
    /// A regular grid of cells filling this box: minx,miny,minz,maxx,maxy,maxz.
    #[arg(
        long,
        value_delimiter = ',',
        requires = "grid_size",
        allow_hyphen_values = true
    )]
    pub grid_box: Option<Vec<f64>>,
    /// Cells per axis of --grid-box: nx,ny,nz.
    #[arg(long, value_delimiter = ',', requires = "grid_box")]
    pub grid_size: Option<Vec<u32>>,
    /// Output: .json (the PVS document) or .pvs (the binary file). While the bake runs, a
    /// journal OUTPUT.journal beside it records finished cells (see --resume).
    #[arg(short, long)]
    pub output: PathBuf,
    /// Raster backend.
    #[arg(long, value_enum, default_value_t = BackendChoice::Auto)]
    pub backend: BackendChoice,
    /// How the GPU backend makes occluders' Projections: `clipped` (each occluder's 8 views
    /// intersected on the CPU, the GPU tests the few edges left) or `counting` (the points go
    /// up as they are; a compute pass projects the views from the cell's corners and one
    /// instanced draw per plane counts them per pixel; needs SHADER_F64). Default: counting on
    /// a hardware GPU with SHADER_F64, clipped on a software one (lavapipe). Same PVS either
    /// way; ignored on the CPU backend.
    #[arg(long, value_name = "clipped|counting")]
    pub gpu_projection: Option<GpuProjection>,
    /// Run ray space factorization's charts on the GPU backend's device (needs SHADER_F64)
    /// instead of the CPU. Same charts; the default keeps them on the CPU, which was faster
    /// on every device measured (each wave of a cell's traversal waits for its submission: on
    /// an NVIDIA H200 328 ms per city cell against 84 on its CPU, measured while the bake's
    /// threads still submitted one at a time). Ignored on the CPU backend.
    #[arg(long)]
    pub rsf_on_gpu: bool,
    /// Read the GPU backend's Depth Maps back (separate planes' and the occlusion sweep's)
    /// and test occludees against them on the CPU, instead of building their pyramids and
    /// answering the tests on the device (the default: only the answers come back, and a
    /// sweep's maps stay there for its later planes). The same PVS; for comparisons.
    /// Ignored on the CPU backend.
    #[arg(long)]
    pub tests_on_cpu: bool,
    /// Read only the occlusion sweep's Depth Maps back (each plane's umbra reprojected from
    /// the CPU's copy), testing separate planes on the device. The same PVS; for
    /// comparisons. Ignored on the CPU backend.
    #[arg(long)]
    pub sweep_maps_on_cpu: bool,
    /// Send each occludee box with its test on the device (six `f64`, 48 bytes more a test)
    /// instead of keeping the bake's object, hierarchy-node and piece boxes on the device,
    /// each uploaded once when first tested (the default). The same PVS; for comparisons.
    /// Ignored on the CPU backend.
    #[arg(long)]
    pub boxes_inline: bool,
    /// Send each counted occluder's points with its plane (24 bytes a point) instead of
    /// keeping the scene's occluder parts on the device, each uploaded once when first
    /// projected (the default with `--gpu-projection counting`). The same PVS; for
    /// comparisons. Ignored on the CPU backend and with clipped projections.
    #[arg(long)]
    pub occluders_inline: bool,
    /// On the GPU backend, ask the device a plane's occludee tests only while they number at
    /// most one per N pixels of its map (default 64, measured on lavapipe); past that the map
    /// comes back and the CPU tests. Smaller N keeps more planes on the device for more CPU
    /// time recording their tests. The same PVS at any N; ignored on the CPU backend.
    #[arg(long, value_name = "N", value_parser = clap::value_parser!(u32).range(1..))]
    pub pixels_per_device_test: Option<u32>,
    /// Device memory the shrunk-occluder sampler's GPU samplers may take together (e.g. 16G;
    /// default 4G, which suits a consumer GPU). Each serves one thread's renders (about 0.7 GB
    /// at 512 pixels on a fine forest, 1.8 GB at 1,024); beyond the budget a level's other
    /// threads wait for one. More lets more threads render at once on a large GPU; the PVS is
    /// the same. Ignored on the CPU backend.
    #[arg(long, value_name = "SIZE", value_parser = parse_size)]
    pub gpu_sampler_memory: Option<u64>,
    /// Depth Map resolution per side (a power of two).
    #[arg(long, default_value_t = BakeSettings::default_settings().resolution)]
    pub resolution: u32,
    /// With the occlusion sweep: how much wider than tall (or taller than wide) a plane's Depth
    /// Map may be, a power of two. Each map follows its rectangle's shape with resolution²
    /// pixels, so that a flat rectangle (a forest's band of crowns beside the cell) gets
    /// squarer pixels; 1 keeps every map square. Separate planes (--no-sweep) are always
    /// square.
    #[arg(long, default_value_t = BakeSettings::default_settings().max_stretch)]
    pub max_stretch: u32,
    /// Extension factor of each plane's rectangle beyond the 90° frustum of the cell's face.
    #[arg(long, default_value_t = BakeSettings::default_settings().extend)]
    pub extend: f64,
    /// Projection planes per direction (each occludee is tested on all of them).
    #[arg(long, default_value_t = BakeSettings::default_settings().planes)]
    pub planes: u32,
    /// Further planes per direction through the middle of the nearest large closed
    /// occluders, which receive their cross-sections (slices) at Depth 0.
    #[arg(long, default_value_t = BakeSettings::default_settings().slice_planes)]
    pub slice_planes: u32,
    /// Where each direction's planes go.
    #[arg(long, value_enum, default_value_t = PlacementChoice::Geometric)]
    pub placement: PlacementChoice,
    /// Only objects whose name matches this glob pattern are occluders (e.g. 'building*');
    /// every object stays an occludee.
    #[arg(long)]
    pub occluders: Option<String>,
    /// UNSAFE: treat alpha-tested and blended triangles (glTF MASK/BLEND, MTL d < 1 or map_d)
    /// as wholly opaque occluders. This may cull visible objects, seen through transparent
    /// texels; the default `--alpha-cards coverage` uses only the surely opaque texels.
    #[arg(long)]
    pub alpha_occluders: bool,
    /// Alpha-tested cards (glTF MASK) as occluders: `coverage` uses the parts of each card
    /// that are opaque at every mip level a renderer may sample (bilinear filtering, box-filtered
    /// mips), conservatively; `ignore` makes cards never occlude. The summary prints the share
    /// of card area that is surely opaque.
    #[arg(long, value_enum, default_value_t = CardChoice::Coverage)]
    pub alpha_cards: CardChoice,
    /// Mip levels the card coverage trusts: 0 (default) = all of them, down to 1×1, which is
    /// safe for any renderer but leaves little opaque on sparse leaf textures; N = levels
    /// 0..N only. A limit assumes the engine never samples foliage from farther levels
    /// (alpha-to-coverage, coverage-preserving mips or a LOD clamp); with plain mipmapping it
    /// may cull objects seen through far cards.
    #[arg(long, default_value_t = 0)]
    pub alpha_mips: u32,
    /// Most polygons per card: rectangles of surely opaque texels, largest first.
    #[arg(long, default_value_t = BakeSettings::default_settings().alpha_card_polygons)]
    pub alpha_card_polygons: u32,
    /// What to do when an alpha-tested material's image is missing or cannot be decoded:
    /// `error` refuses the scene (naming the image), `transparent` keeps its cards as
    /// non-occluders.
    #[arg(long, value_enum, default_value_t = MissingChoice::Error)]
    pub alpha_missing: MissingChoice,
    /// Disable the improved occludee Projection (Durand §4).
    #[arg(long)]
    pub no_improved_projection: bool,
    /// Bake with the occlusion sweep (Durand §5): parallel planes leaving the cell, each
    /// receiving the occluders between it and the previous plane plus the previous plane's
    /// umbra, reprojected. Fuses many small occluders (foliage). Default: chosen per scene —
    /// the sweep when occluder parts smaller than 2 × the median cell side hold at least half
    /// of the occluder area; the summary says which and why.
    #[arg(long, conflicts_with = "no_sweep")]
    pub sweep: bool,
    /// Never sweep: separate planes per direction (--planes, --slice-planes).
    #[arg(long)]
    pub no_sweep: bool,
    /// The most sweep planes per direction.
    #[arg(long, default_value_t = BakeSettings::default_settings().sweep_settings.planes)]
    pub sweep_planes: u32,
    /// Sweep plane spacing: geometric, or the paper's kernel rule ΔD = D(K−1)P/(C·N).
    #[arg(long, value_enum, default_value_t = SpacingChoice::Geometric)]
    pub sweep_spacing: SpacingChoice,
    /// Kernel size K in pixels for --sweep-spacing kernel.
    #[arg(long, default_value_t = BakeSettings::default_settings().sweep_settings.kernel)]
    pub kernel: u32,
    /// Bake each cell as the union of the PVS of sub-cells no larger than SIZE (scene units)
    /// along any axis: tighter PVS (extended projections fuse better from small cells), bake
    /// time roughly proportional to the number of sub-cells.
    #[arg(long, value_name = "SIZE")]
    pub subcell: Option<f64>,
    /// Run ray space factorization first (Leyvand et al. 2003: per horizontal direction, the
    /// umbrae of upright occluders standing on the ground, fused; cities and levels).
    /// Default: on when at least 40 % of the occluder area is upright about --up; the summary
    /// says which and why.
    #[arg(long, conflicts_with = "no_rsf")]
    pub rsf: bool,
    /// Never run ray space factorization.
    #[arg(long)]
    pub no_rsf: bool,
    /// Pixels per side of each of ray space factorization's four charts (slopes × crossings
    /// of the lines leaving each side of the cell).
    #[arg(long, default_value_t = BakeSettings::default_settings().rsf_resolution)]
    pub rsf_resolution: u32,
    /// The scene's up axis (cells are boxes aligned with it; ray space factorization works in
    /// vertical planes).
    #[arg(long, value_enum, default_value_t = UpChoice::Y)]
    pub up: UpChoice,
    /// Run the shrunk-occluder sampler after the planes (fine foliage: fuses leaves of any size
    /// by rendering the cell's faces from sample points with every leaf shrunk for the ball
    /// around the point). Slow: minutes to an hour per cell on two cores (2 min to cull 71 %
    /// of a fine forest's 1-unit cell, where the sweep culls nothing). Default: off; the summary
    /// says which and why.
    #[arg(long, conflicts_with = "no_sampling")]
    pub sampling: bool,
    /// Never run the shrunk-occluder sampler.
    #[arg(long)]
    pub no_sampling: bool,
    /// The sampler's finest ε (scene units): the radius of the ball each sample point stands
    /// for. Smaller culls more and costs about 1/ε² points. Default: 0.35 × the occluder
    /// polygons' median inradius (0.05 for leaves 0.5 across: 1/10 of the leaf; slivers, whose
    /// inradius is under 1/1000 of their longest edge, left out), and 1/√2 of
    /// that on cells where the automatic resolution would render the finest level at 1,024
    /// px: those render at 512 px instead (see --sampling-resolution).
    #[arg(long, value_name = "E")]
    pub sampling_eps: Option<f64>,
    /// The sampler's budget per cell: a number of sample points (e.g. 50000) or of seconds
    /// with an `s` (e.g. 30s), or both separated by a comma. Objects still undecided when it
    /// runs out stay visible. A time budget makes the result depend on the machine's speed.
    #[arg(long, value_name = "N|Ts", value_delimiter = ',')]
    pub sampling_budget: Option<Vec<String>>,
    /// Refinement levels of the sampler: faces are first sampled with balls 2^LEVELS × the
    /// finest ε (larger still while the first level's balls would outnumber the budget's
    /// points), and a ball is split in four only where objects are still undecided. On
    /// coarse foliage the coarse levels prune the finer levels' lists and pay; on fine
    /// foliage they stop at their probe or pilot (--sampling-probe-pay), and 0 saves those
    /// probes (about a minute on a 4×2×4 cell).
    #[arg(long, default_value_t = BakeSettings::default_settings().sampling_settings.levels)]
    pub sampling_levels: u32,
    /// The coarsest ε the sampler renders: coarser levels are split without sampling (the
    /// finest level always runs). Default: every level is sampled (on the coarse forest the
    /// coarsest level proves nothing cell-wide but its per-rectangle results prune the next
    /// level enough to pay for it).
    #[arg(long, value_name = "E")]
    pub sampling_max_eps: Option<f64>,
    /// Each level but the finest is first sampled at every 16th rectangle (at least 8, about 64
    /// at most); when
    /// those prove hidden less than this fraction of the objects they test, the rest of the
    /// level is split without sampling (on fine foliage the coarse levels hide nothing and
    /// cost as much per point as the finest). 0 samples every level whole.
    #[arg(long, value_name = "FRACTION", default_value_t = BakeSettings::default_settings().sampling_settings.probe)]
    pub sampling_probe: f64,
    /// A level's probe must also prove hidden for the cell (at every probed rectangle that
    /// tests them) at least this share of the undecided objects it tests, or the rest of the
    /// level is split without sampling: a coarse level pays only where its balls fuse the
    /// leaves (the coarse forest's levels that pay prove 50–74 %, the fine forest's about 30 %,
    /// where the level costs more than the finest level it prunes). 0 asks for one object.
    #[arg(long, value_name = "FRACTION", default_value_t = BakeSettings::default_settings().sampling_settings.probe_cull)]
    pub sampling_probe_cull: f64,
    /// The level just above the finest, when it passes both probe rules, is sampled whole
    /// only when what one of its rectangles should save the finest level is at least this
    /// many times what it costs, both in polygons drawn (a pilot renders a few probed
    /// rectangles and their quadrants with and without what the probe proved; counted, not
    /// timed). Stops a level that proves much but costs more per rectangle than the finest
    /// points it prunes (fine foliage at twice a fine ε). 0 turns the estimate off.
    #[arg(long, value_name = "RATIO", default_value_t = BakeSettings::default_settings().sampling_settings.probe_pay)]
    pub sampling_probe_pay: f64,
    /// Pixels across each 90° view of the hemicube the sampler renders per point, at every
    /// level; `auto` (the default) picks per cell and level the power of two nearest
    /// 8 × h/ε, h the median distance at which the cell's rays first hit something, within
    /// 256–1024 (a pixel about a quarter of a leaf's shrink at that distance); where that
    /// gives the finest level more than 512 px and ε is automatic too, the cell renders at
    /// 512 px with a √2 finer ε, which culled more in the same time (fine forest, 4×2×4 cell:
    /// 59.6 % against 54.8 % in 13 min). The summary prints the resolutions used.
    #[arg(long, value_name = "N|auto")]
    pub sampling_resolution: Option<String>,
    /// Rays cast from each cell before sampling: objects they see are visible for sure and
    /// are not sampled (0 turns this off).
    #[arg(long, default_value_t = BakeSettings::default_settings().sampling_settings.rays)]
    pub sampling_rays: u64,
    /// The sampler renders each point once per band of occludee distance, the bands' farthest
    /// distances growing by this ratio, with leaves shrunk only as much as that band's
    /// occludees need: more culled for more renders. 0: one render per point.
    #[arg(long, value_name = "RATIO", default_value_t = BakeSettings::default_settings().sampling_settings.band_ratio)]
    pub sampling_band_ratio: f64,
    /// Render each point only by band. By default a point with several bands is first
    /// rendered once for all its candidates (leaves shrunk for the farthest), and only what
    /// that leaves open is rendered for again, band by band, the bands formed over those
    /// objects alone (tighter shrinks): on the fine forest's 4×2×4 cell about 1.5–1.8× the
    /// objects hidden for about the same time.
    #[arg(long)]
    pub sampling_bands_only: bool,
    /// The sampler's tuck pass: as each leaf is drawn (nearest first), its edges whose whole
    /// image already lies beyond what nearer leaves drew are drawn unshrunk, so that leaves
    /// fuse across edges other leaves cover (on the fine forest's 1-unit cell about 1.5× the
    /// objects hidden at the same ε for about 2× the time). It runs on the CPU's hemicube
    /// only: with `--backend gpu` the sampler then renders on the CPU. Default: off.
    #[arg(long, conflicts_with = "no_sampling_tuck")]
    pub sampling_tuck: bool,
    /// The sampler without the tuck pass (the default; every edge shrunk).
    #[arg(long)]
    pub no_sampling_tuck: bool,
    /// How the sampler's render of a face rectangle fuses the leaves. `shrink`: every leaf
    /// shrunk for the whole rectangle's parallax (renders on the GPU too). `sweep`: the
    /// per-rectangle occlusion sweep, each leaf's extended projection onto a plane just
    /// behind it and only the leaves' union eroded as the sweep moves away, so leaves stay
    /// fused at a far coarser ε (CPU only: with `--backend gpu` the sampler renders on the
    /// CPU). It tests each occludee at its own depth in one render per rectangle, so the
    /// bands (`--sampling-band-ratio`, `--sampling-bands-only`) and the tuck pass do not
    /// apply to it; it renders at 512 px unless `--sampling-resolution` says otherwise. Per
    /// sample point it hides at ε 0.125 what `shrink` hides at ε 0.03 on the fine forest, but
    /// each point costs far more: not yet the faster choice per cell (docs/sampling.md).
    #[arg(long, value_enum, default_value_t = FusionChoice::Shrink)]
    pub sampling_fusion: FusionChoice,
    /// How often the sampler saves its progress inside a cell, in seconds, to
    /// OUTPUT.sampler-<cell> (removed when the cell is finished): `bake --resume` then
    /// continues a cell that takes hours from its last save instead of from scratch, with the
    /// same PVS. 0 saves after every chunk of rectangles; `off` never saves.
    #[arg(long, value_name = "SECS|off", default_value = "60", value_parser = parse_checkpoint)]
    pub sampling_checkpoint: Checkpointing,
    /// Split every object larger than SIZE (scene units) along some axis into clusters that
    /// fit: its connected components, grouped or cut along the longest axis. For files whose
    /// objects span the level (materials, one ground mesh, one mesh per tree). The PVS lists
    /// clusters; its `split` table maps them back to the file's objects.
    #[arg(long, value_name = "SIZE")]
    pub split_objects: Option<f32>,
    /// Adaptive subdivision: split a cell whose PVS holds more than N triangles in two along
    /// its longest side and bake the halves (testing only the cell's PVS), down to
    /// --min-cell-size. The PVS keeps every level; the run-time lookup descends to the
    /// smallest cell holding the camera.
    #[arg(long, value_name = "N")]
    pub max_pvs_triangles: Option<u64>,
    /// The smallest cell adaptive subdivision makes (scene units). Default: 1/8 of the
    /// longest side of each cell given to the bake. A half whose PVS is not 2 % smaller than
    /// its parent's is not split again.
    #[arg(long, value_name = "SIZE", requires = "max_pvs_triangles")]
    pub min_cell_size: Option<f64>,
    /// Occluder selection by solid angle: occluder parts whose bounding sphere subtends less
    /// than SR steradians from every point of a cell are not projected for that cell. Faster
    /// on large scenes, at the cost of a looser PVS (never a false cull). 0 (the default)
    /// projects every part that may hide something; 1e-4 is a disc 1 unit across at 89 units.
    #[arg(long, value_name = "SR", default_value_t = 0.0)]
    pub occluder_min_solid_angle: f64,
    /// Write every plane's maps of the baked cells as OpenEXR files into this folder.
    #[arg(long, value_name = "DIR")]
    pub dump_exr: Option<PathBuf>,
    /// Write every plane's maps as 8-bit PNG previews into this folder.
    #[arg(long, value_name = "DIR")]
    pub dump_png: Option<PathBuf>,
    /// Limit --dump-exr/--dump-png to these cell indices (e.g. 0,5,9).
    #[arg(long, value_delimiter = ',', value_name = "I,J,…")]
    pub dump_cells: Option<Vec<usize>>,
    /// Continue an interrupted bake from its journal (OUTPUT.journal, written as cells
    /// finish): finished cells are not baked again. The journal must come from the same
    /// scene, cells, settings, backend and shard (else an error says what to do); without a
    /// journal every cell is baked. A sampler cell left unfinished continues from its last
    /// save (--sampling-checkpoint).
    #[arg(long)]
    pub resume: bool,
    /// Bake only shard I of N (0 ≤ I < N): the cells I, I+N, I+2N, … Writes a shard file
    /// for `umbrasweep merge OUT SHARD…` (.json, or .pvs: format version 5). On Slurm: --shard $SLURM_ARRAY_TASK_ID/N with
    /// --array=0-(N-1); on Kubernetes: $JOB_COMPLETION_INDEX/N.
    #[arg(long, value_name = "I/N")]
    pub shard: Option<umbrasweep::bake::ShardSpec>,
    /// Write 0 for every timing (per-cell and per-culler milliseconds, total seconds), so that
    /// the same inputs give byte-identical files whatever the thread or shard count, and a
    /// resumed bake the same file as an uninterrupted one. (With --sampling the sampler's point
    /// counts may still vary between runs, and its PVS when its budget runs out.)
    #[arg(long)]
    pub reproducible: bool,
    /// Refuse a bake whose estimated peak memory exceeds SIZE (e.g. 16G, 512M, or bytes),
    /// before it starts. Default: this machine's memory (MemTotal).
    #[arg(long, value_name = "SIZE", value_parser = parse_size)]
    pub max_memory: Option<u64>,
    #[command(flatten)]
    pub progress: crate::cli_progress::ProgressArgs,
    /// No progress bar, progress lines or summary.
    #[arg(short, long)]
    pub quiet: bool,
}

/// `--sampling-checkpoint`: seconds between the sampler's saves, or never.
#[derive(Clone, Copy, Debug, PartialEq)]
pub enum Checkpointing {
    /// Never save.
    Off,
    /// Save at most every this many seconds (0: after every chunk).
    Every(f64),
}

fn parse_checkpoint(v: &str) -> Result<Checkpointing, String> {
    if v == "off" {
        return Ok(Checkpointing::Off);
    }
    match v.parse::<f64>() {
        Ok(s) if s >= 0.0 && s.is_finite() => Ok(Checkpointing::Every(s)),
        _ => Err(format!(
            "expected seconds between the sampler's saves (e.g. 60, 0 for every chunk) or `off`, got {v:?}"
        )),
    }
}

/// Parses a memory size: bytes, or a number with K, M, G or T (powers of 1024; an optional
/// `iB` or `B` after it).
pub fn parse_size(s: &str) -> Result<u64, String> {
    let t = s.trim();
    let t = t
        .strip_suffix("iB")
        .or_else(|| t.strip_suffix('B'))
        .unwrap_or(t);
    let (num, shift) = match t.char_indices().last() {
        Some((i, c)) if c.is_ascii_alphabetic() => {
            let shift = match c.to_ascii_uppercase() {
                'K' => 10,
                'M' => 20,
                'G' => 30,
                'T' => 40,
                _ => {
                    return Err(format!(
                        "{s:?}: expected a size such as 16G, 512M or 1073741824"
                    ));
                }
            };
            (&t[..i], shift)
        }
        _ => (t, 0),
    };
    match num.trim().parse::<f64>() {
        Ok(v) if v.is_finite() && v > 0.0 => Ok((v * (1u64 << shift) as f64) as u64),
        _ => Err(format!(
            "{s:?}: expected a size such as 16G, 512M or 1073741824"
        )),
    }
}

/// This machine's memory (MemTotal of /proc/meminfo), if known.
fn machine_memory() -> Option<u64> {
    let info = std::fs::read_to_string("/proc/meminfo").ok()?;
    let line = info.lines().find(|l| l.starts_with("MemTotal:"))?;
    let kb: u64 = line.split_whitespace().nth(1)?.parse().ok()?;
    Some(kb * 1024)
}

fn gib(b: u64) -> String {
    format!("{:.2} GiB", b as f64 / (1u64 << 30) as f64)
}

/// Whether an output path names the binary `.pvs` file (else the `.json` document).
///
/// # Errors
/// Any other extension, naming the path.
pub fn output_is_binary(path: &std::path::Path) -> anyhow::Result<bool> {
    match path.extension().and_then(|e| e.to_str()) {
        Some("json") => Ok(false),
        Some("pvs") => Ok(true),
        _ => bail!(
            "{}: unsupported output format (use a .json or .pvs file name)",
            path.display()
        ),
    }
}

/// Writes a PVS document atomically: the binary `.pvs` file when `binary`, else the JSON.
pub fn write_document(
    path: &std::path::Path,
    doc: &umbrasweep::pvs::PvsDocument,
    binary: bool,
) -> anyhow::Result<()> {
    if binary {
        umbrasweep::pvs::binary::write(path, doc)
    } else {
        umbrasweep::pvs::json::write(path, doc)
    }
    .map_err(anyhow::Error::msg)
}

/// Resolves the cells of the command line: a cells file, `auto` (found from `scene`, with one
/// line of statistics on stderr) or a grid.
fn read_cells(a: &BakeArgs, scene: &scene::Scene) -> anyhow::Result<Vec<Aabb>> {
    let auto = a.cells.as_ref().is_some_and(|p| p.as_os_str() == "auto");
    if let (false, Some(flag)) = (auto, a.auto_cells.first_given()) {
        bail!("{flag} is an option of automatic cells: it needs --cells auto");
    }
    if auto {
        let t = std::time::Instant::now();
        let found = a.auto_cells.compute(scene, &a.scene)?;
        if !a.quiet {
            eprintln!(
                "auto cells  {} ({:.2} s)",
                found.stats,
                t.elapsed().as_secs_f64()
            );
        }
        return Ok(found.cells);
    }
    if let Some(path) = &a.cells {
        return Ok(cells::load_json(path)?);
    }
    let (Some(b), Some(n)) = (&a.grid_box, &a.grid_size) else {
        bail!("give --cells FILE or --grid-box with --grid-size");
    };
    if b.len() != 6 {
        bail!(
            "--grid-box takes 6 numbers: minx,miny,minz,maxx,maxy,maxz (got {})",
            b.len()
        );
    }
    if n.len() != 3 {
        bail!("--grid-size takes 3 counts: nx,ny,nz (got {})", n.len());
    }
    // Rounded outward to f32, like a cells file: the grid never covers less than asked.
    let bounds = Aabb::outward(DVec3::new(b[0], b[1], b[2]), DVec3::new(b[3], b[4], b[5]));
    Ok(cells::grid(bounds, [n[0], n[1], n[2]])?)
}

/// Picks the backend: `auto` takes the GPU only when a hardware adapter exists (a software
/// adapter such as lavapipe is slower than the CPU backend on the same cores), with the
/// projection and ray space factorization's charts asked for.
pub fn make_backend(
    choice: BackendChoice,
    projection: Option<GpuProjection>,
    rsf_on_gpu: bool,
    (tests_on_cpu, sweep_maps_on_cpu, boxes_inline, occluders_inline, pixels_per_test): (
        bool,
        bool,
        bool,
        bool,
        Option<u32>,
    ),
    sampler_memory: Option<u64>,
) -> anyhow::Result<Box<dyn RasterBackend>> {
    use umbrasweep::backend::gpu::{GpuBackend, hardware_adapter_available};
    match choice {
        BackendChoice::Cpu => Ok(Box::new(CpuBackend::new())),
        BackendChoice::Auto if !hardware_adapter_available() => Ok(Box::new(CpuBackend::new())),
        BackendChoice::Auto | BackendChoice::Gpu => match GpuBackend::new() {
            Ok(mut b) => {
                if let Some(projection) = projection
                    && let Err(e) = b.set_projection(projection)
                {
                    bail!(
                        "--gpu-projection {projection}: {e} (use --gpu-projection clipped, or \
                         --backend cpu)"
                    );
                }
                if let Err(e) = b.set_rsf_on_gpu(rsf_on_gpu) {
                    bail!("--rsf-on-gpu: {e} (leave it out: the CPU's charts are the same)");
                }
                b.set_tests_on_device(!tests_on_cpu);
                b.set_keep_sweep_maps(!sweep_maps_on_cpu);
                b.set_resident_boxes(!boxes_inline);
                b.set_resident_parts(!occluders_inline);
                if let Some(n) = pixels_per_test {
                    b.set_pixels_per_device_test(n as usize);
                }
                if let Some(bytes) = sampler_memory {
                    b.set_sampler_memory(bytes);
                }
                Ok(Box::new(b))
            }
            Err(e) => bail!("--backend gpu: {e} (use --backend cpu)"),
        },
    }
}

/// Parses `--sampling-budget` values: points (`50000`) and/or seconds (`30s`).
pub fn parse_budget(
    values: &[String],
    mut s: umbrasweep::settings::SamplingSettings,
) -> anyhow::Result<umbrasweep::settings::SamplingSettings> {
    for v in values {
        let v = v.trim();
        if let Some(t) = v.strip_suffix('s') {
            match t.trim().parse::<f64>() {
                Ok(t) if t.is_finite() && t > 0.0 => s.budget_seconds = Some(t),
                _ => bail!(
                    "--sampling-budget {v:?}: expected a positive number of seconds such as 30s"
                ),
            }
        } else {
            match v.parse::<u64>() {
                Ok(n) if n > 0 => s.budget_points = n,
                _ => bail!(
                    "--sampling-budget {v:?}: expected a positive number of sample points (e.g. 50000) or seconds (e.g. 30s)"
                ),
            }
        }
    }
    Ok(s)
}

pub fn run(a: &BakeArgs) -> anyhow::Result<()> {
    let mut sampling_settings = umbrasweep::settings::SamplingSettings {
        eps: a.sampling_eps,
        levels: a.sampling_levels,
        max_eps: a.sampling_max_eps,
        probe: a.sampling_probe,
        probe_cull: a.sampling_probe_cull,
        probe_pay: a.sampling_probe_pay,
        resolution: match a.sampling_resolution.as_deref() {
            None | Some("auto") => None,
            Some(v) => match v.parse::<u32>() {
                Ok(n) => Some(n),
                Err(_) => bail!(
                    "--sampling-resolution {v:?}: expected pixels per 90° view (e.g. 512) or `auto`"
                ),
            },
        },
        rays: a.sampling_rays,
        band_ratio: a.sampling_band_ratio,
        whole_first: !a.sampling_bands_only,
        tuck: a.sampling_tuck,
        fusion: match a.sampling_fusion {
            FusionChoice::Shrink => SamplingFusion::Shrink,
            FusionChoice::Sweep => SamplingFusion::Sweep,
        },
        ..BakeSettings::default_settings().sampling_settings
    };
    if let Some(b) = &a.sampling_budget {
        sampling_settings = parse_budget(b, sampling_settings)?;
    }
    let settings = BakeSettings {
        resolution: a.resolution,
        max_stretch: a.max_stretch,
        extend: a.extend,
        planes: a.planes,
        slice_planes: a.slice_planes,
        placement: match a.placement {
            PlacementChoice::Geometric => umbrasweep::project::planes::Placement::Geometric,
            PlacementChoice::Quantile => umbrasweep::project::planes::Placement::Quantile,
        },
        alpha_occluders: a.alpha_occluders,
        alpha_cards: match a.alpha_cards {
            CardChoice::Coverage => umbrasweep::settings::AlphaCards::Coverage,
            CardChoice::Ignore => umbrasweep::settings::AlphaCards::Ignore,
        },
        alpha_mips: a.alpha_mips,
        alpha_card_polygons: a.alpha_card_polygons,
        alpha_missing: match a.alpha_missing {
            MissingChoice::Error => umbrasweep::settings::AlphaMissing::Error,
            MissingChoice::Transparent => umbrasweep::settings::AlphaMissing::Transparent,
        },
        occluders: a.occluders.clone(),
        improved_projection: !a.no_improved_projection,
        sweep: if a.sweep {
            SweepChoice::On
        } else if a.no_sweep {
            SweepChoice::Off
        } else {
            SweepChoice::Auto
        },
        sweep_settings: SweepSettings {
            planes: a.sweep_planes,
            kernel: a.kernel,
            spacing: match a.sweep_spacing {
                SpacingChoice::Geometric => Spacing::Geometric,
                SpacingChoice::Kernel => Spacing::Kernel,
            },
        },
        subcell: a.subcell,
        sampling: if a.sampling {
            SweepChoice::On
        } else if a.no_sampling {
            SweepChoice::Off
        } else {
            SweepChoice::Auto
        },
        sampling_settings,
        max_pvs_triangles: a.max_pvs_triangles,
        min_cell_size: a.min_cell_size,
        occluder_min_solid_angle: a.occluder_min_solid_angle,
        rsf: if a.rsf {
            SweepChoice::On
        } else if a.no_rsf {
            SweepChoice::Off
        } else {
            SweepChoice::Auto
        },
        rsf_resolution: a.rsf_resolution,
        up: match a.up {
            UpChoice::Y => UpAxis::Y,
            UpChoice::Z => UpAxis::Z,
        },
    };
    settings.check().map_err(anyhow::Error::msg)?;
    let binary = output_is_binary(&a.output)?;
    let t = std::time::Instant::now();
    let scene = scene::load_with(
        &a.scene,
        &scene::LoadOptions {
            alpha_missing: settings.alpha_missing,
        },
    )?;
    let load_s = t.elapsed().as_secs_f64();
    let cells = read_cells(a, &scene)?;
    let scene = match a.split_objects {
        Some(size) => umbrasweep::scene::split::split_objects(&scene, size)
            .with_context(|| a.scene.display().to_string())?,
        None => scene,
    };
    let limit = a.max_memory.or_else(machine_memory);
    if let Some(limit) = limit {
        let need = bake::estimate_memory(&scene, &settings, rayon::current_num_threads());
        if need > limit {
            bail!(
                "{}: the bake needs about {} ({} triangles{}, {} threads) but {} {}: bake on a \
                 machine with more memory, use fewer threads (RAYON_NUM_THREADS), bake fewer \
                 occluders (--occluders) or fewer card polygons (--alpha-card-polygons, \
                 --alpha-cards ignore), or raise --max-memory if you know it fits",
                a.scene.display(),
                gib(need),
                scene.triangles.len(),
                if settings.sampling == SweepChoice::On {
                    ", with the sampler"
                } else {
                    ""
                },
                rayon::current_num_threads(),
                gib(limit),
                if a.max_memory.is_some() {
                    "is the --max-memory limit"
                } else {
                    "is all of this machine's memory (--max-memory)"
                }
            );
        }
    }
    let backend = make_backend(
        a.backend,
        a.gpu_projection,
        a.rsf_on_gpu,
        (
            a.tests_on_cpu,
            a.sweep_maps_on_cpu,
            a.boxes_inline,
            a.occluders_inline,
            a.pixels_per_device_test,
        ),
        a.gpu_sampler_memory,
    )?;
    let backend = backend.as_ref();
    let which: Vec<usize> = match a.shard {
        Some(s) => s.cells(cells.len()),
        None => (0..cells.len()).collect(),
    };
    // The journal: it also checks, before any work, that the output's folder is writable.
    let inputs = bake::inputs_hash(
        &scene,
        &cells,
        &settings,
        &format!("backend {}", backend.name()),
    );
    let journal_inputs = match a.shard {
        Some(s) => format!("{inputs}-shard-{}-of-{}", s.index, s.count),
        None => inputs.clone(),
    };
    let jpath = bake::journal_path(&a.output);
    let (journal, mut done) = if a.resume && jpath.exists() {
        bake::Journal::resume(&jpath, &journal_inputs)?
    } else {
        if a.resume && !a.quiet {
            eprintln!(
                "note        no journal at {}: baking every cell",
                jpath.display()
            );
        } else if jpath.exists() && !a.quiet {
            eprintln!(
                "warning     replacing {} (the journal of an interrupted bake; --resume \
                 continues it)",
                jpath.display()
            );
        }
        (
            bake::Journal::create(&jpath, &journal_inputs)
                .with_context(|| format!("cannot write next to {}", a.output.display()))?,
            std::collections::BTreeMap::new(),
        )
    };
    // The sampler's saves inside cells, checked against the same inputs as the journal.
    let checkpoints = match a.sampling_checkpoint {
        Checkpointing::Off => None,
        Checkpointing::Every(secs) => Some(bake::SamplerCheckpoints::new(
            &a.output,
            &journal_inputs,
            a.resume,
            secs,
        )),
    };
    done.retain(|k, _| which.binary_search(k).is_ok());
    let resumed = done.len();
    let todo: Vec<usize> = which
        .iter()
        .copied()
        .filter(|i| !done.contains_key(i))
        .collect();
    let bar = if a.quiet {
        indicatif::ProgressBar::hidden()
    } else {
        let b = indicatif::ProgressBar::new(which.len() as u64);
        b.set_style(
            indicatif::ProgressStyle::with_template(
                "{spinner} baking [{bar:40}] {pos}/{len} cells, {elapsed} elapsed, eta {eta}{msg}",
            )
            .expect("valid template")
            .progress_chars("=> "),
        );
        b.set_position(resumed as u64);
        b
    };
    // Where the bar draws nothing (stderr not a terminal), plain lines now and then.
    let plain = match a.progress.progress_every.0 {
        Some(every) if !a.quiet && !std::io::stderr().is_terminal() => Some(
            crate::cli_progress::PlainProgress::new(which.len(), resumed, every),
        ),
        _ => None,
    };
    // The sampler takes minutes per cell: the bar counts its sample points meanwhile.
    let sampler_progress = bake::SamplerProgress::default();
    let work = || crate::cli_progress::SamplerWork::now(&sampler_progress);
    let progress = |k: usize| {
        bar.set_position((resumed + k) as u64);
        if let Some(p) = &plain {
            p.cell_done(k, work());
        }
    };
    let dump = umbrasweep::inspect::DumpOptions {
        exr: a.dump_exr.clone(),
        png: a.dump_png.clone(),
        cells: a.dump_cells.clone(),
    };
    let dump_error = std::sync::Mutex::new(None::<String>);
    let observe = |ci: usize, k: usize, job: &_, map: &_, hdm: &_| {
        if dump.cells.as_ref().is_some_and(|c| !c.contains(&ci)) {
            return;
        }
        if let Err(e) = umbrasweep::inspect::dump_plane(&dump, ci, k, job, map, hdm) {
            dump_error.lock().expect("not poisoned").get_or_insert(e);
        }
    };
    let dumping = dump.exr.is_some() || dump.png.is_some();
    let journal = std::sync::Mutex::new(journal);
    let on_cell =
        |ci: usize, r: &bake::CellResult| journal.lock().expect("not poisoned").append(ci, r);
    let baking = std::sync::atomic::AtomicBool::new(true);
    let mut result = std::thread::scope(|s| {
        let ticker = (!a.quiet).then(|| {
            s.spawn(|| {
                use std::sync::atomic::Ordering::Relaxed;
                let mut pace = bake::RectPace::default();
                while baking.load(Relaxed) {
                    let w = work();
                    let left = pace.update(std::time::Instant::now(), w.points, w.rects);
                    if w.points > 0 {
                        bar.set_message(format!(
                            ", {} sample points ({})",
                            w.points,
                            crate::cli_progress::rectangles(w, left)
                        ));
                    }
                    if let Some(p) = &plain {
                        p.tick(w);
                    }
                    bar.tick();
                    std::thread::park_timeout(std::time::Duration::from_millis(500));
                }
            })
        });
        let r = bake::bake_cells(
            &scene,
            &cells,
            &todo,
            &settings,
            backend,
            bake::BakeHooks {
                progress: Some(&progress),
                observe: dumping.then_some(&observe as bake::PlaneObserver),
                on_cell: Some(&on_cell),
                sampler_progress: Some(&sampler_progress),
                sampler_checkpoints: checkpoints.as_ref(),
            },
        );
        baking.store(false, std::sync::atomic::Ordering::Relaxed);
        if let Some(t) = ticker {
            t.thread().unpark();
        }
        r
    })?;
    bar.finish_and_clear();
    if let Some(e) = dump_error.into_inner().expect("not poisoned") {
        bail!("dumping the planes: {e}");
    }
    if dump.exr.is_some() && result.rsf {
        // Ray space factorization's charts, traversed again for the cells dumped.
        let which: Vec<usize> = match &dump.cells {
            Some(c) => c.iter().copied().filter(|&i| i < cells.len()).collect(),
            None => todo.clone(),
        };
        if let Some(charts) = bake::rsf_charts(&scene, &cells, &which, &settings)? {
            for (ci, ch) in &charts {
                umbrasweep::inspect::dump_charts(&dump, *ci, &cells[*ci], ch)
                    .map_err(|e| anyhow::anyhow!("dumping the ray space charts: {e}"))?;
            }
        }
    }
    // The journal's cells back in their places.
    let mut fresh: std::collections::BTreeMap<usize, bake::CellResult> =
        todo.iter().copied().zip(result.cells.drain(..)).collect();
    result.cells = which
        .iter()
        .map(|i| {
            fresh
                .remove(i)
                .or_else(|| done.remove(i))
                .expect("every cell is baked or in the journal")
        })
        .collect();
    if a.reproducible {
        result.clear_timings();
    }
    let baked: Vec<Aabb> = which.iter().map(|&i| cells[i]).collect();
    let doc = bake::to_document(&scene, &baked, &result, &settings);
    match a.shard {
        Some(spec) => {
            let mut file = bake::ShardFile::new(spec, inputs, cells.len(), doc.clone(), &result);
            if binary {
                // The .pvs holds the cells and objects; the description the rest.
                file.document.cells.clear();
                file.document.objects.clear();
                let json = serde_json::to_string(&file).context("encoding the shard")?;
                umbrasweep::pvs::binary::write_shard(&a.output, &doc, &json)
                    .map_err(anyhow::Error::msg)
            } else {
                let json = serde_json::to_vec(&file).context("encoding the shard")?;
                umbrasweep::util::write_atomic(&a.output, &json).map_err(anyhow::Error::msg)
            }
        }
        None => write_document(&a.output, &doc, binary),
    }
    .with_context(|| "writing the PVS")?;
    let journal = journal.into_inner().expect("not poisoned");
    if let Err(e) = std::fs::remove_file(journal.path()) {
        eprintln!(
            "warning     could not remove the finished bake's journal {}: {e}",
            journal.path().display()
        );
    }
    if !a.quiet {
        let s = doc.summary.as_ref().expect("bake writes a summary");
        eprintln!(
            "scene       {} (loaded in {load_s:.2} s)",
            a.scene.display()
        );
        for w in &scene.warnings {
            eprintln!("warning     {w}");
        }
        eprintln!(
            "backend     {}{}{}",
            s.backend,
            s.adapter
                .as_ref()
                .map(|x| format!(" ({x})"))
                .unwrap_or_default(),
            if s.backend == "gpu" {
                let p = backend.as_gpu().map(|g| g.projection());
                format!(", {} projections", p.unwrap_or_default())
            } else {
                String::new()
            }
        );
        match a.shard {
            Some(spec) => eprintln!(
                "cells       {} (shard {spec}: {} of {} cells)",
                s.cells,
                which.len(),
                cells.len()
            ),
            None => eprintln!("cells       {}", s.cells),
        }
        if resumed > 0 {
            eprintln!(
                "resumed     {resumed} cells from {} ({} baked now)",
                jpath.display(),
                todo.len()
            );
        }
        let replayed = checkpoints
            .as_ref()
            .map_or(0, |c| c.replayed.load(std::sync::atomic::Ordering::Relaxed));
        if replayed > 0 {
            eprintln!(
                "resumed     {replayed} sampler rectangles from checkpoints ({}.sampler-*)",
                a.output.display()
            );
        }
        if result.sweep {
            let sw = &settings.sweep_settings;
            eprintln!(
                "sweep       yes, up to {} planes per direction, {} spacing{} — {}",
                sw.planes,
                match sw.spacing {
                    Spacing::Geometric => "geometric".to_string(),
                    Spacing::Kernel => format!("kernel (K = {})", sw.kernel),
                },
                settings
                    .subcell
                    .map(|x| format!(", sub-cells ≤ {x}"))
                    .unwrap_or_default(),
                result.sweep_reason
            );
        } else {
            eprintln!(
                "sweep       no{} — {}",
                settings
                    .subcell
                    .map(|x| format!(" (sub-cells ≤ {x})"))
                    .unwrap_or_default(),
                result.sweep_reason
            );
        }
        eprintln!(
            "rsf         {} — {}{}",
            if result.rsf { "yes" } else { "no" },
            result.rsf_reason,
            match (result.rsf, result.backend != "cpu", backend.rsf_on_device()) {
                (true, true, true) => " (on the GPU)",
                (true, true, false) => " (charts on the CPU; --rsf-on-gpu runs them on the device)",
                _ => "",
            }
        );
        eprintln!(
            "sampling    {} — {}{}",
            if result.sampling { "yes" } else { "no" },
            result.sampling_reason,
            result
                .sampling_device
                .as_ref()
                .map(|d| format!(" ({d})"))
                .unwrap_or_default()
        );
        for note in &result.notes {
            eprintln!("            {note}");
        }
        if let Some(line) = backend.stats_summary(s.cells) {
            eprintln!("gpu         {line}");
        }
        let planes: usize = result.cells.iter().map(|c| c.planes).sum();
        let occ: usize = result.cells.iter().map(|c| c.occluders_projected).sum();
        let n = result.cells.len().max(1);
        eprintln!(
            "planes      {:.1} per cell, {:.0} occluder Projections per cell",
            planes as f64 / n as f64,
            occ as f64 / n as f64
        );
        match &scene.split {
            Some(m) => eprintln!(
                "objects     {} clusters of {} objects (--split-objects {}: {} objects split)",
                s.objects,
                m.sources.len(),
                m.size,
                m.sources.iter().filter(|x| x.clusters.len() > 1).count()
            ),
            None => eprintln!("objects     {}", s.objects),
        }
        if let Some(limit) = settings.max_pvs_triangles {
            let leaves: Vec<&bake::CellResult> =
                result.cells.iter().flat_map(|c| c.leaves()).collect();
            let tri = |c: &bake::CellResult| -> u64 {
                c.visible
                    .iter()
                    .map(|&o| scene.objects[o as usize].triangles.len() as u64)
                    .sum()
            };
            let over = leaves.iter().filter(|c| tri(c) > limit).count();
            let mean =
                leaves.iter().map(|c| tri(c)).sum::<u64>() as f64 / leaves.len().max(1) as f64;
            eprintln!(
                "subdivided  {} cells into {} leaves ({} cells in the PVS); mean PVS {:.0} \
                 triangles per leaf against the budget {limit}; {over} leaves still over it \
                 (smallest size reached, or halving gained under 2 %)",
                result.cells.len(),
                leaves.len(),
                s.cells,
                mean
            );
        }
        eprintln!(
            "triangles   {} ({} occluders, {} degenerate skipped)",
            s.triangles, s.occluder_triangles, s.degenerate_triangles
        );
        if let Some(c) = &s.alpha_cards {
            eprintln!(
                "alpha cards {} card triangles gave {} surely opaque polygons covering {:.1} % of \
                 their area ({})",
                c.triangles,
                c.polygons,
                100.0 * c.opaque_share,
                if settings.alpha_mips == 0 {
                    "all mip levels trusted".to_string()
                } else {
                    format!("mip levels 0..{} trusted", settings.alpha_mips)
                }
            );
        }
        eprintln!(
            "culled      {:.1} % of objects, {:.1} % of triangles (mean over cells)",
            s.objects_culled_percent, s.triangles_culled_percent
        );
        for c in &s.cullers {
            let points = if c.points > 0.0 {
                format!(
                    ", {:.0} sample points per cell{}",
                    c.points,
                    c.finest_eps
                        .map(|e| format!(" (finest ε {e:.4})"))
                        .unwrap_or_default()
                )
            } else {
                String::new()
            };
            eprintln!(
                "culler      {}: hid {:.1} objects per cell ({:.1} only it), {:.1} ms per cell{points}",
                c.name, c.hidden, c.only, c.ms
            );
            if let Some(why) = &c.cpu_fallback {
                eprintln!("            some renders ran on the CPU's hemicube: {why}");
            }
            for (k, l) in c.levels.iter().enumerate() {
                let mut probe = l.probe_hidden.map_or(String::new(), |h| {
                    format!(
                        "; its probe hid {:.1} % of the objects it tested",
                        100.0 * h
                    )
                });
                if let Some(r) = l.probe_rects {
                    probe += &format!("; its probe sampled {r:.0} rectangles");
                }
                if let (Some(h), Some(t)) = (l.probe_cell_hidden, l.probe_objects) {
                    probe += &format!(
                        "; {h:.0} of the {t:.0} undecided objects it tested were hidden at every probed rectangle"
                    );
                }
                if let (Some(c), Some(v)) = (l.probe_cost, l.pilot_saving) {
                    probe += &format!(
                        "; its pilot: a rectangle draws {c:.0} polygons and saves the finest level {v:.0} (weighted)"
                    );
                }
                if l.probe_only > 0.0 {
                    probe += &format!(
                        "; in {:.0} % of the cells only its probe was sampled (--sampling-probe, --sampling-probe-cull, --sampling-probe-pay)",
                        100.0 * l.probe_only
                    );
                }
                eprintln!(
                    "  level {k}   ε ≤ {:.4}, {} px: {:.0} points, {:.1} s, {:.1} objects hidden (mean per cell, all levels so far){probe}",
                    l.eps, l.resolution, l.points, l.seconds, l.hidden
                );
            }
        }
        if a.reproducible {
            eprintln!(
                "time        {:.2} s in all (timings not recorded: --reproducible)",
                t.elapsed().as_secs_f64()
            );
        } else {
            eprintln!(
                "time        {:.1} ms per cell (median), {:.2} s in all",
                s.median_ms_per_cell, s.total_seconds
            );
        }
        eprintln!("wrote       {}", a.output.display());
    }
    Ok(())
}
