//! Automatic view cells: boxes where a camera can stand, found from the scene itself (the up
//! axis is +y).
//!
//! **The rule.** A regular grid of square columns covers the scene's x–z bounds (side
//! [`AutoCellOptions::cell_size`], the grid centred on the bounds). In each column,
//! `rays_per_side²` rays are cast straight down from above the scene, one per sub-square of
//! the column at a fixed hashed position inside it (deterministic, no random state); each ray
//! is continued from just below every surface it meets, so it sees every storey. A hit is a
//! **walkable surface** when its triangle's plane is at most [`AutoCellOptions::max_slope_deg`]
//! from horizontal (either face may be the upper one, so single-triangle floors work whatever
//! their winding; with [`AutoCellOptions::one_sided`] only the front face) and there is at
//! least [`AutoCellOptions::headroom`] of free space above it: the distance to the previous
//! surface the same ray met above it, unlimited for the first surface (open sky). The walkable
//! heights of a column are sorted and cut into **floors** wherever two heights are more than
//! `headroom / 2` apart; a floor's candidate cell is the column's square × `[lowest height,
//! highest height + band]`.
//!
//! Each candidate box (rounded outward to `f32`) is classified:
//! * **solid** when its centre is inside closed geometry: the winding number of some closed
//!   object ([`crate::scene::SceneObject::closed`]) around the centre is not zero. This is the
//!   parity test, counted with orientation, so the overlapping boxes of one building still
//!   count as inside. Rays in a few fixed, non axis-aligned directions are tried until one
//!   passes clear of every edge and vertex. Solid candidates are dropped (and counted);
//! * **wall** when some triangle meets the box's open interior (an exact separating-axis test
//!   in `f64`; touching a face, as the floor under the cell does, is not meeting it);
//! * **empty** otherwise.
//!
//! Wall and empty cells are both view cells: a camera stands next to walls, and the bake
//! treats cells that hold geometry conservatively. Only empty cells are **merged**: greedily,
//! in the output order, a cell grows in x and then in z over neighbouring empty cells of the
//! same floor whose bottom and top are both within `band / 4` of its own, at most
//! [`AutoCellOptions::max_merge`] columns per side, and only while the union box still
//! classifies as empty (so a merge never crosses a wall, even one lying exactly on a column
//! boundary).
//!
//! With [`AutoCellOptions::region`] the grid covers that box instead, in layers at most `band`
//! tall, and every cell of it that is not solid is a view cell (no rays; for scenes without
//! floors, such as a space station or a forest canopy).
//!
//! Output order: by floor (the floor's index in its column from the bottom, counting solid
//! ones; in a region, the layer), then z, then x of the (first) column. The result depends only
//! on the scene and the options, never on the thread count.

use super::{CellError, check};
use crate::geom::Aabb;
use crate::scene::{self, Scene};
use crate::validate::SceneRays;
use glam::{DVec3, Vec3};
use rayon::prelude::*;
use std::collections::HashMap;

/// Most grid columns (or region cells) [`auto_cells`] accepts.
pub const MAX_COLUMNS: u64 = 4_000_000;

/// Options of [`auto_cells`]. Lengths are in scene units; the up axis is +y.
#[derive(Clone, Debug, PartialEq)]
pub struct AutoCellOptions {
    /// Side of a grid column in x and z. `None`: the larger horizontal extent of the scene (or
    /// of the region) / 32.
    pub cell_size: Option<f32>,
    /// Height of the camera band above a walkable surface (the cell's top is the floor's
    /// highest point + `band`); in a region, the most a layer is tall. Default 2.
    pub band: f32,
    /// Free space needed above a surface for it to be walkable. Default 1.8.
    pub headroom: f32,
    /// Steepest walkable surface, in degrees from horizontal. Default 45.
    pub max_slope_deg: f32,
    /// Only a triangle's front face (counter-clockwise seen from above) is walkable. Off by
    /// default, so that floors work whatever their winding; on for scenes wound consistently
    /// (game levels), where a ray meeting a floor's back face has come through solid rock and
    /// the "floor" is the top of a ceiling. Default false.
    pub one_sided: bool,
    /// Down-rays per column side: `rays_per_side²` rays per column. Default 4 (16 rays).
    pub rays_per_side: u32,
    /// Place cells in this box instead of above walkable surfaces: the grid covers it and
    /// every cell of it that is not solid is a view cell. Default `None`.
    pub region: Option<Aabb>,
    /// Merge neighbouring empty cells into larger boxes. Default true.
    pub merge: bool,
    /// At most this many columns per side in a merged cell. Default 4.
    pub max_merge: u32,
}

impl Default for AutoCellOptions {
    fn default() -> Self {
        AutoCellOptions {
            cell_size: None,
            band: 2.0,
            headroom: 1.8,
            max_slope_deg: 45.0,
            one_sided: false,
            rays_per_side: 4,
            region: None,
            merge: true,
            max_merge: 4,
        }
    }
}

/// What an automatic cell holds.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Hash)]
pub enum CellClass {
    /// No geometry in the cell's interior.
    Empty,
    /// Some triangle meets the cell's interior (a wall, a step, a sloped floor, a prop).
    Wall,
}

/// Counts of one run of [`auto_cells`], for summaries.
#[derive(Clone, Debug, Default, PartialEq)]
pub struct AutoCellStats {
    /// The side of a column used, in x and z (derived or as given; in a region, the larger of
    /// the two actual sides).
    pub cell_size: f64,
    /// Columns in x and z.
    pub grid: [u32; 2],
    /// Columns (`grid[0] × grid[1]`).
    pub columns: u64,
    /// Down-rays cast (0 in a region).
    pub rays: u64,
    /// Trace calls: each down-ray is traced again from below every surface it meets.
    pub traces: u64,
    /// Walkable hits found by the down-rays.
    pub walkable_hits: u64,
    /// Floors found over all columns (candidate cells; in a region, the grid's cells).
    pub floors: usize,
    /// Candidates dropped because their centre is inside closed geometry.
    pub solid: usize,
    /// Candidates holding geometry (kept, never merged).
    pub wall: usize,
    /// Candidates holding no geometry (kept, merged when `merge`).
    pub empty: usize,
    /// View cells before merging (`wall + empty`).
    pub before_merge: usize,
    /// View cells after merging (the length of [`AutoCells::cells`]).
    pub cells: usize,
    /// Merged cells made of more than one column.
    pub merged: usize,
}

impl std::fmt::Display for AutoCellStats {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        write!(
            f,
            "{} cells ({} wall, {} empty; {} before merging) from {} columns of {} \
             ({}×{}), {} floors, {} solid dropped, {} rays",
            self.cells,
            self.wall,
            self.cells - self.wall,
            self.before_merge,
            self.columns,
            short(self.cell_size),
            self.grid[0],
            self.grid[1],
            self.floors,
            self.solid,
            self.rays
        )
    }
}

