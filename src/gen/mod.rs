//! Scene generators for `umbrasweep gen` (owned by the generator work): deterministic, seeded
//! test scenes — a forest of leafy trees (or of instances of a real tree model), a city of
//! box buildings, a field of random boxes — written as OBJ with one `o NAME` per object, plus
//! matching view cells.
//!
//! The library side ([`forest`], [`forest_of_models`], [`city`], [`boxfield`]) builds a
//! [`Generated`] in memory, so tests and benchmarks need no files; [`Generated::to_scene`]
//! turns it into a [`Scene`] and [`write_obj`] writes it. The command itself (flags, checks of
//! the output paths, the summary line) lives in the binary; this module prints nothing and
//! returns [`GenError`].
//!
//! # Command line
//!
//! `umbrasweep gen KIND -o FILE.obj [--seed S] [--cells-out CELLS.json] [--cells N]
//! [--cell-size X[,Y,Z]] …` with `KIND` one of `forest`, `city`, `boxfield`
//! (`umbrasweep gen KIND --help` lists every option). The same options and seed always give
//! byte-identical files (whatever the number of threads); the seed defaults to 1.
//!
//! ## Forest
//!
//! Objects: `ground` (a quad at y = 0), then per tree `treeI_trunk` (a closed prism with caps)
//! and `treeI_crown0` … `treeI_crown{N-1}` (`--crown-split N` angular sectors around the
//! trunk, each with `leaves / N` leaves, ±1). Leaves are separate triangles (or planar quads
//! with `--leaf-quads`) in uniformly random orientations; a leaf's size is its diameter (the
//! longest distance between two of its corners), uniform in `--leaf-size MIN,MAX`
//! (`--leaf-size S` means `0.8·S,1.2·S`). Crowns are vertical cylinders (`--crown-shape
//! cylinder`, the default) or ellipsoids (`--crown-shape ellipsoid`) of radius `--crown-radius`
//! and vertical extent `--crown-height` starting at height `--crown-base`; every leaf lies
//! inside that box (radius and height shrink by up to `size_jitter`, 10 %, per tree). The
//! forest is a square of side `--extent`, or of `--area-per-tree` m² per tree (default 17);
//! trees sit on a jittered grid.
//!
//! A path runs through the middle of the forest along x (a gentle sine, `--path-curve` times
//! the extent in amplitude; 0 makes it straight). No trunk comes within `--path-width / 2` of
//! its centre line, and the view cells (`--cell-size`, default 1×1×1, y from 1.2) sit on that
//! centre line from one edge of the forest to the other, so every cell keeps at least 1 unit
//! (`path_clearance`) from every trunk. Leaves may reach into the path (bushy crowns do).
//!
//! Presets: `--preset coarse|fine|paper` ([`ForestOptions::coarse`], [`ForestOptions::fine`],
//! [`ForestOptions::paper`]); other flags then override single values. Without a preset the
//! options are [`ForestOptions::default`] (the coarse recipe with 100 trees).
//!
//! * Coarse forest — 1,500 trees of 1,000 leaf triangles ~1.5 units across, crowns from 0.3
//!   above the ground, one tree per 17 m², crowns split into 4 objects:
//!   `umbrasweep gen forest --trees 1500 --leaves 1000 --leaf-size 1.5 --crown-base 0.3
//!   --area-per-tree 17 --crown-split 4 -o coarse.obj --cells-out coarse_cells.json`
//!   (the same as `umbrasweep gen forest --preset coarse -o coarse.obj …`).
//! * Fine forest — the same with leaves ~0.5 units across:
//!   `umbrasweep gen forest --trees 1500 --leaves 1000 --leaf-size 0.5 --crown-base 0.3
//!   --area-per-tree 17 --crown-split 4 -o fine.obj --cells-out fine_cells.json`
//!   (or `--preset fine`).
//! * The paper's forest (Durand et al. 2000: ~7,750 trees × 1,000 leaves, 7.8 M triangles):
//!   `umbrasweep gen forest --preset paper -o paper.obj --cells-out paper_cells.json`
//!   (≈ 1 GB of OBJ).
//!
//! With `--tree-model FILE` (any file [`scene::load`](crate::scene::load) reads, e.g. a glTF
//! tree) each tree is one object `treeI` holding all the triangles of an instance of the
//! model, with a random yaw and a scale of `1 ± --scale-jitter` (default 0.2) times
//! `--model-height H / model height` (or 1). Triangles that were not opaque in the model
//! (alpha-tested leaf cards) get the material `translucent` (`d 0.5`) of an MTL file written
//! next to the OBJ, the others `opaque`, so re-importing keeps them occludee-only. The path is
//! kept clear of all opaque model geometry below eye level. With `-o FILE.glb` the forest is
//! written as glTF binary instead ([`write_glb`]), which keeps the model's alpha-tested cards
//! (materials, cutoffs, texture coordinates, wrap modes and the textures' alpha), so that a
//! forest of textured trees bakes with its cards' coverage.
//!
//! ## City
//!
//! `--blocks NX[,NZ]` blocks of `--buildings-per-block N[,M]` buildings, `--street-width`
//! apart (a grid, centred on the origin), after the test city of the ray space factorization
//! paper (Leyvand et al. 2003): each building `building_I_J` (I, J: its lot in the whole
//! city) is `--building-width MIN,MAX` (9–12) wide and deep, `--heights MIN,MAX` tall, rotated
//! by up to `--max-rotation` degrees (30) about the vertical: a podium (one box, or two or
//! three overlapping boxes for T and H shapes) and, for half of the buildings of 3 storeys
//! (`--floor-height`, 3) or more, a narrower tower set back above a storey, its base embedded
//! 1 unit in the podium (overlapping boxes fuse in the Projections; abutting ones would leave a
//! crack). Every box is a closed, outward 12-triangle box and no two boxes of a building share
//! an edge or a corner, so every building is a closed 2-manifold. Object `ground` is a quad under the whole city. Cells (`--cell-size`,
//! default 3,2,3, y from 1) line the centre lines of the streets between blocks, junctions
//! once. Example: `umbrasweep gen city --blocks 12 -o city.obj --cells-out city_cells.json`.
//!
//! ## Boxfield
//!
//! `--boxes N` closed boxes `box0` … with random orientations and sizes in `--box-size MIN,MAX`
//! (1–10 per axis) and centres in the cube of side `--extent` around the origin. Cells are the
//! cells of a grid (`--cell-size`, default 5) over that cube that overlap no box, at most
//! `--cells` (default 100).
//!
//! ## Cells
//!
//! `--cells-out CELLS.json` writes the cells (`{"cells": [{"min": […], "max": […]}, …]}`,
//! [`cells::save_json`](crate::cells::save_json)); `--cells N` keeps N of them spread evenly over the list
//! (first to last along the path or streets). Cells never intersect a trunk, a building or a
//! box.
//!
//! ## Output
//!
//! Coordinates are rounded to 1e-4 when generated and printed exactly (fixed point), so an
//! OBJ re-imports to bit-identical positions and writing stays fast (formatting runs on all
//! cores, in order). Files are written through a temporary file and a rename: a failed run
//! leaves no file behind.
//!
//! [`forest`]: crate::generate::forest()
//! [`forest_of_models`]: crate::generate::forest_of_models()
//! [`city`]: crate::generate::city()
//! [`boxfield`]: crate::generate::boxfield()
//! [`Generated`]: crate::generate::Generated
//! [`Generated::to_scene`]: crate::generate::Generated::to_scene
//! [`Scene`]: crate::scene::Scene
//! [`write_obj`]: crate::generate::write_obj()
//! [`write_glb`]: crate::generate::write_glb()
//! [`GenError`]: crate::generate::GenError
//! [`ForestOptions::coarse`]: crate::generate::ForestOptions::coarse
//! [`ForestOptions::fine`]: crate::generate::ForestOptions::fine
//! [`ForestOptions::paper`]: crate::generate::ForestOptions::paper
//! [`ForestOptions::default`]: crate::generate::ForestOptions::default

