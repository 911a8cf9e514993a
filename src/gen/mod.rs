//! Scene generators for `umbrasweep gen` (owned by the generator work): deterministic, seeded
//! test scenes — a forest of leafy trees (or of instances of a real tree model), a city of
//! box buildings, a field of random boxes — written as OBJ with one `o NAME` per object, plus
//! matching view cells.
//!
//! The library side ([`forest`], [`forest_of_models`], [`city`], [`boxfield`]) builds a
//! [`Generated`] in memory, so tests and benchmarks need no files; [`Generated::to_scene`]
//! turns it into a [`Scene`] and [`write_obj`] writes it. The command-line side is
//! [`GenArgs`] and [`run`].
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
//! kept clear of all opaque model geometry below eye level.
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

mod boxfield;
mod city;
mod forest;
mod write;

pub use boxfield::{BoxfieldOptions, boxfield};
pub use city::{CityOptions, city};
pub use forest::{CrownShape, ForestOptions, TreeModel, forest, forest_of_models};
pub use write::{mtl_path, write_obj};

use crate::geom::Aabb;
use crate::scene::Scene;
use anyhow::{Context, bail};
use glam::{Quat, Vec3};
use rand::{Rng, SeedableRng};
use std::path::{Path, PathBuf};

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

// ---------------------------------------------------------------------------------------
// Command line
// ---------------------------------------------------------------------------------------

/// Options of `umbrasweep gen`: the kind of scene is a subcommand.
#[derive(clap::Args, Debug, Clone)]
pub struct GenArgs {
    /// What to generate.
    #[command(subcommand)]
    pub kind: GenKind,
}

/// The kinds of scene `umbrasweep gen` makes.
#[derive(clap::Subcommand, Debug, Clone)]
pub enum GenKind {
    /// Trees (trunk + leaf crowns, or instances of --tree-model) on a ground plane, with
    /// view cells along a path through the middle.
    Forest(ForestArgs),
    /// Blocks of box buildings with streets between them, with view cells along the streets.
    City(CityArgs),
    /// Randomly oriented boxes in a cube, with view cells in free space.
    Boxfield(BoxfieldArgs),
}

/// Options shared by every kind.
#[derive(clap::Args, Debug, Clone)]
pub struct CommonArgs {
    /// The OBJ file to write (an MTL file beside it too when some faces are translucent).
    #[arg(short = 'o', long = "output", value_name = "FILE.obj")]
    pub output: PathBuf,
    /// Seed of the random generator: the same seed and options give identical files.
    #[arg(long, default_value_t = 1)]
    pub seed: u64,
    /// Also write the matching view cells to this JSON file.
    #[arg(long, value_name = "CELLS.json")]
    pub cells_out: Option<PathBuf>,
    /// Keep at most N cells, spread evenly over the path, streets or free grid cells.
    #[arg(long, value_name = "N")]
    pub cells: Option<usize>,
    /// Size of the cells: X (a cube) or X,Y,Z (default forest: 1,1,1; city: 3,2,3; boxfield: 5).
    #[arg(long, value_name = "X[,Y,Z]", value_parser = parse_size3)]
    pub cell_size: Option<Vec3>,
}

/// A named set of forest options.
#[derive(clap::ValueEnum, Debug, Clone, Copy, PartialEq, Eq)]
pub enum ForestPreset {
    /// 1,500 trees × 1,000 leaves ~1.5 across from 0.3 up, 17 m² per tree, 4 crown objects.
    Coarse,
    /// The coarse forest with leaves ~0.5 across.
    Fine,
    /// The paper's forest: the coarse forest with 7,750 trees (7.8 M triangles).
    Paper,
    /// The shipped demo: 60 trees × 200 leaves, 10 cells.
    Demo,
}

