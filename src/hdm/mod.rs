//! The Hierarchical Depth Map: a max/min pyramid over a plane's Depth Map, and the occludee
//! test against it.
//!
//! Level 0 is the Depth Map itself; each texel of level `k+1` holds the maximum (and the
//! minimum) of its 2×2 children. An occludee with Depth `d` whose Projection overlaps pixels
//! `[i0, i1] × [j0, j1]` is hidden when every one of those pixels holds a Depth strictly below
//! `d` (`+inf`, uncovered, never is). The test starts at the coarsest level where the rectangle
//! spans at most 2×2 texels and descends only into texels whose maximum is not already below
//! `d`.

pub use crate::plane::Coverage;
use crate::plane::{DepthMap, RectQuery};

/// Max and min pyramids of one Depth Map (width and height powers of two).
#[derive(Clone, Debug)]
pub struct Hdm {
    /// Width of level 0 (the Depth Map), in pixels; a power of two.
    pub width: u32,
    /// Height of level 0 (the Depth Map), in pixels; a power of two.
    pub height: u32,
    /// `max[k]` has [`Hdm::level_size`]`(k)` texels, row-major; `max[0]` is the Depth Map. A
    /// map wider than tall keeps halving its width after its height has reached 1 texel (and
    /// the other way round): texel `(i >> k, j >> k)` of level `k` always holds pixel `(i, j)`.
    pub max: Vec<Vec<f32>>,
    /// Like `max`, but each texel holds the smallest Depth of its pixels.
    pub min: Vec<Vec<f32>>,
}

impl Hdm {
    /// Builds the pyramids.
    ///
    /// # Panics
    /// If the width or height is not a power of two or the map's size does not match them.
    pub fn build(map: &DepthMap) -> Hdm {
        let (w, h) = (map.width, map.height);
        assert!(
            w.is_power_of_two() && h.is_power_of_two(),
            "map sizes must be powers of two"
        );
        assert_eq!(map.depth.len(), w as usize * h as usize);
        let mut max = vec![map.depth.clone()];
        let mut min = vec![map.depth.clone()];
        let (mut pw, mut ph) = (w as usize, h as usize);
        while pw > 1 || ph > 1 {
            let (nw, nh) = ((pw / 2).max(1), (ph / 2).max(1));
            let (pmax, pmin) = (max.last().unwrap(), min.last().unwrap());
            let mut nmax = vec![0.0f32; nw * nh];
            let mut nmin = vec![0.0f32; nw * nh];
            // Children of texel (x, y): columns 2x, 2x+1 and rows 2y, 2y+1 that exist.
            let (dx, dy) = (usize::from(pw > 1), usize::from(ph > 1));
            for y in 0..nh {
                let r0 = 2 * y * pw;
                let r1 = (2 * y + dy) * pw;
                for x in 0..nw {
                    let (a, b) = (r0 + 2 * x, r0 + 2 * x + dx);
                    let (c, d) = (r1 + 2 * x, r1 + 2 * x + dx);
                    nmax[y * nw + x] = pmax[a].max(pmax[b]).max(pmax[c].max(pmax[d]));
                    nmin[y * nw + x] = pmin[a].min(pmin[b]).min(pmin[c].min(pmin[d]));
                }
            }
            max.push(nmax);
            min.push(nmin);
            (pw, ph) = (nw, nh);
        }
        Hdm {
            width: w,
            height: h,
            max,
            min,
        }
    }

    /// The texels `(columns, rows)` of level `k`.
    pub fn level_size(&self, k: usize) -> (u32, u32) {
        ((self.width >> k).max(1), (self.height >> k).max(1))
    }

    /// Answers a [`RectQuery`] ([`Hdm::test`]).
    pub fn answer(&self, q: &RectQuery) -> Coverage {
        let [i0, j0, i1, j1] = q.rect;
        self.test(i0, j0, i1, j1, q.depth)
    }

    /// Tests the pixel rectangle `[i0, i1] × [j0, j1]` (inclusive, inside the map) against an
    /// occludee Depth `depth`.
    pub fn test(&self, i0: u32, j0: u32, i1: u32, j1: u32, depth: f32) -> Coverage {
        debug_assert!(i0 <= i1 && j0 <= j1 && i1 < self.width && j1 < self.height);
        let mut level = 0usize;
        // The finest level where the rectangle spans at most 2×2 texels.
        while level + 1 < self.max.len()
            && ((i1 >> level) - (i0 >> level) > 1 || (j1 >> level) - (j0 >> level) > 1)
        {
            level += 1;
        }
        let r = self.level_size(level).0;
        let mut any_covered = false;
        for ty in (j0 >> level)..=(j1 >> level) {
            for tx in (i0 >> level)..=(i1 >> level) {
                if self.min[level][(ty * r + tx) as usize].is_finite() {
                    any_covered = true;
                }
            }
        }
        if !any_covered {
            return Coverage::Empty;
        }
        for ty in (j0 >> level)..=(j1 >> level) {
            for tx in (i0 >> level)..=(i1 >> level) {
                if !self.hidden_in(level, tx, ty, i0, j0, i1, j1, depth) {
                    return Coverage::Partial;
                }
            }
        }
        Coverage::Hidden
    }

