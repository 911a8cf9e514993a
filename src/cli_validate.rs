//! `umbrasweep validate`: argument parsing, reading the scene and the PVS, the progress bar,
//! the table on stdout, the `--json` report and the exit code (0: no false cull, 1: false
//! culls, 2: bad input). The check itself is [`umbrasweep::validate`].

use anyhow::Context as _;
use std::io::IsTerminal as _;
use std::path::PathBuf;
use std::sync::{Arc, OnceLock};
use umbrasweep::validate::{
    CheckOptions, Progress, ProgressFn, SceneRays, ValidateError, check_input, check_with,
};

/// Options of `umbrasweep validate`.
#[derive(clap::Args, Debug, Clone)]
#[command(after_help = "Examples:
  umbrasweep validate data/demo_city.obj demo.json
  umbrasweep validate forest.obj forest_pvs.json --rays 200000 --seed 3 --json report.json
  umbrasweep validate forest.obj forest_pvs.json --hunt --rays 1000000 --json hunt.json
  umbrasweep validate forest.obj forest_pvs.json --confirm-rays 20000000

--hunt spends each cell's whole budget on the objects its PVS culls, rays / culled count
rays each (at least 1), aimed from inside, the faces, edges and corners of the cell at their
surfaces, bounds, edges and vertices. The visible set is then not measured (the |VS|, PVS/VS
and late columns give way to the culled objects hunted and the rays per object). Run without
--hunt to measure PVS/VS, with --hunt to look hard for false culls.

--confirm-rays N follows the sampling with up to N more rays per cell, aimed the hunt's way at
the PVS objects the sample did not see, in 4 rounds that each split their share between the
objects still unconfirmed. Those reached are visible too (and a culled object such a ray
meets on its way is a false cull): |VS+| and PVS/VS+ measure the PVS
against that fuller visible set (objects seen only through slits escape a uniform sample, so
PVS/VS over-states how loose a tight PVS is).")]
pub struct ValidateArgs {
    /// The scene the PVS was baked from (.obj, .gltf, .glb).
    pub scene: PathBuf,
    /// The PVS written by `umbrasweep bake -o` (.json or .pvs).
    pub pvs: PathBuf,
    /// Rays cast per cell (with --hunt: split evenly between the cell's culled objects).
    #[arg(long, default_value_t = 1_000_000)]
    pub rays: u64,
    /// Seed of the random rays (the same seed gives the same result on any thread count).
    #[arg(long, default_value_t = 0)]
    pub seed: u64,
    /// Also write the report as JSON to this file.
    #[arg(long, value_name = "OUT.json")]
    pub json: Option<PathBuf>,
    /// Spend the whole ray budget of each cell on the objects its PVS culls (split evenly
    /// between them) instead of sampling the visible set, which is then not measured.
    #[arg(long)]
    pub hunt: bool,
    /// After the sampling, up to this many more rays per cell aimed at the PVS objects it did
    /// not see; those reached count as visible in |VS+| and PVS/VS+ (0: none).
    #[arg(long, value_name = "N", default_value_t = 0, conflicts_with = "hunt")]
    pub confirm_rays: u64,
    #[command(flatten)]
    pub progress: crate::cli_progress::ProgressArgs,
}

/// Runs `umbrasweep validate`: prints the table on stdout, writes `--json` if asked, and
/// returns the exit code: 0 when no false cull was found, 1 otherwise.
///
/// # Errors
/// Bad input (exit code 2 in `main`): `--rays 0`, an unreadable or malformed scene or PVS, a
/// PVS baked from another scene, an invalid cell; or a `--json` file that cannot be written.
pub fn run(args: &ValidateArgs) -> anyhow::Result<i32> {
    if args.rays == 0 {
        anyhow::bail!(ValidateError::NoRays);
    }
    // The PVS first: reading it is cheap, loading a big scene is not.
    let doc = umbrasweep::pvs::json::read_any(&args.pvs).map_err(anyhow::Error::msg)?;
    let scene = umbrasweep::scene::load_with(
        &args.scene,
        &umbrasweep::scene::LoadOptions {
            alpha_missing: doc.settings.bake.alpha_missing,
        },
    )?;
    let scene = umbrasweep::scene::split::as_baked(scene, doc.split.as_ref())
        .with_context(|| format!("{} against {}", args.pvs.display(), args.scene.display()))?;
    check_input(&scene, &doc, args.rays).with_context(|| {
        format!(
            "{} does not fit {}",
            args.pvs.display(),
            args.scene.display()
        )
    })?;
    let opts = CheckOptions {
        rays: args.rays,
        seed: args.seed,
        progress: if std::io::stderr().is_terminal() {
            Some(progress_bar())
        } else {
            args.progress
                .progress_every
                .0
                .map(crate::cli_progress::plain_rays)
        },
        hunt: args.hunt,
        confirm_rays: args.confirm_rays,
    };
    // The rays it may cast, for the ray caster's build (a slow build pays only for many).
    let confirm = if args.hunt { 0 } else { args.confirm_rays };
    let planned = (doc.cells.len() as u64).saturating_mul(args.rays.saturating_add(confirm));
    let index = SceneRays::for_rays(&scene, planned);
    let report = check_with(&index, &scene, &doc, &opts)?;
    let text = format!(
        "{}{} rays in {:.2} s ({:.2} M rays/s, {} threads)\n",
        report.table(),
        report.rays_cast,
        report.seconds,
        report.rays_per_second() / 1e6,
        rayon::current_num_threads()
    );
    // A closed stdout (`| head`) must not hide the verdict: the exit code and --json still
    // count.
    let _ = std::io::Write::write_all(&mut std::io::stdout().lock(), text.as_bytes());
    if let Some(path) = &args.json {
        let bytes = serde_json::to_vec_pretty(&report)?;
        write_report(path, &bytes)?;
    }
    Ok(if report.false_culls > 0 { 1 } else { 0 })
}

/// Writes the `--json` report: atomically (temporary file, then rename) for a regular file,
/// directly for an existing special file such as `/dev/stdout` or a pipe, which a rename
/// would replace.
fn write_report(path: &std::path::Path, bytes: &[u8]) -> anyhow::Result<()> {
    match std::fs::metadata(path) {
        Ok(m) if !m.is_file() && !m.is_dir() => {
            std::fs::write(path, bytes).with_context(|| format!("{}: cannot write", path.display()))
        }
        _ => umbrasweep::util::write_atomic(path, bytes).map_err(anyhow::Error::msg),
    }
}

/// The progress callback that draws the `validate` bar on stderr: the bar is made when the
/// rays start (so its clock starts then) and cleared when they are done.
fn progress_bar() -> ProgressFn {
    let bar = OnceLock::<indicatif::ProgressBar>::new();
    Arc::new(move |p: Progress| match p {
        Progress::Start { total } => {
            let pb = indicatif::ProgressBar::new(total);
            if let Ok(style) = indicatif::ProgressStyle::with_template(
                "validate {bar:40} {percent:>3}% {human_pos}/{human_len} rays, {per_sec}, eta {eta}",
            ) {
                pb.set_style(style);
            }
            let _ = bar.set(pb);
        }
        Progress::Advance(n) => {
            if let Some(pb) = bar.get() {
                pb.inc(n);
            }
        }
        Progress::Finish => {
            if let Some(pb) = bar.get() {
                pb.finish_and_clear();
            }
        }
    })
}
