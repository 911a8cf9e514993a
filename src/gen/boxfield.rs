//! `gen boxfield`: randomly oriented closed boxes in a cube, with view cells on a grid of
//! that cube wherever they overlap no box.

use super::{GenError, GenObject, Generated, random_rotation, rng_for, spread, uniform};
use crate::geom::Aabb;
use glam::{Quat, Vec3};

/// Options of [`boxfield`].
#[derive(Clone, Debug, PartialEq)]
pub struct BoxfieldOptions {
    /// Seed of the random generator.
    pub seed: u64,
    /// Number of boxes.
    pub boxes: u32,
    /// Side of the cube (centred on the origin) holding the box centres and the cells.
    pub extent: f32,
    /// Range of each side length of a box.
    pub box_size: [f32; 2],
    /// Size of the grid cells tried as view cells.
    pub cell_size: Vec3,
    /// Keep at most this many free cells (spread evenly over the grid order).
    pub max_cells: Option<usize>,
}

impl Default for BoxfieldOptions {
    /// 200 boxes of 1–10 per side in a cube of side 100, at most 100 cells of 5³.
    fn default() -> Self {
        BoxfieldOptions {
            seed: 1,
            boxes: 200,
            extent: 100.0,
            box_size: [1.0, 10.0],
            cell_size: Vec3::splat(5.0),
            max_cells: Some(100),
        }
    }
}

/// An oriented box: centre, rotation, half sizes.
#[derive(Clone, Copy)]
struct Obb {
    centre: Vec3,
    axes: [Vec3; 3],
    half: Vec3,
}

impl Obb {
    fn new(centre: Vec3, rot: Quat, half: Vec3) -> Self {
        Obb {
            centre,
            axes: [rot * Vec3::X, rot * Vec3::Y, rot * Vec3::Z],
            half,
        }
    }

    fn aabb(&self) -> Aabb {
        let r = Vec3::new(
            self.axes
                .iter()
                .zip(self.half.to_array())
                .map(|(a, h)| a.x.abs() * h)
                .sum(),
            self.axes
                .iter()
                .zip(self.half.to_array())
                .map(|(a, h)| a.y.abs() * h)
                .sum(),
            self.axes
                .iter()
                .zip(self.half.to_array())
                .map(|(a, h)| a.z.abs() * h)
                .sum(),
        );
        Aabb::new(self.centre - r, self.centre + r)
    }

    /// Separating-axis test against an axis-aligned box grown by `margin`: true when they may
    /// overlap.
    fn overlaps(&self, b: &Aabb, margin: f32) -> bool {
        let c = b.center();
        let h = b.size() * 0.5 + margin;
        let d = self.centre - c;
        let mut axes: Vec<Vec3> = vec![Vec3::X, Vec3::Y, Vec3::Z];
        axes.extend(self.axes);
        for e in [Vec3::X, Vec3::Y, Vec3::Z] {
            for a in self.axes {
                let x = e.cross(a);
                if x.length_squared() > 1e-6 {
                    axes.push(x.normalize());
                }
            }
        }
        axes.iter().all(|l| {
            let ra = h.x * l.x.abs() + h.y * l.y.abs() + h.z * l.z.abs();
            let rb: f32 = self
                .axes
                .iter()
                .zip(self.half.to_array())
                .map(|(a, hb)| hb * a.dot(*l).abs())
                .sum();
            d.dot(*l).abs() <= ra + rb
        })
    }
}

