//! The ray-space-factorization culler (Leyvand et al. 2003, §4.1): per cell, the objects are
//! visited nearest first, in *waves*; each one not already decided is tested against the four
//! charts (its box, then its pieces), and each one still visible inserts its occluder parts as
//! half umbrae before the next wave. It runs before the planes, which skip what it hid.
//! `choose_rsf` decides per scene whether it runs by default.
//!
//! # Backends
//! The charts are the backend's ([`RasterBackend::rsf_charts`]): the CPU's
//! [`crate::rsf::RayCharts`], or the GPU's (`shaders/rsf.wgsl`), which give the same
//! answers. The traversal is the same on both: a wave tests [`WAVE_DIVISOR`]⁻¹ of the
//! objects tested before it (one object at first) in one call, after one call inserting the
//! parts queued so far, so that the GPU takes one submission per wave rather than one per
//! object. Objects of one wave cannot hide one another; on the bench's street cells (50 per
//! scene, 20,000 rays) waves cost PVS/VS 2.48 → 2.49 on Munich and 1.93 → 1.94 on Etoile
//! against one object per wave, and nothing on the city (divisor 8: 2.51 and 1.97).
//!
//! # Why it is conservative
//! The charts' inserts and tests are conservative (see [`crate::rsf`]). Each pixel's umbra
//! carries a guard, the farthest point of the occluders it was made of, and an occludee is
//! tested only against umbrae whose guard is in front of it: the result does not depend on
//! the order in which objects are visited, which only decides how much is culled. Hidden
//! objects insert nothing (leaving an occluder out is always conservative). Polygons that may
//! be bent (merged with a deviation from their plane) and solids a cell overlaps are left
//! out.

use super::BakeError;
use super::pipeline::{CullState, Culler, CullerWork, PlaneSink};
use super::prepare::Prepared;
use crate::backend::{BackendError, RasterBackend, RsfCharts, RsfOccluder};
use crate::geom::{Aabb, DAabb};
use crate::project::occluders::{Occluders, PartKind};
use crate::project::planes::shrink_bent_polygon;
use crate::rsf::RayCharts;
use std::borrow::Cow;
use std::cmp::Reverse;
use std::collections::BinaryHeap;

/// The ray-space-factorization culler.
pub struct RsfCuller;

/// The automatic rule turns ray space factorization on when at least this share of the
/// occluder area is upright (polygons within [`UPRIGHT_SLOPE`] of vertical, and solids).
pub const RSF_AUTO_UPRIGHT_SHARE: f64 = 0.3;

/// A polygon is upright when the up component of its unit normal is at most this.
pub const UPRIGHT_SLOPE: f64 = 0.2;

impl Culler for RsfCuller {
    fn name(&self) -> &'static str {
        super::RAY_SPACE_FACTORIZATION
    }

    fn cull(
        &self,
        prepared: &Prepared,
        cell: &Aabb,
        backend: &dyn RasterBackend,
        state: &mut CullState,
        _observe: &mut dyn PlaneSink,
    ) -> Result<CullerWork, BakeError> {
        let settings = &prepared.settings;
        let mut charts =
            backend.rsf_charts(&cell.to_f64(), settings.up.index(), settings.rsf_resolution)?;
        traverse(prepared, cell, state, charts.as_mut(), false)?;
        Ok(CullerWork {
            occluders_projected: charts.work()?.polygons,
            ..CullerWork::default()
        })
    }
}

/// The charts of one cell, as a bake without earlier cullers fills them (on the CPU), with
/// the parts of the last objects inserted too (for dumps): what the traversal proves hidden is
/// dropped.
pub fn cell_charts(prepared: &Prepared, cell: &Aabb) -> RayCharts {
    let mut state = CullState {
        hidden: vec![false; prepared.scene.objects.len()],
        known_visible: None,
    };
    let settings = &prepared.settings;
    let mut charts = RayCharts::new(&cell.to_f64(), settings.up.index(), settings.rsf_resolution);
    traverse(prepared, cell, &mut state, &mut charts, true).expect("the CPU's charts never fail");
    charts
}

/// How many objects a wave tests together: one more than a [`WAVE_DIVISOR`]th of those
/// tested before it. Objects of one wave cannot hide one another, so the first waves, where
/// the nearest occluders are, hold one object each; later ones grow, so that a cell takes
/// `O(WAVE_DIVISOR · ln n)` waves (each one insert and one test call on the backend).
pub const WAVE_DIVISOR: usize = 32;