mod boxfield;
mod city;
mod forest;
mod glb;
mod write;

pub use boxfield::{BoxfieldOptions, boxfield};
pub use city::{CityOptions, city};
pub use forest::{CrownShape, ForestOptions, TreeModel, forest, forest_of_models};
pub use glb::write_glb;
pub use write::{mtl_path, write_obj};

use crate::geom::Aabb;
use crate::scene::Scene;
use glam::{Quat, Vec3};
use rand::{Rng, SeedableRng};
use std::path::Path;

/// The 4th index of a [`GenObject`] face that is a triangle.
pub const NO_VERTEX: u32 = u32::MAX;

/// One generated object: an indexed mesh with a name and per-face opacity.
#[derive(Clone, Debug, Default, PartialEq)]
pub struct GenObject {
    /// Unique name (`ground`, `tree12_trunk`, `building_3_7`, …), written as `o NAME`.
    pub name: String,
    /// Corner positions, already rounded to 1e-4 (see [`quantize`]).
    pub vertices: Vec<Vec3>,
    /// Faces as indices into `vertices`: triangles have `[3] == NO_VERTEX`, quads are planar
    /// and convex and split as `(0, 1, 2), (0, 2, 3)`. Counter-clockwise seen from the front;
    /// closed objects face outwards.
    pub faces: Vec<[u32; 4]>,
    /// Per face: false for a non-opaque (alpha-tested) face, written with a `d 0.5` material.
    pub opaque: Vec<bool>,
    /// Per face (or empty: none): the index of its alpha-tested card in
    /// [`Generated::alpha`]'s `cards`, or [`NO_CARD`](crate::scene::alpha::NO_CARD).
    pub cards: Vec<u32>,
}