/// Options of `umbrasweep gen forest` (unset values come from --preset or the defaults).
#[derive(clap::Args, Debug, Clone)]
pub struct ForestArgs {
    #[command(flatten)]
    pub common: CommonArgs,
    /// Start from these options (other flags override single values).
    #[arg(long, value_enum)]
    pub preset: Option<ForestPreset>,
    /// Number of trees (default 100).
    #[arg(long)]
    pub trees: Option<u32>,
    /// Leaves per tree (default 1000).
    #[arg(long)]
    pub leaves: Option<u32>,
    /// Leaf diameter: MIN,MAX, or S for 0.8·S,1.2·S (default 1.5).
    #[arg(long, value_name = "S|MIN,MAX", value_parser = parse_pair)]
    pub leaf_size: Option<Pair>,
    /// Emit leaves as planar quads instead of triangles.
    #[arg(long)]
    pub leaf_quads: bool,
    /// Vertical extent of the crowns (default 4.5).
    #[arg(long)]
    pub crown_height: Option<f32>,
    /// Height where the crowns start (default 0.3).
    #[arg(long)]
    pub crown_base: Option<f32>,
    /// Horizontal radius of the crowns (default 2.2).
    #[arg(long)]
    pub crown_radius: Option<f32>,
    /// Volume the leaves of a crown fill (default cylinder).
    #[arg(long, value_enum)]
    pub crown_shape: Option<CrownShape>,
    /// Split each crown into N objects (angular sectors around the trunk) (default 4).
    #[arg(long, value_name = "N")]
    pub crown_split: Option<u32>,
    /// With --tree-model: split each tree into N objects, angular sectors around its trunk
    /// (default 1: one object per tree).
    #[arg(long, value_name = "N", requires = "tree_model")]
    pub model_split: Option<u32>,
    /// Trunk radius (default 0.15).
    #[arg(long)]
    pub trunk_radius: Option<f32>,
    /// Sides of the trunk prism (default 6).
    #[arg(long)]
    pub trunk_sides: Option<u32>,
    /// Side of the square forest (instead of --area-per-tree).
    #[arg(long, conflicts_with = "area_per_tree")]
    pub extent: Option<f32>,
    /// Ground area per tree in m², giving the side of the forest (default 17; tree models: from the model).
    #[arg(long)]
    pub area_per_tree: Option<f32>,
    /// Width of the trunk-free lane around the path's centre line (default 4).
    #[arg(long)]
    pub path_width: Option<f32>,
    /// Amplitude of the path's sine, as a fraction of the extent (0: straight) (default 0.05).
    #[arg(long)]
    pub path_curve: Option<f32>,
    /// No path: trees anywhere, no cells.
    #[arg(long)]
    pub no_path: bool,
    /// Instance this tree model (OBJ, glTF; Y up, trunk at the origin) instead of making trees.
    #[arg(long, value_name = "FILE")]
    pub tree_model: Option<PathBuf>,
    /// Scale the tree model to this height (before --scale-jitter).
    #[arg(long, requires = "tree_model")]
    pub model_height: Option<f32>,
    /// Random scale of each model instance: 1 ± this (default 0.2).
    #[arg(long, requires = "tree_model")]
    pub scale_jitter: Option<f32>,
}

/// Options of `umbrasweep gen city` (defaults: [`CityOptions::default`]).
#[derive(clap::Args, Debug, Clone)]
pub struct CityArgs {
    #[command(flatten)]
    pub common: CommonArgs,
    /// Blocks: N (N×N) or NX,NZ (default 12).
    #[arg(long, value_name = "N|NX,NZ", value_parser = parse_count2)]
    pub blocks: Option<[u32; 2]>,
    /// Width of the streets between blocks (default 10).
    #[arg(long)]
    pub street_width: Option<f32>,
    /// Buildings per block: N (N×N) or NX,NZ (default 2).
    #[arg(long, value_name = "N|NX,NZ", value_parser = parse_count2)]
    pub buildings_per_block: Option<[u32; 2]>,
    /// Width and depth of buildings: MIN,MAX (default 9,12).
    #[arg(long, value_name = "MIN,MAX", value_parser = parse_pair)]
    pub building_width: Option<Pair>,
    /// Heights of buildings: MIN,MAX (default 6,36).
    #[arg(long, value_name = "MIN,MAX", value_parser = parse_pair)]
    pub heights: Option<Pair>,
    /// Storey height; a tower's setback happens at a whole storey (default 3).
    #[arg(long)]
    pub floor_height: Option<f32>,
    /// Largest rotation of a building about the vertical, in degrees (default 30).
    #[arg(long)]
    pub max_rotation: Option<f32>,
    /// Fraction of H- and T-shaped buildings (default 0.4).
    #[arg(long)]
    pub shaped: Option<f32>,
}

