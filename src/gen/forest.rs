//! `gen forest`: procedural leafy trees (closed trunk prism + crowns of separate leaves) or
//! instances of a tree model, on a ground quad, with view cells along a trunk-free path.

use super::{GenError, GenObject, Generated, ground, random_rotation, rng_for, spread, uniform};
use crate::geom::Aabb;
use crate::scene::Scene;
use glam::{Vec2, Vec3};
use rand::Rng;
use rand::seq::SliceRandom;
use rayon::prelude::*;
use std::f32::consts::TAU;

/// Options of the forest generators; see the module docs of [`super`] (`umbrasweep gen`) for the recipes.
#[derive(Clone, Debug, PartialEq)]
pub struct ForestOptions {
    /// Seed of the random generator.
    pub seed: u64,
    /// Number of trees.
    pub trees: u32,
    /// Leaves per tree (procedural trees).
    pub leaves: u32,
    /// Leaf diameter range `[min, max]` (longest distance between two corners of a leaf).
    pub leaf_size: [f32; 2],
    /// Planar quads instead of triangles for leaves.
    pub leaf_quads: bool,
    /// Vertical extent of a crown.
    pub crown_height: f32,
    /// Height of the lowest point of a crown.
    pub crown_base: f32,
    /// Horizontal radius of a crown.
    pub crown_radius: f32,
    /// Volume the leaf centres fill.
    pub crown_shape: CrownShape,
    /// Objects per crown (angular sectors around the trunk).
    pub crown_split: u32,
    /// Crown radius and height of each tree are scaled by a factor in `[1 - size_jitter, 1]`.
    pub size_jitter: f32,
    /// Trunk radius (the prism's circumradius).
    pub trunk_radius: f32,
    /// Sides of the trunk prism.
    pub trunk_sides: u32,
    /// Side of the square forest (centred on the origin); `None`: from `area_per_tree`.
    pub extent: Option<f32>,
    /// Ground area per tree when `extent` is `None`; `None`: 17 m² for procedural trees, the
    /// model's footprint for tree models.
    pub area_per_tree: Option<f32>,
    /// Keep a trunk-free path through the middle (along x) and put the cells on it.
    pub path: bool,
    /// Width of the trunk-free lane around the path's centre line.
    pub path_width: f32,
    /// Amplitude of the path's sine as a fraction of the extent (one period over the forest).
    pub path_curve: f32,
    /// Least distance between a cell and a trunk.
    pub path_clearance: f32,
    /// Size of the cells.
    pub cell_size: Vec3,
    /// Height of the bottom of the cells.
    pub cell_base: f32,
    /// Keep at most this many cells (spread evenly along the path).
    pub max_cells: Option<usize>,
    /// Tree models: scale the model to this height (before jitter); `None`: scale 1.
    pub model_height: Option<f32>,
    /// Tree models: each instance is scaled by `1 ± scale_jitter`.
    pub scale_jitter: f32,
    /// Tree models: each instance is split into this many objects, angular sectors around its
    /// trunk (by triangle centre), like the procedural crowns' `crown_split`. 1 keeps a tree
    /// one object.
    pub model_split: u32,
}

/// The volume a procedural crown's leaves fill (of radius `crown_radius`, height
/// `crown_height`); `gen forest --crown-shape`.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Default)]
pub enum CrownShape {
    /// A vertical cylinder: the canopy reaches down to --crown-base at its full width.
    #[default]
    Cylinder,
    /// An ellipsoid: round at the top and bottom, so the crowns leave an open band below eye
    /// level between the trunks.
    Ellipsoid,
}