impl GenObject {
    /// An empty object called `name`.
    pub fn new(name: impl Into<String>) -> Self {
        GenObject {
            name: name.into(),
            ..Default::default()
        }
    }

    /// Adds a vertex (rounded with [`quantize`]) and returns its index.
    pub fn vertex(&mut self, p: Vec3) -> u32 {
        self.vertices.push(quantize(p));
        (self.vertices.len() - 1) as u32
    }

    /// Adds a triangle.
    pub fn triangle(&mut self, a: u32, b: u32, c: u32, opaque: bool) {
        self.faces.push([a, b, c, NO_VERTEX]);
        self.opaque.push(opaque);
    }

    /// Adds a planar convex quad (two triangles on import).
    pub fn quad(&mut self, a: u32, b: u32, c: u32, d: u32, opaque: bool) {
        self.faces.push([a, b, c, d]);
        self.opaque.push(opaque);
    }

    /// Number of triangles once quads are split.
    pub fn triangle_count(&self) -> usize {
        self.faces
            .iter()
            .map(|f| if f[3] == NO_VERTEX { 1 } else { 2 })
            .sum()
    }

    /// The triangles (quads split as an importer does) with their opacity.
    pub fn triangles(&self) -> impl Iterator<Item = ([Vec3; 3], bool)> + '_ {
        let v = |i: u32| self.vertices[i as usize];
        self.faces
            .iter()
            .zip(&self.opaque)
            .flat_map(move |(f, &o)| {
                let first = ([v(f[0]), v(f[1]), v(f[2])], o);
                let second = (f[3] != NO_VERTEX).then(|| ([v(f[0]), v(f[2]), v(f[3])], o));
                std::iter::once(first).chain(second)
            })
    }

    /// Bounds of the vertices.
    pub fn bounds(&self) -> Aabb {
        Aabb::from_points(&self.vertices)
    }

    /// Adds a closed, outward-facing box from its 8 corners, corner `i` being on the `+`
    /// side of local axis `k` when bit `k` of `i` is set (the local axes must be a right-handed
    /// frame, i.e. the box a rotated axis-aligned box).
    pub fn closed_box(&mut self, corners: [Vec3; 8]) {
        let base = self.vertices.len() as u32;
        for c in corners {
            self.vertex(c);
        }
        // Quads counter-clockwise seen from outside: -x, +x, -y, +y, -z, +z.
        const QUADS: [[u32; 4]; 6] = [
            [0, 4, 6, 2],
            [1, 3, 7, 5],
            [0, 1, 5, 4],
            [2, 6, 7, 3],
            [0, 2, 3, 1],
            [4, 5, 7, 6],
        ];
        for q in QUADS {
            let [a, b, c, d] = q.map(|i| base + i);
            self.triangle(a, b, c, true);
            self.triangle(a, c, d, true);
        }
    }
}

/// A generated scene: objects in id order and the matching view cells.
#[derive(Clone, Debug, Default, PartialEq)]
pub struct Generated {
    /// Objects in id order (the order of the OBJ file).
    pub objects: Vec<GenObject>,
    /// View cells (see the module docs for where each generator puts them).
    pub cells: Vec<Aabb>,
    /// One line describing the scene, written as an OBJ comment (no file names, so output
    /// bytes do not depend on where they are written).
    pub comment: String,
    /// The alpha-tested cards of a textured tree model (materials, textures and the model's
    /// card triangles, which [`GenObject::cards`] index); `None` for untextured scenes. Kept
    /// by [`Generated::to_scene`]; OBJ output drops them (the cards stay non-opaque).
    pub alpha: Option<crate::scene::alpha::AlphaCards>,
}

impl Generated {
    /// Total number of triangles (quads count as two).
    pub fn triangle_count(&self) -> usize {
        self.objects.iter().map(GenObject::triangle_count).sum()
    }

    /// The object called `name`, if any.
    pub fn object(&self, name: &str) -> Option<&GenObject> {
        self.objects.iter().find(|o| o.name == name)
    }