/// Options of `umbrasweep gen boxfield` (defaults: [`BoxfieldOptions::default`]).
#[derive(clap::Args, Debug, Clone)]
pub struct BoxfieldArgs {
    #[command(flatten)]
    pub common: CommonArgs,
    /// Number of boxes (default 200).
    #[arg(long)]
    pub boxes: Option<u32>,
    /// Side of the cube holding the box centres (default 100).
    #[arg(long)]
    pub extent: Option<f32>,
    /// Box side lengths: MIN,MAX (or S for S,S) (default 1,10).
    #[arg(long, value_name = "MIN,MAX", value_parser = parse_pair)]
    pub box_size: Option<Pair>,
}

/// A value `A` or `A,B` of the command line.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Pair(pub f32, pub Option<f32>);

fn parse_f32(s: &str) -> Result<f32, String> {
    let v: f32 = s
        .trim()
        .parse()
        .map_err(|_| format!("'{s}' is not a number"))?;
    if v.is_finite() {
        Ok(v)
    } else {
        Err(format!("'{s}' is not a finite number"))
    }
}

fn parse_pair(s: &str) -> Result<Pair, String> {
    match s.split(',').collect::<Vec<_>>()[..] {
        [a] => Ok(Pair(parse_f32(a)?, None)),
        [a, b] => Ok(Pair(parse_f32(a)?, Some(parse_f32(b)?))),
        _ => Err(format!("'{s}': expected A or A,B")),
    }
}

fn parse_size3(s: &str) -> Result<Vec3, String> {
    match s.split(',').map(parse_f32).collect::<Result<Vec<_>, _>>()?[..] {
        [a] => Ok(Vec3::splat(a)),
        [x, y, z] => Ok(Vec3::new(x, y, z)),
        _ => Err(format!("'{s}': expected X or X,Y,Z")),
    }
}

fn parse_count2(s: &str) -> Result<[u32; 2], String> {
    let n = |t: &str| {
        t.trim()
            .parse::<u32>()
            .map_err(|_| format!("'{t}' is not a count"))
    };
    match s.split(',').collect::<Vec<_>>()[..] {
        [a] => Ok([n(a)?; 2]),
        [a, b] => Ok([n(a)?, n(b)?]),
        _ => Err(format!("'{s}': expected N or NX,NZ")),
    }
}

/// A required `MIN,MAX` pair (one value `S` means `S,S`).
fn min_max(p: Pair, flag: &str) -> anyhow::Result<[f32; 2]> {
    let [a, b] = [p.0, p.1.unwrap_or(p.0)];
    if a > b {
        bail!("{flag} {a},{b}: MIN must not exceed MAX");
    }
    Ok([a, b])
}

