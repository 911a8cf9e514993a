//! `gen city`: a grid of blocks of closed box buildings (a podium and a set-back tower, some H or T shaped,
//! rotated up to 30°), streets between the blocks, a ground quad, and view cells along the
//! streets at eye height.

use super::{GenError, GenObject, Generated, ground, rng_for, spread, uniform};
use crate::geom::Aabb;
use glam::{Vec2, Vec3};
use rand::Rng;
use rayon::prelude::*;

/// Options of [`city`]; the default is a 12×12-block city.
#[derive(Clone, Debug, PartialEq)]
pub struct CityOptions {
    /// Seed of the random generator.
    pub seed: u64,
    /// Blocks along x and z.
    pub blocks: [u32; 2],
    /// Width of the streets between blocks (and around the city, on the ground quad).
    pub street_width: f32,
    /// Buildings per block along x and z (one lot each).
    pub buildings_per_block: [u32; 2],
    /// Width and depth range of a building's footprint.
    pub building_width: [f32; 2],
    /// Height range of a building.
    pub heights: [f32; 2],
    /// Nominal storey height: setbacks happen at a whole storey.
    pub floor_height: f32,
    /// Largest rotation about the vertical, in degrees.
    pub max_rotation_deg: f32,
    /// Fraction of H- or T-shaped buildings (half each).
    pub shaped_fraction: f32,
    /// Least gap between the rotated footprints of neighbouring lots (and a street's edge).
    pub lot_gap: f32,
    /// Size of the cells.
    pub cell_size: Vec3,
    /// Height of the bottom of the cells.
    pub cell_base: f32,
    /// Keep at most this many cells (spread evenly over the streets).
    pub max_cells: Option<usize>,
}

impl CityOptions {
    /// A `nx × nz`-block city with the default buildings.
    pub const fn with_blocks(nx: u32, nz: u32) -> Self {
        CityOptions {
            seed: 1,
            blocks: [nx, nz],
            street_width: 10.0,
            buildings_per_block: [2, 2],
            building_width: [9.0, 12.0],
            heights: [6.0, 36.0],
            floor_height: 3.0,
            max_rotation_deg: 30.0,
            shaped_fraction: 0.4,
            lot_gap: 2.0,
            cell_size: Vec3::new(3.0, 2.0, 3.0),
            cell_base: 1.0,
            max_cells: None,
        }
    }

    /// The shipped demo (`data/demo_city.obj`): 4×4 blocks, 24 cells.
    pub const fn demo() -> Self {
        CityOptions {
            max_cells: Some(24),
            ..Self::with_blocks(4, 4)
        }
    }
}

impl Default for CityOptions {
    /// 12×12 blocks of 2×2 buildings.
    fn default() -> Self {
        Self::with_blocks(12, 12)
    }
}

/// The city's plan: lot size and block positions.
struct Plan {
    lot: f32,
    block: Vec2,
    size: Vec2,
}

impl Plan {
    fn new(o: &CityOptions) -> Self {
        let t = o.max_rotation_deg.to_radians();
        // Widest axis-aligned extent of a rotated footprint.
        let spread = if t < std::f32::consts::FRAC_PI_4 {
            t.cos() + t.sin()
        } else {
            std::f32::consts::SQRT_2
        };
        let lot = o.building_width[1] * spread + o.lot_gap;
        let block = Vec2::new(
            o.buildings_per_block[0] as f32,
            o.buildings_per_block[1] as f32,
        ) * lot;
        let n = Vec2::new(o.blocks[0] as f32, o.blocks[1] as f32);
        let size = n * block + (n - 1.0) * o.street_width;
        Plan { lot, block, size }
    }

    /// Low corner (x, z) of block `(i, j)`.
    fn block_min(&self, i: u32, j: u32, street: f32) -> Vec2 {
        -0.5 * self.size + Vec2::new(i as f32, j as f32) * (self.block + street)
    }
}

fn check(o: &CityOptions) -> Result<(), GenError> {
    let bad = |m: String| Err(GenError::Options(m));
    if o.blocks.contains(&0) || o.buildings_per_block.contains(&0) {
        return bad("--blocks and --buildings-per-block must be at least 1".into());
    }
    if !(o.building_width[0] > 0.0 && o.building_width[0] <= o.building_width[1]) {
        return bad(format!(
            "--building-width {},{}: must be positive with MIN at most MAX",
            o.building_width[0], o.building_width[1]
        ));
    }
    if !(o.heights[0] > 0.0 && o.heights[0] <= o.heights[1] && o.floor_height > 0.0) {
        return bad(
            "--heights must be positive with MIN at most MAX, --floor-height positive".into(),
        );
    }
    if !(0.0..=90.0).contains(&o.max_rotation_deg) || !(0.0..=1.0).contains(&o.shaped_fraction) {
        return bad("--max-rotation must be in [0, 90] degrees and --shaped in [0, 1]".into());
    }
    if !(o.street_width > 0.0 && o.lot_gap >= 0.2) {
        return bad("--street-width must be positive".into());
    }
    if o.cell_size.cmple(Vec3::ZERO).any() || !o.cell_size.is_finite() {
        return bad(format!(
            "--cell-size {:?}: every side must be positive",
            o.cell_size.to_array()
        ));
    }
    if o.cell_size.x >= o.street_width || o.cell_size.z >= o.street_width {
        return bad(format!(
            "--cell-size {}×{} (x, z) must be narrower than the streets (--street-width {})",
            o.cell_size.x, o.cell_size.z, o.street_width
        ));
    }
    Ok(())
}

