//! The ray-space-factorization culler (Leyvand et al. 2003, §4.1): per cell, the objects are
//! visited nearest first; each one not already decided is tested against the four charts of
//! [`crate::rsf::RayCharts`] (its box, then its pieces), and each one still visible inserts
//! its occluder parts as half umbrae. It runs before the planes, which skip what it hid.
//! `choose_rsf` decides per scene whether it runs by default.
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
use super::pipeline::{CullState, Culler, CullerWork};
use super::prepare::Prepared;
use crate::backend::RasterBackend;
use crate::geom::{Aabb, DAabb};
use crate::hdm::Hdm;
use crate::plane::{DepthMap, PlaneJob};
use crate::project::occluders::{Occluders, PartKind};
use crate::project::planes::shrink_bent_polygon;
use crate::rsf::RayCharts;
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
        "ray_space_factorization"
    }

    fn cull(
        &self,
        prepared: &Prepared,
        cell: &Aabb,
        _backend: &dyn RasterBackend,
        state: &mut CullState,
        _observe: &mut dyn FnMut(&PlaneJob, &DepthMap, &Hdm),
    ) -> Result<CullerWork, BakeError> {
        let charts = traverse(prepared, cell, state, false);
        Ok(CullerWork {
            occluders_projected: charts.work.polygons,
            ..CullerWork::default()
        })
    }
}

/// The charts of one cell, as a bake without earlier cullers fills them, with the parts of
/// the last objects inserted too (for dumps): what the traversal proves hidden is dropped.
pub fn cell_charts(prepared: &Prepared, cell: &Aabb) -> RayCharts {
    let mut state = CullState {
        hidden: vec![false; prepared.scene.objects.len()],
        known_visible: None,
    };
    traverse(prepared, cell, &mut state, true)
}

/// Ray space factorization's traversal of one cell: marks in `state.hidden` what it proves
/// hidden and returns the charts it filled. Parts still waiting when the last object has been
/// tested can hide nothing more; they are inserted only when `drain` (dumps).
fn traverse(prepared: &Prepared, cell: &Aabb, state: &mut CullState, drain: bool) -> RayCharts {
    {
        let settings = &prepared.settings;
        let cell64 = cell.to_f64();
        let mut charts = RayCharts::new(&cell64, settings.up.index(), settings.rsf_resolution);
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
        // Parts of visible objects wait here, nearest first, until an object at least as far
        // as they are is tested: umbrae are then inserted about front to back, which keeps
        // the pixels' guards near (the result is conservative in any order).
        let mut pending: BinaryHeap<Reverse<(OrdF64, u32)>> = BinaryHeap::new();
        let mut buf: Vec<glam::DVec3> = Vec::new();
        let mut insert = |p: u32, charts: &mut RayCharts| {
            insert_part(
                occ,
                &prepared.rsf_edges,
                p as usize,
                &cell64,
                &corners,
                &mut buf,
                charts,
            );
        };
        for &(d, o) in &order {
            while let Some(&Reverse((OrdF64(pd), p))) = pending.peek() {
                if pd > d {
                    break;
                }
                pending.pop();
                insert(p, &mut charts);
            }
            let o = o as usize;
            if !known.is_some_and(|k| k[o]) && hidden(prepared, &charts, o) {
                state.hidden[o] = true;
                continue;
            }
            for &p in &prepared.object_parts[o] {
                let b = &occ.parts[p as usize].bounds;
                if min_angle > 0.0 && b.max_solid_angle_from(&cell64) < min_angle {
                    continue;
                }
                let pd = box_distance(&cell64, b);
                pending.push(Reverse((OrdF64(pd), p)));
            }
        }
        if drain {
            while let Some(Reverse((_, p))) = pending.pop() {
                insert(p, &mut charts);
            }
        }
        charts
    }
}

/// The object's box, else all its pieces, hidden in the charts.
fn hidden(prepared: &Prepared, charts: &RayCharts, o: usize) -> bool {
    let b = prepared.scene.objects[o].bounds.to_f64();
    if charts.box_hidden(&b) {
        return true;
    }
    let pieces = prepared.pieces[o].clone();
    !pieces.is_empty()
        && pieces
            .map(|k| &prepared.piece_boxes[k as usize])
            .all(|pb| charts.box_hidden(pb))
}

/// Inserts one occluder part: polygons (slightly bent ones shrunk in their plane so that
/// every ray from the cell crossing them crosses the real triangles), and solids the cell is
/// outside of.
fn insert_part(
    occ: &Occluders,
    solid_edges: &[Vec<(usize, usize)>],
    p: usize,
    cell: &DAabb,
    corners: &[glam::DVec3; 8],
    buf: &mut Vec<glam::DVec3>,
    charts: &mut RayCharts,
) {
    let part = &occ.parts[p];
    match part.kind {
        PartKind::Polygon { normal } => {
            if part.deviation == 0.0 {
                charts.insert(occ.part_points(p), None);
            } else {
                buf.clear();
                buf.extend_from_slice(occ.part_points(p));
                if shrink_bent_polygon(buf, normal, part.deviation, part.inradius, corners) {
                    charts.insert(buf, None);
                }
            }
        }
        PartKind::Solid { hull } if !hull.overlaps(cell) => {
            charts.insert(occ.part_points(p), Some(&solid_edges[p]));
        }
        PartKind::Solid { .. } => {}
    }
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