impl ForestArgs {
    /// The generator options these flags ask for.
    ///
    /// # Errors
    /// Inconsistent flags (e.g. leaf flags with `--tree-model`), naming the flag.
    pub fn options(&self) -> anyhow::Result<ForestOptions> {
        let mut o = match self.preset {
            None => ForestOptions::default(),
            Some(ForestPreset::Coarse) => ForestOptions::coarse(),
            Some(ForestPreset::Fine) => ForestOptions::fine(),
            Some(ForestPreset::Paper) => ForestOptions::paper(),
            Some(ForestPreset::Demo) => ForestOptions::demo(),
        };
        if self.tree_model.is_some() {
            let procedural = [
                ("--leaves", self.leaves.is_some()),
                ("--leaf-size", self.leaf_size.is_some()),
                ("--leaf-quads", self.leaf_quads),
                ("--crown-height", self.crown_height.is_some()),
                ("--crown-base", self.crown_base.is_some()),
                ("--crown-radius", self.crown_radius.is_some()),
                ("--crown-shape", self.crown_shape.is_some()),
                ("--crown-split", self.crown_split.is_some()),
                ("--trunk-radius", self.trunk_radius.is_some()),
                ("--trunk-sides", self.trunk_sides.is_some()),
            ];
            if let Some((flag, _)) = procedural.iter().find(|(_, given)| *given) {
                bail!("{flag} shapes procedural trees and does not apply with --tree-model");
            }
        }
        o.seed = self.common.seed;
        if let Some(v) = self.trees {
            o.trees = v;
        }
        if let Some(v) = self.leaves {
            o.leaves = v;
        }
        if let Some(p) = self.leaf_size {
            o.leaf_size = match p.1 {
                Some(_) => min_max(p, "--leaf-size")?,
                // In f64, so `1.5` gives exactly the presets' `[1.2, 1.8]`.
                None => [(0.8 * p.0 as f64) as f32, (1.2 * p.0 as f64) as f32],
            };
        }
        o.leaf_quads |= self.leaf_quads;
        set(&mut o.crown_height, self.crown_height);
        set(&mut o.crown_base, self.crown_base);
        set(&mut o.crown_radius, self.crown_radius);
        set(&mut o.crown_shape, self.crown_shape);
        set(&mut o.crown_split, self.crown_split);
        set(&mut o.trunk_radius, self.trunk_radius);
        set(&mut o.trunk_sides, self.trunk_sides);
        if let Some(n) = self.model_split {
            if !(1..=64).contains(&n) {
                bail!("--model-split {n}: must be between 1 and 64");
            }
            o.model_split = n;
        }
        if self.tree_model.is_some() {
            // The model's footprint gives the spacing unless a flag sets it.
            o.area_per_tree = None;
        }
        if self.extent.is_some() {
            o.extent = self.extent;
            o.area_per_tree = None;
        }
        if self.area_per_tree.is_some() {
            o.area_per_tree = self.area_per_tree;
            o.extent = None;
        }
        set(&mut o.path_width, self.path_width);
        set(&mut o.path_curve, self.path_curve);
        o.path &= !self.no_path;
        if let Some(c) = self.common.cell_size {
            o.cell_size = c;
        }
        if self.common.cells.is_some() {
            o.max_cells = self.common.cells;
        }
        if self.model_height.is_some() {
            o.model_height = self.model_height;
        }
        set(&mut o.scale_jitter, self.scale_jitter);
        Ok(o)
    }
}

impl CityArgs {
    /// The generator options these flags ask for.
    ///
    /// # Errors
    /// A `MIN,MAX` flag with MIN above MAX.
    pub fn options(&self) -> anyhow::Result<CityOptions> {
        let mut o = CityOptions {
            seed: self.common.seed,
            ..CityOptions::default()
        };
        set(&mut o.blocks, self.blocks);
        set(&mut o.street_width, self.street_width);
        set(&mut o.buildings_per_block, self.buildings_per_block);
        if let Some(p) = self.building_width {
            o.building_width = min_max(p, "--building-width")?;
        }
        if let Some(p) = self.heights {
            o.heights = min_max(p, "--heights")?;
        }
        set(&mut o.floor_height, self.floor_height);
        set(&mut o.max_rotation_deg, self.max_rotation);
        set(&mut o.shaped_fraction, self.shaped);
        set(&mut o.cell_size, self.common.cell_size);
        if self.common.cells.is_some() {
            o.max_cells = self.common.cells;
        }
        Ok(o)
    }
}

impl BoxfieldArgs {
    /// The generator options these flags ask for.
    ///
    /// # Errors
    /// `--box-size` with MIN above MAX.
    pub fn options(&self) -> anyhow::Result<BoxfieldOptions> {
        let mut o = BoxfieldOptions {
            seed: self.common.seed,
            ..BoxfieldOptions::default()
        };
        set(&mut o.boxes, self.boxes);
        set(&mut o.extent, self.extent);
        if let Some(p) = self.box_size {
            o.box_size = min_max(p, "--box-size")?;
        }
        set(&mut o.cell_size, self.common.cell_size);
        if self.common.cells.is_some() {
            o.max_cells = self.common.cells;
        }
        Ok(o)
    }
}

