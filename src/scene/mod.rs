//! Scenes: import (OBJ, glTF 2.0), objects (the PVS unit), triangles, materials' opacity and
//! closed-mesh detection.
//!
//! Object numbering is a contract shared with other tools; see [`obj`] and [`gltf`] for the
//! exact rules per format.

pub mod alpha;
pub mod closed;
pub mod gltf;
pub mod image;
pub mod ktx2;
pub mod meshopt;
pub mod obj;
pub mod split;

use crate::geom::Aabb;
use glam::Vec3;
use std::ops::Range;
use std::path::{Path, PathBuf};

/// One object: the unit a PVS lists. Its triangles are `Scene::triangles[triangles]`.
#[derive(Clone, Debug)]
pub struct SceneObject {
    /// Name as the rules of the importer give it (OBJ `o`/`g` name, glTF node name or `node<I>`).
    pub name: String,
    /// Range into [`Scene::triangles`] (triangles are stored grouped by object, in id order).
    pub triangles: Range<u32>,
    /// World-space bounds of the object's vertices; [`Aabb::EMPTY`] when it has no triangles.
    pub bounds: Aabb,
    /// True when the object's triangles form closed 2-manifold surfaces (every edge shared by
    /// exactly two triangles with opposite orientation, after welding equal positions).
    pub closed: bool,
}

/// A triangle-soup scene in world space.
#[derive(Clone, Debug, Default)]
pub struct Scene {
    /// The file the scene came from (for messages).
    pub source: PathBuf,
    /// All vertex positions, in world space.
    pub vertices: Vec<Vec3>,
    /// Vertex indices, grouped by object (see [`SceneObject::triangles`]).
    pub triangles: Vec<[u32; 3]>,
    /// Per triangle: false when its material is not opaque (glTF MASK/BLEND, MTL `d` < 1 or
    /// `map_d`). Such triangles are occludees only unless `--alpha-occluders` is given.
    pub opaque: Vec<bool>,
    /// Objects in id order: object `i` has id `i`.
    pub objects: Vec<SceneObject>,
    /// Things skipped on import (points, lines, …), one line each, for the summary.
    pub warnings: Vec<String>,
    /// Alpha-tested cards (glTF `MASK` materials with what their alpha test needs), when the
    /// scene has any; see [`alpha`].
    pub alpha: Option<alpha::AlphaCards>,
    /// When the objects are clusters of the file's objects (`--split-objects`,
    /// [`split::split_objects`]): the mapping back to the file's objects.
    pub split: Option<split::SplitMap>,
}

pub use crate::settings::AlphaMissing;

/// Options of [`load_with`].
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq)]
pub struct LoadOptions {
    /// What to do with a `MASK` material's missing or undecodable image.
    pub alpha_missing: AlphaMissing,
}

/// Errors of scene import. Every variant names the file.
#[derive(Debug, thiserror::Error)]
pub enum SceneError {
    /// The scene file could not be read.
    #[error("{path}: cannot read: {source}")]
    Io {
        /// The file.
        path: PathBuf,
        /// The I/O error.
        #[source]
        source: std::io::Error,
    },
    /// The file has a syntax error at `line` (1-based).
    #[error("{path}:{line}: {message}")]
    Parse {
        /// The file.
        path: PathBuf,
        /// The line of the error, 1-based.
        line: usize,
        /// What is wrong.
        message: String,
    },
    /// The file parsed but its content is unusable; `message` says why.
    #[error("{path}: {message}")]
    Invalid {
        /// The file.
        path: PathBuf,
        /// What is wrong.
        message: String,
    },
    /// The file's extension is none of `.obj`, `.gltf`, `.glb`.
    #[error("{path}: unsupported file type (expected .obj, .gltf or .glb)")]
    UnknownFormat {
        /// The file.
        path: PathBuf,
    },
}

impl Scene {
    /// The triangle's three corners.
    pub fn triangle(&self, t: usize) -> [Vec3; 3] {
        let [a, b, c] = self.triangles[t];
        [
            self.vertices[a as usize],
            self.vertices[b as usize],
            self.vertices[c as usize],
        ]
    }

    /// The id of the object owning triangle `t`.
    pub fn triangle_object(&self, t: u32) -> u32 {
        // Objects are stored in triangle order; binary search on the range starts.
        let i = self.objects.partition_point(|o| o.triangles.end <= t);
        i as u32
    }

