//! The data of an occlusion sweep's reprojection and its exact integer filter: which pixels of
//! a target plane the umbra of a source plane's Depth Map sets. The windows are computed from
//! the two planes' geometry by [`crate::sweep`]; here they are integers only, so that both
//! backends run this same filter on the same windows and give identical maps.
//!
//! # The filter
//!
//! Every target pixel `(i, j)` has a source *window*: the column range `cols[i]` times the row
//! range `rows[j]` ([`Window`]s, inclusive pixel indices of the source map). The target pixel is
//! set when both ranges are valid (`lo ≤ hi`, inside the source map) and every source pixel of
//! the window is in the umbra (Depth `≤ 0`; a NaN is not); an invalid range ([`NO_WINDOW`])
//! sets nothing. The window is a product of a column range (depending only on the target
//! column) and a row range (depending only on the target row), so the test is separable: first,
//! for every source row and target column, "all set in the column range"; then, for every target
//! pixel, "all of those set in the row range". A set pixel receives [`Reprojection::depth`] (the
//! minimum with what it holds).

use super::DepthMap;
use std::sync::Arc;

/// A source window `[lo, hi]` (inclusive pixel indices) along one axis, or — when `lo > hi` —
/// none: the window leaves the source rectangle and the pixel cannot be set.
pub type Window = [u32; 2];

/// The window of a pixel whose rays leave the source rectangle.
pub const NO_WINDOW: Window = [u32::MAX, 0];

/// Sides of a source plane's rectangle beyond which nothing matters, in the order
/// `[u min, v min, u max, v max]`: a side is open when no ray from the cell crossing the plane
/// beyond it meets any object behind the plane
/// ([`crate::project::planes::DirectionPlan::relevant_rect`]). A window reaching past an open
/// side is cut at it: the rays through the part outside meet nothing, so they need no
/// occluder. A window reaching past a closed side sets nothing.
pub type OpenSides = [bool; 4];

/// No open side: every window must lie inside the source rectangle.
pub const CLOSED: OpenSides = [false; 4];

/// Reprojection of one plane's umbra onto the next plane of the sweep.
#[derive(Clone, Debug, PartialEq)]
pub struct Reprojection {
    /// The source plane's Depth Map (its size may differ from the target's). Pixels with
    /// Depth `≤ 0` are the umbra carried forward.
    pub source: Arc<DepthMap>,
    /// Per target column `i` (one entry per column of the target): the source columns its
    /// window overlaps.
    pub cols: Vec<Window>,
    /// Per target row `j`: the source rows its window overlaps.
    pub rows: Vec<Window>,
    /// The Depth written into reprojected pixels: the source plane's Depth relative to the
    /// target plane, rounded up.
    pub depth: f32,
}

impl Reprojection {
    /// Number of source pixels in the umbra (Depth `≤ 0`).
    pub fn source_umbra(&self) -> usize {
        self.source.depth.iter().filter(|&&d| d <= 0.0).count()
    }

    /// Applies the reprojection to `map` (the target's Depth Map): every reprojected pixel
    /// keeps the minimum of its Depth and [`Reprojection::depth`].
    pub fn apply(&self, map: &mut DepthMap) {
        let depth = self.depth;
        let tw = self.cols.len();
        self.for_each_row(|j, row| {
            for (d, &s) in map.depth[j * tw..(j + 1) * tw].iter_mut().zip(row) {
                if s && depth < *d {
                    *d = depth;
                }
            }
        });
    }

    /// The reprojected pixels of the target, row-major: the separable filter of the module
    /// docs. (The GPU backend evaluates the same window test with a summed-area table.)
    pub fn mask(&self) -> Vec<bool> {
        let tw = self.cols.len();
        let mut out = vec![false; tw * self.rows.len()];
        self.for_each_row(|j, row| out[j * tw..(j + 1) * tw].copy_from_slice(row));
        out
    }