impl ForestOptions {
    /// The coarse forest: 1,500 trees of 1,000 leaf triangles ~1.5 units across (1.2–1.8),
    /// crowns from 0.3 above the ground, one tree per 17 m², crowns split into 4 objects.
    ///
    /// The crowns are cylinders, so the canopy reaches down to 0.3 at its full width: ray
    /// sampling then sees 1.8 % of the objects from a path cell (issue 5 describes ~1 %).
    /// Ellipsoid crowns leave an open band between the ground and eye level, through which
    /// it sees 3.5 % (two fifths of them trunks).
    pub const fn coarse() -> Self {
        ForestOptions {
            seed: 1,
            trees: 1500,
            leaves: 1000,
            leaf_size: [1.2, 1.8],
            leaf_quads: false,
            crown_height: 4.5,
            crown_base: 0.3,
            crown_radius: 2.2,
            crown_shape: CrownShape::Cylinder,
            crown_split: 4,
            size_jitter: 0.1,
            trunk_radius: 0.15,
            trunk_sides: 6,
            extent: None,
            area_per_tree: Some(17.0),
            path: true,
            path_width: 4.0,
            path_curve: 0.05,
            path_clearance: 1.0,
            cell_size: Vec3::new(1.0, 1.0, 1.0),
            cell_base: 1.2,
            max_cells: None,
            model_height: None,
            scale_jitter: 0.2,
            model_split: 1,
        }
    }

    /// The fine forest: the coarse forest with leaves ~0.5 units across (0.4–0.6).
    pub const fn fine() -> Self {
        ForestOptions {
            leaf_size: [0.4, 0.6],
            ..Self::coarse()
        }
    }

    /// The forest of Durand et al. 2000: 7,750 trees × 1,000 leaves (7.75 M leaf triangles),
    /// otherwise the coarse forest.
    pub const fn paper() -> Self {
        ForestOptions {
            trees: 7750,
            ..Self::coarse()
        }
    }

    /// The shipped demo (`data/demo_forest.obj`): 60 trees × 200 leaves in ellipsoid crowns
    /// (the recipe it was made with), 10 cells.
    pub const fn demo() -> Self {
        ForestOptions {
            trees: 60,
            leaves: 200,
            crown_shape: CrownShape::Ellipsoid,
            max_cells: Some(10),
            ..Self::coarse()
        }
    }
}

impl Default for ForestOptions {
    /// The coarse forest with 100 trees.
    fn default() -> Self {
        ForestOptions {
            trees: 100,
            ..Self::coarse()
        }
    }
}

/// A tree model to instance: all triangles of a scene as one mesh.
#[derive(Clone, Debug)]
pub struct TreeModel {
    /// Model-space positions (Y up, trunk at the origin).
    pub vertices: Vec<Vec3>,
    /// Triangles as indices into `vertices`.
    pub triangles: Vec<[u32; 3]>,
    /// Per triangle: false when it was not opaque in the model.
    pub opaque: Vec<bool>,
    /// The model's alpha-tested cards (indexed by model triangle), when it has any.
    pub cards: Option<crate::scene::alpha::AlphaCards>,
}

impl TreeModel {
    /// All triangles of `scene` (only the vertices they use).
    pub fn from_scene(scene: &Scene) -> Self {
        let mut remap = vec![u32::MAX; scene.vertices.len()];
        let mut vertices = Vec::new();
        let triangles = scene
            .triangles
            .iter()
            .map(|t| {
                t.map(|i| {
                    let r = &mut remap[i as usize];
                    if *r == u32::MAX {
                        *r = vertices.len() as u32;
                        vertices.push(scene.vertices[i as usize]);
                    }
                    *r
                })
            })
            .collect();
        TreeModel {
            vertices,
            triangles,
            opaque: scene.opaque.clone(),
            cards: scene.alpha.clone(),
        }
    }

    fn bounds(&self) -> Aabb {
        Aabb::from_points(&self.vertices)
    }

    /// Largest horizontal distance from the vertical axis of a vertex of an opaque triangle
    /// reaching below model height `y`: the model's "trunk radius" up to that height.
    fn radius_below(&self, y: f32) -> f32 {
        let mut r: f32 = 0.0;
        for (t, &op) in self.triangles.iter().zip(&self.opaque) {
            let p = t.map(|i| self.vertices[i as usize]);
            if op && p.iter().any(|v| v.y <= y) {
                for v in p {
                    r = r.max(Vec2::new(v.x, v.z).length());
                }
            }
        }
        r
    }
}