/// A length with at most 4 significant decimals, trailing zeros dropped.
fn short(x: f64) -> String {
    let s = format!("{x:.4}");
    let s = s.trim_end_matches('0').trim_end_matches('.');
    s.to_string()
}

/// The result of [`auto_cells`].
#[derive(Clone, Debug, Default)]
pub struct AutoCells {
    /// The view cells, in the module's order; each passes [`crate::cells::check`].
    pub cells: Vec<Aabb>,
    /// Per cell, its class.
    pub classes: Vec<CellClass>,
    /// Counts for the summary.
    pub stats: AutoCellStats,
}

/// Finds the view cells of `scene` by the rule of the module docs.
///
/// # Errors
/// [`CellError::BadGrid`] naming the option for a non-positive or non-finite size, a slope
/// outside 0–90°, zero rays or merge size, a region that is inverted or misses the scene, more
/// than [`MAX_COLUMNS`] columns; an empty scene; and a scene where no walkable surface is found
/// (the message suggests the region option).
pub fn auto_cells(scene: &Scene, opts: &AutoCellOptions) -> Result<AutoCells, CellError> {
    check_options(opts)?;
    let bounds = scene.bounds();
    if bounds.is_empty() || !bounds.min.is_finite() || !bounds.max.is_finite() {
        return Err(CellError::BadGrid(format!(
            "{}: the scene has no triangles to place cells on",
            scene.source.display()
        )));
    }
    let geo = Geometry::new(scene);
    let mut stats = AutoCellStats::default();
    let candidates = match opts.region {
        Some(region) => region_candidates(scene, bounds, region, opts, &mut stats)?,
        None => floor_candidates(scene, bounds, opts, &mut stats)?,
    };
    stats.floors = candidates.len();
    let classes: Vec<Option<CellClass>> = candidates
        .par_iter()
        .map(|c| geo.classify(&c.cell))
        .collect();
    let mut kept: Vec<(Candidate, CellClass)> = candidates
        .into_iter()
        .zip(classes)
        .filter_map(|(c, k)| k.map(|k| (c, k)))
        .collect();
    stats.solid = stats.floors - kept.len();
    stats.wall = kept.iter().filter(|(_, k)| *k == CellClass::Wall).count();
    stats.empty = kept.len() - stats.wall;
    stats.before_merge = kept.len();
    kept.sort_by_key(|(c, _)| c.key());
    let merged = if opts.merge {
        merge(&geo, kept, opts, &mut stats)
    } else {
        kept
    };
    let out = AutoCells {
        cells: merged.iter().map(|(c, _)| c.cell).collect(),
        classes: merged.iter().map(|&(_, k)| k).collect(),
        stats: AutoCellStats {
            cells: merged.len(),
            ..stats
        },
    };
    check(&out.cells, "automatic cells")?;
    Ok(out)
}

/// Refuses bad options, naming the command-line flag.
fn check_options(o: &AutoCellOptions) -> Result<(), CellError> {
    let bad = |m: String| Err(CellError::BadGrid(m));
    let positive = |name: &str, x: f32| {
        if x.is_finite() && x > 0.0 {
            Ok(())
        } else {
            bad(format!("{name} {x}: must be a positive number"))
        }
    };
    if let Some(s) = o.cell_size {
        positive("--cell-size", s)?;
    }
    positive("--band", o.band)?;
    positive("--headroom", o.headroom)?;
    if !(0.0..=90.0).contains(&o.max_slope_deg) {
        return bad(format!(
            "--max-slope {}: must be between 0 and 90 degrees",
            o.max_slope_deg
        ));
    }
    if o.rays_per_side == 0 || o.rays_per_side > 256 {
        return bad(format!(
            "--rays {}: must be between 1 and 256 (rays per column side)",
            o.rays_per_side
        ));
    }
    if o.max_merge == 0 {
        return bad("--max-merge 0: must be at least 1 (1 merges nothing)".into());
    }
    if let Some(r) = o.region
        && (!r.min.is_finite() || !r.max.is_finite() || r.min.cmpge(r.max).any())
    {
        return bad(format!(
            "--region: min {:?} must be below max {:?} on every axis",
            r.min.to_array(),
            r.max.to_array()
        ));
    }
    Ok(())
}

/// One candidate cell: its box and where it came from.
#[derive(Clone, Copy, Debug)]
struct Candidate {
    /// The box, rounded outward to f32.
    cell: Aabb,
    /// Floor index in its column (layer in a region).
    floor: u32,
    /// Column in x and z.
    i: u32,
    j: u32,
}

impl Candidate {
    fn key(&self) -> (u32, u32, u32) {
        (self.floor, self.j, self.i)
    }
}

/// A grid of columns: corner, side per axis, counts.
struct Grid {
    x0: f64,
    z0: f64,
    sx: f64,
    sz: f64,
    nx: u32,
    nz: u32,
}

impl Grid {
    /// Columns of side `size` centred on the x–z extent `min..max`.
    fn centred(min: DVec3, max: DVec3, size: f64) -> Result<Grid, CellError> {
        let n = |ext: f64| (ext / size - 1e-9).ceil().max(1.0);
        let (fx, fz) = (n(max.x - min.x), n(max.z - min.z));
        Grid::checked(
            0.5 * (min.x + max.x) - 0.5 * fx * size,
            0.5 * (min.z + max.z) - 0.5 * fz * size,
            size,
            size,
            fx,
            fz,
            size,
        )
    }

    /// Columns of side at most `size` tiling the x–z extent `min..max` exactly.
    fn tiling(min: DVec3, max: DVec3, size: f64) -> Result<Grid, CellError> {
        let n = |ext: f64| (ext / size - 1e-9).ceil().max(1.0);
        let (fx, fz) = (n(max.x - min.x), n(max.z - min.z));
        Grid::checked(
            min.x,
            min.z,
            (max.x - min.x) / fx,
            (max.z - min.z) / fz,
            fx,
            fz,
            size,
        )
    }

    fn checked(
        x0: f64,
        z0: f64,
        sx: f64,
        sz: f64,
        fx: f64,
        fz: f64,
        size: f64,
    ) -> Result<Grid, CellError> {
        if fx * fz > MAX_COLUMNS as f64 {
            return Err(CellError::BadGrid(format!(
                "--cell-size {}: the grid would have {fx}×{fz} columns (at most {MAX_COLUMNS}): \
                 give a larger --cell-size",
                short(size)
            )));
        }
        Ok(Grid {
            x0,
            z0,
            sx,
            sz,
            nx: fx as u32,
            nz: fz as u32,
        })
    }

    /// Column `(i, j)`'s x–z square: `(xmin, xmax, zmin, zmax)`.
    fn square(&self, i: u32, j: u32) -> (f64, f64, f64, f64) {
        let x = |k: u32| self.x0 + self.sx * f64::from(k);
        let z = |k: u32| self.z0 + self.sz * f64::from(k);
        (x(i), x(i + 1), z(j), z(j + 1))
    }