    /// True when some face is not opaque (the OBJ then comes with an MTL file).
    pub fn has_translucent(&self) -> bool {
        self.objects.iter().any(|o| o.opaque.iter().any(|&x| !x))
    }

    /// The scene as [`Scene::from_objects`] builds it (object ids in order, closed objects
    /// marked), with per-triangle opacity; `source` names it in messages.
    pub fn to_scene(&self, source: impl AsRef<Path>) -> Scene {
        let objects = self
            .objects
            .iter()
            .map(|o| {
                (
                    o.name.clone(),
                    o.triangles().map(|(t, _)| t).collect(),
                    true,
                )
            })
            .collect();
        let mut scene = Scene::from_objects(source.as_ref(), objects);
        let opaque: Vec<bool> = self
            .objects
            .iter()
            .flat_map(|o| o.triangles().map(|(_, op)| op))
            .collect();
        debug_assert_eq!(opaque.len(), scene.opaque.len());
        scene.opaque = opaque;
        if let Some(template) = &self.alpha {
            use crate::scene::alpha::NO_CARD;
            let mut card_of = Vec::with_capacity(scene.triangles.len());
            for o in &self.objects {
                for (f, face) in o.faces.iter().enumerate() {
                    let card = o.cards.get(f).copied().unwrap_or(NO_CARD);
                    card_of.push(card);
                    if face[3] != NO_VERTEX {
                        card_of.push(NO_CARD);
                    }
                }
            }
            debug_assert_eq!(card_of.len(), scene.triangles.len());
            scene.alpha = Some(crate::scene::alpha::AlphaCards {
                card_of,
                ..template.clone()
            });
        }
        scene
    }
}

/// Errors of the generators: bad options or an unreadable tree model.
#[derive(Debug, thiserror::Error)]
pub enum GenError {
    /// Options that cannot make a scene; the message names the option.
    #[error("{0}")]
    Options(String),
    /// The `--tree-model` file could not be loaded.
    #[error(transparent)]
    Model(#[from] crate::scene::SceneError),
    /// [`write_obj`] could not write the OBJ or MTL file; the message names the file and the
    /// I/O error (check the folder exists, is writable and has room).
    #[error("{0}")]
    Write(String),
}

/// Rounds each coordinate to the nearest multiple of 1e-4 (as the nearest `f32`), the
/// precision every generated vertex has, so that the fixed-point OBJ text re-imports to the
/// same bits.
pub fn quantize(p: Vec3) -> Vec3 {
    let q = |x: f32| ((x as f64 * 1e4).round() / 1e4) as f32;
    Vec3::new(q(p.x), q(p.y), q(p.z))
}

/// The random generator of one independent stream (`stream`, `index`) of a seed, so that
/// parallel generation is deterministic.
pub(crate) fn rng_for(seed: u64, stream: u64, index: u64) -> rand_pcg::Pcg64Mcg {
    fn mix(mut z: u64) -> u64 {
        // splitmix64 finaliser.
        z = z.wrapping_add(0x9E37_79B9_7F4A_7C15);
        z = (z ^ (z >> 30)).wrapping_mul(0xBF58_476D_1CE4_E5B9);
        z = (z ^ (z >> 27)).wrapping_mul(0x94D0_49BB_1331_11EB);
        z ^ (z >> 31)
    }
    rand_pcg::Pcg64Mcg::seed_from_u64(mix(mix(mix(seed) ^ stream) ^ index))
}

/// True for a finite number above zero.
pub(crate) fn positive(x: f32) -> bool {
    x > 0.0 && x.is_finite()
}

/// Uniform in `[a, b)` (or `a` when `a >= b`).
pub(crate) fn uniform(rng: &mut impl Rng, a: f32, b: f32) -> f32 {
    if b > a {
        a + (b - a) * rng.random::<f32>()
    } else {
        a
    }
}

/// A uniformly distributed random rotation (Shoemake).
pub(crate) fn random_rotation(rng: &mut impl Rng) -> Quat {
    let (u1, u2, u3): (f32, f32, f32) = (rng.random(), rng.random(), rng.random());
    let tau = std::f32::consts::TAU;
    let (a, b) = ((1.0 - u1).sqrt(), u1.sqrt());
    Quat::from_xyzw(
        a * (tau * u2).sin(),
        a * (tau * u2).cos(),
        b * (tau * u3).sin(),
        b * (tau * u3).cos(),
    )
    .normalize()
}

/// Keeps `n` items spread evenly over `items` (all of them for `None` or `n >= len`).
pub(crate) fn spread<T: Copy>(items: Vec<T>, n: Option<usize>) -> Vec<T> {
    match n {
        Some(n) if n < items.len() => {
            let len = items.len();
            (0..n).map(|i| items[(2 * i + 1) * len / (2 * n)]).collect()
        }
        _ => items,
    }
}

/// A flat quad object `ground` at y = 0 over `[min.x, max.x] × [min.y, max.y]` (x, z), facing up.
pub(crate) fn ground(min: glam::Vec2, max: glam::Vec2) -> GenObject {
    let mut g = GenObject::new("ground");
    let a = g.vertex(Vec3::new(min.x, 0.0, min.y));
    let b = g.vertex(Vec3::new(min.x, 0.0, max.y));
    let c = g.vertex(Vec3::new(max.x, 0.0, max.y));
    let d = g.vertex(Vec3::new(max.x, 0.0, min.y));
    g.triangle(a, b, c, true);
    g.triangle(a, c, d, true);
    g
}

#[cfg(test)]
pub(crate) mod tests {
    use super::*;
    use std::collections::HashMap;