/// The path through the forest: `z = amplitude · sin(TAU · x / extent)`.
struct Path {
    extent: f32,
    amplitude: f32,
    half_width: f32,
}

impl Path {
    fn z(&self, x: f32) -> f32 {
        self.amplitude * (TAU * x / self.extent).sin()
    }

    /// `sqrt(1 + L²)` for the path's largest slope `L`: a point whose vertical offset from the
    /// curve is `d` is at least `d / stretch()` away from it.
    fn stretch(&self) -> f32 {
        let slope = TAU * self.amplitude / self.extent;
        (1.0 + slope * slope).sqrt()
    }

    /// True when a disc of radius `r` at `p` keeps `half_width` from the centre line.
    fn clear(&self, p: Vec2, r: f32) -> bool {
        (p.y - self.z(p.x)).abs() >= (self.half_width + r) * self.stretch() * 1.001 + 1e-3
    }
}

fn check_common(o: &ForestOptions) -> Result<(), GenError> {
    let bad = |m: String| Err(GenError::Options(m));
    if o.trees == 0 {
        return bad("--trees must be at least 1".into());
    }
    let positive = [
        ("--extent", o.extent.unwrap_or(1.0)),
        ("--area-per-tree", o.area_per_tree.unwrap_or(1.0)),
        ("--model-height", o.model_height.unwrap_or(1.0)),
    ];
    for (flag, v) in positive {
        if !(v > 0.0 && v.is_finite()) {
            return bad(format!("{flag} {v}: must be positive"));
        }
    }
    if !(0.0..1.0).contains(&o.scale_jitter) {
        return bad(format!(
            "--scale-jitter {}: must be in [0, 1)",
            o.scale_jitter
        ));
    }
    if o.path {
        if !super::positive(o.path_width) || !(0.0..=0.25).contains(&o.path_curve) {
            return bad(format!(
                "--path-width {} must be positive and --path-curve {} in [0, 0.25]",
                o.path_width, o.path_curve
            ));
        }
        if o.cell_size.cmple(Vec3::ZERO).any() || !o.cell_size.is_finite() {
            return bad(format!(
                "--cell-size {:?}: every side must be positive",
                o.cell_size.to_array()
            ));
        }
        let half_diagonal = 0.5 * Vec2::new(o.cell_size.x, o.cell_size.z).length();
        if half_diagonal + o.path_clearance > 0.5 * o.path_width {
            return bad(format!(
                "cells of {}×{} (x, z) do not fit the path: --path-width must be at least {:.2} (2 × (half the cell's diagonal + {} clearance))",
                o.cell_size.x,
                o.cell_size.z,
                2.0 * (half_diagonal + o.path_clearance),
                o.path_clearance
            ));
        }
    }
    Ok(())
}

/// Places `n` trunks of radius `r` on a jittered grid over the square of side `extent`,
/// keeping them off the path; returns their positions (x, z) in grid order.
fn place_trees(
    o: &ForestOptions,
    extent: f32,
    r: f32,
    path: Option<&Path>,
) -> Result<Vec<Vec2>, GenError> {
    let n = o.trees as usize;
    let mut rng = rng_for(o.seed, 0, 0);
    let mut k = (n as f64).sqrt().ceil() as usize;
    loop {
        let w = extent / k as f32;
        let jitter = (0.5 * w - r - 0.05).max(0.0);
        let mut usable: Vec<(usize, Vec2)> = Vec::new();
        for j in 0..k {
            for i in 0..k {
                let centre = Vec2::new(
                    -0.5 * extent + (i as f32 + 0.5) * w,
                    -0.5 * extent + (j as f32 + 0.5) * w,
                );
                for _ in 0..6 {
                    let p = centre
                        + Vec2::new(
                            uniform(&mut rng, -jitter, jitter),
                            uniform(&mut rng, -jitter, jitter),
                        );
                    if path.is_none_or(|path| path.clear(p, r)) {
                        usable.push((j * k + i, p));
                        break;
                    }
                }
            }
        }
        if usable.len() >= n {
            if usable.len() > n {
                usable.shuffle(&mut rng);
                usable.truncate(n);
                usable.sort_by_key(|u| u.0);
            }
            return Ok(usable.into_iter().map(|u| u.1).collect());
        }
        k += 1;
        if k * k > 64 * n + 1024 {
            return Err(GenError::Options(format!(
                "no room for {n} trees off the path in a forest of side {extent}: raise --extent or --area-per-tree, or narrow --path-width"
            )));
        }
    }
}