    fn record(&self, stats: &mut AutoCellStats) {
        stats.cell_size = self.sx.max(self.sz);
        stats.grid = [self.nx, self.nz];
        stats.columns = u64::from(self.nx) * u64::from(self.nz);
    }
}

/// The derived or given column side for the x–z extent `min..max`.
fn column_size(
    opts: &AutoCellOptions,
    min: DVec3,
    max: DVec3,
    what: &str,
) -> Result<f64, CellError> {
    match opts.cell_size {
        Some(s) => Ok(f64::from(s)),
        None => {
            let s = (max.x - min.x).max(max.z - min.z) / 32.0;
            if s.is_finite() && s > 0.0 {
                Ok(s)
            } else {
                Err(CellError::BadGrid(format!(
                    "{what} has no horizontal extent to derive a cell size from: give --cell-size"
                )))
            }
        }
    }
}

/// The cells of a region: a grid of columns, each cut into layers at most `band` tall.
fn region_candidates(
    scene: &Scene,
    bounds: Aabb,
    region: Aabb,
    opts: &AutoCellOptions,
    stats: &mut AutoCellStats,
) -> Result<Vec<Candidate>, CellError> {
    if !region.overlaps(&bounds) {
        return Err(CellError::BadGrid(format!(
            "--region {:?}..{:?} does not overlap the scene {} (bounds {:?}..{:?})",
            region.min.to_array(),
            region.max.to_array(),
            scene.source.display(),
            bounds.min.to_array(),
            bounds.max.to_array()
        )));
    }
    let (min, max) = (region.min.as_dvec3(), region.max.as_dvec3());
    let size = column_size(opts, min, max, "--region")?;
    let grid = Grid::tiling(min, max, size)?;
    let ny = ((max.y - min.y) / f64::from(opts.band) - 1e-9)
        .ceil()
        .max(1.0);
    if ny * f64::from(grid.nx) * f64::from(grid.nz) > MAX_COLUMNS as f64 {
        return Err(CellError::BadGrid(format!(
            "--region with --band {}: the grid would have {}×{}×{ny} cells (at most \
             {MAX_COLUMNS}): give a larger --cell-size or --band",
            opts.band, grid.nx, grid.nz
        )));
    }
    grid.record(stats);
    let ny = ny as u32;
    let sy = (max.y - min.y) / f64::from(ny);
    let mut out = Vec::with_capacity((grid.nx * grid.nz * ny) as usize);
    for k in 0..ny {
        let y0 = min.y + sy * f64::from(k);
        let y1 = if k + 1 == ny {
            max.y
        } else {
            min.y + sy * f64::from(k + 1)
        };
        for j in 0..grid.nz {
            for i in 0..grid.nx {
                let (x0, x1, z0, z1) = grid.square(i, j);
                let x1 = if i + 1 == grid.nx { max.x } else { x1 };
                let z1 = if j + 1 == grid.nz { max.z } else { z1 };
                out.push(Candidate {
                    cell: Aabb::outward(DVec3::new(x0, y0, z0), DVec3::new(x1, y1, z1)),
                    floor: k,
                    i,
                    j,
                });
            }
        }
    }
    Ok(out)
}

/// The candidate cells above walkable surfaces (the down-ray part of the rule).
fn floor_candidates(
    scene: &Scene,
    bounds: Aabb,
    opts: &AutoCellOptions,
    stats: &mut AutoCellStats,
) -> Result<Vec<Candidate>, CellError> {
    let (min, max) = (bounds.min.as_dvec3(), bounds.max.as_dvec3());
    let size = column_size(opts, min, max, "the scene")?;
    let grid = Grid::centred(min, max, size)?;
    grid.record(stats);
    // About `rays_per_side²` rays per column, each traced again below every floor it meets
    // (taken as four): the ray caster's build for that many (the same hits whichever).
    let planned = u64::from(grid.nx) * u64::from(grid.nz) * u64::from(opts.rays_per_side).pow(2);
    let rays = SceneRays::for_rays(scene, planned.saturating_mul(4));
    let down = Down::new(scene, &rays, bounds, opts);
    let columns: Vec<(u32, u32)> = (0..grid.nz)
        .flat_map(|j| (0..grid.nx).map(move |i| (i, j)))
        .collect();
    let per_column: Vec<(Vec<Candidate>, u64, u64)> = columns
        .par_iter()
        .map(|&(i, j)| down.column(&grid, i, j))
        .collect();
    let n = u64::from(opts.rays_per_side).pow(2);
    stats.rays = stats.columns * n;
    let mut out = Vec::new();
    for (c, traces, walkable) in per_column {
        out.extend(c);
        stats.traces += traces;
        stats.walkable_hits += walkable;
    }
    if out.is_empty() {
        return Err(CellError::BadGrid(format!(
            "{}: no walkable surface found ({} rays down through {} columns of {}: nothing is \
             at most {}° steep with {} of free space above it); place cells in a box instead \
             with --auto-region minx,miny,minz,maxx,maxy,maxz (--region in `umbrasweep cells`), \
             or change --max-slope / --headroom",
            scene.source.display(),
            stats.rays,
            stats.columns,
            short(size),
            opts.max_slope_deg,
            opts.headroom
        )));
    }
    Ok(out)
}

/// The down-ray caster of one scene.
struct Down<'a> {
    scene: &'a Scene,
    rays: &'a SceneRays,
    /// Where rays start: above the scene.
    top: f32,
    /// How far below a hit a ray is traced again.
    step: f64,
    /// Cosine of the steepest walkable slope.
    min_ny: f64,
    /// Back faces are not walkable.
    one_sided: bool,
    opts: &'a AutoCellOptions,
}