    /// The separable filter, streamed: hands `emit` each target row `j` that has a valid
    /// window, with its reprojected pixels. Source rows are read once, in order: pass 1 ("all
    /// set in `cols[i]` of source row `y`") runs on each row as it comes, and pass 2 keeps, per
    /// target column, the last source row where pass 1 failed — a target pixel is set when
    /// that row lies above its row window's start. Row windows move down monotonically with
    /// `j` (each end is the extreme of maps increasing in the pixel's position), which lets a
    /// target row be emitted as soon as the source reaches its window's end; should they not
    /// (a future window rule), the rows are sorted by window end first.
    fn for_each_row(&self, mut emit: impl FnMut(usize, &[bool])) {
        assert!(
            !self.source.is_on_device(),
            "a map kept on a device is reprojected by that device's backend only"
        );
        let (sw, sh) = (self.source.width as usize, self.source.height as usize);
        let tw = self.cols.len();
        let src = &self.source.depth;
        let mut order: Vec<usize> = (0..self.rows.len())
            .filter(|&j| {
                let [lo, hi] = self.rows[j];
                lo <= hi && (hi as usize) < sh
            })
            .collect();
        if !order.is_sorted_by_key(|&j| self.rows[j][1]) {
            order.sort_by_key(|&j| self.rows[j][1]);
        }
        let Some(y0) = order.iter().map(|&j| self.rows[j][0] as usize).min() else {
            return;
        };
        // `last_unset[i] = y + 1` for the last source row `y` read where target column `i`
        // failed pass 1 (0: none yet).
        let mut last_unset = vec![0u32; tw];
        let mut horizontal = vec![false; tw];
        let mut prefix = vec![0u32; sw + 1];
        let mut row = vec![false; tw];
        let mut next = 0;
        for y in y0..sh {
            if next == order.len() {
                break;
            }
            for x in 0..sw {
                let d = src[y * sw + x];
                prefix[x + 1] = prefix[x] + u32::from(d > 0.0 || d.is_nan());
            }
            if prefix[sw] as usize == sw {
                horizontal.fill(false);
            } else {
                for (h, w) in horizontal.iter_mut().zip(&self.cols) {
                    *h = all_set(&prefix, *w, sw);
                }
            }
            let mark = y as u32 + 1;
            for (l, &h) in last_unset.iter_mut().zip(&horizontal) {
                if !h {
                    *l = mark;
                }
            }
            while next < order.len() && self.rows[order[next]][1] as usize == y {
                let j = order[next];
                let lo = self.rows[j][0];
                for (r, &l) in row.iter_mut().zip(&last_unset) {
                    *r = l <= lo;
                }
                emit(j, &row);
                next += 1;
            }
        }
    }
}

/// True when the window is valid and holds no unset pixel (`prefix` counts unset pixels).
fn all_set(prefix: &[u32], w: Window, res: usize) -> bool {
    let [lo, hi] = w;
    if lo > hi || hi as usize >= res {
        return false;
    }
    prefix[hi as usize + 1] == prefix[lo as usize]
}

#[cfg(test)]
mod tests {
    use super::*;
    use rand::{Rng, SeedableRng};

    /// The streamed filter against its definition, pixel by pixel, on arbitrary windows: not
    /// only the monotone ones planes produce but shuffled rows, empty and out-of-range
    /// windows, and sources of another size than the target.
    #[test]
    fn streamed_filter_matches_the_definition_on_any_windows() {
        let mut rng = rand_pcg::Pcg64::seed_from_u64(11);
        for case in 0..200 {
            let (sw, sh) = (rng.random_range(1..40usize), rng.random_range(1..40usize));
            let (tw, th) = (rng.random_range(1..30usize), rng.random_range(1..30usize));
            let hole = [0.0, 0.02, 0.2, 1.0][case % 4];
            let mut source = DepthMap::sized(sw as u32, sh as u32);
            for d in source.depth.iter_mut() {
                if rng.random_range(0.0..1.0) >= hole {
                    *d = -rng.random_range(0.0..1.0f32);
                }
            }
            let mut window = |n: usize| -> Window {
                match rng.random_range(0..10) {
                    0 => NO_WINDOW,
                    1 => [0, n as u32 + rng.random_range(0..3)],
                    _ => {
                        let lo = rng.random_range(0..n as u32);
                        [lo, (lo + rng.random_range(0..4)).min(n as u32 - 1)]
                    }
                }
            };
            let cols: Vec<Window> = (0..tw).map(|_| window(sw)).collect();
            let mut rows: Vec<Window> = (0..th).map(|_| window(sh)).collect();
            if case % 2 == 0 {
                rows.sort_by_key(|w| w[1]);
            }
            let r = Reprojection {
                source: Arc::new(source.clone()),
                cols: cols.clone(),
                rows: rows.clone(),
                depth: -1.0,
            };
            let set = |x: usize, y: usize| source.depth[y * sw + x] <= 0.0;
            let mask = r.mask();
            for (j, &[r0, r1]) in rows.iter().enumerate() {
                for (i, &[c0, c1]) in cols.iter().enumerate() {
                    let valid = c0 <= c1 && (c1 as usize) < sw && r0 <= r1 && (r1 as usize) < sh;
                    let want =
                        valid && (r0..=r1).all(|y| (c0..=c1).all(|x| set(x as usize, y as usize)));
                    assert_eq!(mask[j * tw + i], want, "case {case}, target ({i}, {j})");
                }
            }
        }
    }
}