/// Generates `box0`, `box1`, …: closed boxes with random orientation, size and position;
/// cells are the grid cells of the cube that overlap no box (with a 0.01 margin).
///
/// # Errors
/// [`GenError::Options`] for bad sizes or counts.
pub fn boxfield(o: &BoxfieldOptions) -> Result<Generated, GenError> {
    if o.boxes == 0
        || !super::positive(o.extent)
        || !(o.box_size[0] > 0.0 && o.box_size[0] <= o.box_size[1])
    {
        return Err(GenError::Options(
            "--boxes must be at least 1, --extent positive and --box-size MIN,MAX positive with MIN at most MAX".into(),
        ));
    }
    if o.cell_size.cmple(Vec3::ZERO).any() || !o.cell_size.is_finite() {
        return Err(GenError::Options(format!(
            "--cell-size {:?}: every side must be positive",
            o.cell_size.to_array()
        )));
    }
    let mut boxes = Vec::with_capacity(o.boxes as usize);
    let mut objects = Vec::with_capacity(o.boxes as usize);
    let half_extent = 0.5 * o.extent;
    for i in 0..o.boxes {
        let mut rng = rng_for(o.seed, 4, i as u64);
        let size = Vec3::new(
            uniform(&mut rng, o.box_size[0], o.box_size[1]),
            uniform(&mut rng, o.box_size[0], o.box_size[1]),
            uniform(&mut rng, o.box_size[0], o.box_size[1]),
        );
        let rot = random_rotation(&mut rng);
        let centre = Vec3::new(
            uniform(&mut rng, -half_extent, half_extent),
            uniform(&mut rng, -half_extent, half_extent),
            uniform(&mut rng, -half_extent, half_extent),
        );
        let obb = Obb::new(centre, rot, 0.5 * size);
        let mut obj = GenObject::new(format!("box{i}"));
        obj.closed_box(std::array::from_fn(|k| {
            let s = |bit: usize| if k & bit != 0 { 1.0 } else { -1.0 };
            centre
                + obb.axes[0] * (s(1) * obb.half.x)
                + obb.axes[1] * (s(2) * obb.half.y)
                + obb.axes[2] * (s(4) * obb.half.z)
        }));
        objects.push(obj);
        boxes.push(obb);
    }

    // Grid of candidate cells; each box marks the cells its bounds touch, then exact tests.
    let c = o.cell_size;
    let n = (Vec3::splat(o.extent) / c)
        .floor()
        .max(Vec3::ZERO)
        .as_uvec3();
    let origin = Vec3::splat(-half_extent) + 0.5 * (Vec3::splat(o.extent) - n.as_vec3() * c);
    let count = (n.x * n.y * n.z) as usize;
    let mut blocked = vec![false; count];
    let cell = |i: u32, j: u32, k: u32| {
        let min = origin + Vec3::new(i as f32, j as f32, k as f32) * c;
        Aabb::new(min, min + c)
    };
    let margin = 0.01;
    for b in &boxes {
        let bb = b.aabb();
        let lo = ((bb.min - margin - origin) / c)
            .floor()
            .max(Vec3::ZERO)
            .as_uvec3();
        let hi = ((bb.max + margin - origin) / c).floor().as_ivec3();
        if hi.min_element() < 0 {
            continue;
        }
        let hi = hi.as_uvec3().min(n.saturating_sub(glam::UVec3::ONE));
        for k in lo.z..=hi.z {
            for j in lo.y..=hi.y {
                for i in lo.x..=hi.x {
                    if i >= n.x || j >= n.y || k >= n.z {
                        continue;
                    }
                    let idx = ((k * n.y + j) * n.x + i) as usize;
                    if !blocked[idx] && b.overlaps(&cell(i, j, k), margin) {
                        blocked[idx] = true;
                    }
                }
            }
        }
    }
    let mut cells = Vec::new();
    for k in 0..n.z {
        for j in 0..n.y {
            for i in 0..n.x {
                if !blocked[((k * n.y + j) * n.x + i) as usize] {
                    cells.push(cell(i, j, k));
                }
            }
        }
    }
    Ok(Generated {
        objects,
        cells: spread(cells, o.max_cells),
        comment: format!(
            "boxfield of {} boxes of {}–{} in a cube of side {}",
            o.boxes, o.box_size[0], o.box_size[1], o.extent
        ),
        alpha: None,
    })
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn boxes_are_closed_and_cells_free() {
        let o = BoxfieldOptions {
            boxes: 60,
            extent: 40.0,
            max_cells: None,
            ..Default::default()
        };
        let g = boxfield(&o).unwrap();
        assert_eq!(g.objects.len(), 60);
        assert!(g.cells.len() > 50);
        for b in &g.objects {
            assert!(super::super::tests::closed_outward(b), "{}", b.name);
            // No box corner in a cell, no cell corner... (exact checks live in tests/gen.rs).
            for c in &g.cells {
                assert!(b.vertices.iter().all(|v| !c.contains_point(*v)));
            }
        }
    }

    #[test]
    fn separating_axis_test_finds_overlaps_and_gaps() {
        let rot = Quat::from_rotation_y(0.7);
        let b = Obb::new(Vec3::ZERO, rot, Vec3::splat(1.0));
        assert!(b.overlaps(&Aabb::new(Vec3::splat(0.5), Vec3::splat(3.0)), 0.0));
        assert!(!b.overlaps(
            &Aabb::new(Vec3::new(1.45, -1.0, 1.45), Vec3::splat(3.0)),
            0.0
        ));
        assert!(b.overlaps(&Aabb::new(Vec3::new(1.3, -1.0, 0.0), Vec3::splat(3.0)), 0.0));
    }
}