/// Cells on the path's centre line, from one edge of the forest to the other.
fn path_cells(o: &ForestOptions, path: &Path) -> Vec<Aabb> {
    let c = o.cell_size;
    let count = (path.extent / c.x).floor() as usize;
    let x0 = -0.5 * count as f32 * c.x;
    let cells = (0..count)
        .map(|i| {
            let xc = x0 + (i as f32 + 0.5) * c.x;
            let centre = Vec3::new(xc, o.cell_base + 0.5 * c.y, path.z(xc));
            Aabb::new(centre - 0.5 * c, centre + 0.5 * c)
        })
        .collect();
    spread(cells, o.max_cells)
}

/// Side of the forest: `extent`, or `sqrt(trees × area)` plus the width of the trunk-free
/// lane of trunks of radius `r`, so the wooded part keeps one tree per `area`.
fn side(o: &ForestOptions, area: f32, r: f32) -> f32 {
    o.extent.unwrap_or_else(|| {
        let slope = TAU * o.path_curve;
        let lane = if o.path {
            (o.path_width + 2.0 * r) * (1.0 + slope * slope).sqrt()
        } else {
            0.0
        };
        (o.trees as f32 * area).sqrt() + lane
    })
}

fn layout(o: &ForestOptions, extent: f32, r: f32) -> Result<(Vec<Vec2>, Vec<Aabb>), GenError> {
    let path = o.path.then_some(Path {
        extent,
        amplitude: o.path_curve * extent,
        half_width: 0.5 * o.path_width,
    });
    let positions = place_trees(o, extent, r, path.as_ref())?;
    let cells = path.as_ref().map(|p| path_cells(o, p)).unwrap_or_default();
    Ok((positions, cells))
}

/// Generates a forest of procedural trees: `ground`, then per tree `treeI_trunk` and
/// `treeI_crown0..N`; cells along the path.
///
/// # Errors
/// [`GenError::Options`] for options that cannot make a forest (naming the flag).
pub fn forest(o: &ForestOptions) -> Result<Generated, GenError> {
    check_common(o)?;
    let bad = |m: String| Err(GenError::Options(m));
    if o.crown_split == 0 || o.leaves < o.crown_split {
        return bad(format!(
            "--crown-split {} must be at least 1 and at most --leaves {}",
            o.crown_split, o.leaves
        ));
    }
    if !(o.leaf_size[0] >= 0.01 && o.leaf_size[0] <= o.leaf_size[1] && o.leaf_size[1].is_finite()) {
        return bad(format!(
            "--leaf-size {},{}: sizes must be at least 0.01 and MIN at most MAX",
            o.leaf_size[0], o.leaf_size[1]
        ));
    }
    if !(o.crown_height > 0.0 && o.crown_radius > 0.0 && o.crown_base >= 0.0) {
        return bad(
            "--crown-height and --crown-radius must be positive, --crown-base not negative".into(),
        );
    }
    if !super::positive(o.trunk_radius) || o.trunk_sides < 3 {
        return bad("--trunk-radius must be positive and --trunk-sides at least 3".into());
    }
    if !(0.0..1.0).contains(&o.size_jitter) {
        return bad(format!("size_jitter {}: must be in [0, 1)", o.size_jitter));
    }
    let extent = side(o, o.area_per_tree.unwrap_or(17.0), o.trunk_radius);
    let (positions, cells) = layout(o, extent, o.trunk_radius)?;

    let mut objects = Vec::with_capacity(1 + positions.len() * (1 + o.crown_split as usize));
    let margin = o.crown_radius;
    objects.push(ground(
        Vec2::splat(-0.5 * extent - margin),
        Vec2::splat(0.5 * extent + margin),
    ));
    let trees: Vec<Vec<GenObject>> = positions
        .par_iter()
        .enumerate()
        .map(|(i, &p)| tree(o, i, p))
        .collect();
    objects.extend(trees.into_iter().flatten());
    Ok(Generated {
        objects,
        cells,
        comment: format!(
            "forest of {} trees × {} leaf {} of {}–{}, side {extent}",
            o.trees,
            o.leaves,
            if o.leaf_quads { "quads" } else { "triangles" },
            o.leaf_size[0],
            o.leaf_size[1]
        ),
        alpha: None,
    })
}