    /// Every undirected edge (after welding bit-identical positions) is used exactly twice,
    /// once in each direction, and the enclosed signed volume is positive (outward faces).
    pub(crate) fn closed_outward(o: &GenObject) -> bool {
        let key = |p: Vec3| p.to_array().map(f32::to_bits);
        let mut edges: HashMap<([u32; 3], [u32; 3]), i32> = HashMap::new();
        let mut volume = 0.0f64;
        for (t, _) in o.triangles() {
            for k in 0..3 {
                *edges.entry((key(t[k]), key(t[(k + 1) % 3]))).or_default() += 1;
            }
            let [a, b, c] = t.map(|p| p.as_dvec3());
            volume += a.dot(b.cross(c)) / 6.0;
        }
        volume > 0.0
            && edges
                .iter()
                .all(|(&(a, b), &n)| n == 1 && edges.get(&(b, a)) == Some(&1))
    }

    #[test]
    fn closed_box_is_closed_and_outward() {
        let mut o = GenObject::new("b");
        o.closed_box(std::array::from_fn(|i| {
            Vec3::new(
                (i & 1) as f32,
                ((i >> 1) & 1) as f32 * 2.0,
                ((i >> 2) & 1) as f32 * 3.0,
            )
        }));
        assert_eq!(o.triangle_count(), 12);
        assert!(closed_outward(&o));
        let mut flipped = o.clone();
        for f in &mut flipped.faces {
            f.swap(1, 2);
        }
        assert!(!closed_outward(&flipped));
    }

    #[test]
    fn spread_keeps_first_to_last_evenly() {
        let v: Vec<u32> = (0..100).collect();
        assert_eq!(spread(v.clone(), Some(4)), vec![12, 37, 62, 87]);
        assert_eq!(spread(v.clone(), None).len(), 100);
        assert_eq!(spread(v, Some(1000)).len(), 100);
    }

    #[test]
    fn generators_are_deterministic_and_seeded() {
        let f = |seed| {
            forest(&ForestOptions {
                seed,
                trees: 12,
                leaves: 20,
                ..ForestOptions::coarse()
            })
            .unwrap()
        };
        assert_eq!(f(5), f(5));
        assert_ne!(f(5).objects, f(6).objects);
        let c = |seed| {
            city(&CityOptions {
                seed,
                ..CityOptions::with_blocks(2, 2)
            })
            .unwrap()
        };
        assert_eq!(c(2), c(2));
        assert_ne!(c(2).objects, c(3).objects);
        let b = |seed| {
            boxfield(&BoxfieldOptions {
                seed,
                boxes: 10,
                ..Default::default()
            })
            .unwrap()
        };
        assert_eq!(b(2), b(2));
        assert_ne!(b(2).objects, b(3).objects);
    }

    #[test]
    fn forest_objects_are_named_per_tree_and_sector() {
        let o = ForestOptions {
            trees: 7,
            leaves: 30,
            crown_split: 3,
            ..ForestOptions::coarse()
        };
        let g = forest(&o).unwrap();
        assert_eq!(g.objects.len(), 1 + 7 * (1 + 3));
        assert_eq!(g.objects[0].name, "ground");
        assert_eq!(g.objects[1].name, "tree0_trunk");
        assert_eq!(g.objects[4].name, "tree0_crown2");
        assert_eq!(g.objects[28].name, "tree6_crown2");
        let leaves: usize = g
            .objects
            .iter()
            .filter(|x| x.name.starts_with("tree0_crown"))
            .map(|x| x.faces.len())
            .sum();
        assert_eq!(leaves, 30);
        let scene = g.to_scene("forest");
        assert_eq!(scene.objects.len(), g.objects.len());
        assert_eq!(scene.triangles.len(), g.triangle_count());
    }
}