/// Generates a city: `ground`, then `building_I_J` for every lot `(I, J)` (x, z), with cells
/// along the centre lines of the streets between blocks (x streets first, then the z streets
/// between junctions).
///
/// # Errors
/// [`GenError::Options`] for options that cannot make a city (naming the flag).
pub fn city(o: &CityOptions) -> Result<Generated, GenError> {
    check(o)?;
    let plan = Plan::new(o);
    let s = o.street_width;
    let [bx, bz] = o.buildings_per_block;
    let lots: Vec<(u32, u32, Vec2)> = (0..o.blocks[1] * bz)
        .flat_map(|gz| (0..o.blocks[0] * bx).map(move |gx| (gx, gz)))
        .map(|(gx, gz)| {
            let min = plan.block_min(gx / bx, gz / bz, s);
            let centre = min + (Vec2::new((gx % bx) as f32, (gz % bz) as f32) + 0.5) * plan.lot;
            (gx, gz, centre)
        })
        .collect();
    let mut objects = Vec::with_capacity(1 + lots.len());
    objects.push(ground(-0.5 * plan.size - s, 0.5 * plan.size + s));
    let buildings: Vec<GenObject> = lots
        .par_iter()
        .map(|&(gx, gz, centre)| {
            let id = (gz as u64) * (o.blocks[0] * bx) as u64 + gx as u64;
            building(o, &plan, format!("building_{gx}_{gz}"), centre, id)
        })
        .collect();
    objects.extend(buildings);
    Ok(Generated {
        objects,
        cells: spread(street_cells(o, &plan), o.max_cells),
        comment: format!(
            "city of {}×{} blocks of {}×{} buildings, streets {s} wide",
            o.blocks[0], o.blocks[1], bx, bz
        ),
        alpha: None,
    })
}

/// The shape of one storey, as rectangles `[x0, x1, z0, z1]` in the building's frame.
fn storey_parts(shape: u8, w: f32, d: f32) -> Vec<[f32; 4]> {
    const OVERLAP: f32 = 0.25;
    let (hw, hd) = (0.5 * w, 0.5 * d);
    match shape {
        // H: two wings and a crossbar reaching into them.
        1 => vec![
            [-hw, -hw + w / 3.0, -hd, hd],
            [hw - w / 3.0, hw, -hd, hd],
            [-w / 6.0 - OVERLAP, w / 6.0 + OVERLAP, -d / 6.0, d / 6.0],
        ],
        // T: a bar along the back and a stem reaching into it.
        2 => vec![
            [-hw, hw, hd - d / 3.0, hd],
            [-w / 6.0, w / 6.0, -hd, hd - d / 3.0 + OVERLAP],
        ],
        _ => vec![[-hw, hw, -hd, hd]],
    }
}