impl<'a> Down<'a> {
    fn new(
        scene: &'a Scene,
        rays: &'a SceneRays,
        bounds: Aabb,
        opts: &'a AutoCellOptions,
    ) -> Down<'a> {
        let scale = f64::from(bounds.min.abs().max(bounds.max.abs()).max_element())
            + f64::from(bounds.size().max_element());
        Down {
            scene,
            rays,
            top: bounds.max.y + 1.0,
            step: (scale * 1e-6).max(1e-6),
            min_ny: f64::from(opts.max_slope_deg).to_radians().cos(),
            one_sided: opts.one_sided,
            opts,
        }
    }

    /// The floors of column `(i, j)`, the trace calls and the walkable hits.
    fn column(&self, grid: &Grid, i: u32, j: u32) -> (Vec<Candidate>, u64, u64) {
        let (x0, x1, z0, z1) = grid.square(i, j);
        let n = self.opts.rays_per_side;
        let mut heights = Vec::new();
        let mut traces = 0;
        for b in 0..n {
            for a in 0..n {
                let h = hash(&[i, j, a, b]);
                let fx = (f64::from(a) + 0.1 + 0.8 * unit(h)) / f64::from(n);
                let fz = (f64::from(b) + 0.1 + 0.8 * unit(h >> 32)) / f64::from(n);
                let x = (x0 + (x1 - x0) * fx) as f32;
                let z = (z0 + (z1 - z0) * fz) as f32;
                traces += self.ray(x, z, &mut heights);
            }
        }
        let walkable = heights.len() as u64;
        heights.sort_by(f64::total_cmp);
        let gap = f64::from(self.opts.headroom) / 2.0;
        let mut out = Vec::new();
        let mut k = 0;
        while k < heights.len() {
            let lo = heights[k];
            let mut hi = lo;
            k += 1;
            while k < heights.len() && heights[k] - hi <= gap {
                hi = heights[k];
                k += 1;
            }
            out.push(Candidate {
                cell: Aabb::outward(
                    DVec3::new(x0, lo, z0),
                    DVec3::new(x1, hi + f64::from(self.opts.band), z1),
                ),
                floor: out.len() as u32,
                i,
                j,
            });
        }
        (out, traces, walkable)
    }

    /// Traces one ray down at `(x, z)`, pushing the heights of its walkable hits; returns the
    /// trace calls made.
    fn ray(&self, x: f32, z: f32, heights: &mut Vec<f64>) -> u64 {
        let dir = Vec3::NEG_Y;
        let mut y_origin = self.top;
        let mut above: Option<f64> = None;
        let mut traces = 0;
        // Each round moves the origin down by at least `step`: the bound is only a guard.
        for _ in 0..1 << 16 {
            traces += 1;
            let hits = self.rays.trace(Vec3::new(x, y_origin, z), dir, true);
            let Some(first) = hits.first() else {
                break;
            };
            let mut y = f64::from(y_origin) - f64::from(first.t);
            let mut walkable = false;
            for h in hits.iter().filter(|h| h.t == first.t) {
                if let Some(yy) = self.walkable_height(h.triangle, x, z) {
                    walkable = true;
                    y = yy;
                    break;
                }
            }
            let room = above.map_or(f64::INFINITY, |a| a - y);
            if walkable && room >= f64::from(self.opts.headroom) {
                heights.push(y);
            }
            above = Some(y);
            let mut next = (y.min(f64::from(y_origin) - f64::from(first.t)) - self.step) as f32;
            if next >= y_origin {
                next = y_origin.next_down();
            }
            y_origin = next;
        }
        traces
    }

    /// The height of triangle `t`'s plane at `(x, z)` when the triangle is walkable.
    fn walkable_height(&self, t: u32, x: f32, z: f32) -> Option<f64> {
        let [a, b, c] = self.scene.triangle(t as usize).map(|p| p.as_dvec3());
        let n = (b - a).cross(c - a);
        let len = n.length();
        if len == 0.0 || n.y == 0.0 || n.y.abs() < self.min_ny * len {
            return None;
        }
        if self.one_sided && n.y < 0.0 {
            return None;
        }
        let (x, z) = (f64::from(x), f64::from(z));
        Some(a.y - (n.x * (x - a.x) + n.z * (z - a.z)) / n.y)
    }
}

/// A 64-bit hash of a few numbers (SplitMix64 steps).
fn hash(parts: &[u32]) -> u64 {
    let mut h = 0x243F_6A88_85A3_08D3u64;
    for &p in parts {
        h = (h ^ u64::from(p)).wrapping_add(0x9E37_79B9_7F4A_7C15);
        h = (h ^ (h >> 30)).wrapping_mul(0xBF58_476D_1CE4_E5B9);
        h = (h ^ (h >> 27)).wrapping_mul(0x94D0_49BB_1331_11EB);
        h ^= h >> 31;
    }
    h
}

/// The low 32 bits of `h` as a number in [0, 1).
fn unit(h: u64) -> f64 {
    f64::from(h as u32) / 4_294_967_296.0
}

/// Greedy merging of the empty cells (see the module docs); `kept` is in output order.
fn merge(
    geo: &Geometry,
    kept: Vec<(Candidate, CellClass)>,
    opts: &AutoCellOptions,
    stats: &mut AutoCellStats,
) -> Vec<(Candidate, CellClass)> {
    let index: HashMap<(u32, u32, u32), usize> = kept
        .iter()
        .enumerate()
        .filter(|(_, (_, k))| *k == CellClass::Empty)
        .map(|(n, (c, _))| (c.key(), n))
        .collect();
    let tol = opts.band / 4.0;
    let close =
        |a: &Aabb, b: &Aabb| (a.min.y - b.min.y).abs() <= tol && (a.max.y - b.max.y).abs() <= tol;
    let mut used = vec![false; kept.len()];
    let mut out = Vec::with_capacity(kept.len());
    for n in 0..kept.len() {
        let (seed, class) = kept[n];
        if used[n] {
            continue;
        }
        used[n] = true;
        if class != CellClass::Empty {
            out.push((seed, class));
            continue;
        }
        // A neighbour that may join: empty, free, close in height to the seed.
        let free = |used: &[bool], i: u32, j: u32| {
            index
                .get(&(seed.floor, j, i))
                .copied()
                .filter(|&m| !used[m] && close(&seed.cell, &kept[m].0.cell))
        };
        let mut cell = seed.cell;
        let mut w = 1;
        while w < opts.max_merge {
            let Some(m) = free(&used, seed.i + w, seed.j) else {
                break;
            };
            let u = cell.union(&kept[m].0.cell);
            if geo.classify(&u) != Some(CellClass::Empty) {
                break;
            }
            cell = u;
            used[m] = true;
            w += 1;
        }
        let mut h = 1;
        while h < opts.max_merge {
            let row: Option<Vec<usize>> = (0..w)
                .map(|k| free(&used, seed.i + k, seed.j + h))
                .collect();
            let Some(row) = row else {
                break;
            };
            let u = row.iter().fold(cell, |u, &m| u.union(&kept[m].0.cell));
            if geo.classify(&u) != Some(CellClass::Empty) {
                break;
            }
            cell = u;
            for m in row {
                used[m] = true;
            }
            h += 1;
        }
        if w * h > 1 {
            stats.merged += 1;
        }
        out.push((Candidate { cell, ..seed }, CellClass::Empty));
    }
    out
}

/// One triangle of the classification structure.
#[derive(Clone, Copy, Debug)]
struct Tri {
    p: [DVec3; 3],
    /// Owner object, or `u32::MAX` when it is not closed (left out of the inside test).
    closed_object: u32,
}

/// A node of [`Geometry`]'s BVH: a leaf holds `count > 0` triangles from `first`; an inner
/// node's children are the next node and node `first`.
#[derive(Clone, Copy, Debug)]
struct Node {
    min: DVec3,
    max: DVec3,
    first: u32,
    count: u32,
}

