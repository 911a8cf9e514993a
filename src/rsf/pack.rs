//! Ray space factorization's work packed into flat arrays for the GPU twin
//! (`backend::gpu::rsf`, `shaders/rsf.wgsl`): the charts' frames, each occluder's segments in
//! each chart's local frame with the bounds its pixels' quick rejects use, the columns and
//! rows it may write (the CPU's own per-column rejects, `is_live` and `column_rows`), and
//! the boxes of a test in each chart's frame. Everything is computed here in f64 with the very
//! code [`super::RayCharts::insert`] and [`super::RayCharts::box_hidden`] run, so that the shader repeats
//! only the per-pixel part.

use super::{Frame, PartBounds, chart_segments, column_rows, frames, is_live};
use crate::geom::DAabb;
use glam::DVec3;

/// f64 values per chart frame in [`ChartGeometry::frame_data`].
pub const FRAME_FLOATS: usize = 8;
/// u32 values per occluder record ([`InsertPack::recs`]).
pub const REC_INTS: usize = 4;
/// f64 values per occluder record ([`InsertPack::rec_floats`]).
pub const REC_FLOATS: usize = 4;
/// u32 values per column ([`InsertPack::cols`]).
pub const COL_INTS: usize = 6;
/// u32 values per entry ([`InsertPack::entries`]).
pub const ENTRY_INTS: usize = 3;
/// f64 values per box and chart ([`ChartGeometry::pack_boxes`]).
pub const BOX_FLOATS: usize = 6;

/// The frames of a cell's four charts, for packing.
#[derive(Clone, Debug)]
pub struct ChartGeometry {
    frames: Vec<Frame>,
}

/// One call's inserts, packed (see the module docs). Records and entries are in the order of
/// the occluders, so each pixel meets its occluders in that order.
#[derive(Clone, Debug, Default)]
pub struct InsertPack {
    /// Per (occluder, chart) record: first segment, segment count, 1 when it floats, the
    /// occluder's index in the call.
    pub recs: Vec<u32>,
    /// Per record: `x_lo`, `x_hi`, `h_lo`, the best slope (the bounds of the pixels' quick rejects).
    pub rec_floats: Vec<f64>,
    /// Per segment, its two local points `(X, Z, height)`.
    pub segs: Vec<f64>,
    /// Per column some record may write: chart, column, first and end entry, lowest and
    /// highest row of its entries.
    pub cols: Vec<u32>,
    /// Per (record, column): record, first and last row.
    pub entries: Vec<u32>,
    /// Occluders in the call.
    pub occluders: usize,
}

impl InsertPack {
    /// Columns in the pack.
    pub fn columns(&self) -> usize {
        self.cols.len() / COL_INTS
    }
}

impl ChartGeometry {
    /// The frames of `cell`'s charts, as [`super::RayCharts::new`] makes them.
    ///
    /// # Panics
    /// When `up` is not 1 or 2, or the resolution is 0.
    pub fn new(cell: &DAabb, up: usize, resolution: u32) -> Self {
        ChartGeometry {
            frames: frames(cell, up, resolution),
        }
    }

    /// Per chart, [`FRAME_FLOATS`] values: `w`, `z0`, `z1`, `y0`, `y1`, `s0`, `ds`, 0.
    pub fn frame_data(&self) -> Vec<f64> {
        self.frames
            .iter()
            .flat_map(|f| [f.w, f.z0, f.z1, f.y0, f.y1, f.s0, f.ds, 0.0])
            .collect()
    }

    /// Packs the occluders (points, and a solid's hull edges) of one insert call: per chart,
    /// what [`super::RayCharts::insert`] computes before it visits pixels.
    pub fn pack_inserts<'a>(
        &self,
        occluders: impl Iterator<Item = (&'a [DVec3], Option<&'a [(usize, usize)]>)>,
    ) -> InsertPack {
        let mut pack = InsertPack::default();
        // (chart, column, record, j0, j1) in occluder order, grouped by column below.
        let mut raw: Vec<[u32; 5]> = Vec::new();
        let mut local = Vec::new();
        let mut segs = Vec::new();
        for (o, (pts, hull_edges)) in occluders.enumerate() {
            pack.occluders = o + 1;
            if pts.len() < 3 {
                continue;
            }
            for (c, fr) in self.frames.iter().enumerate() {
                let Some(floating) = chart_segments(fr, pts, hull_edges, &mut local, &mut segs)
                else {
                    continue;
                };
                let b = PartBounds::of(fr, &segs);
                let rec = (pack.recs.len() / REC_INTS) as u32;
                let first = (pack.segs.len() / 6) as u32;
                let mut any = false;
                let (c0, c1) = fr.columns(segs.iter().flat_map(|&(p, q)| [(p.x, p.y), (q.x, q.y)]));
                for i in c0..=c1 {
                    let (m0, m1) = (fr.m_of(i), fr.m_of(i + 1));
                    if !segs.iter().any(|&s| is_live(s, m0, m1)) {
                        continue;
                    }
                    let Some((j0, j1)) = column_rows(fr, &segs, m0, m1) else {
                        continue;
                    };
                    raw.push([c as u32, i as u32, rec, j0 as u32, j1 as u32]);
                    any = true;
                }
                if !any {
                    continue;
                }
                pack.recs
                    .extend([first, segs.len() as u32, floating as u32, o as u32]);
                pack.rec_floats
                    .extend([b.x_lo, b.x_hi, b.h_lo, b.best_slope]);
                for &(p, q) in &segs {
                    pack.segs.extend([p.x, p.y, p.z, q.x, q.y, q.z]);
                }
            }
        }
        // A stable sort keeps each column's entries in occluder order.
        raw.sort_by_key(|e| (e[0], e[1]));
        let mut k = 0;
        while k < raw.len() {
            let (c, i) = (raw[k][0], raw[k][1]);
            let start = pack.entries.len() / ENTRY_INTS;
            let (mut jmin, mut jmax) = (u32::MAX, 0);
            while k < raw.len() && raw[k][0] == c && raw[k][1] == i {
                let [_, _, rec, j0, j1] = raw[k];
                pack.entries.extend([rec, j0, j1]);
                jmin = jmin.min(j0);
                jmax = jmax.max(j1);
                k += 1;
            }
            let end = pack.entries.len() / ENTRY_INTS;
            pack.cols
                .extend([c, i, start as u32, end as u32, jmin, jmax]);
        }
        pack
    }

    /// Appends, per box and chart, [`BOX_FLOATS`] values as [`super::RayCharts::box_hidden`]
    /// takes them: `x0`, `x1` (the box's range beyond the face), `z0`, `z1` (along the side),
    /// the bottom and the top.
    pub fn pack_boxes(&self, boxes: &[DAabb], out: &mut Vec<f64>) {
        for b in boxes {
            for fr in &self.frames {
                let lo = fr.local(b.min);
                let hi = fr.local(b.max);
                out.extend([
                    lo.x.min(hi.x),
                    lo.x.max(hi.x),
                    b.min[fr.b],
                    b.max[fr.b],
                    b.min[fr.up],
                    b.max[fr.up],
                ]);
            }
        }
    }
}
