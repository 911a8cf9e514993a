//! Checking a PVS document against ray-sampled visible sets: input checks (scene/PVS match,
//! cells, ray count), the per-cell and total [`Report`] (the `--json` document) and its
//! human-readable table.

use super::sample::{CellSample, Witness, sample_cell_progress};
use super::trace::SceneRays;
use crate::geom::Aabb;
use crate::pvs::PvsDocument;
use crate::scene::Scene;
use glam::Vec3;
use serde::{Deserialize, Serialize};
use std::fmt::Write as _;

/// Bad input to [`check`]: the CLI reports these with exit code 2.
#[derive(Debug, thiserror::Error)]
pub enum ValidateError {
    /// `--rays 0`.
    #[error("--rays must be at least 1")]
    NoRays,
    /// The scene breaks the importer's invariants.
    #[error(transparent)]
    Scene(#[from] crate::scene::SceneError),
    /// Object count, ids or names of the PVS differ from the scene's.
    #[error("the PVS was baked from another scene: {0}")]
    SceneMismatch(String),
    /// A cell of the PVS is not a valid box.
    #[error("PVS cell {index} is not a valid box (min {min:?}, max {max:?})")]
    BadCell {
        /// Position of the cell in the PVS.
        index: usize,
        min: [f32; 3],
        max: [f32; 3],
    },
}

/// Options of [`check`].
#[derive(Clone, Debug)]
pub struct CheckOptions {
    /// Rays per cell (at least 1).
    pub rays: u64,
    /// Seed of all random streams.
    pub seed: u64,
    /// Show a progress bar on stderr (drawn only when stderr is a terminal).
    pub progress: bool,
}

impl Default for CheckOptions {
    fn default() -> Self {
        CheckOptions {
            rays: 1_000_000,
            seed: 0,
            progress: false,
        }
    }
}

/// An object hit first by some ray but missing from the PVS.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
pub struct FalseCull {
    /// Object id.
    pub object: u32,
    /// Object name.
    pub name: String,
    /// Origin of the witness ray (inside the cell); `None` when the object is visible only
    /// because its bounds overlap the cell.
    pub origin: Option<Vec3>,
    /// Unit direction of the witness ray.
    pub direction: Option<Vec3>,
    /// Where the witness ray meets the object.
    pub hit: Option<Vec3>,
    /// The scene triangle the witness ray hits.
    pub triangle: Option<u32>,
    /// Global index of the witness ray in the cell's budget.
    pub ray: Option<u64>,
    /// `"ray"` (a ray sees it) or `"overlap"` (its bounds overlap the cell).
    pub reason: String,
}

/// The check of one cell.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
pub struct CellReport {
    /// Cell corner (as in the PVS).
    pub min: [f32; 3],
    /// Cell corner (as in the PVS).
    pub max: [f32; 3],
    /// The sampled visible set (VS), ascending.
    pub visible: Vec<u32>,
    /// VS objects absent from the PVS, ascending by object.
    pub false_culls: Vec<FalseCull>,
    /// |PVS|.
    pub pvs: usize,
    /// |VS|.
    pub vs: usize,
    /// |PVS| / |VS| (`None` when the VS is empty).
    pub pvs_over_vs: Option<f64>,
    /// Percentage of the scene's objects the PVS culls.
    pub objects_culled_percent: f64,
    /// Percentage of the scene's triangles the PVS culls.
    pub triangles_culled_percent: f64,
    /// VS objects first found in the last 10 % of the rays.
    pub late_found: u32,
    /// Rays cast (fewer than asked when every object was found early).
    pub rays: u64,
}

/// The check of a whole PVS document: the `--json` output of `umbrasweep validate`.
///
/// Everything in it is deterministic for a given scene, PVS, ray count and seed (no timings),
/// so two runs can be compared byte for byte.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
pub struct Report {
    /// One entry per PVS cell, in PVS order.
    pub cells: Vec<CellReport>,
    /// Total number of false culls over all cells.
    pub false_culls: usize,
    /// Cells with at least one false cull.
    pub cells_with_false_culls: usize,
    /// Rays asked for per cell (`--rays`).
    pub rays_per_cell: u64,
    /// Seed of the random rays (`--seed`).
    pub seed: u64,
    /// Whether see-through triangles blocked rays (the PVS setting `alpha_occluders`).
    pub alpha_occluders: bool,
    /// Objects in the scene.
    pub objects: usize,
    /// Triangles in the scene (degenerate ones included).
    pub triangles: usize,
    /// Sum of |PVS| over sum of |VS| (`None` when no cell sees anything).
    pub pvs_over_vs: Option<f64>,
    /// Mean over cells of [`CellReport::objects_culled_percent`].
    pub objects_culled_percent: f64,
    /// Mean over cells of [`CellReport::triangles_culled_percent`].
    pub triangles_culled_percent: f64,
    /// Sum of [`CellReport::late_found`].
    pub late_found: u64,
    /// Rays cast over all cells.
    pub rays_cast: u64,
    /// Wall-clock seconds spent tracing (not serialised, so reports stay comparable).
    #[serde(skip)]
    pub seconds: f64,
}

impl Report {
    /// Rays traced per second of wall-clock time.
    pub fn rays_per_second(&self) -> f64 {
        if self.seconds > 0.0 {
            self.rays_cast as f64 / self.seconds
        } else {
            0.0
        }
    }

