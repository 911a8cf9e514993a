//! Setup shared by the sampler's probe examples (`sampler_bands`, `sampler_leaks`,
//! `sampler_points`, `sampler_probe`, `sampler_render_bench`, `sampler_slabs`, `sampler_why`,
//! `sweep_bench`): which face of a cell a probe looks out of, the eye on it, the objects
//! beyond it, the sampler's per-scene data, and the arguments most of them begin with. Each
//! example uses part of it.
#![allow(dead_code, reason = "each example uses part of this module")]

use glam::DVec3;
use umbrasweep::bake::{BakeSettings, SamplerData};
use umbrasweep::geom::DAabb;
use umbrasweep::sampler::Occludees;
use umbrasweep::scene::Scene;

/// One face of a cell: outward normal `sign × e_axis`.
#[derive(Clone, Copy, Debug)]
pub struct Face {
    pub axis: usize,
    pub sign: f64,
}

impl Face {
    /// `+x -x +y -y +z -z`.
    ///
    /// # Panics
    /// On any other name.
    pub fn parse(name: &str) -> Face {
        let sign = match name.as_bytes().first() {
            Some(b'+') => 1.0,
            Some(b'-') => -1.0,
            _ => panic!("face {name:?}: expected one of +x -x +y -y +z -z"),
        };
        let axis = match &name[1..] {
            "x" => 0,
            "y" => 1,
            "z" => 2,
            _ => panic!("face {name:?}: expected one of +x -x +y -y +z -z"),
        };
        Face { axis, sign }
    }

    /// Faces numbered as the sampler numbers them: −x, +x, −y, +y, −z, +z.
    pub fn from_index(k: usize) -> Face {
        Face {
            axis: k / 2,
            sign: if k.is_multiple_of(2) { -1.0 } else { 1.0 },
        }
    }

    /// The coordinate of the face's plane along its axis.
    pub fn plane(self, cell: &DAabb) -> f64 {
        if self.sign > 0.0 {
            cell.max[self.axis]
        } else {
            cell.min[self.axis]
        }
    }

    /// `p` moved onto the face's plane along the face's axis.
    pub fn onto(self, cell: &DAabb, mut p: DVec3) -> DVec3 {
        p[self.axis] = self.plane(cell);
        p
    }

    /// The centre of the face.
    pub fn centre(self, cell: &DAabb) -> DVec3 {
        self.onto(cell, cell.center())
    }

    /// Whether a box reaches the outer side of the face's plane (closed half-space).
    pub fn reaches(self, cell: &DAabb, b: &DAabb) -> bool {
        if self.sign > 0.0 {
            b.max[self.axis] >= self.plane(cell)
        } else {
            b.min[self.axis] <= self.plane(cell)
        }
    }

    /// The objects a probe on this face tests, as the sampler picks them: non-empty, not
    /// meeting the cell, reaching the outer side of the face. Their indices and boxes.
    pub fn beyond(self, scene: &Scene, cell: &DAabb) -> (Vec<usize>, Vec<DAabb>) {
        (0..scene.objects.len())
            .filter_map(|o| {
                let b = scene.objects[o].bounds;
                if b.is_empty() {
                    return None;
                }
                let b = b.to_f64();
                (!b.overlaps(cell) && self.reaches(cell, &b)).then_some((o, b))
            })
            .unzip()
    }
}

/// A generator of uniform numbers in `[0, 1)` from `seed` (a 64-bit linear congruential
/// generator's top 53 bits): the examples' fixed pseudo-random points.
pub fn uniform(mut seed: u64) -> impl FnMut() -> f64 {
    move || {
        seed = seed
            .wrapping_mul(6364136223846793005)
            .wrapping_add(1442695040888963407);
        (seed >> 11) as f64 / (1u64 << 53) as f64
    }
}

/// The sampler's data for a scene with every object an occluder, no alpha-tested cards and
/// the default settings.
pub fn sampler_data(scene: &Scene) -> SamplerData {
    let occ = umbrasweep::project::occluders::prepare_with(
        scene,
        &vec![true; scene.objects.len()],
        false,
        None,
    );
    SamplerData::new(&occ, scene, &BakeSettings::default())
}

/// The arguments `SCENE CELLS CELL EPS RES` that most sampler examples begin with
/// (`args[1..=5]`, `args[0]` the program): the scene, the box of cell `CELL` of the cells
/// file, ε and the pixels per view.
///
/// # Panics
/// A file that does not load or an argument that does not parse, naming the argument.
pub fn scene_cell_eps_res(args: &[String]) -> (Scene, DAabb, f64, u32) {
    let scene = umbrasweep::scene::load(std::path::Path::new(&args[1])).expect("SCENE");
    let cells = umbrasweep::cells::load_json(std::path::Path::new(&args[2])).expect("CELLS");
    let ci: usize = args[3].parse().expect("CELL");
    let eps = args[4].parse().expect("EPS");
    let res = args[5].parse().expect("RES");
    (scene, cells[ci].to_f64(), eps, res)
}

/// `n` eyes at fixed pseudo-random places on a cell's faces (the same every run), face by
/// face in turn (numbered as [`Face::from_index`]): the benches' rectangles.
pub fn fixed_eyes(cell: &DAabb, n: usize) -> Vec<(usize, DVec3)> {
    let mut rnd = uniform(7u64);
    (0..n)
        .map(|k| {
            let f = k % 6;
            let mut eye = DVec3::ZERO;
            for a in 0..3 {
                eye[a] = cell.min[a] + rnd() * (cell.max[a] - cell.min[a]);
            }
            (f, Face::from_index(f).onto(cell, eye))
        })
        .collect()
}

/// Objects as the per-rectangle sweep tests them: each its box, one piece (the box again)
/// and the scene triangles of `objects`.
pub struct BoxObjects<'a> {
    pub scene: &'a Scene,
    pub boxes: Vec<DAabb>,
    pub tris: Vec<Vec<u32>>,
}

impl<'a> BoxObjects<'a> {
    /// Scene objects `objects` with their boxes `boxes`.
    pub fn new(scene: &'a Scene, objects: &[usize], boxes: Vec<DAabb>) -> Self {
        BoxObjects {
            scene,
            boxes,
            tris: objects
                .iter()
                .map(|&o| scene.objects[o].triangles.clone().collect())
                .collect(),
        }
    }
}

impl Occludees for BoxObjects<'_> {
    fn len(&self) -> usize {
        self.boxes.len()
    }
    fn object_box(&self, i: usize) -> DAabb {
        self.boxes[i]
    }
    fn pieces(&self, i: usize) -> std::ops::Range<u32> {
        i as u32..i as u32 + 1
    }
    fn piece_box(&self, k: u32) -> DAabb {
        self.boxes[k as usize]
    }
    fn piece_triangles(&self, k: u32) -> &[u32] {
        &self.tris[k as usize]
    }
    fn triangle(&self, t: u32) -> [DVec3; 3] {
        self.scene.triangle(t as usize).map(|p| p.as_dvec3())
    }
}