/// The scene's non-degenerate triangles in `f64` with a binary BVH, for the box and inside
/// tests.
struct Geometry {
    tris: Vec<Tri>,
    nodes: Vec<Node>,
    /// A length of the scene's size, for tolerances.
    scale: f64,
}

/// Directions of the inside test's rays: unit-ish, none along an axis or a diagonal.
const INSIDE_DIRS: [[f64; 3]; 5] = [
    [0.856_3, 0.137_1, 0.498_0],
    [-0.332_9, 0.112_3, 0.936_2],
    [-0.740_7, -0.088_3, -0.666_0],
    [0.224_9, -0.171_2, -0.959_2],
    [0.947_3, 0.324_1, -0.039_1],
];

impl Geometry {
    fn new(scene: &Scene) -> Geometry {
        let mut tris = Vec::with_capacity(scene.triangles.len());
        for (o, obj) in scene.objects.iter().enumerate() {
            for t in obj.triangles.clone() {
                let tri = scene.triangle(t as usize);
                if scene::is_degenerate(tri) {
                    continue;
                }
                tris.push(Tri {
                    p: tri.map(|p| p.as_dvec3()),
                    closed_object: if obj.closed { o as u32 } else { u32::MAX },
                });
            }
        }
        let b = scene.bounds();
        let scale = if b.is_empty() {
            1.0
        } else {
            f64::from(b.min.abs().max(b.max.abs()).max_element() + b.size().max_element())
                .max(1e-30)
        };
        let mut nodes = Vec::with_capacity(2 * tris.len() / 4 + 1);
        if !tris.is_empty() {
            let n = tris.len();
            build(&mut tris, 0, n, &mut nodes);
        }
        Geometry { tris, nodes, scale }
    }

    /// `None` for solid, else wall or empty.
    fn classify(&self, cell: &Aabb) -> Option<CellClass> {
        let (min, max) = (cell.min.as_dvec3(), cell.max.as_dvec3());
        if self.inside(0.5 * (min + max)) {
            None
        } else if self.meets_interior(min, max) {
            Some(CellClass::Wall)
        } else {
            Some(CellClass::Empty)
        }
    }

    /// True when some triangle meets the open box `min..max`.
    fn meets_interior(&self, min: DVec3, max: DVec3) -> bool {
        if self.nodes.is_empty() {
            return false;
        }
        let mut stack = vec![0u32];
        while let Some(n) = stack.pop() {
            let node = self.nodes[n as usize];
            if node.min.cmpgt(max).any() || node.max.cmplt(min).any() {
                continue;
            }
            if node.count > 0 {
                let tris = &self.tris[node.first as usize..(node.first + node.count) as usize];
                if tris.iter().any(|t| tri_meets_open_box(&t.p, min, max)) {
                    return true;
                }
            } else {
                stack.push(node.first);
                stack.push(n + 1);
            }
        }
        false
    }

    /// True when `p` is inside some closed object (non-zero winding number). The first ray
    /// that passes clear of every edge and vertex decides; if none does, the majority of the
    /// rays taken as they come.
    fn inside(&self, p: DVec3) -> bool {
        let mut votes = [0u32; 2];
        for d in INSIDE_DIRS.map(DVec3::from) {
            if let Some(v) = self.winding(p, d, true) {
                return v;
            }
            votes[usize::from(self.winding(p, d, false).unwrap_or(false))] += 1;
        }
        votes[1] > votes[0]
    }

    /// The inside test along the ray from `p` along `d`. When `strict`, `None` when the ray
    /// passes within a rounding error of an edge or vertex of a closed object's triangle,
    /// runs in its plane, or starts on it.
    fn winding(&self, p: DVec3, d: DVec3, strict: bool) -> Option<bool> {
        if self.nodes.is_empty() {
            return Some(false);
        }
        let inv = d.recip();
        let mut count: Vec<(u32, i32)> = Vec::new();
        let mut stack = vec![0u32];
        let tol = 1e-9;
        let t_tol = 1e-9 * self.scale;
        while let Some(n) = stack.pop() {
            let node = self.nodes[n as usize];
            // Slab test, padded a little.
            let pad = DVec3::splat(t_tol);
            let t0 = (node.min - pad - p) * inv;
            let t1 = (node.max + pad - p) * inv;
            let tmin = t0.min(t1).max_element();
            let tmax = t0.max(t1).min_element();
            if tmax < tmin.max(0.0) {
                continue;
            }
            if node.count == 0 {
                stack.push(node.first);
                stack.push(n + 1);
                continue;
            }
            for t in &self.tris[node.first as usize..(node.first + node.count) as usize] {
                if t.closed_object == u32::MAX {
                    continue;
                }
                let [a, b, c] = t.p;
                let (e1, e2) = (b - a, c - a);
                let pv = d.cross(e2);
                let det = e1.dot(pv);
                let nlen = e1.cross(e2).length();
                let tv = p - a;
                if det.abs() <= 1e-12 * nlen {
                    // Parallel: ambiguous only when the ray runs in the triangle's plane.
                    if strict && e1.cross(e2).dot(tv).abs() <= t_tol * nlen {
                        return None;
                    }
                    continue;
                }
                let u = tv.dot(pv) / det;
                if !(-tol..=1.0 + tol).contains(&u) {
                    continue;
                }
                let qv = tv.cross(e1);
                let v = d.dot(qv) / det;
                if v < -tol || u + v > 1.0 + tol {
                    continue;
                }
                let tt = e2.dot(qv) / det;
                if tt < -t_tol {
                    continue;
                }
                if strict && (u <= tol || v <= tol || u + v >= 1.0 - tol || tt <= t_tol) {
                    return None;
                }
                if tt < 0.0 {
                    continue;
                }
                // det = -d·n: a ray leaving an outward-facing surface has det < 0.
                let s = if det < 0.0 { 1 } else { -1 };
                match count.iter_mut().find(|(o, _)| *o == t.closed_object) {
                    Some((_, w)) => *w += s,
                    None => count.push((t.closed_object, s)),
                }
            }
        }
        Some(count.iter().any(|&(_, w)| w != 0))
    }
}

/// Builds the BVH node for `tris[start..end]` and its subtree; returns its index.
fn build(tris: &mut [Tri], start: usize, end: usize, nodes: &mut Vec<Node>) -> u32 {
    let (mut min, mut max) = (DVec3::INFINITY, DVec3::NEG_INFINITY);
    let (mut cmin, mut cmax) = (DVec3::INFINITY, DVec3::NEG_INFINITY);
    for t in &tris[start..end] {
        for p in t.p {
            min = min.min(p);
            max = max.max(p);
        }
        let c = (t.p[0] + t.p[1] + t.p[2]) / 3.0;
        cmin = cmin.min(c);
        cmax = cmax.max(c);
    }
    let me = nodes.len() as u32;
    nodes.push(Node {
        min,
        max,
        first: start as u32,
        count: (end - start) as u32,
    });
    if end - start <= 4 {
        return me;
    }
    let ext = cmax - cmin;
    let axis = if ext.x >= ext.y && ext.x >= ext.z {
        0
    } else if ext.y >= ext.z {
        1
    } else {
        2
    };
    let mid = (start + end) / 2;
    let key = |t: &Tri| t.p[0][axis] + t.p[1][axis] + t.p[2][axis];
    tris[start..end].select_nth_unstable_by(mid - start, |a, b| key(a).total_cmp(&key(b)));
    build(tris, start, mid, nodes);
    let right = build(tris, mid, end, nodes);
    nodes[me as usize].first = right;
    nodes[me as usize].count = 0;
    me
}