/// One procedural tree: trunk, then `crown_split` crown objects.
fn tree(o: &ForestOptions, index: usize, at: Vec2) -> Vec<GenObject> {
    let mut rng = rng_for(o.seed, 1, index as u64);
    let radius = o.crown_radius * uniform(&mut rng, 1.0 - o.size_jitter, 1.0);
    let height = o.crown_height * uniform(&mut rng, 1.0 - o.size_jitter, 1.0);
    let centre = Vec3::new(at.x, o.crown_base + 0.5 * height, at.y);

    let mut out = Vec::with_capacity(1 + o.crown_split as usize);
    let mut trunk = GenObject::new(format!("tree{index}_trunk"));
    let top = o.crown_base + 0.6 * height;
    let n = o.trunk_sides;
    let phase = uniform(&mut rng, 0.0, TAU);
    let ring = |y: f32, t: &mut GenObject| -> Vec<u32> {
        (0..n)
            .map(|k| {
                let a = phase + TAU * k as f32 / n as f32;
                t.vertex(Vec3::new(
                    at.x + o.trunk_radius * a.cos(),
                    y,
                    at.y + o.trunk_radius * a.sin(),
                ))
            })
            .collect()
    };
    let bottom = ring(0.0, &mut trunk);
    let upper = ring(top, &mut trunk);
    let n = n as usize;
    for k in 0..n {
        let k1 = (k + 1) % n;
        trunk.triangle(bottom[k], upper[k], upper[k1], true);
        trunk.triangle(bottom[k], upper[k1], bottom[k1], true);
    }
    for k in 1..n - 1 {
        trunk.triangle(bottom[0], bottom[k], bottom[k + 1], true);
        trunk.triangle(upper[0], upper[k + 1], upper[k], true);
    }
    out.push(trunk);

    let split = o.crown_split as usize;
    let mut crowns: Vec<GenObject> = (0..split)
        .map(|s| {
            let mut c = GenObject::new(format!("tree{index}_crown{s}"));
            let per = o.leaves as usize / split + 1;
            c.vertices.reserve(per * if o.leaf_quads { 4 } else { 3 });
            c.faces.reserve(per);
            c.opaque.reserve(per);
            c
        })
        .collect();
    let sector = TAU / split as f32;
    for l in 0..o.leaves as usize {
        let s = l % split;
        let size = uniform(&mut rng, o.leaf_size[0], o.leaf_size[1]);
        // Leaf corners in its own plane, scaled so the diameter is `size`.
        let mut local = [Vec3::ZERO; 4];
        let corners = if o.leaf_quads {
            let a = uniform(&mut rng, 0.5, 1.0);
            local = [
                Vec3::new(-1.0, -a, 0.0),
                Vec3::new(1.0, -a, 0.0),
                Vec3::new(1.0, a, 0.0),
                Vec3::new(-1.0, a, 0.0),
            ];
            4
        } else {
            for (k, p) in local.iter_mut().take(3).enumerate() {
                let ang = TAU * (0.25 + k as f32 / 3.0) + uniform(&mut rng, -0.3, 0.3);
                *p = Vec3::new(ang.cos(), ang.sin(), 0.0);
            }
            3
        };
        let mut diameter: f32 = 0.0;
        for a in 0..corners {
            for b in a + 1..corners {
                diameter = diameter.max(local[a].distance(local[b]));
            }
        }
        let scale = size / diameter;
        let reach = local[..corners]
            .iter()
            .map(|p| p.length())
            .fold(0.0, f32::max)
            * scale;
        // Centre: uniform in the crown (ellipsoid or cylinder) shrunk by the leaf's reach, in
        // sector `s`.
        let u = loop {
            let u = Vec3::new(
                uniform(&mut rng, -1.0, 1.0),
                uniform(&mut rng, -1.0, 1.0),
                uniform(&mut rng, -1.0, 1.0),
            );
            let inside = match o.crown_shape {
                CrownShape::Ellipsoid => u.length_squared(),
                CrownShape::Cylinder => u.x * u.x + u.z * u.z,
            } <= 1.0;
            if inside {
                break u;
            }
        };
        let horizontal = Vec2::new(u.x, u.z).length();
        let ang = (s as f32 + rng.random::<f32>()) * sector;
        let u = Vec3::new(horizontal * ang.cos(), u.y, horizontal * ang.sin());
        let half = Vec3::new(
            (radius - reach).max(0.0),
            (0.5 * height - reach).max(0.0),
            (radius - reach).max(0.0),
        );
        let c = centre + u * half;
        let rot = random_rotation(&mut rng);
        let crown = &mut crowns[s];
        let ids: Vec<u32> = local[..corners]
            .iter()
            .map(|p| crown.vertex(c + rot * (*p * scale)))
            .collect();
        if o.leaf_quads {
            crown.quad(ids[0], ids[1], ids[2], ids[3], true);
        } else {
            crown.triangle(ids[0], ids[1], ids[2], true);
        }
    }
    out.extend(crowns);
    out
}