/// One building: a podium (one box, or for H and T shapes a few overlapping boxes) and, above
/// a setback at a random storey for half of the taller buildings, a narrower tower embedded
/// in it; no two boxes share a corner.
fn building(o: &CityOptions, plan: &Plan, name: String, centre: Vec2, id: u64) -> GenObject {
    let mut rng = rng_for(o.seed, 3, id);
    let w = uniform(&mut rng, o.building_width[0], o.building_width[1]);
    let d = uniform(&mut rng, o.building_width[0], o.building_width[1]);
    let t = uniform(&mut rng, -o.max_rotation_deg, o.max_rotation_deg).to_radians();
    let h = uniform(&mut rng, o.heights[0], o.heights[1]);
    let r: f32 = rng.random();
    let shape = if r < 0.5 * o.shaped_fraction {
        1
    } else if r < o.shaped_fraction {
        2
    } else {
        0
    };
    let storeys = ((h / o.floor_height).round() as u32).max(1);
    let setback =
        (storeys >= 3 && rng.random_bool(0.5)).then(|| rng.random_range(storeys / 2..storeys));
    let setback_scale = uniform(&mut rng, 0.7, 0.85);
    let (sin, cos) = t.sin_cos();
    let extent = Vec2::new(w * cos.abs() + d * sin.abs(), w * sin.abs() + d * cos.abs());
    let slack = ((plan.lot - o.lot_gap) - extent).max(Vec2::ZERO) * 0.5;
    let centre = centre
        + Vec2::new(
            uniform(&mut rng, -slack.x, slack.x),
            uniform(&mut rng, -slack.y, slack.y),
        );

    let mut b = GenObject::new(name);
    // Tiers, not storeys: the podium (one box, or the overlapping boxes of an H or T) up to the
    // setback, then a narrower tower whose base sits inside the podium, so the boxes overlap
    // rather than abut (abutting boxes would leave a crack between their Projections).
    let top_of_podium = setback.map_or(h, |sb| sb as f32 * (h / storeys as f32));
    let mut tiers = vec![(0.0, top_of_podium, storey_parts(shape, w, d))];
    if top_of_podium < h {
        let base = (top_of_podium - TOWER_EMBED).max(0.0);
        tiers.push((
            base,
            h,
            storey_parts(0, w * setback_scale, d * setback_scale),
        ));
    }
    for (y0, y1, parts) in tiers {
        for [x0, x1, z0, z1] in parts {
            let corners = std::array::from_fn(|i| {
                let x = if i & 1 != 0 { x1 } else { x0 };
                let y = if i & 2 != 0 { y1 } else { y0 };
                let z = if i & 4 != 0 { z1 } else { z0 };
                Vec3::new(
                    centre.x + cos * x + sin * z,
                    y,
                    centre.y - sin * x + cos * z,
                )
            });
            b.closed_box(corners);
        }
    }
    b
}

/// How far a set-back tower reaches down into its podium.
const TOWER_EMBED: f32 = 1.0;

/// Cells on the centre lines of the streets between blocks: along each x street over the
/// whole city, then along each z street between the junctions.
fn street_cells(o: &CityOptions, plan: &Plan) -> Vec<Aabb> {
    let c = o.cell_size;
    let s = o.street_width;
    let (y0, y1) = (o.cell_base, o.cell_base + c.y);
    let mut cells = Vec::new();
    // Streets along x, between block rows j and j + 1.
    for j in 0..o.blocks[1].saturating_sub(1) {
        let zc = plan.block_min(0, j, s).y + plan.block.y + 0.5 * s;
        let count = (plan.size.x / c.x).floor() as usize;
        let x0 = -0.5 * count as f32 * c.x;
        for i in 0..count {
            let x = x0 + i as f32 * c.x;
            cells.push(Aabb::new(
                Vec3::new(x, y0, zc - 0.5 * c.z),
                Vec3::new(x + c.x, y1, zc + 0.5 * c.z),
            ));
        }
    }
    // Streets along z, between block columns i and i + 1, only beside the blocks.
    for i in 0..o.blocks[0].saturating_sub(1) {
        let xc = plan.block_min(i, 0, s).x + plan.block.x + 0.5 * s;
        for j in 0..o.blocks[1] {
            let zmin = plan.block_min(0, j, s).y;
            let count = (plan.block.y / c.z).floor() as usize;
            let z0 = zmin + 0.5 * (plan.block.y - count as f32 * c.z);
            for k in 0..count {
                let z = z0 + k as f32 * c.z;
                cells.push(Aabb::new(
                    Vec3::new(xc - 0.5 * c.x, y0, z),
                    Vec3::new(xc + 0.5 * c.x, y1, z + c.z),
                ));
            }
        }
    }
    cells
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn every_building_is_closed_and_outward() {
        for seed in 1..4 {
            let o = CityOptions {
                seed,
                shaped_fraction: 0.8,
                ..CityOptions::with_blocks(3, 2)
            };
            let g = city(&o).unwrap();
            assert_eq!(g.objects.len(), 1 + 3 * 2 * 4);
            for b in &g.objects[1..] {
                assert!(
                    super::super::tests::closed_outward(b),
                    "{} is not closed",
                    b.name
                );
            }
        }
    }

    #[test]
    fn buildings_stay_in_their_lots_and_cells_on_the_streets() {
        let o = CityOptions::with_blocks(3, 3);
        let g = city(&o).unwrap();
        assert!(!g.cells.is_empty());
        for b in &g.objects[1..] {
            let bb = b.bounds();
            assert!(bb.size().x <= 12.0 * 1.3661 + 0.01 && bb.size().z <= 12.0 * 1.3661 + 0.01);
            for c in &g.cells {
                let flat = |a: &Aabb| {
                    Aabb::new(
                        Vec3::new(a.min.x, 0.0, a.min.z),
                        Vec3::new(a.max.x, 0.0, a.max.z),
                    )
                };
                assert!(!flat(&bb).overlaps(&flat(c)), "{} overlaps a cell", b.name);
                assert_eq!((c.min.y, c.max.y), (1.0, 3.0));
            }
        }
    }
}
