//! Checking a PVS document against ray-sampled visible sets: input checks (scene/PVS match,
//! cells, ray count), the per-cell and total [`Report`] (the `--json` document) and its
//! human-readable table. With [`CheckOptions::hunt`] the rays go to the culled objects instead
//! (`super::hunt`); with [`CheckOptions::confirm_rays`] more rays go to the PVS objects the
//! sample did not see (`super::confirm`).

use super::confirm::{ConfirmCell, confirm_cells};
use super::hunt::{HuntCell, HuntResult, hunt_cells};
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
        /// Lower corner of the cell as stored.
        min: [f32; 3],
        /// Upper corner of the cell as stored.
        max: [f32; 3],
    },
}

/// What [`check_with`] tells a [`CheckOptions::progress`] callback.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum Progress {
    /// The rays start: `total` rays will be reported through [`Progress::Advance`] in all.
    Start {
        /// Rays the whole check casts (or skips).
        total: u64,
    },
    /// `n` more rays were cast (or skipped when a cell's sampling stopped early).
    Advance(u64),
    /// The rays are done (sent once, after the last [`Progress::Advance`]).
    Finish,
}

/// A progress callback of [`CheckOptions::progress`]; it is called from the rayon worker
/// threads, so it must be cheap and thread-safe (a progress bar, a counter).
pub type ProgressFn = std::sync::Arc<dyn Fn(Progress) + Send + Sync>;

/// Options of [`check`]. Build them with `..Default::default()` for the fields you leave
/// alone: fields may be added.
#[derive(Clone)]
pub struct CheckOptions {
    /// Rays per cell (at least 1).
    pub rays: u64,
    /// Seed of all random streams.
    pub seed: u64,
    /// Called with the rays' [`Progress`] (start, advances, finish); `None` (the default)
    /// reports nothing. The library draws nothing itself.
    pub progress: Option<ProgressFn>,
    /// `--hunt`: spend each cell's whole budget on the objects its PVS culls (objects with
    /// area not in its list), split evenly between them
    /// ([`rays_per_culled_object`](super::rays_per_culled_object)), instead of sampling the
    /// visible set. The visible set is then not measured: [`Report::hunt`] is true and the
    /// VS fields of the report are empty (see [`CellReport::visible`]). Default `false`.
    pub hunt: bool,
    /// `--confirm-rays`: after the sampling, up to this many more rays per cell aimed at the
    /// objects of the cell's PVS that the sample did not see (`super::confirm`), so that
    /// [`CellReport::pvs_over_confirmed_vs`] measures the PVS against a fuller visible set.
    /// 0 (the default) confirms nothing; ignored with [`Self::hunt`].
    pub confirm_rays: u64,
}

impl Default for CheckOptions {
    fn default() -> Self {
        CheckOptions {
            rays: 1_000_000,
            seed: 0,
            progress: None,
            hunt: false,
            confirm_rays: 0,
        }
    }
}

impl std::fmt::Debug for CheckOptions {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.debug_struct("CheckOptions")
            .field("rays", &self.rays)
            .field("seed", &self.seed)
            .field("progress", &self.progress.as_ref().map(|_| "Fn(Progress)"))
            .field("hunt", &self.hunt)
            .field("confirm_rays", &self.confirm_rays)
            .finish()
    }
}

/// Sends [`Progress::Start`] to the callback of `opts`, if any, and returns the callback.
fn start_progress(opts: &CheckOptions, total: u64) -> Option<&ProgressFn> {
    let p = opts.progress.as_ref()?;
    p(Progress::Start { total });
    Some(p)
}