/// Ray space factorization's traversal of one cell, in waves (the same on every backend, so
/// that they give the same answers): per wave, the parts of visible objects at most as far as
/// the wave's first object are inserted, then the wave's objects are tested (box, then
/// pieces), and those still visible queue their parts. Marks in `state.hidden` what it proves
/// hidden. Parts still waiting when the last object has been tested can hide nothing more;
/// they are inserted only when `drain` (dumps).
///
/// # Errors
/// The backend's, when its device fails.
fn traverse(
    prepared: &Prepared,
    cell: &Aabb,
    state: &mut CullState,
    charts: &mut dyn RsfCharts,
    drain: bool,
) -> Result<(), BackendError> {
    let settings = &prepared.settings;
    let cell64 = cell.to_f64();
    let scene = prepared.scene;
    let mut order: Vec<(f64, u32)> = scene
        .objects
        .iter()
        .enumerate()
        .filter(|(o, ob)| !state.hidden[*o] && !ob.bounds.is_empty())
        .map(|(o, ob)| (box_distance(&cell64, &ob.bounds.to_f64()), o as u32))
        .collect();
    order.sort_by(|a, b| a.0.total_cmp(&b.0).then(a.1.cmp(&b.1)));
    let known = state.known_visible;
    let occ = &prepared.occluders;
    // Occluder selection by solid angle, as the planes do.
    let min_angle = settings.occluder_min_solid_angle;
    let corners = cell64.corners();
    // Parts of visible objects wait here, nearest first, until a wave starts at an object at
    // least as far as they are: umbrae are then inserted about front to back, which keeps the
    // pixels' guards near (the result is conservative in any order).
    let mut pending: BinaryHeap<Reverse<(OrdF64, u32)>> = BinaryHeap::new();
    let mut batch: Vec<u32> = Vec::new();
    let mut boxes: Vec<DAabb> = Vec::new();
    // The objects of a wave tested, and each one's boxes (a range of `boxes`).
    let mut tested: Vec<usize> = Vec::new();
    let mut groups: Vec<std::ops::Range<usize>> = Vec::new();
    let mut done = 0;
    while done < order.len() {
        let wave = &order[done..(done + 1 + done / WAVE_DIVISOR).min(order.len())];
        done += wave.len();
        batch.clear();
        while let Some(&Reverse((OrdF64(pd), p))) = pending.peek() {
            if pd > wave[0].0 {
                break;
            }
            pending.pop();
            batch.push(p);
        }
        insert_parts(prepared, &batch, &cell64, &corners, charts)?;
        // Each object's box, then its pieces.
        boxes.clear();
        tested.clear();
        groups.clear();
        for &(_, o) in wave {
            let o = o as usize;
            if known.is_some_and(|k| k[o]) {
                continue;
            }
            let start = boxes.len();
            boxes.push(scene.objects[o].bounds.to_f64());
            boxes.extend(
                prepared.pieces[o]
                    .clone()
                    .map(|k| prepared.piece_boxes[k as usize]),
            );
            tested.push(o);
            groups.push(start..boxes.len());
        }
        if !groups.is_empty() {
            let hid = charts.hidden(&boxes, &groups)?;
            for (&o, h) in tested.iter().zip(hid) {
                if h {
                    state.hidden[o] = true;
                }
            }
        }
        for &(_, o) in wave {
            if state.hidden[o as usize] {
                continue;
            }
            for &p in &prepared.object_parts[o as usize] {
                let b = &occ.parts[p as usize].bounds;
                if min_angle > 0.0 && b.max_solid_angle_from(&cell64) < min_angle {
                    continue;
                }
                let pd = box_distance(&cell64, b);
                pending.push(Reverse((OrdF64(pd), p)));
            }
        }
    }
    if drain {
        batch.clear();
        while let Some(Reverse((_, p))) = pending.pop() {
            batch.push(p);
        }
        insert_parts(prepared, &batch, &cell64, &corners, charts)?;
    }
    Ok(())
}