/// True when the closed triangle `tri` meets the open box `min..max` (separating-axis test in
/// `f64`: the box's 3 axes, the triangle's normal and the 9 edge cross products; projections
/// that only touch separate).
fn tri_meets_open_box(tri: &[DVec3; 3], min: DVec3, max: DVec3) -> bool {
    let c = 0.5 * (min + max);
    let h = 0.5 * (max - min);
    let v = tri.map(|p| p - c);
    let separates = |a: DVec3| {
        if a == DVec3::ZERO {
            return false;
        }
        let p = [v[0].dot(a), v[1].dot(a), v[2].dot(a)];
        let r = h.x * a.x.abs() + h.y * a.y.abs() + h.z * a.z.abs();
        let lo = p[0].min(p[1]).min(p[2]);
        let hi = p[0].max(p[1]).max(p[2]);
        lo >= r || hi <= -r
    };
    if separates(DVec3::X) || separates(DVec3::Y) || separates(DVec3::Z) {
        return false;
    }
    let e = [v[1] - v[0], v[2] - v[1], v[0] - v[2]];
    if separates(e[0].cross(e[1])) {
        return false;
    }
    for edge in e {
        for axis in [DVec3::X, DVec3::Y, DVec3::Z] {
            if separates(edge.cross(axis)) {
                return false;
            }
        }
    }
    true
}

#[cfg(test)]
mod tests {
    use super::*;
    use glam::vec3;
    use std::path::Path;

    /// A horizontal quad `x0..x1 × z0..z1` at height `y`, facing up.
    fn floor(x0: f32, x1: f32, z0: f32, z1: f32, y: f32) -> Vec<[Vec3; 3]> {
        let (a, b, c, d) = (
            vec3(x0, y, z0),
            vec3(x0, y, z1),
            vec3(x1, y, z1),
            vec3(x1, y, z0),
        );
        vec![[a, b, c], [a, c, d]]
    }

    fn scene(objects: Vec<(&str, Vec<[Vec3; 3]>)>) -> Scene {
        Scene::from_objects(
            Path::new("test.obj"),
            objects
                .into_iter()
                .map(|(n, t)| (n.to_string(), t, true))
                .collect(),
        )
    }

    fn opts(cell: f32, merge: bool) -> AutoCellOptions {
        AutoCellOptions {
            cell_size: Some(cell),
            merge,
            ..AutoCellOptions::default()
        }
    }

    /// The 12 outward triangles of a box.
    fn solid_box(min: Vec3, max: Vec3) -> Vec<[Vec3; 3]> {
        crate::geom::box_triangles(min, max)
    }

    fn area(c: &Aabb) -> f64 {
        f64::from(c.max.x - c.min.x) * f64::from(c.max.z - c.min.z)
    }

    #[test]
    fn flat_floor_gives_one_cell_per_column() {
        let s = scene(vec![("ground", floor(0.0, 16.0, 0.0, 16.0, 0.0))]);
        let r = auto_cells(&s, &opts(4.0, false)).unwrap();
        assert_eq!(r.stats.columns, 16);
        assert_eq!(r.cells.len(), 16);
        assert_eq!(r.stats.rays, 16 * 16);
        for (n, c) in r.cells.iter().enumerate() {
            assert_eq!(c.min.y, 0.0);
            assert_eq!(c.max.y, 2.0);
            assert_eq!(c.size().x, 4.0);
            assert_eq!(c.size().z, 4.0);
            // z then x.
            assert_eq!(c.min.x, 4.0 * (n % 4) as f32);
            assert_eq!(c.min.z, 4.0 * (n / 4) as f32);
        }
        assert!(r.classes.iter().all(|&k| k == CellClass::Empty));
        // The default cell size: 16 / 32.
        let d = auto_cells(&s, &AutoCellOptions::default()).unwrap();
        assert_eq!(d.stats.cell_size, 0.5);
        assert_eq!(d.stats.columns, 32 * 32);
    }

    #[test]
    fn a_building_has_floors_on_its_roof_not_inside() {
        let s = scene(vec![
            ("ground", floor(0.0, 16.0, 0.0, 16.0, 0.0)),
            (
                "house",
                solid_box(vec3(4.0, 0.0, 4.0), vec3(12.0, 6.0, 12.0)),
            ),
        ]);
        assert!(s.objects[1].closed);
        let r = auto_cells(&s, &opts(4.0, false)).unwrap();
        // The 4 columns under the house: the ground floor is solid, the roof is a floor.
        assert_eq!(r.stats.solid, 4);
        assert_eq!(r.cells.len(), 16);
        for c in &r.cells {
            let under = c.min.x >= 4.0 && c.max.x <= 12.0 && c.min.z >= 4.0 && c.max.z <= 12.0;
            if under {
                assert_eq!((c.min.y, c.max.y), (6.0, 8.0), "{c:?}");
            } else {
                assert_eq!((c.min.y, c.max.y), (0.0, 2.0), "{c:?}");
            }
        }
        // The roof cells come after the ground cells (floor 1).
        assert!(r.cells[12..].iter().all(|c| c.min.y == 6.0));
        // A low roof under a ceiling: not enough headroom.
        let low = scene(vec![
            ("ground", floor(0.0, 16.0, 0.0, 16.0, 0.0)),
            (
                "slab",
                solid_box(vec3(4.0, 0.0, 4.0), vec3(12.0, 1.0, 12.0)),
            ),
            ("ceiling", floor(0.0, 16.0, 0.0, 16.0, 2.5)),
        ]);
        let r = auto_cells(&low, &opts(4.0, false)).unwrap();
        assert!(r.cells.iter().all(|c| c.min.y != 1.0), "{:?}", r.cells);
        // 16 cells on the ceiling, 12 on the ground around the slab; none under it.
        assert_eq!(r.cells.len(), 28);
        assert_eq!(r.stats.solid, 0);
    }