/// One sector of a model tree: the model vertices it uses, its faces (indices into those) and
/// their opacity.
type Sector = (Vec<u32>, Vec<[u32; 4]>, Vec<bool>, Vec<u32>);

/// Generates a forest of instances of `model`: `ground`, then one object `treeI` per tree —
/// or `model_split` objects `treeI_partK`, angular sectors around the trunk — (random yaw, scale `1 ± scale_jitter` times `model_height / model height` or 1), keeping
/// each triangle's opacity; cells along the path, clear of the opaque model geometry below
/// eye level.
///
/// # Errors
/// [`GenError::Options`] for bad options or an empty model.
pub fn forest_of_models(o: &ForestOptions, model: &TreeModel) -> Result<Generated, GenError> {
    check_common(o)?;
    if model.triangles.is_empty() {
        return Err(GenError::Options(
            "--tree-model: the model has no triangles".into(),
        ));
    }
    let b = model.bounds();
    let base_scale = match o.model_height {
        Some(h) if b.size().y > 0.0 => h / b.size().y,
        Some(_) => {
            return Err(GenError::Options(
                "--model-height: the model is flat".into(),
            ));
        }
        None => 1.0,
    };
    let (s_min, s_max) = (
        base_scale * (1.0 - o.scale_jitter),
        base_scale * (1.0 + o.scale_jitter),
    );
    // Trunk radius: opaque geometry reaching below the top of the cells plus the clearance.
    let eye_top = o.cell_base + o.cell_size.y + o.path_clearance;
    let r = (model.radius_below(eye_top / s_min) * s_max).max(0.05);
    let footprint = Vec2::new(b.size().x, b.size().z).length() * base_scale;
    let extent = side(
        o,
        o.area_per_tree
            .unwrap_or((0.5 * footprint).powi(2).max(17.0)),
        r,
    );
    let (positions, cells) = layout(o, extent, r)?;

    let mut objects = Vec::with_capacity(1 + positions.len());
    let margin = 0.5 * Vec2::new(b.size().x, b.size().z).max_element() * s_max;
    objects.push(ground(
        Vec2::splat(-0.5 * extent - margin),
        Vec2::splat(0.5 * extent + margin),
    ));
    // Per sector: the model triangles in it, and the model vertices they use (remapped).
    let split = o.model_split.max(1) as usize;
    let mut sectors: Vec<Sector> = vec![Default::default(); split];
    {
        let mut remap: Vec<Vec<u32>> = vec![vec![u32::MAX; model.vertices.len()]; split];
        for (t, tri) in model.triangles.iter().enumerate() {
            let c = tri
                .iter()
                .map(|&i| model.vertices[i as usize])
                .sum::<Vec3>()
                / 3.0;
            let angle = c.z.atan2(c.x).rem_euclid(TAU);
            let k = ((angle / TAU * split as f32) as usize).min(split - 1);
            let (verts, faces, opaque, cards) = &mut sectors[k];
            let f = tri.map(|i| {
                let r = &mut remap[k][i as usize];
                if *r == u32::MAX {
                    *r = verts.len() as u32;
                    verts.push(i);
                }
                *r
            });
            faces.push([f[0], f[1], f[2], super::NO_VERTEX]);
            opaque.push(model.opaque[t]);
            if let Some(c) = &model.cards {
                cards.push(c.card_of[t]);
            }
        }
    }
    let trees: Vec<GenObject> = positions
        .par_iter()
        .enumerate()
        .flat_map_iter(|(i, &p)| {
            let mut rng = rng_for(o.seed, 2, i as u64);
            let yaw = uniform(&mut rng, 0.0, TAU);
            let scale = uniform(&mut rng, s_min, s_max);
            let (sin, cos) = yaw.sin_cos();
            let place = move |v: Vec3| {
                let rotated = Vec3::new(cos * v.x + sin * v.z, v.y, -sin * v.x + cos * v.z);
                Vec3::new(p.x, 0.0, p.y) + rotated * scale
            };
            let sectors = &sectors;
            (0..split).filter_map(move |k| {
                let (verts, faces, opaque, cards) = &sectors[k];
                if faces.is_empty() {
                    return None;
                }
                let name = if split == 1 {
                    format!("tree{i}")
                } else {
                    format!("tree{i}_part{k}")
                };
                let mut t = GenObject::new(name);
                t.vertices.reserve(verts.len());
                for &v in verts {
                    t.vertex(place(model.vertices[v as usize]));
                }
                t.faces.extend_from_slice(faces);
                t.opaque.extend_from_slice(opaque);
                t.cards.extend_from_slice(cards);
                Some(t)
            })
        })
        .collect();
    objects.extend(trees);
    Ok(Generated {
        objects,
        cells,
        comment: format!(
            "forest of {} model trees ({} triangles each), side {extent}, opaque radius below eye level {r}",
            o.trees,
            model.triangles.len()
        ),
        alpha: model.cards.clone(),
    })
}