/// Inserts occluder parts, in order: polygons (slightly bent ones shrunk in their plane so
/// that every ray from the cell crossing them crosses the real triangles), and solids the cell
/// is outside of.
fn insert_parts(
    prepared: &Prepared,
    parts: &[u32],
    cell: &DAabb,
    corners: &[glam::DVec3; 8],
    charts: &mut dyn RsfCharts,
) -> Result<(), BackendError> {
    if parts.is_empty() {
        return Ok(());
    }
    let occ = &prepared.occluders;
    let mut out: Vec<RsfOccluder> = Vec::with_capacity(parts.len());
    for &p in parts {
        let p = p as usize;
        let part = &occ.parts[p];
        match part.kind {
            PartKind::Polygon { normal } => {
                if part.deviation == 0.0 {
                    out.push(RsfOccluder {
                        points: Cow::Borrowed(occ.part_points(p)),
                        hull_edges: None,
                    });
                } else {
                    let mut buf = occ.part_points(p).to_vec();
                    if shrink_bent_polygon(&mut buf, normal, part.deviation, part.inradius, corners)
                    {
                        out.push(RsfOccluder {
                            points: Cow::Owned(buf),
                            hull_edges: None,
                        });
                    }
                }
            }
            PartKind::Solid { .. } if occ.solid_hull(part).is_some_and(|h| !h.overlaps(cell)) => {
                out.push(RsfOccluder {
                    points: Cow::Borrowed(occ.part_points(p)),
                    hull_edges: Some(&prepared.rsf_edges[p]),
                })
            }
            PartKind::Solid { .. } => {}
        }
    }
    charts.insert(&out)
}

/// An f64 ordered by `total_cmp`, for the heap of pending parts.
#[derive(Clone, Copy, PartialEq)]
struct OrdF64(f64);

impl Eq for OrdF64 {}

impl PartialOrd for OrdF64 {
    fn partial_cmp(&self, o: &Self) -> Option<std::cmp::Ordering> {
        Some(self.cmp(o))
    }
}

impl Ord for OrdF64 {
    fn cmp(&self, o: &Self) -> std::cmp::Ordering {
        self.0.total_cmp(&o.0)
    }
}

/// The distance between two boxes (0 when they overlap).
fn box_distance(a: &DAabb, b: &DAabb) -> f64 {
    let d = (a.min - b.max).max(b.min - a.max).max(glam::DVec3::ZERO);
    d.length()
}

/// Per occluder part, a solid's hull edges ([`crate::rsf::hull_edges`]; empty for
/// polygons), computed once per scene.
pub(super) fn solid_edges(occ: &Occluders) -> Vec<Vec<(usize, usize)>> {
    occ.parts
        .iter()
        .enumerate()
        .map(|(k, part)| match part.kind {
            PartKind::Solid { .. } => crate::rsf::hull_edges(occ.part_points(k)),
            PartKind::Polygon { .. } => Vec::new(),
        })
        .collect()
}

/// The automatic rule: ray space factorization when at least [`RSF_AUTO_UPRIGHT_SHARE`] of the
/// occluder area is upright about `up` (cities, levels; not foliage). Returns the choice and a
/// line saying why.
pub fn choose_rsf(occ: &Occluders, up: usize) -> (bool, String) {
    let (mut upright, mut total) = (0.0f64, 0.0f64);
    for (k, part) in occ.parts.iter().enumerate() {
        let pts = occ.part_points(k);
        match part.kind {
            PartKind::Polygon { normal } => {
                let a = polygon_area(pts);
                total += a;
                if normal[up].abs() <= UPRIGHT_SLOPE {
                    upright += a;
                }
            }
            PartKind::Solid { .. } => {
                let e = part.bounds.max - part.bounds.min;
                let a = 2.0 * (e.x * e.y + e.y * e.z + e.z * e.x);
                total += a;
                upright += a;
            }
        }
    }
    if total <= 0.0 {
        return (false, "no occluders".into());
    }
    let share = upright / total;
    let on = share >= RSF_AUTO_UPRIGHT_SHARE;
    (
        on,
        format!(
            "{:.0} % of the occluder area is upright; it runs from {:.0} %",
            100.0 * share,
            100.0 * RSF_AUTO_UPRIGHT_SHARE
        ),
    )
}

fn polygon_area(pts: &[glam::DVec3]) -> f64 {
    let mut n = glam::DVec3::ZERO;
    for k in 1..pts.len().saturating_sub(1) {
        n += (pts[k] - pts[0]).cross(pts[k + 1] - pts[0]);
    }
    0.5 * n.length()
}