    /// True when all level-0 pixels of texel `(tx, ty)` of `level` inside the rectangle hold a
    /// Depth below `depth`.
    #[expect(
        clippy::too_many_arguments,
        reason = "a hot inner query over a texel rectangle; passing the corners as scalars keeps it allocation- and struct-free"
    )]
    fn hidden_in(
        &self,
        level: usize,
        tx: u32,
        ty: u32,
        i0: u32,
        j0: u32,
        i1: u32,
        j1: u32,
        depth: f32,
    ) -> bool {
        let r = self.level_size(level).0;
        let idx = (ty * r + tx) as usize;
        if self.max[level][idx] < depth {
            return true;
        }
        // A texel wholly inside the rectangle whose maximum is not below `depth` holds a pixel
        // that fails: no need to look further. Only texels on the rectangle's border descend.
        let (x0, x1) = (tx << level, ((tx + 1) << level) - 1);
        let (y0, y1) = (ty << level, ((ty + 1) << level) - 1);
        let inside = x0 >= i0 && x1 <= i1 && y0 >= j0 && y1 <= j1;
        if level == 0 || inside || self.min[level][idx] >= depth {
            return false;
        }
        let l = level - 1;
        for cy in 2 * ty..2 * ty + 2 {
            for cx in 2 * tx..2 * tx + 2 {
                // Children outside the rectangle do not matter.
                let (x0, x1) = (cx << l, ((cx + 1) << l) - 1);
                let (y0, y1) = (cy << l, ((cy + 1) << l) - 1);
                if x1 < i0 || x0 > i1 || y1 < j0 || y0 > j1 {
                    continue;
                }
                if !self.hidden_in(l, cx, cy, i0, j0, i1, j1, depth) {
                    return false;
                }
            }
        }
        true
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn brute(map: &DepthMap, i0: u32, j0: u32, i1: u32, j1: u32, d: f32) -> Coverage {
        let r = map.width;
        let px: Vec<f32> = (j0..=j1)
            .flat_map(|j| (i0..=i1).map(move |i| map.depth[(j * r + i) as usize]))
            .collect();
        if px.iter().all(|&v| v < d) {
            Coverage::Hidden
        } else if px.iter().all(|v| v.is_infinite()) {
            Coverage::Empty
        } else {
            Coverage::Partial
        }
    }

    /// A deterministic pseudo-random map with holes and varied Depths.
    fn random_map(w: u32, h: u32) -> DepthMap {
        let mut map = DepthMap::sized(w, h);
        let mut x = 12345u64;
        for (k, d) in map.depth.iter_mut().enumerate() {
            x = x
                .wrapping_mul(6364136223846793005)
                .wrapping_add(1442695040888963407);
            let r = (x >> 33) as u32 % 100;
            let block = (k as u32 % w) / 8 + (k as u32 / w) / 8;
            *d = if block.is_multiple_of(3) && r < 97 {
                (r % 10) as f32
            } else if r < 30 {
                f32::INFINITY
            } else {
                (r % 7) as f32
            };
        }
        map
    }

    /// Square and stretched maps (wider than tall and the other way round): the pyramid's
    /// answer equals the brute-force one.
    #[test]
    fn pyramid_test_matches_brute_force() {
        let mut checked = 0;
        for (w, h) in [(32u32, 32u32), (128, 8), (4, 64), (16, 1)] {
            let map = random_map(w, h);
            let hdm = Hdm::build(&map);
            assert_eq!(hdm.level_size(hdm.max.len() - 1), (1, 1));
            for i0 in (0..w).step_by(3) {
                for j0 in (0..h).step_by(5) {
                    for s in [0u32, 1, 2, 5, 9, 17, 70] {
                        let (i1, j1) = ((i0 + s).min(w - 1), (j0 + s / 2).min(h - 1));
                        for d in [0.5f32, 5.0, 9.5, 100.0] {
                            let got = hdm.test(i0, j0, i1, j1, d);
                            let want = brute(&map, i0, j0, i1, j1, d);
                            let ctx = format!("{w}×{h}: rect ({i0},{j0})-({i1},{j1}) depth {d}");
                            // Hidden is exact; Empty may be reported as Partial (coarse texels
                            // straddle the rectangle) but never the other way round.
                            assert_eq!(got == Coverage::Hidden, want == Coverage::Hidden, "{ctx}");
                            if got == Coverage::Empty {
                                assert_eq!(want, Coverage::Empty, "{ctx}");
                            }
                            checked += 1;
                        }
                    }
                }
            }
        }
        assert!(checked > 3000, "{checked}");
    }

    #[test]
    fn equal_depth_is_not_hidden() {
        let mut map = DepthMap::new(4);
        map.depth.iter_mut().for_each(|d| *d = 1.0);
        let hdm = Hdm::build(&map);
        assert_eq!(hdm.test(0, 0, 3, 3, 1.0), Coverage::Partial);
        assert_eq!(hdm.test(0, 0, 3, 3, 1.0f32.next_up()), Coverage::Hidden);
    }
}