    /// The human-readable table: one line per cell, a total line, then every false cull with
    /// the ray that proves it, and a one-line verdict.
    pub fn table(&self) -> String {
        let mut s = String::new();
        let _ = writeln!(
            s,
            "{:>6} {:>7} {:>7} {:>7} {:>10} {:>10} {:>5} {:>11}",
            "cell", "|PVS|", "|VS|", "PVS/VS", "obj cull%", "tri cull%", "late", "false culls"
        );
        let ratio = |r: Option<f64>| r.map_or_else(|| "-".to_string(), |r| format!("{r:.2}"));
        for (i, c) in self.cells.iter().enumerate() {
            let _ = writeln!(
                s,
                "{:>6} {:>7} {:>7} {:>7} {:>10.1} {:>10.1} {:>5} {:>11}",
                i,
                c.pvs,
                c.vs,
                ratio(c.pvs_over_vs),
                c.objects_culled_percent,
                c.triangles_culled_percent,
                c.late_found,
                c.false_culls.len()
            );
        }
        // Totals: sums of |PVS| and |VS| (and their ratio), mean culled percentages (the same
        // as the percentages of all cells' objects and triangles), sums of the counts.
        let _ = writeln!(
            s,
            "{:>6} {:>7} {:>7} {:>7} {:>10.1} {:>10.1} {:>5} {:>11}",
            "total",
            self.cells.iter().map(|c| c.pvs).sum::<usize>(),
            self.cells.iter().map(|c| c.vs).sum::<usize>(),
            ratio(self.pvs_over_vs),
            self.objects_culled_percent,
            self.triangles_culled_percent,
            self.late_found,
            self.false_culls
        );
        let v = |p: Option<Vec3>| {
            p.map_or_else(
                || "-".to_string(),
                |p| format!("({}, {}, {})", p.x, p.y, p.z),
            )
        };
        for (i, c) in self.cells.iter().enumerate() {
            for f in &c.false_culls {
                let _ = writeln!(
                    s,
                    "FALSE CULL cell {i}: object {} {:?} is visible but not in the PVS",
                    f.object, f.name
                );
                if f.origin.is_some() {
                    let _ = writeln!(
                        s,
                        "    ray {} from {} direction {} hits {} (triangle {})",
                        f.ray.unwrap_or(0),
                        v(f.origin),
                        v(f.direction),
                        v(f.hit),
                        f.triangle.unwrap_or(0)
                    );
                } else {
                    let _ = writeln!(s, "    its bounds overlap the cell (visible by definition)");
                }
            }
        }
        if self.false_culls == 0 {
            let _ = writeln!(
                s,
                "no false cull in {} cells ({} rays per cell, seed {})",
                self.cells.len(),
                self.rays_per_cell,
                self.seed
            );
        } else {
            let _ = writeln!(
                s,
                "{} false culls in {} of {} cells: the PVS is NOT conservative",
                self.false_culls,
                self.cells_with_false_culls,
                self.cells.len()
            );
        }
        if self.late_found > 0 {
            let _ = writeln!(
                s,
                "note: {} visible objects were first found in the last 10 % of the rays; \
                 more rays (--rays) may find more",
                self.late_found
            );
        }
        s
    }
}

/// Checks that `doc` was baked from `scene` (same object count, ids and names), that its
/// cells are valid boxes and that `rays` is not 0.
///
/// # Errors
/// [`ValidateError::NoRays`], [`ValidateError::Scene`] (broken scene invariants),
/// [`ValidateError::SceneMismatch`] or [`ValidateError::BadCell`].
pub fn check_input(scene: &Scene, doc: &PvsDocument, rays: u64) -> Result<(), ValidateError> {
    if rays == 0 {
        return Err(ValidateError::NoRays);
    }
    scene.validate()?;
    if doc.objects.len() != scene.objects.len() {
        return Err(ValidateError::SceneMismatch(format!(
            "it has {} objects, the scene has {}",
            doc.objects.len(),
            scene.objects.len()
        )));
    }
    for (i, (p, o)) in doc.objects.iter().zip(&scene.objects).enumerate() {
        if p.id as usize != i {
            return Err(ValidateError::SceneMismatch(format!(
                "its object {i} has id {}",
                p.id
            )));
        }
        if p.name != o.name {
            return Err(ValidateError::SceneMismatch(format!(
                "its object {i} is named {:?}, the scene's is {:?}",
                p.name, o.name
            )));
        }
    }
    let n = scene.objects.len() as u32;
    for (index, c) in doc.cells.iter().enumerate() {
        let ok = c.min.iter().chain(&c.max).all(|v| v.is_finite())
            && (0..3).all(|k| c.min[k] <= c.max[k]);
        if !ok {
            return Err(ValidateError::BadCell {
                index,
                min: c.min,
                max: c.max,
            });
        }
        if let Some(bad) = c.visible.iter().find(|&&id| id >= n) {
            return Err(ValidateError::SceneMismatch(format!(
                "cell {index} lists object {bad}, the scene has {n} objects"
            )));
        }
    }
    Ok(())
}

/// Samples the visible set of every cell of `doc` and compares it with the cell's PVS.
/// Builds the BVH of `scene` first; use [`check_with`] to reuse one.
///
/// Runs on the current rayon pool; the report (apart from `seconds`) does not depend on its
/// size.
///
/// # Errors
/// Bad input, see [`check_input`].
pub fn check(
    scene: &Scene,
    doc: &PvsDocument,
    opts: &CheckOptions,
) -> Result<Report, ValidateError> {
    check_input(scene, doc, opts.rays)?;
    let rays = SceneRays::new(scene);
    check_with(&rays, scene, doc, opts)
}

/// [`check`] with a [`SceneRays`] already built from `scene`.
///
/// # Errors
/// Bad input, see [`check_input`].
pub fn check_with(
    index: &SceneRays,
    scene: &Scene,
    doc: &PvsDocument,
    opts: &CheckOptions,
) -> Result<Report, ValidateError> {
    check_input(scene, doc, opts.rays)?;
    let alpha = doc.settings.alpha_occluders;
    let progress = opts.progress.then(|| {
        let total = opts.rays.saturating_mul(doc.cells.len() as u64);
        let pb = indicatif::ProgressBar::new(total);
        if let Ok(style) = indicatif::ProgressStyle::with_template(
            "validate {bar:40} {percent:>3}% {human_pos}/{human_len} rays, {per_sec}, eta {eta}",
        ) {
            pb.set_style(style);
        }
        pb
    });
    let start = std::time::Instant::now();
    let mut cells = Vec::with_capacity(doc.cells.len());
    for (i, c) in doc.cells.iter().enumerate() {
        let cell = Aabb::new(Vec3::from(c.min), Vec3::from(c.max));
        let sample = sample_cell_progress(
            index,
            scene,
            cell,
            opts.rays,
            opts.seed,
            i as u64,
            alpha,
            progress.as_ref(),
        );
        cells.push(cell_report(scene, c, &sample));
    }
    let seconds = start.elapsed().as_secs_f64();
    if let Some(pb) = &progress {
        pb.finish_and_clear();
    }
    Ok(summarize(scene, opts, alpha, cells, seconds))
}

/// Compares one cell's PVS with its sample.
pub fn cell_report(scene: &Scene, cell: &crate::pvs::PvsCell, sample: &CellSample) -> CellReport {
    let n = scene.objects.len();
    let mut in_pvs = vec![false; n];
    for &o in &cell.visible {
        if let Some(x) = in_pvs.get_mut(o as usize) {
            *x = true;
        }
    }
    let pvs = in_pvs.iter().filter(|&&b| b).count();
    let total_tris = scene.triangles.len();
    let culled_tris: usize = scene
        .objects
        .iter()
        .zip(&in_pvs)
        .filter(|(_, in_pvs)| !**in_pvs)
        .map(|(o, _)| o.triangles.len())
        .sum();
    let false_culls = sample
        .visible
        .iter()
        .zip(&sample.witness)
        .filter(|(o, _)| !in_pvs[**o as usize])
        .map(|(&o, w)| false_cull(scene, o, w.as_ref()))
        .collect();
    let vs = sample.visible.len();
    CellReport {
        min: cell.min,
        max: cell.max,
        visible: sample.visible.clone(),
        false_culls,
        pvs,
        vs,
        pvs_over_vs: (vs > 0).then(|| pvs as f64 / vs as f64),
        objects_culled_percent: percent(n - pvs, n),
        triangles_culled_percent: percent(culled_tris, total_tris),
        late_found: sample.late_found,
        rays: sample.rays_cast,
    }
}

fn false_cull(scene: &Scene, object: u32, w: Option<&Witness>) -> FalseCull {
    FalseCull {
        object,
        name: scene.objects[object as usize].name.clone(),
        origin: w.map(|w| w.origin),
        direction: w.map(|w| w.direction),
        hit: w.map(|w| w.hit),
        triangle: w.map(|w| w.triangle),
        ray: w.map(|w| w.ray),
        reason: if w.is_some() { "ray" } else { "overlap" }.to_string(),
    }
}

fn percent(part: usize, whole: usize) -> f64 {
    if whole == 0 {
        0.0
    } else {
        100.0 * part as f64 / whole as f64
    }
}

fn summarize(
    scene: &Scene,
    opts: &CheckOptions,
    alpha: bool,
    cells: Vec<CellReport>,
    seconds: f64,
) -> Report {
    let n = cells.len();
    let mean = |f: &dyn Fn(&CellReport) -> f64| {
        if n == 0 {
            0.0
        } else {
            cells.iter().map(f).sum::<f64>() / n as f64
        }
    };
    let sum_pvs: usize = cells.iter().map(|c| c.pvs).sum();
    let sum_vs: usize = cells.iter().map(|c| c.vs).sum();
    Report {
        false_culls: cells.iter().map(|c| c.false_culls.len()).sum(),
        cells_with_false_culls: cells.iter().filter(|c| !c.false_culls.is_empty()).count(),
        rays_per_cell: opts.rays,
        seed: opts.seed,
        alpha_occluders: alpha,
        objects: scene.objects.len(),
        triangles: scene.triangles.len(),
        pvs_over_vs: (sum_vs > 0).then(|| sum_pvs as f64 / sum_vs as f64),
        objects_culled_percent: mean(&|c| c.objects_culled_percent),
        triangles_culled_percent: mean(&|c| c.triangles_culled_percent),
        late_found: cells.iter().map(|c| u64::from(c.late_found)).sum(),
        rays_cast: cells.iter().map(|c| c.rays).sum(),
        seconds,
        cells,
    }
}