#[cfg(test)]
mod tests {
    use super::*;

    fn small() -> ForestOptions {
        ForestOptions {
            trees: 30,
            leaves: 40,
            ..ForestOptions::coarse()
        }
    }

    #[test]
    fn trunks_are_closed_and_outward() {
        let g = forest(&small()).unwrap();
        let trunk = g.object("tree3_trunk").unwrap();
        assert_eq!(trunk.triangle_count(), 4 * 6 - 4);
        assert!(super::super::tests::closed_outward(trunk));
    }

    #[test]
    fn cells_keep_clear_of_trunks_and_sit_at_eye_height() {
        for seed in 1..6 {
            let g = forest(&ForestOptions { seed, ..small() }).unwrap();
            assert!(!g.cells.is_empty());
            for o in g.objects.iter().filter(|o| o.name.ends_with("_trunk")) {
                let b = o.bounds();
                let axis = Vec2::new(b.center().x, b.center().z);
                for c in &g.cells {
                    assert!((1.0..=1.3).contains(&c.min.y) && (2.0..=2.5).contains(&c.max.y));
                    let nearest =
                        axis.clamp(Vec2::new(c.min.x, c.min.z), Vec2::new(c.max.x, c.max.z));
                    assert!(
                        nearest.distance(axis) >= 1.0 + 0.15,
                        "{} too close to a cell",
                        o.name
                    );
                }
            }
        }
    }