    #[test]
    fn two_storeys_give_two_floors_per_column() {
        let s = scene(vec![
            ("ground", floor(0.0, 8.0, 0.0, 8.0, 0.0)),
            ("upper", floor(0.0, 8.0, 0.0, 8.0, 3.0)),
        ]);
        let r = auto_cells(&s, &opts(4.0, false)).unwrap();
        assert_eq!(r.stats.columns, 4);
        assert_eq!(r.stats.floors, 8);
        assert_eq!(r.cells.len(), 8);
        assert!(
            r.cells[..4]
                .iter()
                .all(|c| c.min.y == 0.0 && c.max.y == 2.0)
        );
        assert!(
            r.cells[4..]
                .iter()
                .all(|c| c.min.y == 3.0 && c.max.y == 5.0)
        );
        // Merged: one cell per storey.
        let m = auto_cells(&s, &opts(4.0, true)).unwrap();
        assert_eq!(m.cells.len(), 2);
    }

    #[test]
    fn back_faces_are_walkable_unless_one_sided() {
        // A floor wound clockwise seen from above (its normal points down), and a level's
        // slab of rock: a floor on top, the ceiling of the room below 4 under it, both wound
        // toward the open space.
        let down: Vec<[Vec3; 3]> = floor(0.0, 8.0, 0.0, 8.0, 0.0)
            .into_iter()
            .map(|[a, b, c]| [a, c, b])
            .collect();
        let s = scene(vec![("floor", down)]);
        assert_eq!(auto_cells(&s, &opts(4.0, false)).unwrap().cells.len(), 4);
        let one = AutoCellOptions {
            one_sided: true,
            ..opts(4.0, false)
        };
        assert!(auto_cells(&s, &one).is_err());
        let ceiling: Vec<[Vec3; 3]> = floor(0.0, 8.0, 0.0, 8.0, 6.0)
            .into_iter()
            .map(|[a, b, c]| [a, c, b])
            .collect();
        let level = scene(vec![
            ("upper", floor(0.0, 8.0, 0.0, 8.0, 10.0)),
            ("ceiling", ceiling),
            ("lower", floor(0.0, 8.0, 0.0, 8.0, 0.0)),
        ]);
        let both = auto_cells(&level, &opts(4.0, false)).unwrap();
        assert_eq!(both.stats.floors, 12, "{:?}", both.cells);
        let r = auto_cells(&level, &one).unwrap();
        assert_eq!(r.stats.floors, 8);
        assert!(r.cells.iter().all(|c| c.min.y == 0.0 || c.min.y == 10.0));
    }

    #[test]
    fn steep_slopes_are_not_walkable() {
        // 60° from horizontal: rises tan(60°) per unit of x.
        let k = 60f32.to_radians().tan();
        let (a, b, c, d) = (
            vec3(0.0, 0.0, 0.0),
            vec3(0.0, 0.0, 8.0),
            vec3(8.0, 8.0 * k, 8.0),
            vec3(8.0, 8.0 * k, 0.0),
        );
        let ramp = vec![[a, b, c], [a, c, d]];
        let s = scene(vec![("ramp", ramp.clone())]);
        let e = auto_cells(&s, &opts(2.0, false)).unwrap_err().to_string();
        assert!(
            e.contains("no walkable surface") && e.contains("--auto-region"),
            "{e}"
        );
        // Walkable with max 65°.
        let steep = AutoCellOptions {
            max_slope_deg: 65.0,
            ..opts(2.0, false)
        };
        let r = auto_cells(&s, &steep).unwrap();
        assert!(!r.cells.is_empty());
        // A 30° ramp is walkable with 45°; its cells hold the ramp: wall.
        let k = 30f32.to_radians().tan();
        let gentle = vec![[
            vec3(0.0, 0.0, 0.0),
            vec3(0.0, 0.0, 8.0),
            vec3(8.0, 8.0 * k, 8.0),
        ]];
        let r = auto_cells(&scene(vec![("ramp", gentle)]), &opts(2.0, false)).unwrap();
        assert!(!r.cells.is_empty());
    }

    #[test]
    fn a_wall_through_a_column_makes_it_a_wall_cell_and_stops_merging() {
        // A thin wall at x = 6 (inside column 1 of 0..4, 4..8), 1 tall, from z = 0 to 16.
        let wall = vec![
            [
                vec3(6.0, 0.0, 0.0),
                vec3(6.0, 1.0, 0.0),
                vec3(6.0, 1.0, 16.0),
            ],
            [
                vec3(6.0, 0.0, 0.0),
                vec3(6.0, 1.0, 16.0),
                vec3(6.0, 0.0, 16.0),
            ],
        ];
        let s = scene(vec![
            ("ground", floor(0.0, 16.0, 0.0, 16.0, 0.0)),
            ("wall", wall.clone()),
        ]);
        let r = auto_cells(&s, &opts(4.0, false)).unwrap();
        assert_eq!(r.cells.len(), 16);
        for (c, k) in r.cells.iter().zip(&r.classes) {
            let want = if c.min.x == 4.0 {
                CellClass::Wall
            } else {
                CellClass::Empty
            };
            assert_eq!(*k, want, "{c:?}");
        }
        assert_eq!(r.stats.wall, 4);
        // Merged: nothing crosses x = 6; the wall cells stay as they are.
        let m = auto_cells(&s, &opts(4.0, true)).unwrap();
        assert!(m.cells.len() < 16);
        for (c, k) in m.cells.iter().zip(&m.classes) {
            if *k == CellClass::Empty {
                assert!(c.max.x <= 6.0 || c.min.x >= 6.0, "{c:?}");
            }
        }
        // A wall exactly on a column boundary (x = 8) touches both columns: both stay
        // empty, but no merged cell crosses it.
        let on_edge: Vec<[Vec3; 3]> = wall
            .iter()
            .map(|t| t.map(|p| vec3(8.0, p.y, p.z)))
            .collect();
        let s = scene(vec![
            ("ground", floor(0.0, 16.0, 0.0, 16.0, 0.0)),
            ("wall", on_edge),
        ]);
        let r = auto_cells(&s, &opts(4.0, false)).unwrap();
        assert!(r.classes.iter().all(|&k| k == CellClass::Empty));
        let m = auto_cells(&s, &opts(4.0, true)).unwrap();
        assert!(m.cells.iter().all(|c| c.max.x <= 8.0 || c.min.x >= 8.0));
        assert_eq!(m.cells.len(), 2);
    }

    #[test]
    fn merging_keeps_the_area_and_respects_max_merge() {
        let s = scene(vec![("ground", floor(0.0, 40.0, 0.0, 40.0, 0.0))]);
        let plain = auto_cells(&s, &opts(4.0, false)).unwrap();
        let merged = auto_cells(&s, &opts(4.0, true)).unwrap();
        assert_eq!(plain.cells.len(), 100);
        assert!(merged.cells.len() < plain.cells.len());
        let sum = |c: &[Aabb]| c.iter().map(area).sum::<f64>();
        assert_eq!(sum(&plain.cells), sum(&merged.cells));
        assert_eq!(sum(&merged.cells), 1600.0);
        // 10 columns per side with at most 4: 4 + 4 + 2 per side, 9 cells.
        assert_eq!(merged.cells.len(), 9);
        assert!(
            merged
                .cells
                .iter()
                .all(|c| c.size().x <= 16.0 && c.size().z <= 16.0)
        );
        assert_eq!(merged.stats.before_merge, 100);
        assert_eq!(merged.stats.cells, 9);
        // No two merged cells overlap in their interiors.
        for (a, c) in merged.cells.iter().enumerate() {
            for d in &merged.cells[a + 1..] {
                let ov = c.min.cmplt(d.max).all() && d.min.cmplt(c.max).all();
                assert!(!ov, "{c:?} {d:?}");
            }
        }
    }