fn set<T>(dst: &mut T, v: Option<T>) {
    if let Some(v) = v {
        *dst = v;
    }
}

/// Checks that a file can be created at `path` (its folder exists and is writable), before
/// any long generation.
fn check_writable(path: &Path, what: &str) -> anyhow::Result<()> {
    let dir = match path.parent() {
        Some(d) if !d.as_os_str().is_empty() => d,
        _ => Path::new("."),
    };
    if path.is_dir() {
        bail!("{what} {}: is a directory", path.display());
    }
    tempfile::NamedTempFile::new_in(dir).with_context(|| {
        format!(
            "{what} {}: cannot create a file in {}",
            path.display(),
            dir.display()
        )
    })?;
    Ok(())
}

/// Runs `umbrasweep gen`: generates the scene, writes the OBJ (and MTL) and the cells, and
/// prints a one-line summary.
///
/// # Errors
/// Bad options, an unloadable `--tree-model`, or an unwritable output; nothing is left
/// behind on error.
pub fn run(args: &GenArgs) -> anyhow::Result<()> {
    let common = match &args.kind {
        GenKind::Forest(a) => &a.common,
        GenKind::City(a) => &a.common,
        GenKind::Boxfield(a) => &a.common,
    };
    let ext_ok = common
        .output
        .extension()
        .is_some_and(|e| e.eq_ignore_ascii_case("obj"));
    if !ext_ok {
        bail!(
            "-o {}: the output must be an .obj file",
            common.output.display()
        );
    }
    if common.cells == Some(0) {
        bail!("--cells 0: keep at least one cell");
    }
    check_writable(&common.output, "-o")?;
    if let Some(c) = &common.cells_out {
        if c == &common.output {
            bail!("--cells-out {}: same file as -o", c.display());
        }
        check_writable(c, "--cells-out")?;
    }

    if let GenKind::Forest(a) = &args.kind
        && a.no_path
        && common.cells_out.is_some()
    {
        bail!("--cells-out: the forest's cells lie on its path; drop --no-path");
    }
    let (mut generated, kind) = match &args.kind {
        GenKind::Forest(a) => {
            let o = a.options()?;
            let g = match &a.tree_model {
                Some(path) => {
                    let scene = crate::scene::load(path)?;
                    let model = TreeModel::from_scene(&scene);
                    forest_of_models(&o, &model)?
                }
                None => forest(&o)?,
            };
            (g, "forest")
        }
        GenKind::City(a) => (city(&a.options()?)?, "city"),
        GenKind::Boxfield(a) => (boxfield(&a.options()?)?, "boxfield"),
    };
    generated.comment = format!(
        "umbrasweep gen {kind} --seed {}: {}",
        common.seed, generated.comment
    );
    if common.cells_out.is_some() && generated.cells.is_empty() {
        bail!(
            "--cells-out: this {kind} has no room for view cells (see --cell-size and the {kind} options)"
        );
    }

    write_obj(&common.output, &generated).map_err(anyhow::Error::msg)?;
    if let Some(c) = &common.cells_out
        && let Err(e) = crate::cells::save_json(c, &generated.cells)
    {
        let _ = std::fs::remove_file(&common.output);
        if generated.has_translucent() {
            let _ = std::fs::remove_file(mtl_path(&common.output));
        }
        bail!("{e}");
    }
    println!(
        "wrote {}: {} objects, {} triangles{}{}",
        common.output.display(),
        generated.objects.len(),
        generated.triangle_count(),
        if generated.has_translucent() {
            format!(" (materials in {})", mtl_path(&common.output).display())
        } else {
            String::new()
        },
        match &common.cells_out {
            Some(c) => format!("; {} cells to {}", generated.cells.len(), c.display()),
            None => String::new(),
        }
    );
    Ok(())
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