    #[test]
    fn leaves_are_in_range_and_in_the_crown_box() {
        let o = ForestOptions {
            leaf_quads: true,
            ..small()
        };
        let g = forest(&o).unwrap();
        for obj in g.objects.iter().filter(|x| x.name.contains("_crown")) {
            for f in &obj.faces {
                let p: Vec<Vec3> = f.iter().map(|&i| obj.vertices[i as usize]).collect();
                let mut d: f32 = 0.0;
                for a in &p {
                    for b in &p {
                        d = d.max(a.distance(*b));
                    }
                }
                assert!(d >= o.leaf_size[0] - 1e-3 && d <= o.leaf_size[1] + 1e-3);
                for v in p {
                    assert!(
                        v.y >= o.crown_base - 1e-3 && v.y <= o.crown_base + o.crown_height + 1e-3
                    );
                }
            }
        }
    }

    #[test]
    fn model_instances_keep_opacity() {
        let model = TreeModel {
            vertices: vec![Vec3::ZERO, Vec3::X, Vec3::Y, Vec3::Z],
            triangles: vec![[0, 1, 2], [0, 2, 3]],
            opaque: vec![true, false],
            cards: None,
        };
        let o = ForestOptions {
            trees: 5,
            ..ForestOptions::coarse()
        };
        let g = forest_of_models(&o, &model).unwrap();
        assert_eq!(g.objects.len(), 6);
        assert_eq!(g.objects[3].name, "tree2");
        assert_eq!(g.objects[3].opaque, vec![true, false]);
        assert!(g.has_translucent());
        let s = g.to_scene("m");
        assert_eq!(s.opaque.iter().filter(|&&x| !x).count(), 5);
    }

    #[test]
    fn model_split_makes_sectors_around_the_trunk() {
        // Four triangles, one per quadrant around the trunk axis, one of them translucent.
        let mut vertices = Vec::new();
        let mut triangles = Vec::new();
        for (k, (x, z)) in [(1.0, 0.2), (-0.2, 1.0), (-1.0, -0.2), (0.2, -1.0)]
            .iter()
            .enumerate()
        {
            let b = vertices.len() as u32;
            vertices.extend([
                Vec3::new(*x, 1.0, *z),
                Vec3::new(*x * 1.1, 1.5, *z * 1.1),
                Vec3::new(*x, 2.0 + k as f32, *z),
            ]);
            triangles.push([b, b + 1, b + 2]);
        }
        let model = TreeModel {
            vertices,
            triangles,
            opaque: vec![true, false, true, true],
            cards: None,
        };
        let o = ForestOptions {
            trees: 3,
            model_split: 4,
            ..ForestOptions::coarse()
        };
        let g = forest_of_models(&o, &model).unwrap();
        // The ground, then four one-triangle sectors per tree, in order.
        assert_eq!(g.objects.len(), 1 + 3 * 4);
        assert_eq!(g.objects[1].name, "tree0_part0");
        assert_eq!(g.objects[4].name, "tree0_part3");
        for t in 0..3 {
            let parts = &g.objects[1 + 4 * t..5 + 4 * t];
            assert!(
                parts
                    .iter()
                    .all(|p| p.faces.len() == 1 && p.vertices.len() == 3)
            );
            assert_eq!(
                parts.iter().map(|p| p.opaque[0]).collect::<Vec<_>>(),
                [true, false, true, true]
            );
        }
        // Split or not, the same triangles in the same places.
        let whole = forest_of_models(
            &ForestOptions {
                model_split: 1,
                ..o
            },
            &model,
        )
        .unwrap();
        let tris = |g: &Generated| {
            let s = g.to_scene("m");
            let mut v: Vec<[[u32; 3]; 3]> = (0..s.triangles.len())
                .map(|t| s.triangle(t).map(|p| p.to_array().map(f32::to_bits)))
                .collect();
            v.sort();
            v
        };
        assert_eq!(tris(&g), tris(&whole));
    }
}