/// Sends [`Progress::Finish`] to `progress`, if any.
fn finish_progress(progress: Option<&ProgressFn>) {
    if let Some(p) = progress {
        p(Progress::Finish);
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
    /// Global index of the witness ray in the cell's budget. With `--hunt`, culled object
    /// number `k` of the cell (ascending by id) owns rays `[k·m, (k+1)·m)`, `m` being
    /// [`CellReport::rays_per_culled_object`]; the witness may be a ray aimed at another
    /// culled object that met this one first. With `--confirm-rays`, a confirming ray met
    /// it: the index is within its round's budget, object in doubt number `k` owning rays
    /// `[k·m, (k+1)·m)` of that round.
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
    /// The sampled visible set (VS), ascending. Not measured with `--hunt`: empty, and `vs`
    /// 0, `pvs_over_vs` `None`, `late_found` 0.
    pub visible: Vec<u32>,
    /// VS objects absent from the PVS, ascending by object. With `--hunt`: the culled
    /// objects a hunting ray saw, and culled objects whose bounds overlap the cell.
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
    /// Rays cast (fewer than asked when every object was found early; with `--hunt`, the
    /// culled objects' budgets less the rays not cast once an object was seen).
    pub rays: u64,
    /// `--hunt` only (absent otherwise): the culled objects with area that were hunted.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub hunted: Option<usize>,
    /// `--hunt` only (absent otherwise): rays cast at each hunted object, `rays / hunted`
    /// and at least 1 (0 when the cell culls nothing).
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub rays_per_culled_object: Option<u64>,
    /// `--confirm-rays` only (absent otherwise): the objects of the PVS outside the sampled
    /// VS that a confirming ray saw, ascending. They are visible: the VS plus these is a
    /// fuller visible set.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub confirmed: Option<Vec<u32>>,
    /// `--confirm-rays` only: |PVS| / (|VS| + confirmed) (`None` when both are empty).
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub pvs_over_confirmed_vs: Option<f64>,
}

/// The check of a whole PVS document: the `--json` output of `umbrasweep validate`.
///
/// Everything in it is deterministic for a given scene, PVS, ray count, seed and mode (no
/// timings), so two runs can be compared byte for byte. The `--hunt` fields (`hunt`,
/// `hunted_objects`, `rays_per_culled_object`, and per cell `hunted` and
/// `rays_per_culled_object`) are written only in hunt mode, so a plain report is unchanged;
/// reading a report without them gives `false` and `None`.
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
    /// Whether the rays hunted the culled objects (`--hunt`) instead of sampling the visible
    /// set; then the VS fields (`pvs_over_vs`, `late_found`, and per cell `visible`, `vs`,
    /// `pvs_over_vs`, `late_found`) are not measured. Written only when `true`.
    #[serde(default, skip_serializing_if = "std::ops::Not::not")]
    pub hunt: bool,
    /// `--hunt` only: (cell, culled object) pairs hunted, over all cells.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub hunted_objects: Option<u64>,
    /// `--hunt` only: the fewest rays any culled object of any cell got (the minimum of
    /// [`CellReport::rays_per_culled_object`] over the cells that cull something; 0 when none
    /// does).
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub rays_per_culled_object: Option<u64>,
    /// `--confirm-rays` only: the confirmation budget per cell.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub confirm_rays: Option<u64>,
    /// `--confirm-rays` only: objects confirmed visible over all cells (the sum of the cells'
    /// [`CellReport::confirmed`]).
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub confirmed_objects: Option<u64>,
    /// `--confirm-rays` only: sum of |PVS| over sum of |VS| + confirmed.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub pvs_over_confirmed_vs: Option<f64>,
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
    /// the ray that proves it, and a one-line verdict. In hunt mode the VS columns give way
    /// to the number of culled objects hunted and the rays cast at each.
    pub fn table(&self) -> String {
        let mut s = if self.hunt {
            self.hunt_rows()
        } else {
            self.rows()
        };
        self.false_cull_lines(&mut s);
        if self.false_culls == 0 {
            if self.hunt {
                let _ = writeln!(
                    s,
                    "no false cull in {} cells (hunt: {} culled objects, at least {} rays \
                     each, seed {})",
                    self.cells.len(),
                    self.hunted_objects.unwrap_or(0),
                    self.rays_per_culled_object.unwrap_or(0),
                    self.seed
                );
            } else {
                let _ = writeln!(
                    s,
                    "no false cull in {} cells ({} rays per cell, seed {})",
                    self.cells.len(),
                    self.rays_per_cell,
                    self.seed
                );
            }
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

    /// The per-cell and total lines of a hunt: |PVS|, culled objects hunted, rays per
    /// culled object, culled percentages, false culls.
    fn hunt_rows(&self) -> String {
        let mut s = String::new();
        let _ = writeln!(
            s,
            "{:>6} {:>7} {:>7} {:>9} {:>10} {:>10} {:>11}",
            "cell", "|PVS|", "hunted", "rays/obj", "obj cull%", "tri cull%", "false culls"
        );
        for (i, c) in self.cells.iter().enumerate() {
            let _ = writeln!(
                s,
                "{:>6} {:>7} {:>7} {:>9} {:>10.1} {:>10.1} {:>11}",
                i,
                c.pvs,
                c.hunted.unwrap_or(0),
                c.rays_per_culled_object.unwrap_or(0),
                c.objects_culled_percent,
                c.triangles_culled_percent,
                c.false_culls.len()
            );
        }
        let _ = writeln!(
            s,
            "{:>6} {:>7} {:>7} {:>9} {:>10.1} {:>10.1} {:>11}",
            "total",
            self.cells.iter().map(|c| c.pvs).sum::<usize>(),
            self.hunted_objects.unwrap_or(0),
            self.rays_per_culled_object
                .map_or_else(|| "-".to_string(), |r| format!(">={r}")),
            self.objects_culled_percent,
            self.triangles_culled_percent,
            self.false_culls
        );
        s
    }

    /// The per-cell and total lines of the plain sampling; with `--confirm-rays`, two more
    /// columns: the VS with the confirmed objects (`|VS+|`) and the PVS over it.
    fn rows(&self) -> String {
        let mut s = String::new();
        let confirm = self.confirm_rays.is_some();
        let ratio = |r: Option<f64>| r.map_or_else(|| "-".to_string(), |r| format!("{r:.2}"));
        let row = |s: &mut String, cols: [String; 8], plus: Option<[String; 2]>| {
            let _ = write!(
                s,
                "{:>6} {:>7} {:>7} {:>7} {:>10} {:>10} {:>5} {:>11}",
                cols[0], cols[1], cols[2], cols[3], cols[4], cols[5], cols[6], cols[7]
            );
            if let Some([a, b]) = plus {
                let _ = write!(s, " {a:>7} {b:>8}");
            }
            s.push('\n');
        };
        let head = |a: &str| a.to_string();
        row(
            &mut s,
            [
                "cell",
                "|PVS|",
                "|VS|",
                "PVS/VS",
                "obj cull%",
                "tri cull%",
                "late",
                "false culls",
            ]
            .map(head),
            confirm.then(|| ["|VS+|", "PVS/VS+"].map(head)),
        );
        for (i, c) in self.cells.iter().enumerate() {
            let plus = c
                .confirmed
                .as_ref()
                .map(|f| [(c.vs + f.len()).to_string(), ratio(c.pvs_over_confirmed_vs)]);
            row(
                &mut s,
                [
                    i.to_string(),
                    c.pvs.to_string(),
                    c.vs.to_string(),
                    ratio(c.pvs_over_vs),
                    format!("{:.1}", c.objects_culled_percent),
                    format!("{:.1}", c.triangles_culled_percent),
                    c.late_found.to_string(),
                    c.false_culls.len().to_string(),
                ],
                plus,
            );
        }
        // Totals: sums of |PVS| and |VS| (and their ratio), mean culled percentages (the same
        // as the percentages of all cells' objects and triangles), sums of the counts.
        let sum_vs: usize = self.cells.iter().map(|c| c.vs).sum();
        row(
            &mut s,
            [
                "total".to_string(),
                self.cells.iter().map(|c| c.pvs).sum::<usize>().to_string(),
                sum_vs.to_string(),
                ratio(self.pvs_over_vs),
                format!("{:.1}", self.objects_culled_percent),
                format!("{:.1}", self.triangles_culled_percent),
                self.late_found.to_string(),
                self.false_culls.to_string(),
            ],
            self.confirmed_objects.map(|n| {
                [
                    (sum_vs as u64 + n).to_string(),
                    ratio(self.pvs_over_confirmed_vs),
                ]
            }),
        );
        if let (Some(rays), Some(n)) = (self.confirm_rays, self.confirmed_objects) {
            let _ = writeln!(
                s,
                "confirmation: up to {rays} more rays per cell at the PVS objects the sample did \
                 not see found {n} of them visible (|VS+|, PVS/VS+)"
            );
        }
        s
    }

    /// Every false cull with the ray that proves it.
    fn false_cull_lines(&self, s: &mut String) {
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

/// [`check`] with a [`SceneRays`] already built from `scene`. With [`CheckOptions::hunt`],
/// hunts the culled objects of every cell instead of sampling the visible sets.
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
    let alpha = doc.settings.bake.alpha_occluders;
    if opts.hunt {
        return Ok(hunt_with(index, scene, doc, opts));
    }
    let per_cell = opts.rays.saturating_add(opts.confirm_rays);
    let progress = start_progress(opts, per_cell.saturating_mul(doc.cells.len() as u64));
    let start = std::time::Instant::now();
    let mut cells = Vec::with_capacity(doc.cells.len());
    for (i, c) in doc.cells.iter().enumerate() {
        let cell = cell_box(c);
        let sample = sample_cell_progress(
            index, scene, cell, opts.rays, opts.seed, i as u64, alpha, progress,
        );
        cells.push(cell_report(scene, c, &sample));
    }
    let confirm_cast =
        (opts.confirm_rays > 0).then(|| confirm(index, scene, doc, opts, &mut cells, progress));
    let seconds = start.elapsed().as_secs_f64();
    finish_progress(progress);
    let mut report = summarize(scene, opts, alpha, cells, seconds);
    if let Some(cast) = confirm_cast {
        let confirmed: usize = report
            .cells
            .iter()
            .map(|c| c.confirmed.as_ref().map_or(0, Vec::len))
            .sum();
        let sum_pvs: usize = report.cells.iter().map(|c| c.pvs).sum();
        let sum_vs = report.cells.iter().map(|c| c.vs).sum::<usize>() + confirmed;
        report.confirm_rays = Some(opts.confirm_rays);
        report.confirmed_objects = Some(confirmed as u64);
        report.pvs_over_confirmed_vs = (sum_vs > 0).then(|| sum_pvs as f64 / sum_vs as f64);
        report.rays_cast = report.rays_cast.saturating_add(cast);
    }
    Ok(report)
}

/// `--confirm-rays` (`super::confirm`): spends the confirmation budget of every cell on the
/// objects of its PVS with area that its sample did not see (objects overlapping the cell are
/// visible by definition, and in the sample), fills in the cells' `confirmed` and
/// `pvs_over_confirmed_vs`, and adds the culled objects a confirming ray met to their false
/// culls. Returns the rays cast.
fn confirm(
    index: &SceneRays,
    scene: &Scene,
    doc: &PvsDocument,
    opts: &CheckOptions,
    cells: &mut [CellReport],
    progress: Option<&ProgressFn>,
) -> u64 {
    let jobs: Vec<ConfirmCell> = doc
        .cells
        .iter()
        .zip(cells.iter())
        .enumerate()
        .map(|(i, (c, r))| {
            let in_pvs = pvs_mask(scene, c);
            ConfirmCell {
                cell: cell_box(c),
                cell_index: i as u64,
                doubt: targetable_where(index, |o| {
                    in_pvs[o as usize] && r.visible.binary_search(&o).is_err()
                }),
                culled: targetable_where(index, |o| !in_pvs[o as usize]),
            }
        })
        .collect();
    let alpha = doc.settings.bake.alpha_occluders;
    let found = confirm_cells(
        index,
        scene,
        &jobs,
        opts.confirm_rays,
        opts.seed,
        alpha,
        progress,
    );
    let mut cast = 0u64;
    for (r, f) in cells.iter_mut().zip(found) {
        cast = cast.saturating_add(f.rays_cast);
        let seen = r.vs + f.objects.len();
        r.pvs_over_confirmed_vs = (seen > 0).then(|| r.pvs as f64 / seen as f64);
        r.confirmed = Some(f.objects);
        // Culled objects a confirming ray met are false culls like the sample's (those the
        // sample found already keep the sample's witness).
        for (o, w) in &f.false_culls {
            if !r.false_culls.iter().any(|x| x.object == *o) {
                r.false_culls.push(false_cull(scene, *o, Some(w)));
            }
        }
        r.false_culls.sort_by_key(|x| x.object);
    }
    cast
}

/// A PVS cell's box.
fn cell_box(c: &crate::pvs::PvsCell) -> Aabb {
    Aabb::new(Vec3::from(c.min), Vec3::from(c.max))
}

/// The objects with area (the ones rays can aim at) that `keep` keeps, ascending.
fn targetable_where(index: &SceneRays, keep: impl Fn(u32) -> bool) -> Vec<u32> {
    index
        .targetable_objects()
        .iter()
        .copied()
        .filter(|&o| keep(o))
        .collect()
}

/// The PVS of `cell` as a mask over the scene's objects.
fn pvs_mask(scene: &Scene, cell: &crate::pvs::PvsCell) -> Vec<bool> {
    let mut in_pvs = vec![false; scene.objects.len()];
    for &o in &cell.visible {
        if let Some(x) = in_pvs.get_mut(o as usize) {
            *x = true;
        }
    }
    in_pvs
}

/// [`check_with`] in hunt mode (input already checked).
fn hunt_with(index: &SceneRays, scene: &Scene, doc: &PvsDocument, opts: &CheckOptions) -> Report {
    let alpha = doc.settings.bake.alpha_occluders;
    let cells: Vec<HuntCell> = doc
        .cells
        .iter()
        .enumerate()
        .map(|(i, c)| {
            let in_pvs = pvs_mask(scene, c);
            HuntCell {
                cell: cell_box(c),
                cell_index: i as u64,
                culled: targetable_where(index, |o| !in_pvs[o as usize]),
                bystanders: Vec::new(),
            }
        })
        .collect();
    let total = cells
        .iter()
        .map(|c| {
            let m = super::hunt::rays_per_culled_object(opts.rays, c.culled.len());
            m.saturating_mul(c.culled.len() as u64)
        })
        .fold(0u64, u64::saturating_add);
    let progress = start_progress(opts, total);
    let start = std::time::Instant::now();
    let results = hunt_cells(index, scene, &cells, opts.rays, opts.seed, alpha, progress);
    let seconds = start.elapsed().as_secs_f64();
    finish_progress(progress);
    let reports = doc
        .cells
        .iter()
        .zip(&cells)
        .zip(&results)
        .map(|((c, h), r)| hunt_report(scene, c, h, r))
        .collect();
    let mut report = summarize(scene, opts, alpha, reports, seconds);
    report.hunt = true;
    report.pvs_over_vs = None;
    report.hunted_objects = Some(cells.iter().map(|c| c.culled.len() as u64).sum());
    report.rays_per_culled_object = Some(
        results
            .iter()
            .zip(&cells)
            .filter(|(_, c)| !c.culled.is_empty())
            .map(|(r, _)| r.rays_per_object)
            .min()
            .unwrap_or(0),
    );
    report
}

/// The report of one hunted cell: the VS is not measured; the false culls are the culled
/// objects a ray saw, then (as in [`cell_report`]) culled objects no ray saw whose bounds
/// overlap the cell.
fn hunt_report(
    scene: &Scene,
    cell: &crate::pvs::PvsCell,
    hunt: &HuntCell,
    result: &HuntResult,
) -> CellReport {
    let in_pvs = pvs_mask(scene, cell);
    let bounds = hunt.cell;
    let mut culls: Vec<(u32, Option<&Witness>)> =
        result.seen.iter().map(|(o, w)| (*o, Some(w))).collect();
    for (o, obj) in scene.objects.iter().enumerate() {
        let o = o as u32;
        if !in_pvs[o as usize]
            && obj.bounds.overlaps(&bounds)
            && result.seen.binary_search_by_key(&o, |e| e.0).is_err()
        {
            culls.push((o, None));
        }
    }
    culls.sort_by_key(|e| e.0);
    let mut r = cell_report(scene, cell, &CellSample::default());
    r.false_culls = culls
        .into_iter()
        .map(|(o, w)| false_cull(scene, o, w))
        .collect();
    r.rays = result.rays_cast;
    r.hunted = Some(hunt.culled.len());
    r.rays_per_culled_object = Some(result.rays_per_object);
    r
}

/// Compares one cell's PVS with its sample.
pub fn cell_report(scene: &Scene, cell: &crate::pvs::PvsCell, sample: &CellSample) -> CellReport {
    let n = scene.objects.len();
    let in_pvs = pvs_mask(scene, cell);
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
        hunted: None,
        rays_per_culled_object: None,
        confirmed: None,
        pvs_over_confirmed_vs: None,
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
        hunt: false,
        hunted_objects: None,
        rays_per_culled_object: None,
        confirm_rays: None,
        confirmed_objects: None,
        pvs_over_confirmed_vs: None,
        seconds,
        cells,
    }
}