    /// Bounds of the whole scene.
    pub fn bounds(&self) -> Aabb {
        self.objects.iter().fold(Aabb::EMPTY, |b, o| {
            if o.bounds.is_empty() {
                b
            } else {
                b.union(&o.bounds)
            }
        })
    }

    /// Number of triangles with zero area (skipped as occluders, counted in summaries).
    pub fn degenerate_triangles(&self) -> usize {
        (0..self.triangles.len())
            .filter(|&t| is_degenerate(self.triangle(t)))
            .count()
    }

    /// Builds a scene from objects given as (name, triangles, opaque); used by tests and
    /// generators. Objects keep the given order as ids.
    pub fn from_objects(source: &Path, objects: Vec<(String, Vec<[Vec3; 3]>, bool)>) -> Scene {
        let mut s = Scene {
            source: source.to_path_buf(),
            ..Default::default()
        };
        for (name, tris, opaque) in objects {
            let start = s.triangles.len() as u32;
            let mut bounds = Aabb::EMPTY;
            for t in tris {
                let base = s.vertices.len() as u32;
                for p in t {
                    bounds.grow(p);
                    s.vertices.push(p);
                }
                s.triangles.push([base, base + 1, base + 2]);
                s.opaque.push(opaque);
            }
            s.objects.push(SceneObject {
                name,
                triangles: start..s.triangles.len() as u32,
                bounds,
                closed: false,
            });
        }
        closed::mark_closed_objects(&mut s);
        s
    }

    /// Checks the invariants the culling relies on (finite coordinates, indices in range,
    /// objects covering the triangles in order).
    ///
    /// # Errors
    /// [`SceneError::Invalid`] naming the first problem found.
    pub fn validate(&self) -> Result<(), SceneError> {
        let invalid = |message: String| SceneError::Invalid {
            path: self.source.clone(),
            message,
        };
        if let Some(i) = self.vertices.iter().position(|v| !v.is_finite()) {
            return Err(invalid(format!(
                "vertex {} has a NaN or infinite coordinate ({:?})",
                i + 1,
                self.vertices[i]
            )));
        }
        let n = self.vertices.len() as u32;
        if let Some(t) = self
            .triangles
            .iter()
            .position(|t| t.iter().any(|&i| i >= n))
        {
            return Err(invalid(format!("triangle {t} indexes a missing vertex")));
        }
        if self.triangles.len() != self.opaque.len() {
            return Err(invalid("opacity flags do not match triangles".into()));
        }
        let mut next = 0u32;
        for o in &self.objects {
            if o.triangles.start != next || o.triangles.end < o.triangles.start {
                return Err(invalid(format!(
                    "object {} has a bad triangle range",
                    o.name
                )));
            }
            next = o.triangles.end;
        }
        if next as usize != self.triangles.len() {
            return Err(invalid("objects do not cover all triangles".into()));
        }
        if let Some(a) = &self.alpha
            && a.card_of.len() != self.triangles.len()
        {
            return Err(invalid("alpha-card flags do not match triangles".into()));
        }
        if self.triangles.is_empty() {
            return Err(invalid("the scene has no triangles".into()));
        }
        Ok(())
    }
}

/// True for a triangle of zero area (including NaN-free collinear corners).
pub fn is_degenerate(t: [Vec3; 3]) -> bool {
    let n = (t[1] - t[0]).as_dvec3().cross((t[2] - t[0]).as_dvec3());
    n.length_squared() == 0.0
}

/// Loads a scene by its extension (`.obj`, `.gltf`, `.glb`), checks it and marks closed
/// objects.
///
/// # Errors
/// A [`SceneError`] naming the file: unreadable, malformed, unsupported, NaN or infinite
/// coordinates, or no triangles at all.
pub fn load(path: &Path) -> Result<Scene, SceneError> {
    load_with(path, &LoadOptions::default())
}

/// [`load`] with import options (what to do with alpha-tested materials' missing images).
///
/// # Errors
/// As [`load`].
pub fn load_with(path: &Path, options: &LoadOptions) -> Result<Scene, SceneError> {
    let ext = path
        .extension()
        .and_then(|e| e.to_str())
        .map(|e| e.to_ascii_lowercase());
    let mut scene = match ext.as_deref() {
        Some("obj") => obj::load(path)?,
        Some("gltf") | Some("glb") => gltf::load_with(path, options)?,
        _ => {
            return Err(SceneError::UnknownFormat {
                path: path.to_path_buf(),
            });
        }
    };
    scene.source = path.to_path_buf();
    scene.validate()?;
    closed::mark_closed_objects(&mut scene);
    Ok(scene)
}