    #[test]
    fn regions_fill_a_box_without_solid_cells() {
        let s = scene(vec![
            ("ground", floor(0.0, 16.0, 0.0, 16.0, 0.0)),
            (
                "block",
                solid_box(vec3(0.0, 0.0, 0.0), vec3(8.0, 8.0, 16.0)),
            ),
        ]);
        let o = AutoCellOptions {
            region: Some(Aabb::new(vec3(0.0, 0.0, 0.0), vec3(16.0, 4.0, 16.0))),
            ..opts(4.0, false)
        };
        let r = auto_cells(&s, &o).unwrap();
        // 4×4 columns, 2 layers; the half inside the block is solid.
        assert_eq!(r.stats.floors, 32);
        assert_eq!(r.stats.solid, 16);
        assert!(r.cells.iter().all(|c| c.min.x >= 8.0));
        let far = AutoCellOptions {
            region: Some(Aabb::new(vec3(100.0, 0.0, 0.0), vec3(116.0, 4.0, 16.0))),
            ..o
        };
        let e = auto_cells(&s, &far).unwrap_err().to_string();
        assert!(
            e.contains("--region") && e.contains("does not overlap"),
            "{e}"
        );
    }

    #[test]
    fn bad_options_name_the_option() {
        let s = scene(vec![("ground", floor(0.0, 16.0, 0.0, 16.0, 0.0))]);
        for (o, name) in [
            (opts(0.0, true), "--cell-size"),
            (opts(f32::NAN, true), "--cell-size"),
            (
                AutoCellOptions {
                    band: -1.0,
                    ..opts(1.0, true)
                },
                "--band",
            ),
            (
                AutoCellOptions {
                    headroom: f32::INFINITY,
                    ..opts(1.0, true)
                },
                "--headroom",
            ),
            (
                AutoCellOptions {
                    max_slope_deg: 95.0,
                    ..opts(1.0, true)
                },
                "--max-slope",
            ),
            (
                AutoCellOptions {
                    rays_per_side: 0,
                    ..opts(1.0, true)
                },
                "--rays",
            ),
            (
                AutoCellOptions {
                    max_merge: 0,
                    ..opts(1.0, true)
                },
                "--max-merge",
            ),
            (opts(0.001, true), "--cell-size"),
        ] {
            let e = auto_cells(&s, &o).unwrap_err().to_string();
            assert!(e.contains(name), "{name}: {e}");
        }
    }

    #[test]
    fn separating_axis_test_is_strict_and_exact() {
        let (min, max) = (DVec3::ZERO, DVec3::ONE);
        let t = |a: [f64; 3], b: [f64; 3], c: [f64; 3]| {
            tri_meets_open_box(&[a.into(), b.into(), c.into()], min, max)
        };
        // On a face: touching only.
        assert!(!t([0.0, 0.0, 0.0], [1.0, 0.0, 0.0], [0.0, 0.0, 1.0]));
        assert!(!t([-5.0, 1.0, -5.0], [5.0, 1.0, -5.0], [0.0, 1.0, 5.0]));
        // Through the middle.
        assert!(t([-5.0, 0.5, -5.0], [5.0, 0.5, -5.0], [0.0, 0.5, 5.0]));
        // Big triangle whose plane cuts a corner off the box.
        assert!(t([1.9, 0.0, 0.0], [0.0, 1.9, 0.0], [0.0, 0.0, 1.9]));
        // The same plane beyond the far corner: outside.
        assert!(!t([3.1, 0.0, 0.0], [0.0, 3.1, 0.0], [0.0, 0.0, 3.1]));
        // Beside the edge x = y = 1, bounds overlapping the box: outside beyond it, inside
        // before it.
        assert!(!t([1.7, 0.5, 0.5], [0.5, 1.7, 0.5], [0.5, 1.7, 0.6]));
        assert!(t([1.3, 0.5, 0.5], [0.5, 1.3, 0.5], [0.5, 1.3, 0.6]));
        // In the plane z = 0.5 with bounds overlapping the box, beyond the edge x = y = 1:
        // only an edge axis separates it.
        assert!(!t([2.0, 0.5, 0.5], [0.5, 2.0, 0.5], [2.0, 2.0, 0.5]));
        assert!(t([1.5, 0.0, 0.5], [0.0, 1.5, 0.5], [2.0, 2.0, 0.5]));
    }

    #[test]
    fn inside_test_handles_overlapping_parts_and_edges() {
        let mut parts = solid_box(vec3(0.0, 0.0, 0.0), vec3(4.0, 2.0, 2.0));
        parts.extend(solid_box(vec3(1.0, 0.0, 0.0), vec3(3.0, 2.0, 6.0)));
        let s = scene(vec![("h", parts)]);
        assert!(s.objects[0].closed);
        let g = Geometry::new(&s);
        assert!(g.inside(DVec3::new(2.0, 1.0, 1.0))); // in both parts
        assert!(g.inside(DVec3::new(0.5, 1.0, 1.0)));
        assert!(g.inside(DVec3::new(2.0, 1.0, 5.0)));
        assert!(!g.inside(DVec3::new(0.5, 1.0, 5.0)));
        assert!(!g.inside(DVec3::new(-1.0, 1.0, 1.0)));
        // Open geometry never holds anything.
        let open = Scene::from_objects(
            Path::new("t"),
            vec![("f".into(), floor(0.0, 1.0, 0.0, 1.0, 0.0), true)],
        );
        assert!(!Geometry::new(&open).inside(DVec3::new(0.5, -1.0, 0.5)));
    }

    #[test]
    fn results_do_not_depend_on_the_thread_count() {
        let s = scene(vec![
            ("ground", floor(0.0, 30.0, 0.0, 30.0, 0.0)),
            ("a", solid_box(vec3(3.0, 0.0, 5.0), vec3(9.0, 7.0, 11.0))),
            ("b", solid_box(vec3(15.0, 0.0, 2.0), vec3(21.0, 3.0, 26.0))),
        ]);
        let run = |threads| {
            rayon::ThreadPoolBuilder::new()
                .num_threads(threads)
                .build()
                .unwrap()
                .install(|| auto_cells(&s, &opts(1.5, true)).unwrap())
        };
        let (a, b) = (run(1), run(3));
        assert_eq!(a.cells, b.cells);
        assert_eq!(a.classes, b.classes);
        assert_eq!(a.stats, b.stats);
    }
}
